// render/insert/incident_light: environment lobes sharper than the light's
// N directions resolve (a sun) pass analytically. The threshold against the
// quadrature error it is derived from; the incident light of a table under a
// small, very bright sun against an independent quadrature (1 M Fibonacci
// directions through the scene's closed form: the sharpest sun is ~3 of their
// spacings wide); the transmittance towards a half-hidden sun against the
// same brute force.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "render/lighting/incident_light.h"
#include "render/lighting/scene_field.h"
#include "render/sg/prefiltered.h"
#include "render/sg/sphere.h"
#include "render/sg/visibility.h"
#include "tests/support/analytic_scene.h"

namespace nerfar {
namespace {

// Σ G(d_i)·4π/N over N Fibonacci directions, relative to the lobe's integral:
// the worst over axes spread over the sphere.
double WorstQuadratureError(int n, double sharpness) {
  const std::vector<Vec3> dirs = FibonacciSphere(n);
  double worst = 0.0;
  for (const Vec3& axis : FibonacciSphere(200)) {
    double sum = 0.0;
    for (const Vec3& d : dirs) sum += SgShape(axis, sharpness, d);
    worst = std::max(worst, std::abs(sum * 4.0 * kPi / n / SgUnitIntegral(sharpness) - 1.0));
  }
  return worst;
}

TEST(CompactLobes, ThresholdIsWhereTheDirectionsStopCarryingALobe) {
  // CompactSharpness claims: up to λ = N/(4π) (σ = h) the N directions
  // integrate a lobe within 1-2 % whatever its axis, and not far past it
  // (λ × 8: σ = h/2.8) they no longer do.
  for (int n : {512, 1024, 2048}) {
    const double at = WorstQuadratureError(n, CompactSharpness(n));
    const double beyond = WorstQuadratureError(n, 8.0 * CompactSharpness(n));
    std::printf("N %d: λ_c %.0f, worst quadrature error %.4f at λ_c, %.3f at 8 λ_c\n", n, CompactSharpness(n), at,
                beyond);
    EXPECT_LT(at, 0.02);
    EXPECT_GT(beyond, 0.2);
  }
}

TEST(CompactLobes, SplitKeepsTheMostEnergeticCompactLobesWithinTheBudget) {
  const double sharp = CompactSharpness(1024);
  const auto lobe = [](double sharpness, double mu) { return Sg{{0, 0, 1}, sharpness, {mu, mu, mu}}; };
  // Energies ∝ μ/λ: 1, 3 and 2 (× 2π) for the three compact ones.
  const SgMixture env = {lobe(2.0, 1.0), lobe(2.0 * sharp, 2.0 * sharp), lobe(3.0 * sharp, 9.0 * sharp),
                         lobe(4.0 * sharp, 8.0 * sharp)};
  SgMixture broad, compact;
  SplitCompactLobes(env, 1024, 2, &broad, &compact);
  ASSERT_EQ(compact.size(), 2u);
  ASSERT_EQ(broad.size(), 2u);
  EXPECT_EQ(compact[0].sharpness, 3.0 * sharp);  // original order kept
  EXPECT_EQ(compact[1].sharpness, 4.0 * sharp);
  EXPECT_EQ(broad[0].sharpness, 2.0);
  EXPECT_EQ(broad[1].sharpness, 2.0 * sharp);  // the least energetic compact lobe stays broad
  SplitCompactLobes(env, 1024, 0, &broad, &compact);
  EXPECT_TRUE(compact.empty());
  EXPECT_EQ(broad.size(), env.size());
}

// A table (the analytic scene's plane, no sphere or medium) under a sun of
// sharpness λ (energy 8.7 in luminance, about the sunroom's) and a dim sky.
struct SunnyTable {
  testing::AnalyticScene scene;
  Vec3 center{0.05, -0.02, 0.06};
  SgMixture environment;
  explicit SunnyTable(
      double sharpness, testing::AnalyticSceneParams params =
                            [] {
                              testing::AnalyticSceneParams p;
                              p.has_sphere = p.has_medium = false;
                              return p;
                            }())
      : scene(params) {
    Sg sun;
    sun.axis = Normalized(Vec3{-0.66, -0.36, 0.65});
    sun.sharpness = sharpness;
    const double mu = 8.7 / SgUnitIntegral(sharpness);
    sun.amplitude = {mu, 0.93 * mu, 0.83 * mu};
    environment = {sun, Sg{{0, 0, 1}, 1.5, {0.25, 0.3, 0.45}}};
  }
  const Sg& sun() const { return environment[0]; }
};

// The true incident light at the centre, by brute force: per direction of a
// 1 M Fibonacci set, Ĉ + (1 − Ô)·L_env from the scene's closed form.
struct TrueLight {
  std::vector<Vec3> dirs;
  std::vector<Vec3> radiance;
  double transmittance_to_sun = 0;  // ∫ G_sun (1 − Ô) / ∫ G_sun
  TrueLight(const SunnyTable& t, int n = 1000000) : dirs(FibonacciSphere(n)), radiance(n) {
    double seen = 0, all = 0;
    for (int i = 0; i < n; ++i) {
      const auto range = IntersectBox(t.scene.Box(), t.center, dirs[i]);
      Vec3 colour;
      double opacity = 0, depth = 0;
      if (range) t.scene.RenderOne(t.center, dirs[i], range->first, range->second, colour, opacity, depth);
      radiance[i] = colour + Evaluate(t.environment, dirs[i]) * (1.0 - opacity);
      const double g = SgShape(t.sun().axis, t.sun().sharpness, dirs[i]);
      seen += g * (1.0 - opacity), all += g;
    }
    transmittance_to_sun = seen / all;
  }
  double Omega() const { return 4.0 * kPi / dirs.size(); }
};

// Luminance flux within `cone_rad` of `axis` and its mean direction, of a
// radiance function over the directions.
template <class Radiance>
std::pair<double, Vec3> ConeFlux(const std::vector<Vec3>& dirs, double omega, const Vec3& axis, double cone_rad,
                                 const Radiance& radiance) {
  double flux = 0;
  Vec3 mean;
  const double c = std::cos(cone_rad);
  for (size_t i = 0; i < dirs.size(); ++i) {
    if (Dot(dirs[i], axis) < c) continue;
    const double y = LuminanceOf(radiance(i)) * omega;
    flux += y;
    mean += dirs[i] * y;
  }
  return {flux, Normalized(mean)};
}

double AngleDeg(const Vec3& a, const Vec3& b) { return std::acos(std::clamp(Dot(a, b), -1.0, 1.0)) * 180.0 / kPi; }

// Relative RMS of the light's irradiance against the truth's over 64 normals
// (DESIGN.md's lighting error).
double LightingError(const SgMixture& light, const TrueLight& truth) {
  double num = 0, den = 0;
  for (const Vec3& n : FibonacciSphere(64)) {
    double e_true = 0;
    for (size_t i = 0; i < truth.dirs.size(); ++i) {
      const double c = Dot(truth.dirs[i], n);
      if (c > 0) e_true += LuminanceOf(truth.radiance[i]) * c;
    }
    e_true *= truth.Omega();
    const double e = LuminanceOf(Irradiance(light, n));
    num += (e - e_true) * (e - e_true), den += e_true * e_true;
  }
  return std::sqrt(num / den);
}

// Tolerances: the sun's flux within 5 % and its centre within 0.5° (the
// analytic lobe is the environment's own, attenuated by a transmittance of
// 1 here: what is left is the fitted broad part's spill into the cone);
// lighting error 0.05 (the 32-lobe fit of the table and sky, ~0.02-0.03).
// The sampled path (analytic_compact_lobes off) is printed beside it: the
// issue's failure, the sun's flux and direction at the mercy of where the
// 1024 directions fall.
TEST(CompactLobes, IncidentLightKeepsASmallSunsEnergyAndDirection) {
  for (double sharpness : {2000.0, 10000.0}) {  // a 5° sun, a 1° one
    const SunnyTable table(sharpness);
    const TrueLight truth(table);
    const double cone = 5.0 * kPi / 180.0;
    const auto [true_flux, true_dir] =
        ConeFlux(truth.dirs, truth.Omega(), table.sun().axis, cone, [&](size_t i) { return truth.radiance[i]; });
    for (bool analytic : {true, false}) {
      IncidentLightOptions options;
      options.analytic_compact_lobes = analytic;
      IncidentLight light;
      light.Refresh(table.scene, table.environment, table.center, options);
      const auto [flux, dir] = ConeFlux(truth.dirs, truth.Omega(), table.sun().axis, cone,
                                        [&](size_t i) { return Evaluate(light.light(), truth.dirs[i]); });
      const double error = LightingError(light.light(), truth);
      std::printf("λ %.0f, %s: sun flux %.3f (truth %.3f), centre off by %.2f°, lighting error %.3f\n", sharpness,
                  analytic ? "analytic" : "sampled ", flux, true_flux, AngleDeg(dir, true_dir), error);
      if (!analytic) continue;
      ASSERT_EQ(light.compact().size(), 1u);
      EXPECT_NEAR(flux, true_flux, 0.05 * true_flux);
      EXPECT_LT(AngleDeg(dir, true_dir), 0.5);
      EXPECT_LT(error, 0.05);
      // Its width is the environment's: the refit does not smear it.
      EXPECT_EQ(light.compact()[0].sharpness, sharpness);
    }
  }
}

// The table's opaque sphere half in front of the sun, seen from the centre:
// the lobe's transmittance against the brute force's, within 1/16 (the
// bundle's 16 rays resolve it in such steps); the sun wholly hidden and
// wholly free at the ends.
TEST(CompactLobes, TransmittanceOfAHalfHiddenSun) {
  testing::AnalyticSceneParams p;
  p.has_medium = false;
  p.sphere_center = {-0.2, 0.1, 0.08};
  p.sphere_radius = 0.08;
  for (double offset_deg : {-4.0, 0.0, 4.0}) {
    SunnyTable table(2000.0, p);
    // Put the sun on the sphere's silhouette seen from the centre, moved
    // inwards (−) or outwards (+) by offset: a great-circle step from the
    // direction to the sphere's centre.
    const Vec3 to_c = p.sphere_center - table.center;
    const double alpha = std::asin(p.sphere_radius / Length(to_c)) + offset_deg * kPi / 180.0;
    const Vec3 u = Normalized(to_c), side = Normalized(Cross(u, Vec3{0, 0, 1}));
    table.environment[0].axis = Normalized(u * std::cos(alpha) + side * std::sin(alpha));
    const TrueLight truth(table, 400000);
    const std::vector<double> t = LobeTransmittance(table.scene, table.center, {table.sun()}, 16);
    std::printf("sun %+.0f° off the silhouette: transmittance %.3f (truth %.3f)\n", offset_deg, t[0],
                truth.transmittance_to_sun);
    EXPECT_NEAR(t[0], truth.transmittance_to_sun, 1.0 / 16.0);
  }
}

// A compact light `nerfar env` placed at a distance (a lamp 1.2 m from the
// origin) reaches the object's light as seen from its centre (the lobe
// EnvironmentSeenFrom gives), and shadows re-aim it from each receiver with
// its distance from there (by hand); the broad lobe stays distant. Both for
// ours and for the environment-only light.
TEST(CompactLobes, ALampAtADistanceKeepsItForTheShadows) {
  const SunnyTable table(3000);
  const std::vector<double> placed = {1.2, 0.0};
  std::vector<double> from_center;
  const SgMixture seen = EnvironmentSeenFrom(table.environment, placed, table.center, &from_center);
  const double lamp_distance = Length(table.sun().axis * 1.2 - table.center);  // by hand
  ASSERT_EQ(from_center.size(), 2u);
  EXPECT_NEAR(from_center[0], lamp_distance, 1e-12);
  EXPECT_TRUE(std::isinf(from_center[1]));
  for (const LightSource source : {LightSource::kFull, LightSource::kEnvironmentOnly}) {
    IncidentLightOptions options;
    options.source = source;
    IncidentLight light;
    light.Refresh(table.scene, table.environment, table.center, options, nullptr, placed);
    const SgMixture& lobes = light.light();
    ASSERT_EQ(light.lobe_distances().size(), lobes.size());
    int lamps = 0;
    for (size_t k = 0; k < lobes.size(); ++k) {
      if (lobes[k].sharpness != seen[0].sharpness || lobes[k].axis != seen[0].axis) continue;
      ++lamps;
      EXPECT_NEAR(light.lobe_distances()[k], lamp_distance, 1e-12) << LightSourceName(source);
    }
    EXPECT_EQ(lamps, 1) << LightSourceName(source);
    // Without the distances the same light keeps the lamp distant (as before).
    IncidentLight distant;
    distant.Refresh(table.scene, table.environment, table.center, options);
    for (size_t k = 0; k < distant.light().size(); ++k) {
      if (distant.light()[k].sharpness != table.sun().sharpness) continue;
      EXPECT_TRUE(std::isinf(distant.lobe_distances()[k])) << LightSourceName(source);
    }
  }
}

// DESIGN.md's extremes through the analytic path: a λ = 1e4 sun of μ = 1e6
// (integral 628), a second one below the table (hidden: transmittance 0),
// and a lobe just sharper than the threshold; the light, its prefiltered
// map and its distances finite, amplitudes ≥ 0, the visible sun's
// sharpness and radiance kept exactly, the hidden one's amplitude 0.
TEST(CompactLobes, ExtremesStayFiniteAndExact) {
  const SunnyTable table(1e4);
  SgMixture env = table.environment;
  env[0].amplitude = {1e6, 1e6, 1e6};
  env.push_back(Sg{Normalized(Vec3{0.2, 0.1, -1.0}), 1e4, {1e6, 1e6, 1e6}});
  env.push_back(Sg{Normalized(Vec3{0.3, 0.8, 0.5}), 1.001 * CompactSharpness(1024), {50, 50, 50}});
  IncidentLightOptions options;
  IncidentLight light;
  light.Refresh(table.scene, env, table.center, options);
  ASSERT_EQ(light.compact().size(), 3u);
  EXPECT_EQ(light.compact()[0].amplitude, env[0].amplitude);  // nothing in the way
  EXPECT_EQ(light.compact()[0].sharpness, 1e4);
  EXPECT_EQ(light.compact()[1].amplitude, Vec3(0, 0, 0));  // behind the table
  EXPECT_EQ(light.light().size(), static_cast<size_t>(options.fit.lobes));
  for (const Sg& lobe : light.light()) {
    for (int c = 0; c < 3; ++c) EXPECT_TRUE(std::isfinite(lobe.amplitude[c]) && lobe.amplitude[c] >= 0.0);
    EXPECT_TRUE(std::isfinite(lobe.sharpness) && lobe.sharpness > 0.0);
  }
  for (double d : light.lobe_distances()) EXPECT_FALSE(std::isnan(d));
  const PrefilteredRadiance map(light.samples(), 9, light.compact());
  for (const Vec3& d : {env[0].axis, env[1].axis, env[2].axis, Vec3{0, 0, 1}})
    for (float r : {0.0f, 0.25f, 1.0f}) {
      const Vec3f v = map.Lookup(Vec3f(d), r);
      EXPECT_TRUE(std::isfinite(v.x) && v.x >= 0.0f && std::isfinite(v.z) && v.z >= 0.0f) << r;
    }
  // The mirror level at the sun's axis holds most of its radiance: the map
  // is capped at 384 texels a side (~0.009 rad at the octahedron's face
  // centres), about this lobe's width 0.01, and its peak is read bilinearly
  // from such texels (measured 0.64 μ).
  const float peak = map.Lookup(Vec3f(env[0].axis), 0.0f).x;
  EXPECT_GT(peak, 0.5e6);
  EXPECT_LT(peak, 1.05e6);
}

}  // namespace
}  // namespace nerfar
