// Sharp sources in the environment fit (render/lighting/env_shadow.h,
// env_sources.cpp, the chroma selection of env_fit.cpp) on surface samples
// built here: a table plane with three balls on it, occluding analytically
// (ray-sphere tests, no NeRF), lit by a small bright SG "sun" and a constant
// sky. Observed radiance from brute-force quadrature of the light times the
// analytic visibility over a fine grid of directions, independent of the
// bundles and the search under test.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>

#include "calib/core/random.h"
#include "render/lighting/env_fit.h"
#include "render/lighting/env_shadow.h"
#include "render/nerf/nerf_field.h"
#include "render/sg/sg.h"
#include "render/sg/sphere.h"
#include "render/sg/visibility.h"

namespace nerfar {
namespace {

const Aabb kBox{{-0.6, -0.6, -0.05}, {0.6, 0.6, 0.6}};
struct Ball {
  Vec3 centre;
  double radius;
};
const Ball kBalls[3] = {{{-0.15, 0.05, 0.08}, 0.08}, {{0.2, -0.15, 0.1}, 0.1}, {{0.1, 0.25, 0.06}, 0.06}};
constexpr double kOffset = 1e-3;  // rays start where they have risen this far above the surface (SurfaceRay)

Vec3 Direction(double azimuth_deg, double elevation_deg) {
  const double az = azimuth_deg * kPi / 180, el = elevation_deg * kPi / 180;
  return {std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)};
}

// Whether the ray o + t·d, t > 0, meets a ball.
bool Blocked(const Vec3& o, const Vec3& d) {
  for (const Ball& b : kBalls) {
    const Vec3 oc = o - b.centre;
    const double half_b = Dot(oc, d), c = Dot(oc, oc) - b.radius * b.radius;
    const double disc = half_b * half_b - c;
    if (disc > 0 && -half_b + std::sqrt(disc) > 0) return true;
  }
  return false;
}

// Whether the ray from x (normal n) towards d is blocked, started as
// SurfaceRay starts it: on the ray, kOffset above the surface.
bool BlockedFrom(const Vec3& x, const Vec3& n, const Vec3& d) {
  return Blocked(x + d * (kOffset / std::max(Dot(n, d), 1.0 / kLayerSlant)), d);
}

EnvShadowRays AnalyticShadows() {
  return [](const std::vector<EnvSurfaceRay>& rays, std::vector<float>* transmittance) {
    transmittance->resize(rays.size());
    for (size_t k = 0; k < rays.size(); ++k)
      (*transmittance)[k] = Blocked(Vec3(rays[k].origin), Vec3(rays[k].dir)) ? 0.0f : 1.0f;
  };
}

// ∫ V(d) L(d) max(n·d, 0) dd for one lobe by a polar grid about its axis out
// to where G < 1e-9 (fine against the lobe's width), V analytic.
double LobeIrradianceBruteForce(const Vec3& x, const Vec3& n, const Vec3& axis, double sharpness) {
  const double theta_max = std::min(kPi, std::acos(std::max(-1.0, 1.0 - 20.7 / sharpness)));
  Vec3 u = Normalized(Cross(std::fabs(axis.z) < 0.9 ? Vec3{0, 0, 1} : Vec3{1, 0, 0}, axis));
  const Vec3 v = Cross(axis, u);
  const int rings = 120, sectors = 240;
  double sum = 0;
  for (int r = 0; r < rings; ++r) {
    const double t0 = theta_max * r / rings, t1 = theta_max * (r + 1) / rings, t = 0.5 * (t0 + t1);
    const double ring_area = 2 * kPi * (std::cos(t0) - std::cos(t1)) / sectors;
    for (int s = 0; s < sectors; ++s) {
      const double phi = 2 * kPi * (s + 0.5) / sectors;
      const Vec3 d = axis * std::cos(t) + (u * std::cos(phi) + v * std::sin(phi)) * std::sin(t);
      const double c = Dot(n, d);
      if (c <= 0 || BlockedFrom(x, n, d)) continue;
      sum += std::exp(sharpness * (std::cos(t) - 1)) * c * ring_area;
    }
  }
  return sum;
}

// A constant sky of unit radiance over the upper hemisphere through the balls.
double SkyIrradianceBruteForce(const Vec3& x, const Vec3& n) {
  static const std::vector<Vec3> dirs = FibonacciSphere(4000);
  double sum = 0;
  for (const Vec3& d : dirs)
    if (d.z > 0 && Dot(n, d) > 0 && !BlockedFrom(x, n, d)) sum += Dot(n, d);
  return sum * 4 * kPi / dirs.size();
}

struct Scene {
  Vec3 sun_axis = Direction(30, 50);
  double sun_sharpness = 2000;
  Vec3 sun_rgb{1, 1, 1};  // amplitude, times kSunAmplitude
  Vec3 sky_rgb{1, 1, 1};  // radiance, times kSkyRadiance
  Vec3 albedo{0.6, 0.45, 0.3};
  // A patch of another material on the last ball (its lower side facing −x),
  // all within one albedo cell of the fit (EnvEstimateOptions::albedo_cell_m).
  std::optional<Vec3> patch_albedo;
};
constexpr double kSunAmplitude = 1500, kSkyRadiance = 0.3;

// Table points on a 36 x 36 grid and points on the balls' upper parts; the
// visibility cache (R rays) from the analytic occluders.
EnvSurfaceSamples MakeSamples(const Scene& scene) {
  EnvSurfaceSamples s;
  for (int j = 0; j < 36; ++j)
    for (int i = 0; i < 36; ++i) {
      const Vec3 p{-0.5 + (i + 0.5) / 36.0, -0.5 + (j + 0.5) / 36.0, 0.0};
      bool inside = false;
      for (const Ball& b : kBalls) inside = inside || Length(p - b.centre) < b.radius;
      if (inside) continue;
      s.positions.push_back(Vec3f(p));
      s.normals.push_back(Vec3f{0, 0, 1});
    }
  std::vector<Vec3> albedo(s.size(), scene.albedo);
  for (const Ball& b : kBalls)
    for (const Vec3& n : FibonacciSphere(160))
      if (n.z > -0.2) {
        s.positions.push_back(Vec3f(b.centre + n * b.radius));
        s.normals.push_back(Vec3f(n));
        const bool patch = &b == &kBalls[2] && n.x < 0 && n.y < 0.5 && n.z < 0.6;
        albedo.push_back(patch ? scene.patch_albedo.value_or(scene.albedo) : scene.albedo);
      }
  const int R = 64;
  s.rays_per_point = R;
  s.ray_offset_m = static_cast<float>(kOffset);
  for (size_t i = 0; i < s.size(); ++i) {
    const Vec3 x(s.positions[i]), n(s.normals[i]);
    for (int j = 0; j < R; ++j) {
      // Cosine-distributed about n (Malley), turned per sample.
      const double r = std::sqrt((j + 0.5) / R), phi = 2.399963 * j + 6.283 * UnitDouble(CounterHash(3, 1, i, 0));
      Vec3 t = Normalized(Cross(std::fabs(n.z) < 0.9 ? Vec3{0, 0, 1} : Vec3{1, 0, 0}, n));
      const Vec3 d = Normalized(t * (r * std::cos(phi)) + Cross(n, t) * (r * std::sin(phi)) + n * std::sqrt(1 - r * r));
      s.ray_dirs.push_back(Vec3f(d));
      s.opacity.push_back(BlockedFrom(x, n, d) ? 1.0f : 0.0f);
    }
    const double sun = kSunAmplitude * LobeIrradianceBruteForce(x, n, scene.sun_axis, scene.sun_sharpness);
    const double sky = kSkyRadiance * SkyIrradianceBruteForce(x, n);
    const Vec3 e = scene.sun_rgb * sun + scene.sky_rgb * sky;
    const Vec3& a = albedo[i];
    s.radiance.push_back(Vec3f(Vec3{a.x * e.x, a.y * e.y, a.z * e.z} / kPi));
    s.e_nerf.push_back(Vec3f{});
  }
  return s;
}

EnvEstimateOptions Options() {
  EnvEstimateOptions o = EnvEstimateOptions::Preset("fast");
  o.sources_max = 2;
  return o;
}

double Chroma(const Vec3& rgb, int c) { return rgb[c] / LuminanceOf(rgb); }

// The bundle's irradiance against brute force on table points across a
// ball's shadow: exact where the lobe is wholly open or hidden, and within
// the bundle's stratification error in the penumbra (64 rays: a ray stands
// for 1/64 of the lobe, so a shadow edge crossing the bundle is resolved to
// about that; 0.03 of the open irradiance allows twice it).
TEST(EnvSharp, BundleIrradianceMatchesBruteForceAcrossAPenumbra) {
  const Vec3 axis = Direction(0, 60);
  const double sharpness = 300;  // ~3.3 degrees: a penumbra a few cm wide under a ball 8 cm up
  EnvSurfaceSamples s;
  const Ball& b = kBalls[0];
  const Vec3 shadow_centre = b.centre - axis * (b.centre.z / axis.z);
  for (int k = 0; k < 60; ++k) {
    s.positions.push_back(Vec3f(shadow_centre + Vec3{-0.15 + 0.3 * k / 59.0, 0.0, 0.0}));
    s.normals.push_back(Vec3f{0, 0, 1});
  }
  s.ray_offset_m = static_cast<float>(kOffset);
  const std::vector<double> column = BundleIrradiance(s, AnalyticShadows(), AllSamples(s), axis, sharpness, 64, 1);
  const double open = UnitIrradiance(axis.z, sharpness);
  int penumbra = 0, open_count = 0, hidden = 0;
  for (size_t i = 0; i < s.size(); ++i) {
    const double truth = LobeIrradianceBruteForce(Vec3(s.positions[i]), {0, 0, 1}, axis, sharpness);
    EXPECT_NEAR(column[i], truth, 0.03 * open) << "sample " << i;
    if (truth > 0.999 * open) {
      ++open_count;
      EXPECT_NEAR(column[i], open, 1e-6 * open);
    } else if (truth < 1e-3 * open) {
      ++hidden;
      EXPECT_EQ(column[i], 0.0);
    } else {
      ++penumbra;
    }
  }
  EXPECT_GT(penumbra, 5);
  EXPECT_GT(open_count, 5);
  EXPECT_GT(hidden, 2);
}

// A light at a finite distance, seen from each sample (AimAt): a point
// source (bundle of one ray, λ = 1e4) 0.5 m above the origin, over open
// table points out to 0.4 m, against the inverse-square law by hand: E =
// E⊥(origin) · cos θ · (D / r)², θ from the normal to the light, r the range.
// 1e-3 of E⊥: the SG's unit irradiance at λ = 1e4 is 2π/λ · cos θ to 1e-4 at
// these cosines (≥ 0.75).
TEST(EnvSharp, ALightAtADistanceTurnsAndFallsOffOverTheTable) {
  const double distance = 0.5, sharpness = 1e4;
  const Vec3 axis{0, 0, 1};
  EnvSurfaceSamples s;
  for (int k = 0; k < 9; ++k) {
    s.positions.push_back(Vec3f{static_cast<float>(0.05 * k), static_cast<float>(-0.02 * k), 0});
    s.normals.push_back(Vec3f{0, 0, 1});
  }
  const EnvShadowRays open = [](const std::vector<EnvSurfaceRay>& rays, std::vector<float>* transmittance) {
    transmittance->assign(rays.size(), 1.0f);
  };
  const std::vector<double> column = BundleIrradiance(s, open, AllSamples(s), {axis}, {sharpness}, 1, 1, {distance})[0];
  const double normal_irradiance = 2 * kPi / sharpness;
  for (size_t i = 0; i < s.size(); ++i) {
    const Vec3 to = axis * distance - Vec3(s.positions[i]);
    const double range = std::sqrt(Dot(to, to));
    const double truth = normal_irradiance * (to.z / range) * (distance / range) * (distance / range);
    EXPECT_NEAR(column[i], truth, 1e-3 * normal_irradiance) << "sample " << i;
  }
  EXPECT_LT(column.back(), 0.5 * column.front());  // the far point: cos θ · (D / r)² = 0.44
}

// The coarse search, refinement and size choice place a small sun from its
// shadows and shading: within 2 degrees of the true axis (the issue's
// acceptance; the coarse grid is 5 degrees apart, so this is the
// refinement's work; measured 1.15), sharp (λ ≥ 300), its energy within 15 %
// of the truth.
TEST(EnvSharp, FindsASmallSunFromItsShadows) {
  const Scene scene;
  const EnvSurfaceSamples s = MakeSamples(scene);
  EnvFitReport report;
  const SgMixture light = FitEnvironment(s, kBox, Options(), &report, nullptr, AnalyticShadows());
  ASSERT_GE(report.sources, 1);
  const auto sun = std::max_element(light.begin(), light.end(), [](const Sg& a, const Sg& b) {
    return LuminanceOf(Integral(a)) < LuminanceOf(Integral(b));
  });
  ASSERT_NE(sun, light.end());
  EXPECT_GT(Dot(sun->axis, scene.sun_axis), std::cos(2.0 * kPi / 180))
      << "off by " << std::acos(std::min(1.0, Dot(sun->axis, scene.sun_axis))) * 180 / kPi << " degrees";
  EXPECT_GE(sun->sharpness, 300);
  const double truth = kSunAmplitude * SgUnitIntegral(scene.sun_sharpness);
  EXPECT_NEAR(LuminanceOf(Integral(*sun)), truth, 0.15 * truth);
  // Without shadow rays (the dictionary alone) no lobe is that sharp.
  EnvFitReport plain;
  for (const Sg& g : FitEnvironment(s, kBox, Options(), &plain)) EXPECT_LE(g.sharpness, 48);
  EXPECT_EQ(plain.sources, 0);
}

// Neutral light on coloured surfaces: albedo and light trade colour freely,
// so no lobe earns a chroma of its own and every lobe is grey (equal RGB
// within 5 %, the acceptance).
TEST(EnvSharp, NeutralLightGivesNeutralLobes) {
  Scene scene;
  scene.albedo = {0.7, 0.4, 0.2};
  EnvFitReport report;
  const SgMixture light = FitEnvironment(MakeSamples(scene), kBox, Options(), &report, nullptr, AnalyticShadows());
  ASSERT_FALSE(light.empty());
  EXPECT_EQ(report.coloured_lobes, 0);
  for (const Sg& g : light)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(Chroma(g.amplitude, c), 1.0, 0.05) << "lobe sharpness " << g.sharpness;
}

// Neutral light on a grey table and balls, one ball with a saturated green
// patch on its side, within one albedo cell: a coloured lobe from the patch's
// side could explain the patch, but the light is neutral, so no lobe may keep
// a colour (every lobe grey within 5 %, the acceptance), neither by
// its likelihood gain nor on the cells it was not fitted to.
TEST(EnvSharp, AGreenPatchUnderNeutralLightGivesNeutralLobes) {
  Scene scene;
  scene.albedo = {0.5, 0.5, 0.5};
  scene.patch_albedo = Vec3{0.05, 0.8, 0.05};
  EnvFitReport report;
  EnvEstimateOptions o = EnvEstimateOptions::Preset("balanced");
  o.sources_max = 2;
  const SgMixture light = FitEnvironment(MakeSamples(scene), kBox, o, &report, nullptr, AnalyticShadows());
  ASSERT_FALSE(light.empty());
  EXPECT_EQ(report.coloured_lobes, 0);
  for (const Sg& g : light)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(Chroma(g.amplitude, c), 1.0, 0.05) << "lobe sharpness " << g.sharpness;
}

// A blue sky beside a white sun: the shadows (sky only) are bluer than the
// lit table, so the relative colour is supported by the data: the sun stays
// the white point and the broad lobes come out blue (blue over red at least
// twice the sun's; the truth is 0.45 / 0.12 = 3.75 times).
TEST(EnvSharp, BlueSkyBesideAWhiteSunKeepsItsColour) {
  Scene scene;
  scene.sky_rgb = Vec3{0.12, 0.22, 0.45} / LuminanceOf(Vec3{0.12, 0.22, 0.45});
  EnvFitReport report;
  const SgMixture light = FitEnvironment(MakeSamples(scene), kBox, Options(), &report, nullptr, AnalyticShadows());
  ASSERT_GE(report.sources, 1);
  EXPECT_GE(report.coloured_lobes, 1);
  Vec3 sun, sky;
  for (const Sg& g : light) (g.sharpness >= 300 ? sun : sky) += Integral(g);
  ASSERT_GT(LuminanceOf(sky), 0);
  EXPECT_NEAR(Chroma(sun, 0), Chroma(sun, 2), 0.05 * Chroma(sun, 0));
  EXPECT_GT(sky.z / sky.x, 2 * sun.z / sun.x);
}

// Shadow rays through a NeRF pass the surface's own translucent layer
// (density up to the fog density, within the layer's length) and are stopped
// by denser matter, and by the fog itself beyond the layer. This rests on the
// renderer skipping samples of opacity below min_alpha entirely.
TEST(EnvSharp, NerfShadowRaysPassTheSurfacesOwnLayerOnly) {
  const Aabb box{{0, 0, 0}, {0.2, 0.2, 1.0}};
  const double voxel = 0.005;
  NerfField field = NerfField::Dense(box, voxel, kNerfEmptyDensityRaw, Vec3f{0, 0, 0});
  const float fog = 15, floor = 20, solid = 2000;  // 1/m: the fog is below the floor the rays pass
  for (int k = 0; k < field.res[2]; ++k)
    for (int j = 0; j < field.res[1]; ++j)
      for (int i = 0; i < field.res[0]; ++i) {
        const double z = k * voxel;
        // Fog 0-10 cm and 50-60 cm; a solid slab 30-35 cm.
        const bool in_fog = z < 0.1 || (z > 0.5 && z < 0.6), in_solid = z > 0.3 && z < 0.35;
        if (in_fog || in_solid) field.density[field.Slot(i, j, k)] = std::log(in_solid ? solid : fog);
      }
  field.UpdateOccupancy(1.0f);
  const EnvShadowRays shadow = NerfShadowRays(field, NerfRenderOptions::Preset("live"), floor);
  const Vec3f up{0, 0, 1}, start{0.1f, 0.1f, 0.01f};
  const auto through = [&](const Vec3f& origin, float layer) {
    std::vector<float> out;
    shadow({EnvSurfaceRay{origin, up, layer}}, &out);
    return out[0];
  };
  const float far_fog = std::exp(-fog * 0.1f);
  // Above the solid slab, no layer: the far fog dims the ray as the renderer integrates it.
  EXPECT_NEAR(through({0.1f, 0.1f, 0.4f}, 0.0f), far_fog, 0.05f);
  // From inside the near fog with its layer: the layer passes, the slab stops it.
  EXPECT_LT(through(start, 0.1f), 0.05f);
  // A ray that only crosses fog within its layer, then open space: open.
  EXPECT_GT(through({0.1f, 0.1f, 0.4f}, 0.25f), 0.95f);
}

}  // namespace
}  // namespace nerfar
