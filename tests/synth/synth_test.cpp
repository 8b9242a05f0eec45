// render/synth: the renderer against exact references (SG irradiance, sphere
// and rectangle lights on a Lambertian plane, the probe of analytic lights),
// the references against brute-force quadrature, determinism across thread
// counts, the tag mat against an independent detector (OpenCV aruco, the
// corner convention of board.json), the scene writer against the project's
// readers, and the synthetic camera stream.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <opencv2/aruco.hpp>
#include <opencv2/imgproc.hpp>

#include "calib/board.h"
#include "calib/core/exr.h"
#include "calib/core/image_io.h"
#include "calib/core/parallel.h"
#include "calib/dataset.h"
#include "calib/object.h"
#include "render/mesh/mesh.h"
#include "render/synth/camera_stream.h"
#include "render/synth/reference.h"
#include "render/synth/renderer.h"
#include "render/synth/scenes.h"
#include "render/synth/writer.h"
#include "tests/support/support.h"

namespace nerfar::synth {
namespace {

constexpr double kAlbedo = 0.5;

// A white-ish Lambertian plane z = 0, 100 m wide (effectively infinite for
// the lights used here), and a camera 1 m above the origin looking down.
Scene PlaneScene() {
  Scene scene;
  SurfaceMaterial m;
  m.albedo = {static_cast<float>(kAlbedo), static_cast<float>(kAlbedo), static_cast<float>(kAlbedo)};
  scene.rectangles.push_back({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, 50.0f, 50.0f, scene.AddMaterial(m), -1});
  return scene;
}

Pose TopDownCamera() { return LookAt({0, 0, 1}, {0, 0, 0}); }

// World point where the centre ray of pixel (x, y) meets z = 0.
Vec3 PlanePoint(const CameraIntrinsics& camera, const Pose& pose, double x, double y) {
  const Vec3 d = pose.rotation * Vec3{(x - camera.cx) / camera.fx, (y - camera.cy) / camera.fy, 1.0};
  const double t = -pose.translation.z / d.z;
  return pose.translation + d * t;
}

struct Residuals {
  double mean = 0, sigma_of_mean = 0, rms_relative = 0;
};

// Residuals of a rendered plane against a per-pixel reference radiance.
template <typename Reference>
Residuals CompareToReference(const ImageF& image, const CameraIntrinsics& camera, const Pose& pose, Reference&& ref,
                             int channel) {
  std::vector<double> r;
  double rel2 = 0;
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x) {
      const double expected = ref(PlanePoint(camera, pose, x + 0.5, y + 0.5))[channel];
      const double diff = image.at(x, y, channel) - expected;
      r.push_back(diff / expected);
      rel2 += (diff / expected) * (diff / expected);
    }
  Residuals out;
  for (double v : r) out.mean += v;
  out.mean /= r.size();
  double var = 0;
  for (double v : r) var += (v - out.mean) * (v - out.mean);
  out.sigma_of_mean = std::sqrt(var / (r.size() - 1) / r.size());
  out.rms_relative = std::sqrt(rel2 / r.size());
  return out;
}

TEST(SynthReference, SgIrradianceMatchesBruteForceQuadrature) {
  // Brute force: midpoint rule on a 2000 x 4000 (theta, phi) grid around the
  // lobe axis; its error is below 1e-5 relative for lambda <= 200 (the lobe
  // spans >= 30 cells), so 1e-4 is a safe bound.
  for (double lambda : {0.01, 1.0, 10.0, 200.0}) {
    for (double angle_deg : {0.0, 30.0, 80.0, 95.0, 150.0}) {
      const double alpha = angle_deg * kPi / 180;
      const Vec3 n{std::sin(alpha), 0, std::cos(alpha)};
      const int nt = 2000, np = 4000;
      double brute = 0;
      const double theta_max = std::min(kPi, 40.0 / std::sqrt(lambda));  // lobe < e^-800 beyond
      for (int i = 0; i < nt; ++i) {
        const double theta = (i + 0.5) * theta_max / nt;
        const double lobe = std::exp(lambda * (std::cos(theta) - 1));
        double ring = 0;
        for (int j = 0; j < np; ++j) {
          const double phi = (j + 0.5) * 2 * kPi / np;
          const Vec3 w{std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
          ring += std::max(0.0, Dot(n, w));
        }
        brute += lobe * ring * std::sin(theta);
      }
      brute *= (theta_max / nt) * (2 * kPi / np);
      const double exact = SgLobeIrradiance(lambda, std::cos(alpha));
      EXPECT_NEAR(exact, brute, 1e-4 * std::max(brute, 1e-3 * 2 * kPi / lambda))
          << "lambda " << lambda << " angle " << angle_deg;
    }
  }
}

TEST(SynthReference, SgIrradianceLimits) {
  // lambda -> 0: the lobe is 1 everywhere, E = pi (to O(lambda)).
  EXPECT_NEAR(SgLobeIrradiance(1e-4, 0.3), kPi, 1e-3) << "uniform sky";
  // lambda large, axis along the normal: E -> sphere integral 2 pi / lambda (1 - 1/lambda): exact to O(1/lambda^2).
  const double lambda = 1e4;
  EXPECT_NEAR(SgLobeIrradiance(lambda, 1.0) * lambda / (2 * kPi), 1 - 1 / lambda, 1e-6) << "narrow lobe on the normal";
  // Narrow lobe below the horizon: nothing.
  EXPECT_NEAR(SgLobeIrradiance(lambda, -0.5), 0.0, 1e-12);
  // Finite over the whole range of DESIGN.md.
  for (double l : {1e-4, 1e-2, 1.0, 1e2, 1e4})
    for (double c : {-1.0, -0.01, 0.0, 0.01, 1.0}) EXPECT_TRUE(std::isfinite(SgLobeIrradiance(l, c)));
}

TEST(SynthReference, RectangleIrradianceMatchesSphereLimitFarAway) {
  // A tiny rectangle far away is a point source: E = L A cos_light cos / d^2.
  RectangleLight l{{0.3f, 0.1f, 5.0f}, {1, 0, 0}, {0, -1, 0}, 0.005f, 0.005f, {2, 2, 2}, false};
  const Vec3 p{0, 0, 0};
  const Vec3 e = RectangleLightIrradiance(l, p, {0, 0, 1});
  const Vec3 to = Vec3(l.center) - p;
  const double d = Length(to), c = to.z / d;
  const double expected = 2 * 0.01 * 0.01 * c * c / (d * d);
  EXPECT_NEAR(e.x / expected, 1.0, 1e-5) << "point-source limit (error O((size/d)^2) = 1e-6)";
  // Behind a one-sided emitter: nothing.
  l.v_axis = {0, 1, 0};
  EXPECT_EQ(RectangleLightIrradiance(l, p, {0, 0, 1}).x, 0.0);
}

TEST(SynthRender, PlaneUnderEnvironmentSgsMatchesClosedForm) {
  Scene scene = PlaneScene();
  scene.environment.lobes = {{Vec3f(Normalized(Vec3{0.3, 0.2, 0.93})), 5.0f, {2.0f, 1.5f, 1.0f}},
                             {Vec3f(Normalized(Vec3{1, 0, 0.2})), 30.0f, {10.0f, 10.0f, 10.0f}},
                             {{0, 0, -1}, 2.0f, {1.0f, 1.0f, 1.0f}}};
  scene.Build();
  const CameraIntrinsics camera = SynthCamera(32, 24);
  RenderOptions options;
  options.spp = 64;
  const ImageF image = RenderView(scene, camera, TopDownCamera(), options, 0);
  const Vec3 e = SgIrradiance(scene.environment.lobes, {0, 0, 1});
  for (int c = 0; c < 3; ++c) {
    const Residuals r = CompareToReference(
        image, camera, TopDownCamera(), [&](const Vec3&) { return e * (kAlbedo / kPi); }, c);
    // Unbiased estimator: the mean residual is within 5 standard errors (from
    // the pixels' own spread, 768 pixels x 64 samples) plus 1e-4 for float sums.
    EXPECT_LT(std::fabs(r.mean), 5 * r.sigma_of_mean + 1e-4) << "channel " << c << " sigma " << r.sigma_of_mean;
    // Loose sanity bound on the per-pixel noise (measured about 0.15 at 64 spp).
    EXPECT_LT(r.rms_relative, 0.3) << "per-pixel noise at 64 spp";
  }
}

TEST(SynthRender, PlaneUnderSmallSphereLightMatchesClosedForm) {
  Scene scene = PlaneScene();
  const SphereLight light{{0.6f, 0.1f, 0.4f}, 0.01f, {1000, 800, 600}};  // outside the view
  scene.AddSphereLight(light);
  scene.Build();
  const CameraIntrinsics camera = SynthCamera(48, 36);
  RenderOptions options;
  options.spp = 4;
  const ImageF image = RenderView(scene, camera, TopDownCamera(), options, 0);
  // Point-light limit (exact for a sphere above the horizon): a L r^2 cos / d^2 / ... = a/pi * pi L (r/d)^2 cos.
  auto ref = [&](const Vec3& p) { return SphereLightIrradiance(light, p, {0, 0, 1}) * (kAlbedo / kPi); };
  for (int c = 0; c < 3; ++c) {
    const Residuals r = CompareToReference(image, camera, TopDownCamera(), ref, c);
    // Cone sampling of a light 1/40 rad wide: cos varies by < 2% inside the cone, and
    // the box filter over a pixel (~1.5 cm on the plane, light 0.5 m away) moves the
    // mean by < 0.1%: every pixel within 1%, the mean within 0.2%.
    EXPECT_LT(r.rms_relative, 0.01) << "channel " << c;
    EXPECT_LT(std::fabs(r.mean), 0.002) << "channel " << c;
  }
}

TEST(SynthRender, PlaneUnderRectangleLightMatchesLambertFormula) {
  Scene scene = PlaneScene();
  const Vec3 n = Normalized(Vec3{0.5, -0.2, -0.5});
  const Vec3 v = Normalized(Vec3{0, 0, 1} - n * n.z), u = Cross(v, n);
  const RectangleLight light{{-0.5f, 0.2f, 0.5f}, Vec3f(u), Vec3f(v), 0.1f, 0.05f, {50, 40, 30}, false};
  scene.AddRectangleLight(light);
  scene.Build();
  const CameraIntrinsics camera = SynthCamera(32, 24);
  RenderOptions options;
  options.spp = 64;
  const ImageF image = RenderView(scene, camera, TopDownCamera(), options, 0);
  auto ref = [&](const Vec3& p) { return RectangleLightIrradiance(light, p, {0, 0, 1}) * (kAlbedo / kPi); };
  for (int c = 0; c < 3; ++c) {
    const Residuals r = CompareToReference(image, camera, TopDownCamera(), ref, c);
    // Unbiased area sampling: mean within 5 standard errors, plus 0.3% for
    // evaluating the reference at pixel centres instead of over the pixel box.
    EXPECT_LT(std::fabs(r.mean), 5 * r.sigma_of_mean + 0.003) << "channel " << c;
    EXPECT_LT(r.rms_relative, 0.1) << "per-pixel noise at 64 spp";
  }
}

TEST(SynthRender, ProbeOfAnalyticLightsMatchesReference) {
  Scene scene;
  scene.AddSphereLight({{0.3f, 0.1f, 0.2f}, 0.05f, {100, 90, 80}});
  // Normal u x v = (1,0,0) x (0,0,-1) = +y: facing the probe point.
  scene.AddRectangleLight({{-0.2f, -0.3f, 0.1f}, {1, 0, 0}, {0, 0, -1}, 0.1f, 0.08f, {20, 30, 40}, false});
  scene.environment.lobes = {{Vec3f(Normalized(Vec3{0.2, 0.5, 0.8})), 8.0f, {3.0f, 2.0f, 1.0f}}};
  scene.Build();
  const Vec3 point{0, 0, 0.05};
  RenderOptions options;
  options.spp = 16;
  const int w = 128, h = 64;
  const ImageF probe = RenderProbe(scene, point, w, h, options);
  const ImageF ref = ReferenceProbe(scene, point, w, h, 8);
  // Flux through the sphere (sum of radiance x pixel solid angle): pixels on
  // light edges differ (jittered vs regular sub-directions) but their sum is
  // unbiased; 64x64... sub-samples on ~100 edge pixels keep it within 1%.
  double flux = 0, flux_ref = 0, abs_diff = 0;
  for (int j = 0; j < h; ++j) {
    const double solid = (2 * kPi / w) * (std::cos(kPi * j / h) - std::cos(kPi * (j + 1) / h));
    for (int i = 0; i < w; ++i) {
      flux += probe.at(i, j, 0) * solid;
      flux_ref += ref.at(i, j, 0) * solid;
      abs_diff += std::fabs(probe.at(i, j, 0) - ref.at(i, j, 0)) * solid;
    }
  }
  EXPECT_NEAR(flux / flux_ref, 1.0, 0.01);
  // Interior pixels agree exactly up to float rounding: the L1 difference is
  // dominated by edge pixels (< 5% of the flux).
  EXPECT_LT(abs_diff / flux_ref, 0.05);
  double u, v;
  EquirectCoordinates(Normalized(Vec3{-0.2, -0.3, 0.1} - point), u, v);
  EXPECT_NEAR(probe.at(static_cast<int>(u * w), static_cast<int>(v * h), 2), 40.0f, 1e-3) << "panel seen directly";
  EquirectCoordinates(Normalized(Vec3{0.3, 0.1, 0.2} - point), u, v);
  EXPECT_NEAR(probe.at(static_cast<int>(u * w), static_cast<int>(v * h), 0), 100.0f, 1e-3) << "bulb seen directly";
}

TEST(SynthRender, DeterministicAcrossThreadCounts) {
  const SynthScene synth = MakeSynthScene("lamps", 3);
  const CameraIntrinsics camera = SynthCamera(64, 48);
  const std::vector<Pose> poses = HemisphereCameras(2, 3, 1, synth.aabb);
  RenderOptions options;
  options.spp = 4;
  options.bounce = true;
  const int before = ThreadCount();
  SetThreadCount(1);
  const ImageF one = RenderView(synth.scene, camera, poses[0], options, 7);
  SetThreadCount(2);
  const ImageF two = RenderView(synth.scene, camera, poses[0], options, 7);
  SetThreadCount(before);
  ASSERT_EQ(one.pixels.size(), two.pixels.size());
  EXPECT_TRUE(one.pixels == two.pixels) << "bit-identical with 1 and 2 threads";
  double sum = 0;
  for (float v : one.pixels) sum += v;
  EXPECT_GT(sum, 0.0) << "the scene is lit";
}

TEST(SynthScenes, BoardMatchesTheSharedLayout) {
  const Board board = MakeTagBoard();
  ASSERT_EQ(board.tags.size(), 12u);
  for (const BoardTag& tag : board.tags) {
    // Up points away from the table centre; corners TL, TR, BR, BL read upright:
    // TL - BL is along up, TR - TL along right = up x z.
    EXPECT_GT(Dot(tag.up_direction, Vec3{tag.center.x, tag.center.y, 0}), 0.0) << "tag " << tag.id;
    const Vec3 right = Cross(tag.up_direction, Vec3{0, 0, 1});
    EXPECT_NEAR(Dot(tag.corners[0] - tag.corners[3], tag.up_direction), kTagSize, 1e-12);
    EXPECT_NEAR(Dot(tag.corners[1] - tag.corners[0], right), kTagSize, 1e-12);
    EXPECT_NEAR(Dot(tag.corners[2] - tag.corners[3], right), kTagSize, 1e-12);
  }
  NERFAR_REQUIRE_SHARED_SCENES(scenes);
  const Board shared = ReadBoard(scenes + "/lamps/board.json");
  ASSERT_EQ(shared.tags.size(), board.tags.size());
  for (size_t k = 0; k < board.tags.size(); ++k) {
    EXPECT_EQ(shared.tags[k].id, board.tags[k].id);
    for (int c = 0; c < 4; ++c)
      EXPECT_LT(Length(shared.tags[k].corners[c] - board.tags[k].corners[c]), 1e-6) << "tag " << k << " corner " << c;
  }
}

// Renders the mat from above and detects the tags with OpenCV's aruco
// (DICT_APRILTAG_36h11, whose corner order board.json follows): every tag is
// found with its id, and each detected corner lies on the projection of the
// board corner with the same index.
TEST(SynthScenes, TagsDetectedWithBoardCornerOrder) {
  const SynthScene synth = MakeSynthScene("lamps", 1);
  CameraIntrinsics camera = SynthCamera(1280, 960);
  const Pose pose = LookAt({0.0, -0.05, 1.1}, {0, 0, 0});
  RenderOptions options;
  options.spp = 4;
  const ImageF image = RenderView(synth.scene, camera, pose, options, 0);
  const Image8 display = ToGray(ToneMapToDisplay(image, 2.0f * ExposureForPercentile(image)));
  cv::Mat gray(display.height, display.width, CV_8UC1, const_cast<uint8_t*>(display.pixels.data()));
  std::vector<int> ids;
  std::vector<std::vector<cv::Point2f>> corners;
  const cv::Ptr<cv::aruco::Dictionary> dict = cv::aruco::getPredefinedDictionary(cv::aruco::DICT_APRILTAG_36h11);
  cv::aruco::detectMarkers(gray, dict, corners, ids);
  // Objects and shadows hide a few tags; a wrong orientation would give no match at all.
  EXPECT_GE(ids.size(), 6u) << "most tags visible from above";
  const Pose T_camera_world = pose.Inverse();
  for (size_t k = 0; k < ids.size(); ++k) {
    const BoardTag* tag = synth.board.FindTag(ids[k]);
    ASSERT_NE(tag, nullptr) << "detected id " << ids[k] << " is on the board";
    for (int c = 0; c < 4; ++c) {
      Vec2 px;
      ASSERT_TRUE(Project(camera, T_camera_world * tag->corners[c], px));
      // OpenCV's corners put pixel centres at integers: shift by 0.5. Sub-pixel
      // corner refinement is off by default: within 3 px, while a cell is ~10 px
      // and a corner order turned by 90 degrees would be off by ~60 px.
      EXPECT_NEAR(corners[k][c].x + 0.5, px.x, 3.0) << "tag " << ids[k] << " corner " << c;
      EXPECT_NEAR(corners[k][c].y + 0.5, px.y, 3.0) << "tag " << ids[k] << " corner " << c;
    }
  }
}

TEST(SynthScenes, CamerasOnTheUpperHemisphere) {
  const Aabb aabb{{-0.62, -0.42, -0.05}, {0.62, 0.42, 0.60}};
  const std::vector<Pose> poses = HemisphereCameras(50, 9, 1, aabb);
  ASSERT_EQ(poses.size(), 50u);
  for (const Pose& p : poses) {
    const Vec3 c = p.translation;
    const double distance = Length(c), elevation = std::asin(c.z / distance) * 180 / kPi;
    // Target within 3 cm of the centre moves these by < 3 cm / 0.8 m = 2.1 deg.
    EXPECT_GT(elevation, 15 - 2.5);
    EXPECT_LT(elevation, 70 + 2.5);
    EXPECT_GT(distance, 0.8 - 0.05);
    EXPECT_LT(distance, 1.3 + 0.05);
    EXPECT_FALSE(c.x > aabb.min.x && c.x < aabb.max.x && c.y > aabb.min.y && c.y < aabb.max.y && c.z < aabb.max.z);
    EXPECT_NEAR(p.rotation.Column(0).z, 0.0, 1e-12) << "no roll: the image x axis is horizontal";
    EXPECT_GT(Dot(p.rotation.Column(2), Normalized(-c)), std::cos(3.0 * kPi / 180)) << "looks at the centre";
  }
}

TEST(SynthWriter, TinySceneFolderPassesTheReaders) {
  testing::TempDir dir;
  SynthOptions options;
  options.scene = "window";
  options.output_dir = dir.path();
  options.width = 64;
  options.height = 48;
  options.views = 24;
  options.test_views = 2;
  options.spp = 2;
  options.insert_spp = 4;
  options.probe_spp = 1;
  options.contact_sheet_views = 4;
  const SynthReport report = WriteSynthDataset(options);
  EXPECT_EQ(report.images, 24 + 2 + 2 + 2 * 2 * 2);
  const Dataset train = ReadDataset(dir.File("transforms_train.json"));
  const Dataset all = ReadDataset(dir.File("transforms.json"));
  const Dataset test = ReadDataset(dir.File("transforms_test.json"));
  EXPECT_EQ(train.frames.size(), 24u);
  EXPECT_EQ(all.frames.size(), 24u);
  EXPECT_EQ(test.frames.size(), 2u);
  EXPECT_EQ(train.camera.width, 64);
  EXPECT_NEAR(train.camera.fx, 32 / std::tan(kPi / 6), 1e-9);
  ASSERT_TRUE(train.aabb.has_value());
  const ImageF first = ReadExrRgb(train.frames[0].image_path);
  EXPECT_EQ(first.width, 64);
  EXPECT_EQ(ReadBoard(dir.File("board.json")).tags.size(), 12u);
  const ImageF env = ReadExrRgb(dir.File("env.exr"));
  EXPECT_EQ(env.width, 256);
  EXPECT_EQ(env.height, 128);
  double env_max = 0;
  for (float v : env.pixels) env_max = std::max<double>(env_max, v);
  EXPECT_NEAR(env_max, 38.0, 1e-3) << "the window patch radiance";
  EXPECT_TRUE(std::filesystem::exists(dir.File("contact_sheet.png")));
  EXPECT_TRUE(std::filesystem::exists(dir.File("lights.json")));
  for (const std::string object : {"sphere_glossy", "torus_diffuse"}) {
    const std::string folder = dir.File("insert/" + object);
    const ObjectPlacement placement = ReadObjectPlacement(folder + "/pose.json");
    ASSERT_TRUE(placement.center_world.has_value());
    const Material material = ReadMaterial(dir.File("objects/" + object + ".json"));
    const TriangleMesh mesh = ReadMesh(material.mesh);
    // Resting on the table: the lowest vertex at z = 0 (float positions: 1e-6).
    double lowest = 1e9;
    for (const Vec3f& p : TransformMesh(mesh, placement.T_world_object, placement.scale).positions)
      lowest = std::min<double>(lowest, p.z);
    EXPECT_NEAR(lowest, 0.0, 1e-5) << object;
    const ImageF probe = ReadExrRgb(folder + "/probe.exr");
    EXPECT_EQ(probe.width, 256);
    const ImageF depth = ReadExrChannel(folder + "/depth_000.exr", "Y");
    const Image8 mask = ReadImage8(folder + "/mask_000.png");
    EXPECT_EQ(depth.width, 64);
    EXPECT_EQ(mask.width, 64);
    const ImageF rgb = ReadExrRgb(folder + "/rgb_000.exr"), bg = ReadExrRgb(dir.File("insert/bg_000.exr"));
    // Same random numbers with and without the object: pixels far from it are
    // bit-identical (at least the black background and the far table).
    size_t same = 0, masked = 0;
    for (size_t i = 0; i < rgb.pixels.size(); ++i) same += rgb.pixels[i] == bg.pixels[i];
    for (uint8_t m : mask.pixels) masked += m == 255;
    EXPECT_GT(same, rgb.pixels.size() / 4) << object;
    // Depth along the viewing axis is positive exactly where something is hit.
    for (int y = 0; y < depth.height; ++y)
      for (int x = 0; x < depth.width; ++x)
        if (mask.at(x, y) == 255) {
          EXPECT_GT(depth.at(x, y), 0.5f) << "cameras are >= 0.75 m from the table centre";
        }
    (void)masked;
  }
}

TEST(SynthCameraStream, FramesCarryTheirTruePose) {
  CameraStreamOptions options;
  options.width = 640;
  options.height = 480;
  options.frames = 3;
  options.noise_sigma = 2;
  SyntheticCameraSource source(options);
  Frame frame;
  std::vector<Frame> frames;
  while (source.Next(frame, 0) == FrameStatus::kOk) frames.push_back(frame);
  ASSERT_EQ(frames.size(), 3u);
  Frame end;
  EXPECT_EQ(source.Next(end, 0), FrameStatus::kEndOfStream);
  for (size_t k = 0; k < frames.size(); ++k) {
    ASSERT_TRUE(frames[k].T_world_camera_true.has_value());
    EXPECT_EQ(frames[k].index, static_cast<int64_t>(k));
    EXPECT_EQ(frames[k].image.width, 640);
    if (k > 0) {
      // Smooth: at 30 fps the camera moves a few millimetres per frame (< 2 cm).
      EXPECT_LT(Length(frames[k].T_world_camera_true->translation - frames[k - 1].T_world_camera_true->translation),
                0.02);
    }
  }
  // The same frame again is identical (noise fixed by the seed and index).
  const Frame again = source.RenderFrame(frames[1].t_ns * 1e-9, 1);
  EXPECT_TRUE(again.image.pixels == frames[1].image.pixels);
  // The true pose explains the image: detected tag corners (OpenCV aruco) lie
  // on the board corners projected with it. Noise sigma 2 levels, 4 samples
  // per pixel, no sub-pixel refinement: within 2 px (a tag is ~40 px here).
  const Image8 gray = ToGray(frames[0].image);
  cv::Mat mat(gray.height, gray.width, CV_8UC1, const_cast<uint8_t*>(gray.pixels.data()));
  std::vector<int> ids;
  std::vector<std::vector<cv::Point2f>> corners;
  cv::aruco::detectMarkers(mat, cv::aruco::getPredefinedDictionary(cv::aruco::DICT_APRILTAG_36h11), corners, ids);
  EXPECT_GE(ids.size(), 2u) << "tags visible in the first frame";
  const Pose T_camera_world = frames[0].T_world_camera_true->Inverse();
  for (size_t k = 0; k < ids.size(); ++k) {
    const BoardTag* tag = source.board().FindTag(ids[k]);
    ASSERT_NE(tag, nullptr);
    for (int c = 0; c < 4; ++c) {
      Vec2 px;
      ASSERT_TRUE(Project(source.camera(), T_camera_world * tag->corners[c], px));
      EXPECT_NEAR(corners[k][c].x + 0.5, px.x, 2.0) << "tag " << ids[k] << " corner " << c;
      EXPECT_NEAR(corners[k][c].y + 0.5, px.y, 2.0) << "tag " << ids[k] << " corner " << c;
    }
  }
}

TEST(SynthScenes, UnknownSceneIsAnInputError) {
  EXPECT_THROW(MakeSynthScene("nope", 1), InputError);
  SynthOptions options;
  options.output_dir = "/tmp/x";
  options.spp = 0;
  options.width = 2;
  EXPECT_EQ(options.Validate().size(), 2u);
}

}  // namespace
}  // namespace nerfar::synth
