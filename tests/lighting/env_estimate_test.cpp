// The environment estimator on synthetic NeRF grids whose radiance is
// computed here, independently of the estimator, from a known light by
// brute-force quadrature with analytic visibility.
#include "render/lighting/env_estimate.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <map>

#include "calib/core/error.h"
#include "calib/core/log.h"
#include "calib/core/parallel.h"
#include "render/lighting/seen_radiance.h"
#include "render/lighting/view_quality.h"
#include "render/sg/sphere.h"
#include "render/sg/visibility.h"
#include "tests/support/analytic_field.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

using testing::MakeField;
using testing::OrientedBox;
using testing::Shape;

// Floor slab (top at z = 0 over the whole box) and a floating sphere.
const Aabb kBox{{-1, -1, -0.2}, {1, 1, 1.0}};
const Vec3 kBall{0.1, -0.05, 0.45};
const double kBallRadius = 0.25;

Shape FloorAndBall() {
  Shape s;
  s.sd = [](const Vec3& p) { return std::min(p.z, Length(p - kBall) - kBallRadius); };
  s.project = [](const Vec3& p, Vec3* x, Vec3* n) {
    if (p.z < Length(p - kBall) - kBallRadius) {
      *x = {p.x, p.y, 0};
      *n = {0, 0, 1};
    } else {
      *n = Normalized(p - kBall);
      *x = kBall + *n * kBallRadius;
    }
  };
  return s;
}

// Does the ray x + t·d (t > 0) hit the ball or the floor's top inside the box?
bool Blocked(const Vec3& x, const Vec3& d) {
  const Vec3 oc = x - kBall;
  const double b = Dot(oc, d), c = Dot(oc, oc) - kBallRadius * kBallRadius;
  const double disc = b * b - c;
  if (disc > 0 && -b + std::sqrt(disc) > 1e-9 && -b - std::sqrt(disc) > 1e-9) return true;
  if (d.z < 0 && x.z > 1e-9) {
    const double t = -x.z / d.z;
    const Vec3 hit = x + d * t;
    if (std::fabs(hit.x) <= 1 && std::fabs(hit.y) <= 1) return true;
  }
  return false;
}

SgMixture TrueEnvironment() {
  const double el = 35 * kPi / 180, az = 40 * kPi / 180;
  return {Sg{{0, 0, 1}, 1.5, {0.3, 0.35, 0.45}},
          Sg{{std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)}, 20.0, {8, 7, 6}}};
}

// Irradiance at x with normal n by brute force over 8192 Fibonacci
// directions with exact visibility (quadrature error ~1e-3 for λ ≤ 20).
Vec3 TrueIrradiance(const SgMixture& env, const Vec3& x, const Vec3& n) {
  static const std::vector<Vec3> dirs = FibonacciSphere(8192);
  Vec3 e;
  for (const Vec3& d : dirs) {
    const double c = Dot(n, d);
    if (c <= 0 || Blocked(x + n * 1e-6, d)) continue;
    e += Evaluate(env, d) * c;
  }
  return e * (4 * kPi / dirs.size());
}

EnvEstimateOptions TestOptions() {
  EnvEstimateOptions o = EnvEstimateOptions::Preset("fast");
  o.views = 40;
  o.pixels_per_view = 48;
  o.rays_per_point = 128;
  o.brisque_max = 100;  // BRISQUE off: flat synthetic renders are not natural images (tested on its own below)
  o.min_view_elevation_deg = 5;
  // The test grids' surfaces are sharp (density falls from σ = 20 to 0.1 /m
  // within half a voxel) and their voxels coarse (4 cm): one voxel of offset
  // leaves the surface without moving the ray origins much closer to lamps.
  o.ray_offset_voxels = 1;
  return o;
}

std::vector<Vec3> UpperNormals() {
  std::vector<Vec3> normals;
  for (const Vec3& n : FibonacciSphere(128))
    if (n.z > 0) normals.push_back(n);
  return normals;
}

const NerfField& LitFloorField() {
  static const NerfField field = [] {
    const SgMixture env = TrueEnvironment();
    std::map<std::pair<double, double>, Vec3> floor;  // floor vertices of one column share their surface point
    return MakeField(kBox, 0.04, FloorAndBall(), [&](const Vec3& x, const Vec3& n) {
      if (n.z == 1.0) {
        const auto it = floor.find({x.x, x.y});
        if (it != floor.end()) return it->second;
        return floor[{x.x, x.y}] = TrueIrradiance(env, x, n) * (0.5 / kPi);
      }
      return TrueIrradiance(env, x, n) * (0.5 / kPi);
    });
  }();
  return field;
}

TEST(EnvEstimate, RecoversAKnownEnvironmentOnALambertianScene) {
  const NerfField& field = LitFloorField();
  EnvEstimateReport report;
  const EnvLight est = EstimateEnvironment(field, TestOptions(), &report);
  ASSERT_GT(report.samples, 1000u);
  ASSERT_FALSE(est.lobes.empty());
  EXPECT_LE(est.lobes.size(), 32u);
  std::vector<Vec3> e_est, e_true;
  for (const Vec3& n : UpperNormals()) {
    e_est.push_back(Irradiance(est.lobes, n));
    e_true.push_back(Irradiance(TrueEnvironment(), n));
  }
  const double rms = RelativeIrradianceRms(e_est, e_true);
  // The scene has no near-field light, so the absolute scale comes from the
  // grey-world albedo prior (0.5, the scene's albedo); the shape comes from the
  // shading and the ball's shadow. 20 % (the aim on real scenes):
  // grid discretisation (surfaces within a fraction of a 4 cm voxel, normals
  // from a trilinear gradient), 128 rays per point and the dictionary's lobe spacing.
  // 22 %, not 20: until this session the scale prior's weight was set in
  // absolute irradiance units (0.19 here, but 2x off at radiance x1e3); made
  // relative to the scene's typical irradiance it gives 0.209 here and the
  // same answer at any exposure (ScalesWithRadianceFrom1em3To1e3).
  EXPECT_LT(rms, 0.22) << "relative RMS irradiance over the upper hemisphere";
  EXPECT_FALSE(est.negligible);  // there is no near field: the environment is all the light
  // The brightest lobe points near the window lobe (within 25°).
  const Sg* best = &est.lobes[0];
  for (const Sg& g : est.lobes)
    if (LuminanceOf(g.amplitude) * SgUnitIntegral(g.sharpness) >
        LuminanceOf(best->amplitude) * SgUnitIntegral(best->sharpness))
      best = &g;
  EXPECT_GT(Dot(best->axis, TrueEnvironment()[1].axis), std::cos(25 * kPi / 180));
}

TEST(EnvEstimate, IsDeterministicAcrossThreadCounts) {
  const NerfField& field = LitFloorField();
  EnvEstimateOptions o = TestOptions();
  o.views = 10;
  SetThreadCount(1);
  const EnvLight a = EstimateEnvironment(field, o);
  SetThreadCount(2);
  const EnvLight b = EstimateEnvironment(field, o);
  SetThreadCount(0);
  ASSERT_EQ(a.lobes.size(), b.lobes.size());
  for (size_t k = 0; k < a.lobes.size(); ++k) {
    EXPECT_EQ(a.lobes[k].axis, b.lobes[k].axis);
    EXPECT_EQ(a.lobes[k].sharpness, b.lobes[k].sharpness);
    EXPECT_EQ(a.lobes[k].amplitude, b.lobes[k].amplitude);
  }
  EXPECT_EQ(a.env_to_near_surface, b.env_to_near_surface);
}

// HDR: the loss is relative (floor and robust scale in units of the mean
// observed luminance) and the priors scale with the data, so multiplying
// every radiance by s must multiply the estimate by s. Checked at s = 1e-3
// and 1e3 (the field's log colour is shifted by ln s, exact in float up to
// rounding of the shifted coefficient).
TEST(EnvEstimate, ScalesWithRadianceFrom1em3To1e3) {
  const NerfField& base = LitFloorField();
  EnvEstimateOptions o = TestOptions();
  o.views = 10;
  const EnvLight ref = EstimateEnvironment(base, o);
  ASSERT_FALSE(ref.lobes.empty());
  for (double scale : {1e-3, 1e3}) {
    NerfField field = base;
    for (size_t slot = 0; slot < field.SlotCount(); ++slot)
      for (int c = 0; c < 3; ++c) field.color[slot * kNerfColorCoeffs + c * 4] += static_cast<float>(std::log(scale));
    const EnvLight est = EstimateEnvironment(field, o);
    std::vector<Vec3> e_est, e_ref;
    for (const Vec3& n : UpperNormals()) {
      e_est.push_back(Irradiance(est.lobes, n) / scale);
      e_ref.push_back(Irradiance(ref.lobes, n));
    }
    // 1 %: float rounding of the shifted log colours (~1e-6 relative) can flip
    // a pixel pick or an active-set choice, which moves the result slightly;
    // a loss that were not scale-free would be off by orders of magnitude.
    EXPECT_LT(RelativeIrradianceRms(e_est, e_ref), 0.01) << "scale " << scale;
    EXPECT_EQ(est.negligible, ref.negligible);
  }
}

// All light inside the NeRF: a floor (albedo 0.5) lit by an emitting sphere
// of radiance `lit_by`, while the grid's sphere itself shows radiance `le`
// (equal for a faithful NeRF; lower for a lamp the cameras saw dimmer).
NerfField LampOverFloor(double le, double lit_by) {
  const Vec3 lamp{0.4, 0.3, 0.35};
  const double rho = 0.15;
  Shape s;
  s.sd = [&](const Vec3& p) { return std::min(p.z, Length(p - lamp) - rho); };
  s.project = [&](const Vec3& p, Vec3* x, Vec3* n) {
    if (p.z < Length(p - lamp) - rho) {
      *x = {p.x, p.y, 0};
      *n = {0, 0, 1};
    } else {
      *n = Normalized(p - lamp);
      *x = lamp + *n * rho;
    }
  };
  return MakeField(kBox, 0.04, s, [&](const Vec3& x, const Vec3&) {
    if (x.z > 1e-6) return Vec3{le, le, le};  // the lamp's surface
    // A uniform sphere of radiance L seen whole above the horizon gives
    // E = π L (ρ/D)² cos θ.
    const Vec3 to = lamp - x;
    const double dist = Length(to);
    const double e = kPi * lit_by * (rho / dist) * (rho / dist) * std::max(0.0, to.z / dist);
    return Vec3{e, e, e} * (0.5 / kPi);
  });
}

// All light inside the NeRF: a floor lit by an emitting sphere, no environment.
TEST(EnvEstimate, FlagsTheEnvironmentNegligibleWhenAllLightIsInside) {
  const NerfField field = LampOverFloor(30, 30);
  // A small bright source needs enough rays per point: with 128 rays about
  // 2 hit the lamp and E_nerf is quantised noise that the fit then fills with
  // environment light (docs/BENCHMARKS.md "env" measures this trade).
  EnvEstimateOptions o = TestOptions();
  o.rays_per_point = 512;
  // This test's 1900 samples spread over 4 m² lie ~5 cm apart; pool over ~3 neighbours' spacing.
  o.near_field_pool_m = 0.15;
  // Stronger minimum-energy prior: light that only the few samples near the
  // lamp could refute stays out (on the known-environment scene above this
  // weight costs accuracy: 0.39 instead of 0.18 relative RMS; hence not the default).
  o.light_energy_weight = 1e-2;
  EnvEstimateReport report;
  const EnvLight est = EstimateEnvironment(field, o, &report);
  EXPECT_LT(est.env_to_near_surface, 0.05);
  EXPECT_LT(est.env_to_near_center, 0.05);
  EXPECT_TRUE(est.negligible);
  // The baseline that ignores the near field must instead invent an environment.
  EnvEstimateOptions physg = TestOptions();
  physg.ignore_near_field = true;
  const EnvLight wrong = EstimateEnvironment(field, physg);
  double e_wrong = 0;
  for (const Vec3& n : UpperNormals()) e_wrong += LuminanceOf(Irradiance(wrong.lobes, n));
  EXPECT_GT(e_wrong, 0);
  EXPECT_FALSE(wrong.negligible);
}

// A trained NeRF's emitters can be dimmer than the light they cast (towards
// directions no camera saw). Here the floor is lit 3x brighter than the
// NeRF's lamp explains (albedo 0.5 under a lamp of 3·le, the grid's lamp at
// le): without the near-field gain the fit must make the rest up as
// environment light; with it the estimate is negligible again.
TEST(EnvEstimate, NearFieldGainAbsorbsADimNerfLamp) {
  const NerfField field = LampOverFloor(30, 3 * 30);
  EnvEstimateOptions o = TestOptions();  // as in the test above
  // Measured: with the default normal_balance (0.75) the gained estimate
  // stays at 0.35 of the near field (the floor's few tilted samples near the
  // lamp get the weight of the whole floor); the gain is an option off by
  // default, tested here on the unbalanced fit it was made for.
  o.normal_balance = 0;
  o.rays_per_point = 512;
  o.near_field_pool_m = 0.15;
  o.light_energy_weight = 1e-2;
  EnvEstimateReport without_report;
  const EnvLight without = EstimateEnvironment(field, o, &without_report);
  EXPECT_FALSE(without.negligible) << "the missing 2/3 of the light must show up as environment";
  EXPECT_GT(without.env_to_near_surface, 0.3);
  o.near_field_gain_max = 8;
  EnvEstimateReport report;
  const EnvLight est = EstimateEnvironment(field, o, &report);
  // The albedo prior (0.5, the true albedo) fixes the split between albedo
  // and gain only weakly; albedos are clamped to 1, so g >= 1.5 is forced by
  // the data and g = 3 is the truth.
  EXPECT_GT(report.fit.near_field_gain, 1.5);
  EXPECT_LT(report.fit.near_field_gain, 4.5);
  EXPECT_LT(est.env_to_near_surface, 0.05);
  EXPECT_TRUE(est.negligible);
}

// Fog in front of a surface: a floor under a 30 cm layer of fog holding
// vertical opacity 0.3 (σ = 1.19 /m). Seen from 45 to 90 degrees elevation
// the fog holds less than half of a ray's opacity, so the surface is the
// median of the opacity (on the floor), while the expected depth would sit
// ~5 cm above it; depth-map normals face up. Views from lower down are not
// drawn (there the fog alone exceeds half the opacity: a fog layer then is
// the surface the cameras see).
TEST(EnvEstimate, FindsTheSurfaceUnderAFogLayer) {
  Shape floor;
  floor.sd = [](const Vec3& p) { return p.z; };
  floor.project = [](const Vec3& p, Vec3* x, Vec3* n) {
    *x = {p.x, p.y, 0};
    *n = {0, 0, 1};
  };
  NerfField field = MakeField(kBox, 0.04, floor, [](const Vec3&, const Vec3&) { return Vec3{0.3, 0.3, 0.3}; });
  const double fog_sigma = -std::log(0.7) / 0.3;
  for (int k = 0; k < field.res[2]; ++k)
    for (int j = 0; j < field.res[1]; ++j)
      for (int i = 0; i < field.res[0]; ++i) {
        const double z = field.origin.z + k * field.voxel_m;
        if (z <= 0.02 || z > 0.3) continue;  // above the floor's own ramp
        const int32_t slot = field.Slot(i, j, k);
        field.density[slot] = std::max(field.density[slot], static_cast<float>(std::log(fog_sigma)));
      }
  field.UpdateOccupancy(0.01f);
  EnvEstimateOptions o = TestOptions();
  o.views = 20;
  o.min_view_elevation_deg = 45;
  o.max_surface_spread_voxels = 1e6;  // the fog spreads the opacity; this test is about the median
  const EnvSurfaceSamples samples = SampleSurfaces(field, o);
  ASSERT_GT(samples.size(), 200u);
  // Rays through the box's side walls cross the fog lengthwise (there the fog
  // is the first surface): only the inner part of the floor is checked.
  int off_floor = 0, tilted = 0, inner = 0;
  for (size_t i = 0; i < samples.size(); ++i) {
    // Half a voxel: the floor's density ramp spans a third of a voxel and the
    // march steps half a voxel (2 cm).
    if (std::fabs(samples.positions[i].x) > 0.7 || std::fabs(samples.positions[i].y) > 0.7) continue;
    ++inner;
    if (std::fabs(samples.positions[i].z) > 0.02) ++off_floor;
    if (samples.normals[i].z < std::cos(10 * kPi / 180)) ++tilted;
  }
  ASSERT_GT(inner, 100);
  EXPECT_LT(off_floor, inner / 50) << "of " << inner;
  EXPECT_LT(tilted, inner / 50) << "of " << inner;
}

// The other way: the same emitting sphere over the floor plus a real distant
// environment (the known two-lobe one, tripled) must not be flagged: its
// irradiance on the floor, brute-forced below, is a sizeable share of the
// lamp's, so both ratios must come out well above the 5 % threshold.
TEST(EnvEstimate, KeepsAnEnvironmentThatAddsToAnInsideLamp) {
  const Vec3 lamp{0.4, 0.3, 0.35};
  const double rho = 0.15, le = 30;
  SgMixture env = TrueEnvironment();
  for (Sg& g : env) g.amplitude = g.amplitude * 3.0;
  Shape s;
  s.sd = [&](const Vec3& p) { return std::min(p.z, Length(p - lamp) - rho); };
  s.project = [&](const Vec3& p, Vec3* x, Vec3* n) {
    if (p.z < Length(p - lamp) - rho) {
      *x = {p.x, p.y, 0};
      *n = {0, 0, 1};
    } else {
      *n = Normalized(p - lamp);
      *x = lamp + *n * rho;
    }
  };
  static const std::vector<Vec3> dirs = FibonacciSphere(4096);
  double floor_env = 0, floor_lamp = 0;
  std::map<std::pair<double, double>, Vec3> floor;
  const NerfField field = MakeField(kBox, 0.04, s, [&](const Vec3& x, const Vec3&) {
    if (x.z > 1e-6) return Vec3{le, le, le};
    const auto it = floor.find({x.x, x.y});
    if (it != floor.end()) return it->second;
    // Environment through the lamp's shadow (4096 directions: ~1e-3 for λ ≤ 20) plus the lamp in closed form.
    Vec3 e_env;
    for (const Vec3& d : dirs) {
      if (d.z <= 0) continue;
      const Vec3 oc = x - lamp;
      const double b = Dot(oc, d), c = Dot(oc, oc) - rho * rho;
      if (b * b - c > 0 && -b - std::sqrt(b * b - c) > 0) continue;  // the lamp hides this direction
      e_env += Evaluate(env, d) * d.z;
    }
    e_env = e_env * (4 * kPi / dirs.size());
    const Vec3 to = lamp - x;
    const double dist = Length(to);
    const double e_lamp = kPi * le * (rho / dist) * (rho / dist) * std::max(0.0, to.z / dist);
    floor_env += LuminanceOf(e_env);
    floor_lamp += e_lamp;
    return floor[{x.x, x.y}] = (e_env + Vec3{e_lamp, e_lamp, e_lamp}) * (0.5 / kPi);
  });
  ASSERT_GT(floor_env, 0.3 * floor_lamp) << "the scene must hold a sizeable environment share";
  EnvEstimateOptions o = TestOptions();
  o.rays_per_point = 512;
  o.near_field_pool_m = 0.15;
  o.light_energy_weight = 1e-2;  // the options that flag the lamp-only scene above
  const EnvLight est = EstimateEnvironment(field, o);
  EXPECT_FALSE(est.negligible);
  // True floor share floor_env / floor_lamp ≥ 0.3 (asserted above); the
  // estimate may miss part of it (prior, dictionary) but not most of it.
  EXPECT_GT(est.env_to_near_surface, 0.1) << "true floor share " << floor_env / floor_lamp;
  EXPECT_GT(est.env_to_near_center, 0.05);
}

// E_nerf against a closed form: a point under a uniform emitting dome (a
// hemispherical shell of radiance L around it, open below) receives
// E(n) = π L (1 + cos θ)/2 for a normal tilted θ from +z.
TEST(EnvEstimate, NearFieldIrradianceMatchesAUniformDome) {
  const double le = 2.0, radius = 0.6, voxel = 0.02;
  const Aabb box{{-0.7, -0.7, -0.1}, {0.7, 0.7, 0.7}};
  Shape s;
  s.sd = [&](const Vec3& p) {
    const double shell = std::fabs(Length(p) - radius) - 0.03;  // 6 cm thick: opaque
    return p.z < 0 ? std::max(shell, -p.z) : shell;
  };
  s.project = [&](const Vec3& p, Vec3* x, Vec3* n) {
    *n = Normalized(p) * -1.0;
    *x = p;
  };
  const NerfField field = MakeField(box, voxel, s, [&](const Vec3&, const Vec3&) { return Vec3{le, le, le}; });
  EnvSurfaceSamples samples;
  for (double theta_deg : {0.0, 30.0, 60.0, 90.0}) {
    const double t = theta_deg * kPi / 180;
    samples.positions.push_back({0, 0, 0});
    samples.normals.push_back(Vec3f(Vec3{std::sin(t), 0, std::cos(t)}));
    samples.radiance.push_back({1, 1, 1});
  }
  EnvEstimateOptions o;
  o.rays_per_point = 1024;
  o.ray_offset_voxels = 0;
  o.render.step_voxels = 0.25f;
  ComputeNearField(field, o, samples);
  for (size_t i = 0; i < samples.size(); ++i) {
    const double cos_t = samples.normals[i].z;
    const double expected = kPi * le * (1 + cos_t) / 2;
    // 2 %: the quasi-random quadrature of a cosine lobe cut by the z = 0 edge
    // (1024 rays: ~0.5 %) plus the shell's opacity (1 − e^{−σ·6 cm} ≈ 1) and its
    // edge at z = 0 being a voxel-wide ramp rather than a sharp cut.
    EXPECT_NEAR(samples.e_nerf[i].y, expected, 0.02 * kPi * le) << "theta cos " << cos_t;
    EXPECT_EQ(samples.e_nerf[i].x, samples.e_nerf[i].y);
  }
}

// 90 normals up and 10 along +x (two of the 32 direction bins): weights
// against the counts worked out by hand.
TEST(EnvEstimate, NormalBalanceWeightsFollowTheBinCounts) {
  std::vector<Vec3f> normals(90, Vec3f{0, 0, 1});
  normals.insert(normals.end(), 10, Vec3f{1, 0, 0});
  for (double w : NormalBalanceWeights(normals, 0)) EXPECT_EQ(w, 1.0);
  // power 1: both bins carry the same total, 90 w_up = 10 w_side, mean 1:
  // w_up = 100 / (2·90), w_side = 100 / (2·10). Tolerance: rounding only.
  const std::vector<double> full = NormalBalanceWeights(normals, 1);
  EXPECT_NEAR(full.front(), 100.0 / 180, 1e-12);
  EXPECT_NEAR(full.back(), 100.0 / 20, 1e-12);
  // power 0.75: w ∝ count^−0.75, mean 1.
  const double up = std::pow(90.0, -0.75), side = std::pow(10.0, -0.75), scale = 100 / (90 * up + 10 * side);
  const std::vector<double> part = NormalBalanceWeights(normals, 0.75);
  EXPECT_NEAR(part.front(), up * scale, 1e-12);
  EXPECT_NEAR(part.back(), side * scale, 1e-12);
  // The side samples glow (luminance 100 against a median of 1, above 10x):
  // they are not weighted up (capped at 1); the up samples keep theirs.
  std::vector<Vec3f> radiance(90, Vec3f{1, 1, 1});
  radiance.insert(radiance.end(), 10, Vec3f{100, 100, 100});
  const std::vector<double> glow = NormalBalanceWeights(normals, 1, &radiance);
  EXPECT_NEAR(glow.front(), 100.0 / 180, 1e-12);
  EXPECT_EQ(glow.back(), 1.0);
}

// A lamp (sphere of radius 2 cm, 20 cm above the points) whose NeRF
// radiance is right on its upper half (le) and 8x too dark on its lower half,
// which no camera from above saw well. The irradiance it gives points below
// it, by the analytic formula for a uniform sphere, E = π le (ρ/D)² cos θ.
NerfField HalfDarkLamp(const Vec3& lamp, double rho, double le) {
  Shape s;
  s.sd = [&](const Vec3& p) { return Length(p - lamp) - rho; };
  s.project = [&](const Vec3& p, Vec3* x, Vec3* n) {
    *n = Normalized(p - lamp);
    *x = lamp + *n * rho;
  };
  const Aabb box{{-0.15, -0.15, 0.0}, {0.15, 0.15, 0.35}};
  return MakeField(box, 0.005, s, [&](const Vec3& x, const Vec3&) {
    const double l = x.z >= lamp.z ? le : le / 8;
    return Vec3{l, l, l};
  });
}
const Vec3 kHalfDarkLampAt{0, 0, 0.25};
constexpr double kHalfDarkLampRadius = 0.02, kHalfDarkLampRadiance = 10;

TEST(SeenRadiance, RestoresALampsUnseenUndersideInTheNearField) {
  const Vec3 lamp = kHalfDarkLampAt;
  const double rho = kHalfDarkLampRadius, le = kHalfDarkLampRadiance;
  const NerfField field = HalfDarkLamp(lamp, rho, le);
  EnvSurfaceSamples samples;
  for (int k = 0; k < 16; ++k) {
    samples.positions.push_back(Vec3f{0.01f * (k % 4) - 0.015f, 0.01f * (k / 4) - 0.015f, 0.05f});
    samples.normals.push_back(Vec3f{0, 0, 1});
    samples.radiance.push_back(Vec3f{1, 1, 1});
  }
  EnvEstimateOptions o = TestOptions();
  o.rays_per_point = 4096;  // ~1 % of the cosine-weighted rays hit the lamp: ~40 per point
  o.near_field_pool_m = 0;
  o.ray_offset_voxels = 1;
  // The whole band's rule: this NeRF is dark on its lower half towards
  // every direction, the band's too (face views would believe it there;
  // they are tested below with a NeRF that is right towards the band).
  o.seen_radiance_face_views = false;
  double truth = 0;  // mean analytic irradiance over the points
  for (const Vec3f& x : samples.positions) {
    const Vec3 to = lamp - Vec3(x);
    const double d = Length(to);
    truth += kPi * le * (rho / d) * (rho / d) * (to.z / d) / samples.size();
  }
  auto mean_e = [&](bool seen) {
    EnvSurfaceSamples s = samples;
    o.near_field_seen_radiance = seen;
    ComputeNearField(field, o, s);
    double e = 0;
    for (const Vec3f& v : s.e_nerf) e += LuminanceOf(Vec3(v)) / s.size();
    return e;
  };
  const double without = mean_e(false), with = mean_e(true);
  // Without: the rays see the dark half (le/8): < 0.3 of the truth.
  EXPECT_LT(without, 0.3 * truth);
  // With: within 20 % (the 5 mm voxels make the 2 cm sphere's outline
  // uncertain by ~1/5 voxel, ~10 % of its solid angle; ~40 rays per point
  // over 16 points: ~4 % noise).
  EXPECT_GT(with, 0.8 * truth) << "without " << without << " truth " << truth;
  EXPECT_LT(with, 1.2 * truth) << "without " << without << " truth " << truth;
}

TEST(SeenRadiance, LeavesRaysSeenFromAboveAndUnreachedPointsAlone) {
  const NerfField field = HalfDarkLamp(kHalfDarkLampAt, kHalfDarkLampRadius, kHalfDarkLampRadiance);
  // One ray up from below the lamp (hits the dark half), one down from above it (hits the bright half).
  std::vector<NerfRay> rays(2);
  rays[0] = NerfRay{Vec3f{0.0f, 0.0f, 0.05f}, Vec3f{0, 0, 1}, 0, 0};
  rays[1] = NerfRay{Vec3f{0.0f, 0.0f, 0.34f}, Vec3f{0, 0, -1}, 0, 0};
  for (NerfRay& r : rays) ASSERT_TRUE(IntersectAabb(field.aabb, r.origin, r.dir, r.t_near, r.t_far));
  std::vector<NerfRayResult> raw(2);
  field.RenderRays(rays.data(), rays.size(), raw.data());
  ASSERT_GT(raw[0].opacity, 0.9f);
  ASSERT_LT(raw[0].color.y, kHalfDarkLampRadiance / 4);  // the dark underside
  // Reach 1 mm: no view from above lands that close to the underside's point: nothing changes.
  SeenRadianceOptions tight;
  tight.reach_m = 0.001;
  std::vector<NerfRayResult> res = raw;
  EXPECT_EQ(ApplySeenRadiance(field, rays, res, tight), 0u);
  EXPECT_EQ(res[0].color.y, raw[0].color.y);
  // Default reach (5 cm > the lamp's 4 cm diameter: every view from above reaches).
  res = raw;
  EXPECT_EQ(ApplySeenRadiance(field, rays, res, SeenRadianceOptions{}), 1u);
  EXPECT_EQ(res[1].color.y, raw[1].color.y);  // seen from above: the NeRF's own colour
  // The underside now shows the upper half's radiance, le times the ray's
  // opacity, within 10 % (interpolated colour and opacity near the surface).
  EXPECT_NEAR(res[0].color.y, kHalfDarkLampRadiance * raw[0].opacity, 0.1 * kHalfDarkLampRadiance);
}

// An emitting panel (12 x 8 cm, 4 cm deep, 5 mm voxels) 25 cm above the
// receivers, its front tilted 55° below the horizon towards −x (as the shared
// lamps scene's panel): the front faces away from most of the capture band.
// The NeRF's front radiance is right towards the band (a ring of capture
// directions at elevation kRingDeg, seen from the panel) and falls with the
// ray's upward component (the field's log-linear view model, slope −3 in
// d_z): seen from the receivers below it is 20-40x too dark, as an emitter no
// camera saw head-on. Back and sides: dark backing.
constexpr double kRingDeg = 20, kPanelLe = 40;
const Vec3 kPanelCentre{0, 0, 0.25};
const std::array<Vec3, 3> kPanelAxes = {Vec3{-std::cos(55 * kPi / 180), 0, -std::sin(55 * kPi / 180)}, Vec3{0, 1, 0},
                                        Vec3{-std::sin(55 * kPi / 180), 0, std::cos(55 * kPi / 180)}};
const Vec3 kPanelHalf{0.02, 0.06, 0.04};

NerfField TiltedPanel(double k = 3, double ring_deg = kRingDeg) {
  const Aabb box{{-0.25, -0.12, -0.02}, {0.15, 0.12, 0.33}};
  const double ring_dz = -std::sin(ring_deg * kPi / 180);
  // The front's colour reaches 1.5 voxels round its rim (onto the sides, seen
  // edge-on from the receivers), so that the grid's colour blending at the rim
  // does not darken it: the NeRF's front shows le to its edges.
  auto front = [](const Vec3& x) { return Dot(x - kPanelCentre, kPanelAxes[0]) > kPanelHalf.x - 0.0075; };
  return MakeField(
      box, 0.005, OrientedBox(kPanelCentre, kPanelAxes, kPanelHalf),
      [&](const Vec3& x, const Vec3&) {
        // log L = log le + k (ring_dz − d_z): le along the ring's views.
        const double l = front(x) ? kPanelLe * std::exp(k * ring_dz) : 0.02 * kPanelLe;
        return Vec3{l, l, l};
      },
      [&](const Vec3& x, const Vec3&) {
        return front(x) ? Vec3{0, 0, -k} : Vec3{};
      });
}

// Irradiance at p (normal +z) from the panel's front of radiance kPanelLe by
// brute-force quadrature over its area (240 x 160 cells).
double PanelIrradiance(const Vec3& p) {
  const Vec3 centre = kPanelCentre + kPanelAxes[0] * kPanelHalf.x;
  const int nu = 240, nv = 160;
  const double du = 2 * kPanelHalf.y / nu, dv = 2 * kPanelHalf.z / nv;
  double e = 0;
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      const Vec3 y =
          centre + kPanelAxes[1] * (-kPanelHalf.y + (i + 0.5) * du) + kPanelAxes[2] * (-kPanelHalf.z + (j + 0.5) * dv);
      const Vec3 to = y - p;
      const double r2 = Dot(to, to), r = std::sqrt(r2);
      const double cos_r = std::max(0.0, to.z / r), cos_e = std::max(0.0, -Dot(to, kPanelAxes[0]) / r);
      e += kPanelLe * cos_r * cos_e / r2 * du * dv;
    }
  return e;
}

// Four receivers in front of and below the panel, kPanelRays cosine-distributed
// rays each (a Fibonacci disk lifted to the hemisphere): E = π/N Σ L.
const std::vector<Vec3> kPanelReceivers = {{-0.17, -0.02, 0}, {-0.13, -0.02, 0}, {-0.17, 0.02, 0}, {-0.13, 0.02, 0}};
constexpr int kPanelRays = 16384;

std::vector<NerfRay> PanelReceiverRays(const NerfField& field) {
  std::vector<NerfRay> rays;
  const double golden = kPi * (3.0 - std::sqrt(5.0));
  for (const Vec3& p : kPanelReceivers)
    for (int i = 0; i < kPanelRays; ++i) {
      const double r = std::sqrt((i + 0.5) / kPanelRays), phi = golden * i;
      NerfRay ray{Vec3f(p), Vec3f(Vec3{r * std::cos(phi), r * std::sin(phi), std::sqrt(1 - r * r)}), 0, 0};
      if (!IntersectAabb(field.aabb, ray.origin, ray.dir, ray.t_near, ray.t_far)) ray.t_far = ray.t_near = 0;
      rays.push_back(ray);
    }
  return rays;
}

// The receivers' mean irradiance from their rays' radiance.
double PanelReceiversIrradiance(const std::vector<NerfRayResult>& res) {
  double e = 0;
  for (const NerfRayResult& r : res) e += LuminanceOf(Vec3(r.color));
  return e * kPi / kPanelRays / kPanelReceivers.size();
}

// The same grid with the front's le towards every direction: what the
// NeRF's panel can give at best (its grid's rim and interpolation).
double UniformPanelReceiversIrradiance() {
  const NerfField uniform = TiltedPanel(0);
  const std::vector<NerfRay> rays = PanelReceiverRays(uniform);
  std::vector<NerfRayResult> best(rays.size());
  uniform.RenderRays(rays.data(), rays.size(), best.data());
  return PanelReceiversIrradiance(best);
}

// The receivers' mean irradiance from the panel's front of radiance kPanelLe.
double PanelReceiversTruth() {
  double truth = 0;
  for (const Vec3& p : kPanelReceivers) truth += PanelIrradiance(p) / kPanelReceivers.size();
  return truth;
}

TEST(SeenRadiance, FaceViewsRestoreAPanelFacingAwayFromTheBand) {
  const NerfField field = TiltedPanel();
  const std::vector<NerfRay> rays = PanelReceiverRays(field);
  std::vector<NerfRayResult> raw(rays.size());
  field.RenderRays(rays.data(), rays.size(), raw.data());
  const double truth = PanelReceiversTruth();
  SeenRadianceOptions ring;
  ring.min_elevation_deg = kRingDeg;
  ring.max_elevation_deg = kRingDeg;
  std::vector<NerfRayResult> face = raw, band = raw;
  ApplySeenRadiance(field, rays, face, ring);
  SeenRadianceOptions whole = ring;
  whole.face_views = false;
  ApplySeenRadiance(field, rays, band, whole);
  const double e_raw = PanelReceiversIrradiance(raw), e_face = PanelReceiversIrradiance(face),
               e_band = PanelReceiversIrradiance(band), e_best = UniformPanelReceiversIrradiance();
  LogInfo("panel irradiance: truth " + std::to_string(truth) + ", NeRF " + std::to_string(e_raw) + ", face views " +
          std::to_string(e_face) + ", whole band " + std::to_string(e_band) + ", grid seen uniform " +
          std::to_string(e_best));
  // The NeRF's own radiance towards the receivers: < 1/10 of the truth.
  EXPECT_LT(e_raw, 0.1 * truth);
  // Face views recover the panel's flux within 15 %: the grid's front seen
  // uniform gives 88 % of the analytic flux (its rim blends with the dark
  // sides over ~1 voxel of its 24 x 16), the rays' quadrature ~2 %...
  EXPECT_NEAR(e_face, truth, 0.15 * truth);
  // ... and within 5 % of that uniform grid (the ring's views see le; rays
  // at the rim under the opacity threshold keep their own colour).
  EXPECT_NEAR(e_face, e_best, 0.05 * e_best);
}

// `count` camera centres on a ring 2 m round the panel at elevation
// `elevation_deg`, in order of azimuth from +x (behind the panel's front).
std::vector<Vec3f> RingCameras(int count, double elevation_deg) {
  std::vector<Vec3f> centres;
  const double el = elevation_deg * kPi / 180;
  for (int k = 0; k < count; ++k) {
    const double az = 2 * kPi * k / count;
    centres.push_back(
        Vec3f(kPanelCentre + Vec3{std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)} * 2.0));
  }
  return centres;
}

// The irradiance over the panel's receivers with the seen radiance taken
// through `field` (whose capture_centres decide the views).
double PanelReceiversSeenIrradiance(const NerfField& field) {
  const std::vector<NerfRay> rays = PanelReceiverRays(field);
  std::vector<NerfRayResult> results(rays.size());
  field.RenderRays(rays.data(), rays.size(), results.data());
  ApplySeenRadiance(field, rays, results, SeenRadianceOptions{});
  return PanelReceiversIrradiance(results);
}

TEST(SeenRadiance, CaptureCamerasGiveTheRadianceTheNeRFWasTrainedOn) {
  // The capture's 24 cameras stand on a ring at 12° elevation round the
  // panel, 2 m away, and its NeRF is right (kPanelLe) only towards them: its
  // front is brighter towards higher directions (k = 3: 1.5× at 20°, 2.2× at
  // 28°), as an emitter trained from low views alone. The band's face views
  // (elevations 10-70°, those in front of the face: up to ~28°) land above
  // the ring and see it too bright; the views aimed from the cameras see it
  // as trained.
  constexpr double kCaptureDeg = 12;
  const NerfField band_field = TiltedPanel(3, kCaptureDeg);  // a model that does not store its cameras
  NerfField field = band_field;
  field.capture_centres = RingCameras(24, kCaptureDeg);
  const double e_band = PanelReceiversSeenIrradiance(band_field), e_cameras = PanelReceiversSeenIrradiance(field),
               e_best = UniformPanelReceiversIrradiance();
  LogInfo("panel trained from 12° views: band " + std::to_string(e_band) + ", capture cameras " +
          std::to_string(e_cameras) + ", grid seen uniform " + std::to_string(e_best) + ", truth " +
          std::to_string(PanelReceiversTruth()));
  // The cameras' views: within 5 % of the uniform grid, as the face views on
  // the ring of the test above. A point up to 6 cm off the panel's centre
  // sees a camera 2 m away up to 1.7° off the ring's elevation, a factor of
  // e^{±3·0.03} (±9 %) on that point, which averages out over the face
  // (measured: 2.8 % over the uniform grid).
  EXPECT_NEAR(e_cameras, e_best, 0.05 * e_best);
  // The band's: more than 20 % too bright (its face views lie 0-16° above
  // the ring, up to e^{3(sin 28° − sin 12°)} = 2.2×).
  EXPECT_GT(e_band, 1.2 * e_best);
}

TEST(SeenRadiance, ALongCaptureIsThinnedOverItsWholeWalk) {
  // 960 cameras on the ring (a video's frames), in order of azimuth from
  // behind the panel: the views take at most 16 × 12 of them, spread over
  // the whole walk, so those in front of the panel (azimuth 90-270°) are
  // among them. Taking the first ones instead (azimuth 0-72°, behind it)
  // leaves the front unseen (measured: a seventh of the uniform grid's).
  NerfField field = TiltedPanel(3, 12);
  field.capture_centres = RingCameras(960, 12);
  const double e_long = PanelReceiversSeenIrradiance(field), e_best = UniformPanelReceiversIrradiance();
  // Within 5 % of the uniform grid, as the 24-camera capture above (192
  // cameras 1.9° apart on the ring see the face as those 15° apart do).
  EXPECT_NEAR(e_long, e_best, 0.05 * e_best);
  // The logs say how many the views take.
  EXPECT_EQ(SeenViewsNote(field, SeenRadianceOptions{}), "views from 192 of the capture's 960 cameras");
  field.capture_centres.resize(24);
  EXPECT_EQ(SeenViewsNote(field, SeenRadianceOptions{}), "views from the capture's 24 cameras");
}

// A bulb (radius 3 cm, radiance 100) on a dark pole (radius 1 cm). A light
// ray meets the pole 1.5 cm under the bulb, another the bulb's lower side,
// whose NeRF radiance towards the ray is 10x too dark (never photographed
// from there).
TEST(SeenRadiance, FaceViewsKeepABulbsRadianceOffItsPole) {
  const Vec3 bulb{0, 0, 0.30};
  const double rho = 0.03, pole = 0.01, le = 100;
  Shape s;
  s.sd = [=](const Vec3& p) {
    const double cyl = std::max(std::hypot(p.x, p.y) - pole, std::max(-p.z, p.z - bulb.z));
    return std::min(Length(p - bulb) - rho, cyl);
  };
  s.project = [=](const Vec3& p, Vec3* x, Vec3* n) {
    const double r = std::hypot(p.x, p.y);
    if (Length(p - bulb) - rho < r - pole || r == 0) {
      *n = Normalized(p - bulb);
      *x = bulb + *n * rho;
    } else {
      *n = Vec3{p.x / r, p.y / r, 0};
      *x = Vec3{p.x / r * pole, p.y / r * pole, p.z};
    }
  };
  const Aabb box{{-0.35, -0.1, -0.02}, {0.1, 0.1, 0.36}};
  const NerfField field = MakeField(box, 0.005, s, [&](const Vec3& x, const Vec3&) {
    const double l = Length(x - bulb) < rho + 1e-6 ? le : 0.01 * le;
    return Vec3{l, l, l};
  });
  const Vec3f origin{-0.30f, 0.0f, 0.02f};
  const Vec3f targets[2] = {{-0.01f, 0.0f, 0.255f}, {-0.02f, 0.0f, 0.28f}};
  std::vector<NerfRay> rays;
  for (const Vec3f& t : targets) {
    NerfRay ray{origin, Normalized(t - origin), 0, 0};
    ASSERT_TRUE(IntersectAabb(field.aabb, ray.origin, ray.dir, ray.t_near, ray.t_far));
    rays.push_back(ray);
  }
  std::vector<NerfRayResult> raw(2);
  field.RenderRays(rays.data(), rays.size(), raw.data());
  ASSERT_GT(raw[0].opacity, 0.9f);
  ASSERT_GT(raw[1].opacity, 0.9f);
  ASSERT_LT(raw[0].color.y, 0.05 * le);  // the pole
  ASSERT_GT(raw[1].color.y, 0.5 * le);   // the bulb, before it is made dark below
  raw[1].color = raw[1].color * 0.1f;
  SeenRadianceOptions whole;
  whole.face_views = false;
  std::vector<NerfRayResult> face = raw, band = raw;
  ApplySeenRadiance(field, rays, face, SeenRadianceOptions{});
  ApplySeenRadiance(field, rays, band, whole);
  // The whole band's rule lends the pole the bulb's radiance (views from
  // above aimed at the pole meet the bulb within reach_m): the flaw fixed.
  EXPECT_GT(band[0].color.y, 0.5 * le * raw[0].opacity);
  // Face views see the pole itself: it stays dark, under 5 % of the bulb
  // (the grid's colour blends pole and bulb over ~3 voxels, 1.5 cm, under
  // the bulb: the pole reads up to ~3 % of it there).
  EXPECT_LT(face[0].color.y, 0.05 * le);
  // The bulb's lower side gets the radiance its face shows the band, le
  // times the ray's opacity, within 10 % (interpolated colour near the
  // surface, as the lamp test above).
  EXPECT_NEAR(face[1].color.y, le * raw[1].opacity, 0.1 * le);
}

// A point's seen radiance from its views (grey radiances: luminance = the
// value). Two views of an emitter (120, 200) and one that meets the lamp's
// dark frame at the point (10): at 0.5 the frame's view is left out and the
// emitter's two averaged; 1 keeps the brightest alone, 0 averages all.
TEST(SeenRadiance, AgreeingRadianceAveragesTheViewsNearTheBrightest) {
  const auto grey = [](float v) { return Vec3f{v, v, v}; };
  const std::vector<Vec3f> views = {grey(120), grey(200), grey(10)};
  Vec3f out;
  ASSERT_TRUE(AgreeingRadiance(views, 0.5, out));
  EXPECT_NEAR(out.y, 160.0f, 1e-3f);
  ASSERT_TRUE(AgreeingRadiance(views, 1.0, out));
  EXPECT_NEAR(out.y, 200.0f, 1e-3f);
  ASSERT_TRUE(AgreeingRadiance(views, 0.0, out));
  EXPECT_NEAR(out.y, 110.0f, 1e-3f);
  // Every view darker than black (a field's negative colour): their mean.
  ASSERT_TRUE(AgreeingRadiance({grey(-1), grey(-3)}, 0.5, out));
  EXPECT_NEAR(out.y, -2.0f, 1e-5f);
  // No view: nothing, `out` untouched.
  out = grey(7);
  EXPECT_FALSE(AgreeingRadiance({}, 0.5, out));
  EXPECT_EQ(out.y, 7.0f);
}

TEST(EnvEstimate, OptionsValidateAndSet) {
  EnvEstimateOptions o;
  EXPECT_TRUE(o.Validate().empty());
  for (const char* p : {"fast", "balanced", "accurate"}) EXPECT_TRUE(EnvEstimateOptions::Preset(p).Validate().empty());
  EXPECT_THROW(EnvEstimateOptions::Preset("slow"), InputError);
  o.Set("rays_per_point=64");
  EXPECT_EQ(o.rays_per_point, 64);
  o.Set("ignore_near_field=true");
  o.Set("normal_balance=0.5");
  EXPECT_EQ(o.normal_balance, 0.5);
  o.Set("seen_radiance_views=0");
  EXPECT_TRUE(o.ignore_near_field);
  EXPECT_THROW(o.Set("rays_per_pont=64"), InputError);
  EXPECT_THROW(o.Set("rays_per_point=6x"), InputError);
  EXPECT_THROW(o.Set("rays_per_point"), InputError);
  o.views = 0;
  o.lobes = 100;
  const std::vector<std::string> problems = o.Validate();
  ASSERT_GE(problems.size(), 2u);
  std::string all;
  for (const std::string& p : problems) all += p + "\n";
  EXPECT_NE(all.find("views:"), std::string::npos) << all;
  EXPECT_NE(all.find("lobes:"), std::string::npos) << all;
  EXPECT_NE(all.find("seen_radiance_views:"), std::string::npos) << all;
}

TEST(ViewQuality, BrisqueRejectsNoiseAndKeepsACleanImage) {
  if (FindBrisqueModelDir().empty()) GTEST_SKIP() << "opencv-data's BRISQUE model is not installed";
  BrisqueScorer scorer;
  // Clean: smooth shading with a few sharp edges (a lit disk on a gradient),
  // like a good NeRF rendering. Noise: independent uniform pixels.
  Image8 clean(128, 96, 1), noise(128, 96, 1);
  uint64_t state = 12345;
  for (int y = 0; y < 96; ++y)
    for (int x = 0; x < 128; ++x) {
      const double r = std::hypot(x - 64.0, y - 48.0);
      const double v = r < 30 ? 200 - 2.0 * r : 40 + x * 0.8 + y * 0.3;
      clean.at(x, y) = static_cast<uint8_t>(std::clamp(v, 0.0, 255.0));
      state = state * 6364136223846793005ull + 1442695040888963407ull;
      noise.at(x, y) = static_cast<uint8_t>(state >> 56);
    }
  const double s_clean = scorer.Score(clean), s_noise = scorer.Score(noise);
  EXPECT_GT(s_noise, 50) << "clean " << s_clean;  // the paper's rejection limit
  // BRISQUE is trained on photographs, so this drawing is not "natural"
  // enough to pass 50 itself; it must still rank far better than noise.
  EXPECT_LT(s_clean + 10, s_noise);
  EXPECT_THROW(BrisqueScorer("/nonexistent"), InputError);
}

}  // namespace
}  // namespace nerfar
