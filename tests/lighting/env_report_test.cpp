// The environment report: the evaluation's irradiance error against hand
// computations and shared/eval/metrics.py's own numbers, the residual and its
// colours, which samples a view sees, and the picture's layout with its
// samples drawn where an independent pinhole projection puts them.
#include "render/lighting/env_report.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "render/sg/sphere.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

ImageF Constant(int width, int height, float value) { return ImageF(width, height, 3, value); }

// metrics.py's fib_dirs(64), printed by numpy (independent data): rows 0, 1, 17, 31, 40, 63.
TEST(EnvReport, EvaluationNormalsAreThoseOfMetricsPy) {
  const std::vector<Vec3> all = EvaluationNormals(false), upper = EvaluationNormals(true);
  ASSERT_EQ(all.size(), 64u);
  ASSERT_EQ(upper.size(), 32u);
  const struct {
    int i;
    Vec3 n;
  } expected[] = {
      {0, {0.063808712704, -0.164116749779, 0.984375}},    {1, {-0.271345698139, 0.133881464274, 0.953125}},
      {17, {-0.357091373373, 0.816800762388, 0.453125}},   {31, {0.9798239737, -0.199250696203, 0.015625}},
      {40, {-0.946569934859, -0.182889906215, -0.265625}}, {63, {-0.005355918157, -0.17600333382, -0.984375}}};
  for (const auto& e : expected)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(all[e.i][c], e.n[c], 1e-10) << "normal " << e.i << " component " << c;
  for (int i = 0; i < 32; ++i) EXPECT_EQ(upper[i], all[i]);  // the upper ones come first (z falls with i)
}

// A uniform sky of radiance L gives E = πL on every normal. The same sky
// with its lower half black gives E(n) = πL(1 + n_z)/2 (the visible part of
// the upper hemisphere, by hand). With metrics.py's normals z_i = 1 − (2i+1)/64
// the relative RMS is sqrt(mean(((1 − z_i)/2)²)), over i < 32 (--upper) or all 64.
TEST(EnvReport, IrradianceErrorMatchesHandComputedCases) {
  const ImageF uniform = Constant(256, 128, 1.0f);
  ImageF upper_lit = uniform;
  for (int y = 64; y < 128; ++y)
    for (int x = 0; x < 256; ++x)
      for (int c = 0; c < 3; ++c) upper_lit.at(x, y, c) = 0;
  for (const bool upper : {true, false}) {
    const int count = upper ? 32 : 64;
    double sum = 0;
    for (int i = 0; i < count; ++i) {
      const double z = 1.0 - (2.0 * i + 1.0) / 64;
      sum += std::pow((1 - z) / 2, 2);
    }
    const double by_hand = std::sqrt(sum / count);
    // 5e-4: the panorama's pixels (1.4°) resolve where the cosine lobe meets
    // the horizon to ~1e-4 of E (measured: 0.2886254 and 0.5773435 by
    // metrics.py on the same panorama, 0.2886399 and 0.5773326 by hand).
    EXPECT_NEAR(IrradianceError(upper_lit, uniform, upper), by_hand, 5e-4) << (upper ? "upper" : "sphere");
    EXPECT_NEAR(IrradianceError(upper_lit, uniform, upper), upper ? 0.2886254 : 0.5773435, 1e-5) << "metrics.py";
  }
  // Twice the radiance: E = 2πL against πL on every normal, a relative error
  // of 1. 1e-4: the two grids' sums of the clamped cosine differ by their own
  // quadrature error (~1e-5 of πL at 64 x 32).
  EXPECT_NEAR(IrradianceError(Constant(64, 32, 2.0f), Constant(128, 64, 1.0f), true), 1.0, 1e-4);
  EXPECT_EQ(IrradianceError(uniform, uniform, true), 0.0);
  EXPECT_EQ(IrradianceError(Constant(8, 4, 0), Constant(8, 4, 0), true), 0.0);
  EXPECT_TRUE(std::isinf(IrradianceError(uniform, Constant(8, 4, 0), true)));
}

TEST(EnvReport, ResidualIsLog2OfModelOverObserved) {
  EXPECT_DOUBLE_EQ(ResidualLog2({2, 2, 2}, {1, 1, 1}), 1.0);
  EXPECT_DOUBLE_EQ(ResidualLog2({0.5f, 0.5f, 0.5f}, {1, 1, 1}), -1.0);
  EXPECT_DOUBLE_EQ(ResidualLog2({1, 0, 0}, {1, 0, 0}), 0.0);
  EXPECT_EQ(ResidualLog2({0, 0, 0}, {1, 1, 1}), -INFINITY);  // nothing modelled where light was seen
  EXPECT_EQ(ResidualLog2({1, 1, 1}, {0, 0, 0}), INFINITY);
  EXPECT_EQ(ResidualLog2({0, 0, 0}, {0, 0, 0}), 0.0);
}

TEST(EnvReport, DivergingScaleRunsBlueWhiteRed) {
  using C = std::array<std::uint8_t, 3>;
  EXPECT_EQ(DivergingColour(-1), (C{33, 102, 172}));
  EXPECT_EQ(DivergingColour(0), (C{247, 247, 247}));
  EXPECT_EQ(DivergingColour(1), (C{178, 24, 43}));
  EXPECT_EQ(DivergingColour(-7), DivergingColour(-1));  // clamped
  EXPECT_EQ(DivergingColour(INFINITY), DivergingColour(1));
  // The sign reads from the hue: bluer than red below 0, redder above.
  for (double t = -1; t <= 1.001; t += 0.1) {
    const auto c = DivergingColour(t);
    if (t < -0.05) {
      EXPECT_GT(c[2], c[0]) << t;
    } else if (t > 0.05) {
      EXPECT_GT(c[0], c[2]) << t;
    }
  }
}

// --- A scene to draw: a slab whose top is the plane z = 0 (2 cm voxels,
// 20 cm deep), seen by the sampled views' camera (128 x 96, 60°).

NerfField Slab() {
  const Aabb box{{-0.6, -0.4, -0.2}, {0.6, 0.4, 0.3}};
  NerfField field = NerfField::Dense(box, 0.02, kNerfEmptyDensityRaw, Vec3f{-1, -1, -1});
  for (int k = 0; k < field.res[2]; ++k)
    for (int j = 0; j < field.res[1]; ++j)
      for (int i = 0; i < field.res[0]; ++i) {
        const double z = field.origin.z + k * field.voxel_m;
        field.density[field.Slot(i, j, k)] = z <= 0 ? 8.0f : kNerfEmptyDensityRaw;
      }
  field.UpdateOccupancy(1.0f);
  return field;
}

CameraIntrinsics SampledCamera() {
  CameraIntrinsics c;
  c.width = 128;
  c.height = 96;
  c.fx = c.fy = 64 / std::tan(30 * kPi / 180);
  c.cx = 64;
  c.cy = 48;
  return c;
}

// Samples every 20 cm on the slab's top, the model alternately twice and half
// what was observed; and one sample 15 cm inside the slab, which no view sees.
EnvEstimateReport Estimate() {
  EnvEstimateReport e;
  e.views.camera = SampledCamera();
  const Vec3 eyes[] = {{0.9, -0.5, 0.7}, {-0.8, -0.6, 0.9}, {0.1, 0.9, 0.8}, {-0.7, 0.7, 0.6}};
  for (const Vec3& eye : eyes) e.views.poses.push_back(LookAt(eye, {0, 0, 0}));
  e.views.kept = {true, true, false, true};  // the third view was rejected: never shown
  for (double x = -0.4; x <= 0.41; x += 0.2)
    for (double y = -0.2; y <= 0.21; y += 0.2) {
      const bool bright = e.surface.positions.size() % 2 == 0;
      e.surface.positions.push_back(Vec3f(Vec3{x, y, 0}));
      e.surface.radiance.push_back({0.3f, 0.3f, 0.3f});
      e.fit.modelled.push_back(bright ? Vec3f{0.6f, 0.6f, 0.6f} : Vec3f{0.15f, 0.15f, 0.15f});
    }
  e.surface.positions.push_back(Vec3f(Vec3{0.1, 0.1, -0.15}));
  e.surface.radiance.push_back({0.3f, 0.3f, 0.3f});
  e.fit.modelled.push_back({0.6f, 0.6f, 0.6f});
  return e;
}

// The pinhole of calib/camera.h written out: world → camera (OpenCV axes) by
// the pose's inverse, then u = fx·x/z + cx, v = fy·y/z + cy.
Vec2 ProjectByHand(const CameraIntrinsics& c, const Pose& T_world_camera, const Vec3f& p_world) {
  const Vec3 d = Vec3(p_world) - T_world_camera.translation;
  const Mat3& R = T_world_camera.rotation;
  const Vec3 p{R(0, 0) * d.x + R(1, 0) * d.y + R(2, 0) * d.z, R(0, 1) * d.x + R(1, 1) * d.y + R(2, 1) * d.z,
               R(0, 2) * d.x + R(1, 2) * d.y + R(2, 2) * d.z};
  return {c.fx * p.x / p.z + c.cx, c.fy * p.y / p.z + c.cy};
}

TEST(EnvReport, SamplesSeenInAViewAreThoseOnItsSurface) {
  const CameraIntrinsics camera = SampledCamera();
  // Straight down from 1 m: camera x is world +x, camera y world −y (calib/core/math.h LookAt).
  const Pose pose = LookAt({0, 0, 1}, {0, 0, 0});
  const ImageF depth(camera.width, camera.height, 1, 1.0f);  // the plane z = 0, 1 m along the axis
  const std::vector<Vec3f> points = {{0.1f, 0.2f, 0},
                                     {0.1f, 0.2f, -0.3f},  // on the plane; 30 cm below it
                                     {0, 0, 2},
                                     {3, 0, 0}};  // behind the camera; out of view
  const std::vector<SampleInView> seen = SamplesSeenInView(camera, pose, depth, points, 0.02);
  ASSERT_EQ(seen.size(), 1u);
  EXPECT_EQ(seen[0].sample, 0u);
  // 1e-5 px: the positions are floats (0.1f is 0.1 to 1.5e-9 m, 2e-7 px here).
  EXPECT_NEAR(seen[0].pixel.x, camera.cx + camera.fx * 0.1, 1e-5);
  EXPECT_NEAR(seen[0].pixel.y, camera.cy - camera.fy * 0.2, 1e-5);
}

bool Contains(const PictureRect& outer, const PictureRect& inner) {
  return inner.x >= outer.x && inner.y >= outer.y && inner.x + inner.width <= outer.x + outer.width &&
         inner.y + inner.height <= outer.y + outer.height;
}
bool Overlap(const PictureRect& a, const PictureRect& b) {
  return a.x < b.x + b.width && b.x < a.x + a.width && a.y < b.y + b.height && b.y < a.y + a.height;
}

TEST(EnvReport, PictureShowsPanoramasAndSamplesWhereTheyProject) {
  const NerfField field = Slab();
  const EnvEstimateReport estimate = Estimate();
  EnvLight env;
  // One red lobe towards azimuth −90° (−y: u = 3/4), elevation 30° (v = 1/3), half maximum at 15°.
  const double el = 30 * kPi / 180;
  env.lobes.push_back(Sg{{0, -std::cos(el), std::sin(el)}, 20, {8, 1, 1}});
  const ImageF truth = Constant(64, 32, 0.5f);
  EnvReportOptions options;
  EnvReportLayout layout;
  const Image8 page = RenderEnvReport(field, env, estimate, &truth, options, &layout);

  const PictureRect whole{0, 0, page.width, page.height};
  std::vector<PictureRect> parts = {layout.estimate, layout.truth, layout.difference, layout.irradiance};
  parts.insert(parts.end(), layout.views.begin(), layout.views.end());
  for (size_t a = 0; a < parts.size(); ++a) {
    EXPECT_GT(parts[a].width, 0) << a;
    EXPECT_TRUE(Contains(whole, parts[a])) << a;
    for (size_t b = 0; b < a; ++b) EXPECT_FALSE(Overlap(parts[a], parts[b])) << a << " " << b;
  }
  for (const PictureRect& r : {layout.estimate, layout.truth, layout.difference}) {
    EXPECT_EQ(r.width, options.panorama_width);
    EXPECT_EQ(r.height * 2, r.width);
  }
  // The truth (uniform 0.5) sets the exposure: 1 / its mean luminance.
  EXPECT_FLOAT_EQ(layout.exposure, 2.0f);
  EXPECT_TRUE(std::isfinite(layout.irradiance_error_upper));

  // The estimate panel: inside the lobe (3 px off its axis diagonally, clear
  // of the axis cross) red dominates; far from it the sky is black.
  const auto at = [&](const PictureRect& r, double x, double y) {
    return page.Pixel(r.x + static_cast<int>(x), r.y + static_cast<int>(y));
  };
  const double w = layout.estimate.width, h = layout.estimate.height;
  const std::uint8_t* lobe = at(layout.estimate, 0.75 * w + 3, h / 3 + 3);
  EXPECT_GT(lobe[0], 200);
  EXPECT_GT(lobe[0], lobe[1] + 20);
  const std::uint8_t* far = at(layout.estimate, 0.3 * w, 0.6 * h);
  EXPECT_LT(std::max({far[0], far[1], far[2]}), 20);

  // Three views (the rejected one left out), each the kept poses' own.
  ASSERT_EQ(layout.views.size(), 3u);
  for (const Pose& pose : layout.view_poses) {
    bool kept = false;
    for (size_t v = 0; v < estimate.views.poses.size(); ++v)
      kept = kept || (estimate.views.kept[v] && pose.translation == estimate.views.poses[v].translation);
    EXPECT_TRUE(kept);
  }
  // Each sample on the slab shows its residual's colour where the pinhole
  // puts it (dots of ~2.5 px radius: the centre pixel is fully covered); the
  // sample inside the slab shows nowhere (the grey backdrop stays grey).
  const size_t hidden = estimate.surface.size() - 1;
  int drawn = 0;
  for (size_t k = 0; k < layout.views.size(); ++k) {
    const CameraIntrinsics& camera = layout.view_cameras[k];
    EXPECT_NEAR(static_cast<double>(camera.height) / camera.width, 96.0 / 128.0, 0.01);
    for (size_t i = 0; i < estimate.surface.size(); ++i) {
      const Vec2 p = ProjectByHand(camera, layout.view_poses[k], estimate.surface.positions[i]);
      if (!(p.x >= 3 && p.y >= 3 && p.x < camera.width - 3 && p.y < camera.height - 3)) continue;
      const std::uint8_t* pixel = at(layout.views[k], p.x, p.y);
      if (i == hidden) {
        EXPECT_TRUE(pixel[0] == pixel[1] && pixel[1] == pixel[2]) << "view " << k;
        continue;
      }
      const auto expected = DivergingColour(ResidualLog2(estimate.fit.modelled[i], estimate.surface.radiance[i]));
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(pixel[c], expected[c], 3) << "view " << k << " sample " << i;
      ++drawn;
    }
  }
  EXPECT_GT(drawn, 20);  // most of the 15 samples in each of 3 views
}

TEST(EnvReport, WithoutTruthTheEstimateStandsAlone) {
  const NerfField field = Slab();
  EnvLight env;
  env.lobes.push_back(Sg{{0, 0, 1}, 3, {1, 1, 1}});
  EnvReportOptions options;
  options.views = 2;
  EnvReportLayout layout;
  const Image8 page = RenderEnvReport(field, env, Estimate(), nullptr, options, &layout);
  EXPECT_GT(page.width, 0);
  EXPECT_EQ(layout.difference.width, 0);
  EXPECT_EQ(layout.irradiance.width, 0);
  EXPECT_EQ(layout.views.size(), 2u);
  // The estimate's own mean radiance sets the exposure: the lobe's sphere
  // integral 2πμ(1 − e^{−2λ})/λ over 4π, so k = 2λ / (1 − e^{−2λ}) at μ = 1.
  // 1e-3: a 512 x 256 panorama's quadrature of a λ = 3 lobe (~1e-5).
  EXPECT_NEAR(layout.exposure, 6.0 / (1.0 - std::exp(-6.0)), 1e-3);
}

// A light placed at a distance says how far it is; a distant one does not.
TEST(EnvReport, ALightAtADistanceSaysHowFar) {
  const NerfField field = Slab();
  EnvLight env;
  env.lobes = {Sg{{0, 0, 1}, 30, {9, 9, 9}}, Sg{{1, 0, 0}, 3, {1, 1, 1}}};
  env.distance_m = {1.72, 0};
  EnvReportOptions options;
  options.views = 1;
  EnvReportLayout layout;
  RenderEnvReport(field, env, Estimate(), nullptr, options, &layout);
  int placed = 0, far = 0;
  for (const std::string& line : layout.lines) {
    if (line.find("sharpness 30 ") != std::string::npos)
      placed += line.find("; 1.72 m from the origin") != std::string::npos;
    if (line.find("sharpness 3 ") != std::string::npos) far += line.find("m from the origin") == std::string::npos;
  }
  EXPECT_EQ(placed, 1);
  EXPECT_EQ(far, 1);
}

TEST(EnvReport, BadTruthFilesNameTheFileAndTheProblem) {
  testing::TempDir dir;
  const auto expect_error = [](const std::string& path, const std::string& needle) {
    try {
      ReadTruePanorama(path);
      ADD_FAILURE() << "accepted " << path;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expect_error(dir.File("missing.exr"), "missing.exr");
  WriteExrRgb(dir.File("square.exr"), Constant(32, 32, 1));
  expect_error(dir.File("square.exr"), "expected an equirect panorama");
  ImageF negative = Constant(32, 16, 1);
  negative.at(5, 7, 1) = -1;
  WriteExrRgb(dir.File("negative.exr"), negative, ExrPixelType::kFloat);
  expect_error(dir.File("negative.exr"), "pixel (5, 7)");
  testing::WriteText(dir.File("text.exr"), "not an image");
  expect_error(dir.File("text.exr"), "text.exr");
  WriteExrRgb(dir.File("good.exr"), Constant(32, 16, 1));
  EXPECT_EQ(ReadTruePanorama(dir.File("good.exr")).width, 32);
}

// A sharp source's line says where its evidence lies, with the figures it
// was given; a dictionary lobe (no support) has no line.
TEST(EnvReport, ASharpSourceSaysWhereItsEvidenceLies) {
  const SgMixture lobes = {Sg{{0, 0, 1}, 3, {1, 1, 1}}, Sg{{1, 0, 0}, 9000, {500, 500, 500}}};
  SourceSupport patch;
  patch.half_share = 0.003;
  patch.radius_m = 0.16;
  patch.centre = {-0.13, 0.26, 0.01};
  const std::vector<std::string> lines = SourceSupportLines(lobes, {SourceSupport{}, patch});
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0],
            "sharp source at azimuth 0, elevation 0 deg: half its gain from 0.3 % of the samples, within 0.16 m of "
            "(-0.13, 0.26, 0.01)");
}

}  // namespace
}  // namespace nerfar
