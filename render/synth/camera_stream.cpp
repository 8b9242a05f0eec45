#include "render/synth/camera_stream.h"

#include <algorithm>
#include <cmath>

#include "calib/core/error.h"
#include "calib/core/image_io.h"
#include "calib/core/parallel.h"
#include "calib/core/random.h"
#include "render/synth/renderer.h"
#include "render/synth/scenes.h"
#include "render/synth/writer.h"

namespace nerfar::synth {

namespace {

constexpr double kDeg = kPi / 180.0;
constexpr double kGridM = 0.005;  // baked irradiance grid spacing on the table top
constexpr int kBakeSamples = 16;  // light samples per grid point (noise ~ 1/4 of one sample)

}  // namespace

std::vector<std::string> CameraStreamOptions::Validate() const {
  std::vector<std::string> p;
  if (width < 16 || width > 8192 || height < 16 || height > 8192)
    p.push_back("size: " + std::to_string(width) + "x" + std::to_string(height) + " (expected 16..8192 each)");
  if (!(hfov_deg > 5 && hfov_deg < 170)) p.push_back("hfov_deg: " + std::to_string(hfov_deg) + " (expected 5..170)");
  if (!(fps > 0 && fps <= 1000)) p.push_back("fps: " + std::to_string(fps) + " (expected (0, 1000])");
  if (frames < 0) p.push_back("frames: " + std::to_string(frames) + " (expected >= 0)");
  if (samples_per_pixel < 1 || samples_per_pixel > 256)
    p.push_back("samples_per_pixel: " + std::to_string(samples_per_pixel) + " (expected 1..256)");
  if (!(noise_sigma >= 0 && noise_sigma <= 100))
    p.push_back("noise_sigma: " + std::to_string(noise_sigma) + " (expected 0..100)");
  if (!(shutter_s >= 0 && shutter_s <= 1)) p.push_back("shutter_s: " + std::to_string(shutter_s) + " (expected 0..1)");
  if (!(exposure_variation >= 0 && exposure_variation <= 0.9))
    p.push_back("exposure_variation: " + std::to_string(exposure_variation) + " (expected 0..0.9)");
  if (!(speed > 0 && speed <= 100)) p.push_back("speed: " + std::to_string(speed) + " (expected (0, 100])");
  return p;
}

struct SyntheticCameraSource::Impl {
  CameraStreamOptions options;
  SynthScene synth;
  CameraIntrinsics camera;
  int grid_w = 0, grid_h = 0;
  std::vector<Vec3f> irradiance;  // on the table-top grid, row-major
  double exposure = 1;            // base exposure scale before tone mapping
  double phase[16] = {};
  int64_t next_index = 0;

  Vec3f TableIrradiance(float x, float y) const {
    const float gx = std::clamp((x + 0.6f) / static_cast<float>(kGridM), 0.0f, grid_w - 1.001f);
    const float gy = std::clamp((y + 0.4f) / static_cast<float>(kGridM), 0.0f, grid_h - 1.001f);
    const int ix = static_cast<int>(gx), iy = static_cast<int>(gy);
    const float fx = gx - ix, fy = gy - iy;
    auto at = [&](int i, int j) { return irradiance[static_cast<size_t>(j) * grid_w + i]; };
    return (at(ix, iy) * (1 - fx) + at(ix + 1, iy) * fx) * (1 - fy) +
           (at(ix, iy + 1) * (1 - fx) + at(ix + 1, iy + 1) * fx) * fy;
  }
};

SyntheticCameraSource::SyntheticCameraSource(const CameraStreamOptions& options) : impl_(std::make_unique<Impl>()) {
  {
    Problems problems("synthetic camera");
    for (const std::string& p : options.Validate()) problems.Add("", p);
    problems.ThrowIfAny();
  }
  Impl& m = *impl_;
  m.options = options;
  m.synth = MakeSynthScene(options.scene, options.seed);
  m.camera = SynthCamera(options.width, options.height);
  m.camera.fx = m.camera.fy = 0.5 * options.width / std::tan(0.5 * options.hfov_deg * kDeg);
  Rng rng(options.seed, 0x57a3, 0, 0);
  for (double& p : m.phase) p = rng.Uniform(0, 2 * kPi);
  // Bake the direct irradiance of the table top (shadows of every object included).
  m.grid_w = static_cast<int>(std::lround(1.2 / kGridM)) + 1;
  m.grid_h = static_cast<int>(std::lround(0.8 / kGridM)) + 1;
  m.irradiance.assign(static_cast<size_t>(m.grid_w) * m.grid_h, Vec3f{0, 0, 0});
  RenderOptions bake;
  bake.seed = options.seed;
  ParallelFor(
      m.irradiance.size(),
      [&](size_t i) {
        const float x = static_cast<float>(-0.6 + kGridM * static_cast<double>(i % m.grid_w));
        const float y = static_cast<float>(-0.4 + kGridM * static_cast<double>(i / m.grid_w));
        m.irradiance[i] =
            EstimateIrradiance(m.synth.scene, {x, y, static_cast<float>(kTagSheetZ)}, {0, 0, 1}, kBakeSamples, bake, i);
      },
      64);
  // Exposure: paper under the median table irradiance shows at 0.6 after Reinhard.
  std::vector<float> lum;
  for (const Vec3f& e : m.irradiance) lum.push_back(0.2126f * e.x + 0.7152f * e.y + 0.0722f * e.z);
  std::nth_element(lum.begin(), lum.begin() + lum.size() / 2, lum.end());
  const double paper = kPaperAlbedo * std::max(1e-6f, lum[lum.size() / 2]) / kPi;
  m.exposure = 1.5 / paper;
}

SyntheticCameraSource::~SyntheticCameraSource() = default;

std::string SyntheticCameraSource::Describe() const {
  const CameraStreamOptions& o = impl_->options;
  return "synthetic:" + o.scene + " " + std::to_string(o.width) + "x" + std::to_string(o.height) + " seed " +
         std::to_string(o.seed);
}

const CameraIntrinsics& SyntheticCameraSource::camera() const { return impl_->camera; }
const Board& SyntheticCameraSource::board() const { return impl_->synth.board; }

Pose SyntheticCameraSource::PoseAt(double t_s) const {
  const double* p = impl_->phase;
  const double t = t_s * impl_->options.speed;
  // Slow orbit with wandering elevation, distance and aim, plus a little roll
  // and hand tremor: smooth (every derivative continuous), seeded phases.
  const double azimuth = p[0] + 0.25 * t + 0.3 * std::sin(0.31 * t + p[1]);
  const double elevation = (48 + 14 * std::sin(0.23 * t + p[2]) + 4 * std::sin(0.71 * t + p[3])) * kDeg;
  const double distance = 0.85 + 0.12 * std::sin(0.17 * t + p[4]) + 0.04 * std::sin(0.53 * t + p[5]);
  const Vec3 target{0.08 * std::sin(0.2 * t + p[6]), 0.05 * std::sin(0.27 * t + p[7]), 0.0};
  const Vec3 tremor{0.002 * std::sin(9.1 * t + p[8]), 0.002 * std::sin(7.3 * t + p[9]),
                    0.0015 * std::sin(8.2 * t + p[10])};
  const Vec3 eye =
      target +
      Vec3{std::cos(elevation) * std::cos(azimuth), std::cos(elevation) * std::sin(azimuth), std::sin(elevation)} *
          distance +
      tremor;
  Pose pose = LookAt(eye, target);
  const double roll = (3 * std::sin(0.4 * t + p[11]) + 0.4 * std::sin(6.1 * t + p[12])) * kDeg;
  const Vec3 wobble{0.3 * kDeg * std::sin(5.3 * t + p[13]), 0.3 * kDeg * std::sin(6.7 * t + p[14]), roll};
  pose.rotation = pose.rotation * RotationFromAxisAngle(wobble, Length(wobble));
  return pose;
}

Frame SyntheticCameraSource::RenderFrame(double t_s, int64_t index) const {
  const Impl& m = *impl_;
  const CameraStreamOptions& o = m.options;
  const int spp = o.samples_per_pixel;
  // One pose per sample slot across the shutter (all equal without blur).
  std::vector<Pose> poses(spp);
  for (int s = 0; s < spp; ++s)
    poses[s] = PoseAt(t_s + (o.shutter_s > 0 ? ((s + 0.5) / spp - 0.5) * o.shutter_s : 0.0));
  const double exposure = m.exposure * (1 + o.exposure_variation * std::sin(2 * kPi * t_s / 5.0 + m.phase[15]));
  const int side = static_cast<int>(std::lround(std::sqrt(static_cast<double>(spp))));
  const bool square = side * side == spp;
  const Scene& scene = m.synth.scene;
  RenderOptions light;
  light.seed = o.seed;
  ImageF linear(o.width, o.height, 3);
  ParallelFor(
      linear.PixelCount(),
      [&](size_t index_px) {
        const int x = static_cast<int>(index_px % o.width), y = static_cast<int>(index_px / o.width);
        Rng rng(o.seed, 0x5eed0000ull + static_cast<uint64_t>(index), index_px, 0);
        Vec3f sum{0, 0, 0};
        for (int s = 0; s < spp; ++s) {
          float sx = rng.Uniform(), sy = rng.Uniform();
          if (square) sx = (s % side + sx) / side, sy = (s / side + sy) / side;
          const Pose& pose = poses[s];
          const Vec3 d_cam{(x + sx - m.camera.cx) / m.camera.fx, (y + sy - m.camera.cy) / m.camera.fy, 1.0};
          const Ray ray{Vec3f(pose.translation), Vec3f(Normalized(pose.rotation * d_cam)), 0.0f, 1e30f};
          Hit hit;
          if (!scene.Intersect(ray, hit)) continue;
          const SurfaceMaterial& mat = scene.materials[hit.material];
          if (mat.emission.x > 0 || mat.emission.y > 0 || mat.emission.z > 0) {
            sum += scene.Emission(hit);
          } else if (mat.texture >= 0 && hit.point.z > -1e-4f && hit.normal.z > 0.99f) {
            // Table top or tag sheet: exact albedo, baked light.
            sum += scene.Albedo(hit) * m.TableIrradiance(hit.point.x, hit.point.y) * (1.0f / static_cast<float>(kPi));
          } else {
            // Other surfaces: one light sample each, with shadows.
            const Vec3f e = EstimateIrradiance(scene, hit.point + hit.normal * 1e-4f, hit.normal, 1, light,
                                               Mix64(static_cast<uint64_t>(index)) ^ (index_px * spp + s));
            sum += scene.Albedo(hit) * e * (1.0f / static_cast<float>(kPi));
          }
        }
        float* p = linear.Pixel(x, y);
        for (int c = 0; c < 3; ++c) p[c] = sum[c] / spp;
      },
      256);
  Frame frame;
  frame.image = ToneMapToDisplay(linear, static_cast<float>(exposure));
  if (o.noise_sigma > 0) {
    ParallelFor(
        frame.image.PixelCount(),
        [&](size_t i) {
          Rng rng(o.seed, 0x4015e00ull + static_cast<uint64_t>(index), i, 1);
          for (int c = 0; c < frame.image.channels; ++c) {
            uint8_t& v = frame.image.pixels[i * frame.image.channels + c];
            v = static_cast<uint8_t>(std::clamp(std::lround(v + o.noise_sigma * rng.Normal()), 0L, 255L));
          }
        },
        1024);
  }
  if (o.grayscale) frame.image = ToGray(frame.image);
  frame.index = index;
  frame.t_ns = static_cast<int64_t>(std::llround(t_s * 1e9));
  frame.T_world_camera_true = PoseAt(t_s);
  return frame;
}

FrameStatus SyntheticCameraSource::Next(Frame& frame, int /*timeout_ms*/) {
  Impl& m = *impl_;
  if (m.options.frames > 0 && m.next_index >= m.options.frames) return FrameStatus::kEndOfStream;
  const int64_t index = m.next_index++;
  frame = RenderFrame(static_cast<double>(index) / m.options.fps, index);
  return FrameStatus::kOk;
}

}  // namespace nerfar::synth
