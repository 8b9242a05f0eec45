// render/insert: κ (paper eq. 8) under sharp distant lobes, as a small
// source gives them (a lamp of a few degrees: λ ~ 1e3, a sun: λ ~ 1e4),
// against brute force. A sphere (radius 4 cm, 1 cm above the table, exact
// sphere visibility) under one SG lobe from elevation 35°; the truth at each
// table point integrates the lobe (its own quadrature, fine enough for any
// sharpness) against visibility traced here to the sphere. The shadow's
// umbra must be as deep and its penumbra as wide as the truth's.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <vector>

#include "calib/core/parallel.h"
#include "render/insert/inserter.h"
#include "tests/insert/insert_fixtures.h"
#include "tests/insert/test_camera.h"
#include "tests/support/analytic_scene.h"

namespace nerfar {
namespace {

const Vec3 kSphereCentre{0, 0, 0.05};
constexpr double kSphereRadius = 0.04;

// Does the ray x + t·d (t > 0) meet the sphere?
bool SphereBlocks(const Vec3& x, const Vec3& d) {
  const Vec3 oc = x - kSphereCentre;
  const double b = Dot(oc, d), c = Dot(oc, oc) - kSphereRadius * kSphereRadius;
  return b < 0 && b * b > c;
}

// κ at a table point (normal +z) under one lobe: Σ G cos V / Σ G cos over
// 64 x 64 directions of equal weight under the lobe (the inverse of its
// falloff in 1 − cos ψ, so they follow the lobe at any sharpness). Points
// whose sphere lies beyond the lobe's extent (1 − cos ψ > 12/λ: the lobe
// holds e^−12 ≈ 6e-6 of itself there) are lit: κ = 1.
double KappaByQuadrature(const Sg& lobe, const Vec3& x) {
  const Vec3 to = kSphereCentre - x;
  const double sphere_angle = std::asin(std::min(1.0, kSphereRadius / Length(to)));
  const double apart = std::acos(std::clamp(Dot(Normalized(to), lobe.axis), -1.0, 1.0));
  const double extent = std::acos(std::max(-1.0, 1 - 12 / lobe.sharpness));
  if (apart > sphere_angle + extent) return 1.0;
  constexpr int kRadial = 64, kAround = 64;
  const Vec3 t1 = Normalized(Cross(Vec3{0, 0, 1}, lobe.axis)), t2 = Cross(lobe.axis, t1);
  const double spread = -std::expm1(-2 * lobe.sharpness);  // 1 − e^{−2λ}
  double seen = 0, all = 0;
  for (int i = 0; i < kRadial; ++i) {
    const double u = -std::log1p(-(i + 0.5) / kRadial * spread) / lobe.sharpness;  // 1 − cos ψ
    const double c = 1 - u, s = std::sqrt(std::max(0.0, 1 - c * c));
    for (int j = 0; j < kAround; ++j) {
      const double phi = 2 * kPi * (j + 0.5) / kAround;
      const Vec3 d = lobe.axis * c + (t1 * std::cos(phi) + t2 * std::sin(phi)) * s;
      if (d.z <= 0) continue;
      all += d.z;
      if (!SphereBlocks(x, d)) seen += d.z;
    }
  }
  return all > 0 ? seen / all : 1.0;
}

struct SharpShadow {
  double normalised_error = 0;     // Σ|κ − κ_ref| / Σ(1 − κ_ref) (DESIGN.md's shadow metric without the blur)
  double umbra_kappa = 0;          // mean κ where κ_ref < 0.02
  size_t umbra = 0;                // those pixels
  size_t penumbra = 0, found = 0;  // pixels with κ_ref, κ in [0.1, 0.9]
};

// κ of the rendered layer at every table pixel against the quadrature there.
SharpShadow CompareUnder(double sharpness) {
  const Sg lobe = testing::OneLobe({-std::cos(35 * kPi / 180), 0, std::sin(35 * kPi / 180)}, sharpness, 5.0)[0];
  const SgMixture light = {lobe};
  const testing::SphereObject sphere(kSphereCentre, kSphereRadius);
  const testing::AnalyticScene scene(testing::PlainTable());
  // Nearly straight down over the shadow (x from 0 to 14 cm): 0.9 mm pixels,
  // a few across the sharpest lobe's penumbra at the shadow's far end.
  const CameraIntrinsics camera = testing::TestCamera(240, 180);
  const Pose cam = LookAt({0.07, -0.02, 0.2}, {0.07, 0.0, 0.0});
  InsertOptions options;
  options.kappa_step = 1;  // κ at every pixel: nothing interpolated
  options.shadow_epsilon = 1e-4;
  Inserter inserter(scene, {}, options);
  ImageF frame(camera.width, camera.height, 3, 1.0f);
  InsertLayers layers;
  inserter.Render(camera, cam, {sphere.Object(&light)}, frame, &layers);
  const PixelRect& rect = layers.kappa_rect;
  const int width = rect.x1 - rect.x0;
  std::vector<double> truth(size_t(width) * (rect.y1 - rect.y0), -1);  // −1: not a table pixel
  ParallelFor(truth.size(), [&](size_t i) {
    const std::optional<Vec3> p =
        testing::TablePointAt(layers, camera, cam, rect.x0 + int(i % width), rect.y0 + int(i / width));
    if (p) truth[i] = KappaByQuadrature(lobe, *p);
  });
  SharpShadow r;
  double error = 0, shadow = 0;
  for (int y = rect.y0; y < rect.y1; ++y)
    for (int x = rect.x0; x < rect.x1; ++x) {
      const double reference = truth[size_t(y - rect.y0) * width + (x - rect.x0)];
      if (reference < 0) continue;
      const double kappa = layers.kappa.at(x - rect.x0, y - rect.y0);
      error += std::abs(kappa - reference);
      shadow += 1 - reference;
      if (reference < 0.02) ++r.umbra, r.umbra_kappa += kappa;
      r.penumbra += reference >= 0.1 && reference <= 0.9;
      r.found += kappa >= 0.1 && kappa <= 0.9;
    }
  r.normalised_error = shadow > 0 ? error / shadow : 0;
  r.umbra_kappa = r.umbra ? r.umbra_kappa / r.umbra : 1;
  std::printf("λ %.0f: normalised error %.3f, umbra κ %.3f over %zu pixels, penumbra %zu pixels (truth %zu)\n",
              sharpness, r.normalised_error, r.umbra_kappa, r.umbra, r.found, r.penumbra);
  return r;
}

// The truth and κ are taken at the same pixel centres, so the pixels' size
// does not enter the comparison: the bounds are about κ as insertion
// computes it with its default options (its κ lattice included). The umbra
// (where the truth is below 0.02) within 0.05 of black; the penumbra's area
// (its width along the shadow's outline) within 25 % of the truth's: a
// lamp's shadow as soft as it is and a sun's as hard; the shadow metric
// under 0.15 (the end-to-end target is 0.40 with everything else on
// top).
void ExpectSharpShadow(double sharpness) {
  const SharpShadow r = CompareUnder(sharpness);
  ASSERT_GT(r.umbra, 500u) << "the umbra is in view";
  ASSERT_GT(r.penumbra, 100u) << "the penumbra is in view";
  EXPECT_LT(r.umbra_kappa, 0.05) << "λ " << sharpness;
  EXPECT_NEAR(double(r.found) / r.penumbra, 1.0, 0.25) << "λ " << sharpness;
  EXPECT_LT(r.normalised_error, 0.15) << "λ " << sharpness;
}

TEST(KappaSharp, WideLampLambda1e2) { ExpectSharpShadow(1e2); }
TEST(KappaSharp, SmallLampLambda1e3) { ExpectSharpShadow(1e3); }
TEST(KappaSharp, SunLambda1e4) { ExpectSharpShadow(1e4); }

}  // namespace
}  // namespace nerfar
