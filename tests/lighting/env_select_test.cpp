// The environment fit's model selection (EnvFitReport::evidence) on surface
// samples built here by hand: a floor and a sphere's upper half, lit by a
// point lamp inside the scene (the near field, computed analytically) with
// or without a distant light (irradiance from render/sg's analytic SG
// irradiance, no occlusion), observed with 10 % multiplicative noise.
#include <gtest/gtest.h>

#include <cmath>

#include "calib/core/random.h"
#include "render/lighting/env_estimate.h"
#include "render/sg/sphere.h"
#include "render/sg/visibility.h"

namespace nerfar {
namespace {

const Aabb kBox{{-1, -1, -0.2}, {1, 1, 1.0}};
const Vec3 kLamp{0.3, 0.2, 0.8};
constexpr double kLampIntensity = 3;  // radiant intensity (irradiance × m²)
constexpr double kAlbedo = 0.5;
constexpr double kNoise = 0.1;  // relative standard deviation of the observations

// Point-lamp irradiance I·max(n·l, 0)/r² (exact for a point source, no occluder here).
Vec3 LampIrradiance(const Vec3& x, const Vec3& n) {
  const Vec3 to = kLamp - x;
  const double r2 = Dot(to, to);
  const double e = kLampIntensity * std::max(0.0, Dot(n, to) / std::sqrt(r2)) / r2;
  return Vec3{1, 1, 1} * e;
}

// A window-like distant light: a sharp lobe at elevation 35 degrees and a dim sky.
SgMixture Window() {
  const double el = 35 * kPi / 180, az = 40 * kPi / 180;
  return {Sg{{0, 0, 1}, 1.5, {0.3, 0.35, 0.45}},
          Sg{{std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)}, 20.0, {8, 7, 6}}};
}

// 30 x 30 floor points and 600 points on the upper half of a sphere of
// radius 0.25 at (−0.3, −0.2, 0.25); nothing occluded (opacity cache 0).
EnvSurfaceSamples Samples(const SgMixture& distant) {
  EnvSurfaceSamples s;
  for (int j = 0; j < 30; ++j)
    for (int i = 0; i < 30; ++i) {
      s.positions.push_back(Vec3f{-0.9f + 0.06f * i, -0.9f + 0.06f * j, 0.0f});
      s.normals.push_back(Vec3f{0, 0, 1});
    }
  for (const Vec3& n : FibonacciSphere(1200))
    if (n.z > 0) {
      s.positions.push_back(Vec3f(Vec3{-0.3, -0.2, 0.25} + n * 0.25));
      s.normals.push_back(Vec3f(n));
    }
  s.rays_per_point = 8;
  s.ray_dirs.assign(s.size() * 8, Vec3f{0, 0, 1});
  s.opacity.assign(s.size() * 8, 0.0f);
  for (size_t i = 0; i < s.size(); ++i) {
    const Vec3 x(s.positions[i]), n(s.normals[i]);
    const Vec3 e_near = LampIrradiance(x, n);
    const Vec3 e_total = e_near + Irradiance(distant, n);
    // Uniform noise of standard deviation kNoise (half-width √3·kNoise).
    const double u = 2 * UnitDouble(CounterHash(7, 1, i, 0)) - 1;
    s.radiance.push_back(Vec3f(e_total * (kAlbedo / kPi * (1 + std::sqrt(3.0) * kNoise * u))));
    s.e_nerf.push_back(Vec3f(e_near));
  }
  return s;
}

EnvEstimateOptions FitOptions() {
  EnvEstimateOptions o = EnvEstimateOptions::Preset("fast");  // 120-lobe dictionary, 8 iterations
  return o;
}

// All light from the lamp inside: whatever the fit finds in the noise, the
// environment does not pay for its parameters. Fitted to pure noise, k free
// parameters lower the negative log-likelihood by about k/2 on average (a
// chi-square with k degrees of freedom, halved); BIC asks for (k/2)·ln n,
// 7.3x that at n = 1500: the margin of this test.
TEST(EnvSelect, AllLightInsideIsNotSupported) {
  const EnvSurfaceSamples s = Samples({});
  EnvFitReport report;
  const SgMixture light = FitEnvironment(s, kBox, FitOptions(), &report);
  EXPECT_GT(report.near_only_loss, 0);
  EXPECT_LE(report.evidence, report.evidence_needed) << "lobes " << report.active_lobes;
  EXPECT_FALSE(report.environment_supported);
  // Turned off, the test says nothing.
  EnvEstimateOptions off = FitOptions();
  off.evidence_bic_factor = 0;
  EnvFitReport off_report;
  FitEnvironment(s, kBox, off, &off_report);
  EXPECT_TRUE(off_report.environment_supported);
  EXPECT_EQ(off_report.evidence_needed, 0);
}

// A distant window adds about as much light as the lamp: the environment is
// supported by far (the near field alone leaves residuals of the order of
// the observations, log-residuals ~0.5 against the noise's 0.1), and its
// irradiance comes back: relative RMS over the upper normals against the
// analytic irradiance below 0.25 (the fit's error on the noise-free synthetic
// grid scene is 0.18; 10 % noise on 1500 samples adds little).
TEST(EnvSelect, ADistantLightIsSupportedAndRecovered) {
  const EnvSurfaceSamples s = Samples(Window());
  EnvFitReport report;
  const SgMixture light = FitEnvironment(s, kBox, FitOptions(), &report);
  EXPECT_TRUE(report.environment_supported);
  EXPECT_GT(report.evidence, 5 * report.evidence_needed);
  std::vector<Vec3> e_est, e_true;
  for (const Vec3& n : FibonacciSphere(128))
    if (n.z > 0) {
      e_est.push_back(Irradiance(light, n));
      e_true.push_back(Irradiance(Window(), n));
    }
  EXPECT_LT(RelativeIrradianceRms(e_est, e_true), 0.25);
}

// env.json carries the evidence and the flag; files without the evidence keys still read.
TEST(EnvSelect, EnvJsonCarriesTheEvidence) {
  EnvLight env;
  env.lobes = Window();
  env.negligible = true;
  env.evidence = 12.5;
  env.evidence_needed = 300;
  const EnvLight back = ParseEnvLight(SerializeEnvLight(env), "test");
  EXPECT_TRUE(back.negligible);
  EXPECT_EQ(back.evidence, 12.5);
  EXPECT_EQ(back.evidence_needed, 300);
  const EnvLight old = ParseEnvLight(
      R"({"format": "nerfar-env", "version": 1, "lobes": [], "negligible": false,
          "energy": {"env_to_near_surface": 0, "env_to_near_center": 0, "threshold": 0.05}})",
      "old");
  EXPECT_EQ(old.evidence, 0);
  EXPECT_EQ(old.evidence_needed, 0);
}

// SupportOfGains against counts made by hand. A patch of 10 samples within
// 2 cm holding gain 10 each beside 990 samples spread over a 1 m square
// with 0.01 each: half of the positive total (109.9 / 2 = 54.95) is reached
// with the sixth patch sample, so 6 of the 1000 samples (0.6 %) hold it, all
// within the patch's 1.8 cm. Equal gains on a 33 × 30 grid over a 1 m
// square: half of the samples (495) hold half, and a disc of radius 0.3 m
// holds only about 280 of the grid's points, so they reach farther than
// that from their mean. Samples without a positive gain count among all
// the samples but hold none of it.
TEST(EnvSelect, SourceSupportCountsTheSamplesThatHoldHalfTheGain) {
  std::vector<Vec3f> positions;
  std::vector<double> gain;
  for (int k = 0; k < 10; ++k) {
    positions.push_back(Vec3f{0.3f + 0.002f * k, -0.2f, 0});
    gain.push_back(10);
  }
  for (int k = 0; k < 990; ++k) {
    positions.push_back(Vec3f{static_cast<float>(k % 33) / 33 - 0.5f, static_cast<float>(k / 33) / 30 - 0.5f, 0});
    gain.push_back(0.01);
  }
  const SourceSupport patch = SupportOfGains(positions, gain);
  EXPECT_DOUBLE_EQ(patch.half_share, 0.006);
  EXPECT_LE(patch.radius_m, 0.02);
  EXPECT_GE(patch.centre.x, 0.3 - 1e-6);  // the mean of six of the patch's samples (equal gains: any six)
  EXPECT_LE(patch.centre.x, 0.318 + 1e-6);
  EXPECT_NEAR(patch.centre.y, -0.2, 1e-6);

  std::vector<double> equal(990, 1.0);
  const SourceSupport spread = SupportOfGains(std::vector<Vec3f>(positions.begin() + 10, positions.end()), equal);
  EXPECT_DOUBLE_EQ(spread.half_share, 0.5);
  EXPECT_GT(spread.radius_m, 0.3);

  std::vector<double> mixed(1000, -1.0);
  mixed[3] = 2.0;
  const SourceSupport one = SupportOfGains(positions, mixed);
  EXPECT_DOUBLE_EQ(one.half_share, 0.001);
  EXPECT_DOUBLE_EQ(one.radius_m, 0.0);
  EXPECT_DOUBLE_EQ(SupportOfGains(positions, std::vector<double>(1000, 0.0)).half_share, 0.0);
}

}  // namespace
}  // namespace nerfar
