#include "render/synth/renderer.h"

#include <algorithm>
#include <cmath>

#include "calib/core/error.h"
#include "calib/core/parallel.h"
#include "calib/core/random.h"

namespace nerfar::synth {

namespace {

constexpr float kPiF = static_cast<float>(kPi);
// Shadow and bounce rays start this far above the surface (metres): well below
// the 0.5 mm the tag sheets float above the table, well above float rounding
// at 1 m (about 1e-7 m).
constexpr float kRayOffset = 1e-4f;

Vec3f FacingGeometricNormal(const Hit& hit) { return hit.front ? hit.geometric_normal : -hit.geometric_normal; }

void Frame(const Vec3f& n, Vec3f& t1, Vec3f& t2) {
  const Vec3f a = std::fabs(n.x) > 0.9f ? Vec3f{0, 1, 0} : Vec3f{1, 0, 0};
  t1 = Normalized(Cross(a, n));
  t2 = Cross(n, t1);
}

float GgxD(float n_dot_h, float alpha) {
  const float a2 = alpha * alpha;
  const float d = n_dot_h * n_dot_h * (a2 - 1) + 1;
  return a2 / (kPiF * d * d);
}

float SmithG1(float n_dot_v, float alpha) {
  const float a2 = alpha * alpha;
  return 2 * n_dot_v / (n_dot_v + std::sqrt(a2 + (1 - a2) * n_dot_v * n_dot_v));
}

// BRDF value (without the cosine); n is the shading normal facing wo.
Vec3f Brdf(const SurfaceMaterial& m, const Vec3f& albedo, const Vec3f& n, const Vec3f& wo, const Vec3f& wi) {
  if (!m.glossy) return albedo * (1.0f / kPiF);
  const float n_wi = Dot(n, wi), n_wo = Dot(n, wo);
  Vec3f f = albedo * ((1.0f - m.metallic) / kPiF);
  if (n_wi <= 0 || n_wo <= 0) return f;
  const Vec3f h = Normalized(wi + wo);
  const float alpha = std::max(m.roughness * m.roughness, 1e-3f);
  const float h_wi = std::max(0.0f, Dot(h, wi));
  const float fresnel_w = std::pow(1.0f - h_wi, 5.0f);
  const Vec3f f0 = Vec3f{m.f0, m.f0, m.f0} * (1.0f - m.metallic) + albedo * m.metallic;
  const Vec3f fresnel = f0 + (Vec3f{1, 1, 1} - f0) * fresnel_w;
  const float spec =
      GgxD(std::max(0.0f, Dot(n, h)), alpha) * SmithG1(n_wi, alpha) * SmithG1(n_wo, alpha) / (4 * n_wi * n_wo);
  return f + fresnel * spec;
}

// Light arriving at a surface point from one sample of every light, each with
// a shadow ray, weighted by `brdf(wi)` and the cosine. Consumes 3 random
// numbers per light whatever happens, so paths that the inserted object does
// not touch see the same numbers with or without it.
template <typename BrdfFn>
Vec3f DirectLight(const Scene& scene, const Vec3f& point, const Vec3f& geometric_normal, const Vec3f& normal, Rng& rng,
                  BrdfFn&& brdf) {
  const Vec3f origin = point + geometric_normal * kRayOffset;
  Vec3f sum{0, 0, 0};
  const int lights = scene.LightCount();
  for (int k = 0; k < lights; ++k) {
    const float u1 = rng.Uniform(), u2 = rng.Uniform(), u3 = rng.Uniform();
    const LightSample ls = scene.SampleLight(k, point, u1, u2, u3);
    if (!(ls.pdf > 0) || (ls.radiance.x <= 0 && ls.radiance.y <= 0 && ls.radiance.z <= 0)) continue;
    const float cos_n = Dot(normal, ls.wi);
    if (cos_n <= 0 || Dot(geometric_normal, ls.wi) <= 0) continue;
    const Ray shadow{origin, ls.wi, 0.0f, std::isinf(ls.distance) ? 1e30f : ls.distance * (1.0f - 1e-4f) - kRayOffset};
    if (shadow.t_max <= 0 || scene.Occluded(shadow)) continue;
    sum += brdf(ls.wi) * ls.radiance * (cos_n / ls.pdf);
  }
  return sum;
}

// Direct light leaving a hit towards wo.
Vec3f Direct(const Scene& scene, const Hit& hit, const Vec3f& wo, Rng& rng) {
  const SurfaceMaterial& m = scene.materials[hit.material];
  const Vec3f albedo = scene.Albedo(hit);
  return DirectLight(scene, hit.point, FacingGeometricNormal(hit), hit.normal, rng,
                     [&](const Vec3f& wi) { return Brdf(m, albedo, hit.normal, wo, wi); });
}

// Samples the bounce direction; returns the weight f cos / pdf (0 if none).
Vec3f SampleBounce(const Scene& scene, const Hit& hit, const Vec3f& wo, Rng& rng, Vec3f& wi) {
  const SurfaceMaterial& m = scene.materials[hit.material];
  const Vec3f albedo = scene.Albedo(hit);
  const float u0 = rng.Uniform(), u1 = rng.Uniform(), u2 = rng.Uniform();
  Vec3f t1, t2;
  Frame(hit.normal, t1, t2);
  if (!m.glossy) {
    // Cosine-weighted: f cos / pdf = albedo.
    const float r = std::sqrt(u1), phi = 2 * kPiF * u2;
    wi = t1 * (r * std::cos(phi)) + t2 * (r * std::sin(phi)) + hit.normal * std::sqrt(std::max(0.0f, 1 - u1));
    return albedo;
  }
  // Glossy: one-sample mixture of cosine and GGX half-vector sampling (equal odds).
  const float alpha = std::max(m.roughness * m.roughness, 1e-3f);
  if (u0 < 0.5f) {
    const float r = std::sqrt(u1), phi = 2 * kPiF * u2;
    wi = t1 * (r * std::cos(phi)) + t2 * (r * std::sin(phi)) + hit.normal * std::sqrt(std::max(0.0f, 1 - u1));
  } else {
    const float cos_h = std::sqrt((1 - u1) / (1 + (alpha * alpha - 1) * u1));
    const float sin_h = std::sqrt(std::max(0.0f, 1 - cos_h * cos_h)), phi = 2 * kPiF * u2;
    const Vec3f h = t1 * (sin_h * std::cos(phi)) + t2 * (sin_h * std::sin(phi)) + hit.normal * cos_h;
    wi = h * (2 * Dot(wo, h)) - wo;
  }
  wi = Normalized(wi);
  const float cos_n = Dot(hit.normal, wi);
  if (cos_n <= 0) return {0, 0, 0};
  const Vec3f h = Normalized(wi + wo);
  const float pdf_diffuse = cos_n / kPiF;
  const float pdf_spec = GgxD(std::max(0.0f, Dot(hit.normal, h)), alpha) * std::max(0.0f, Dot(hit.normal, h)) /
                         (4 * std::max(1e-8f, Dot(wo, h)));
  const float pdf = 0.5f * (pdf_diffuse + pdf_spec);
  if (!(pdf > 0)) return {0, 0, 0};
  return Brdf(m, albedo, hit.normal, wo, wi) * (cos_n / pdf);
}

// Radiance leaving a (non-emitting) hit towards wo.
Vec3f Shade(const Scene& scene, const Hit& hit, const Vec3f& wo, Rng& rng, bool bounce) {
  Vec3f l = Direct(scene, hit, wo, rng);
  if (!bounce) return l;
  Vec3f wi;
  const Vec3f weight = SampleBounce(scene, hit, wo, rng, wi);
  if (weight.x <= 0 && weight.y <= 0 && weight.z <= 0) return l;
  Hit next;
  const Ray ray{
      hit.point + FacingGeometricNormal(hit) * kRayOffset * (Dot(wi, FacingGeometricNormal(hit)) < 0 ? -1.0f : 1.0f),
      wi, 0.0f, 1e30f};
  // Emitters and the environment met by the bounce ray were counted by NEE.
  if (!scene.Intersect(ray, next)) return l;
  const SurfaceMaterial& m = scene.materials[next.material];
  if (m.emission.x > 0 || m.emission.y > 0 || m.emission.z > 0) return l;
  return l + weight * Direct(scene, next, -wi, rng);
}

// Radiance along a ray: emission where it meets an emitter, shading otherwise, 0 on a miss.
Vec3f TraceRadiance(const Scene& scene, const Ray& ray, Rng& rng, bool bounce, bool environment_on_miss) {
  Hit hit;
  if (!scene.Intersect(ray, hit)) return environment_on_miss ? scene.EnvironmentRadiance(ray.dir) : Vec3f{0, 0, 0};
  const SurfaceMaterial& m = scene.materials[hit.material];
  if (m.emission.x > 0 || m.emission.y > 0 || m.emission.z > 0) return scene.Emission(hit);
  return Shade(scene, hit, -ray.dir, rng, bounce);
}

void StratifiedSample(int k, int spp, int side, Rng& rng, float& sx, float& sy) {
  const float r1 = rng.Uniform(), r2 = rng.Uniform();
  if (side * side == spp) {
    sx = (static_cast<float>(k % side) + r1) / side;
    sy = (static_cast<float>(k / side) + r2) / side;
  } else {
    sx = r1;
    sy = r2;
  }
}

int SquareSide(int spp) {
  int side = static_cast<int>(std::lround(std::sqrt(static_cast<double>(spp))));
  return side * side == spp ? side : 0;
}

Ray CameraRay(const CameraIntrinsics& camera, const Pose& T_world_camera, double x, double y) {
  const Vec3 d_cam{(x - camera.cx) / camera.fx, (y - camera.cy) / camera.fy, 1.0};
  const Vec3 d = Normalized(T_world_camera.rotation * d_cam);
  return {Vec3f(T_world_camera.translation), Vec3f(d), 0.0f, 1e30f};
}

}  // namespace

std::vector<std::string> RenderOptions::Validate() const {
  std::vector<std::string> problems;
  if (spp < 1 || spp > 1 << 16) problems.push_back("spp: " + std::to_string(spp) + " (expected 1..65536)");
  return problems;
}

ImageF RenderView(const Scene& scene, const CameraIntrinsics& camera, const Pose& T_world_camera,
                  const RenderOptions& options, uint64_t stream) {
  NERFAR_CHECK(scene.built());
  NERFAR_CHECK(options.Validate().empty());
  NERFAR_CHECK(camera.width > 0 && camera.height > 0);
  ImageF image(camera.width, camera.height, 3);
  const int side = SquareSide(options.spp);
  const size_t count = image.PixelCount();
  ParallelFor(
      count,
      [&](size_t index) {
        const int x = static_cast<int>(index % camera.width), y = static_cast<int>(index / camera.width);
        Vec3 sum{0, 0, 0};
        for (int k = 0; k < options.spp; ++k) {
          Rng rng(options.seed, stream, index, static_cast<uint64_t>(k));
          float sx, sy;
          StratifiedSample(k, options.spp, side, rng, sx, sy);
          const Ray ray = CameraRay(camera, T_world_camera, x + sx, y + sy);
          sum += Vec3(TraceRadiance(scene, ray, rng, options.bounce, false));
        }
        float* p = image.Pixel(x, y);
        p[0] = static_cast<float>(sum.x / options.spp);
        p[1] = static_cast<float>(sum.y / options.spp);
        p[2] = static_cast<float>(sum.z / options.spp);
      },
      256);
  return image;
}

void RenderFirstHit(const Scene& scene, const CameraIntrinsics& camera, const Pose& T_world_camera, int object_id,
                    ImageF& depth, Image8& mask) {
  NERFAR_CHECK(scene.built());
  depth = ImageF(camera.width, camera.height, 1, 0.0f);
  mask = Image8(camera.width, camera.height, 1, 0);
  const Vec3 forward = T_world_camera.rotation.Column(2);
  ParallelFor(
      depth.PixelCount(),
      [&](size_t index) {
        const int x = static_cast<int>(index % camera.width), y = static_cast<int>(index / camera.width);
        const Ray ray = CameraRay(camera, T_world_camera, x + 0.5, y + 0.5);
        Hit hit;
        if (!scene.Intersect(ray, hit)) return;
        depth.at(x, y) = static_cast<float>(hit.t * Dot(Vec3(ray.dir), forward));
        if (object_id >= 0 && hit.object_id == object_id) mask.at(x, y) = 255;
      },
      256);
}

ImageF RenderProbe(const Scene& scene, const Vec3& point, int width, int height, const RenderOptions& options) {
  NERFAR_CHECK(scene.built());
  NERFAR_CHECK(width > 0 && height > 0);
  ImageF image(width, height, 3);
  const int side = SquareSide(options.spp);
  const Vec3f origin(point);
  ParallelFor(
      image.PixelCount(),
      [&](size_t index) {
        const int i = static_cast<int>(index % width), j = static_cast<int>(index / width);
        Vec3 sum{0, 0, 0};
        for (int k = 0; k < options.spp; ++k) {
          Rng rng(options.seed, ~uint64_t{0}, index, static_cast<uint64_t>(k));
          float sx, sy;
          StratifiedSample(k, options.spp, side, rng, sx, sy);
          const Vec3f d(EquirectDirection((i + sx) / width, (j + sy) / height));
          sum += Vec3(TraceRadiance(scene, Ray{origin, d, 0.0f, 1e30f}, rng, options.bounce, true));
        }
        float* p = image.Pixel(i, j);
        p[0] = static_cast<float>(sum.x / options.spp);
        p[1] = static_cast<float>(sum.y / options.spp);
        p[2] = static_cast<float>(sum.z / options.spp);
      },
      64);
  return image;
}

ImageF RenderEnvironment(const Scene& scene, int width, int height, int supersample) {
  NERFAR_CHECK(width > 0 && height > 0 && supersample > 0);
  ImageF image(width, height, 3, 0.0f);
  if (!scene.environment.Present()) return image;
  ParallelFor(image.PixelCount(), [&](size_t index) {
    const int i = static_cast<int>(index % width), j = static_cast<int>(index / width);
    Vec3 sum{0, 0, 0};
    for (int a = 0; a < supersample; ++a)
      for (int b = 0; b < supersample; ++b) {
        const Vec3 d = EquirectDirection((i + (b + 0.5) / supersample) / width, (j + (a + 0.5) / supersample) / height);
        sum += Vec3(scene.EnvironmentRadiance(Vec3f(d)));
      }
    const double n = static_cast<double>(supersample) * supersample;
    float* p = image.Pixel(i, j);
    p[0] = static_cast<float>(sum.x / n);
    p[1] = static_cast<float>(sum.y / n);
    p[2] = static_cast<float>(sum.z / n);
  });
  return image;
}

Vec3f EstimateIrradiance(const Scene& scene, const Vec3f& point, const Vec3f& normal, int samples,
                         const RenderOptions& options, uint64_t stream) {
  NERFAR_CHECK(scene.built());
  NERFAR_CHECK_GT(samples, 0);
  const Vec3f n = Normalized(normal);
  Vec3 sum{0, 0, 0};
  for (int k = 0; k < samples; ++k) {
    Rng rng(options.seed, stream, 0, static_cast<uint64_t>(k));
    // E = integral of L cos: the direct estimator with brdf = 1.
    Vec3f e = DirectLight(scene, point, n, n, rng, [](const Vec3f&) { return Vec3f{1, 1, 1}; });
    if (options.bounce) {
      Vec3f t1, t2;
      Frame(n, t1, t2);
      const float u1 = rng.Uniform(), u2 = rng.Uniform();
      const float r = std::sqrt(u1), phi = 2 * kPiF * u2;
      const Vec3f wi =
          Normalized(t1 * (r * std::cos(phi)) + t2 * (r * std::sin(phi)) + n * std::sqrt(std::max(0.0f, 1 - u1)));
      Hit next;
      if (scene.Intersect(Ray{point + n * kRayOffset, wi, 0.0f, 1e30f}, next)) {
        const SurfaceMaterial& m = scene.materials[next.material];
        // Cosine-weighted direction: L cos / pdf = pi L.
        if (m.emission.x <= 0 && m.emission.y <= 0 && m.emission.z <= 0) e += Direct(scene, next, -wi, rng) * kPiF;
      }
    }
    sum += Vec3(e);
  }
  return Vec3f(sum / static_cast<double>(samples));
}

}  // namespace nerfar::synth
