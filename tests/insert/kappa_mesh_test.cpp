// render/insert: κ (paper eq. 8) from baked SSDF fields of real meshes
// against brute force — the irradiance ratio with visibility ray-traced
// against the true triangles (Möller–Trumbore over every triangle, written
// here independently of render/ssdf) — for one non-convex object (a torus
// whose hole lets light through) and for two objects at once (the union of
// their fields: the smaller signed distance).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>

#include "render/insert/inserter.h"
#include "render/insert/shadow_terms.h"
#include "render/insert/ssdf_visibility.h"
#include "render/sg/sphere.h"
#include "render/ssdf/ssdf.h"
#include "tests/insert/test_camera.h"
#include "tests/support/analytic_scene.h"

namespace nerfar {
namespace {

// One posed mesh: world triangles and their bounding sphere.
struct WorldMesh {
  std::vector<std::array<Vec3, 3>> triangles;
  Vec3 center;
  double radius = 0;

  WorldMesh(const TriangleMesh& mesh, const Pose& T, double scale) {
    const TriangleMesh world = TransformMesh(mesh, T, scale);
    for (const auto& f : world.triangles)
      triangles.push_back({Vec3(world.positions[f[0]]), Vec3(world.positions[f[1]]), Vec3(world.positions[f[2]])});
    const BoundingSphere bs = ComputeBoundingSphere(world);
    center = bs.center;
    radius = bs.radius;
  }

  // Does the ray x + t·d (t > 0) hit a triangle?
  bool Blocks(const Vec3& x, const Vec3& d) const {
    const Vec3 oc = x - center;  // bounding-sphere rejection first
    const double b = Dot(oc, d), c = Dot(oc, oc) - radius * radius;
    if (c > 0 && (b > 0 || b * b < c)) return false;
    for (const auto& t : triangles) {
      const Vec3 e1 = t[1] - t[0], e2 = t[2] - t[0];
      const Vec3 p = Cross(d, e2);
      const double det = Dot(e1, p);
      if (std::abs(det) < 1e-14) continue;
      const Vec3 s = x - t[0];
      const double u = Dot(s, p) / det;
      if (u < 0 || u > 1) continue;
      const Vec3 q = Cross(s, e1);
      const double v = Dot(d, q) / det;
      if (v < 0 || u + v > 1) continue;
      if (Dot(e2, q) / det > 1e-6) return true;
    }
    return false;
  }
};

// κ at a table point (normal +z): Σ Y(L)·cos·V / Σ Y(L)·cos over 6000
// Fibonacci directions (spacing ~0.046 rad, a quarter of the sharp lobe's
// width 1/√λ ≈ 0.16 rad).
double BruteForceKappa(const SgMixture& light, const std::vector<const WorldMesh*>& meshes, const Vec3& x) {
  static const std::vector<Vec3> dirs = FibonacciSphere(6000);
  double seen = 0, all = 0;
  for (const Vec3& d : dirs) {
    if (d.z <= 0) continue;
    const double w = LuminanceOf(Evaluate(light, d)) * d.z;
    all += w;
    bool blocked = false;
    for (const WorldMesh* m : meshes) blocked = blocked || m->Blocks(x, d);
    if (!blocked) seen += w;
  }
  return all > 0 ? seen / all : 1.0;
}

SgMixture TestLight() {
  Sg sun;
  sun.axis = Normalized(Vec3{0.35, 0.15, 1.0});
  sun.sharpness = 40.0;
  sun.amplitude = {5, 5, 5};
  Sg sky;
  sky.axis = {0, 0, 1};
  sky.sharpness = 0.5;
  sky.amplitude = {0.3, 0.3, 0.3};
  return {sun, sky};
}

testing::AnalyticSceneParams TableOnly() {
  testing::AnalyticSceneParams p;
  p.has_sphere = false;
  p.has_medium = false;
  p.checker_size_m = 0;
  return p;
}

struct Bakes {
  TriangleMesh torus = MakeTorus(0.7, 0.3, 32, 16);
  TriangleMesh box = MakeBox({0.6, 0.6, 0.6});
  SsdfField torus_field, box_field;
  Bakes() {
    // The paper's 16³ grid with a reduced direction map (16², 4 bisections):
    // enough for a soft sun of λ = 40, quick in a unit test.
    SsdfBakeOptions o;
    o.grid = 16;
    o.dirs = 16;
    o.components = 24;
    o.bisection_steps = 4;
    torus_field = BakeSsdf(torus, o, std::nullopt);
    box_field = BakeSsdf(box, o, std::nullopt);
  }
};
const Bakes& GetBakes() {
  static const Bakes bakes;
  return bakes;
}

struct KappaComparison {
  double normalised_error = 0;  // Σ|κ − κ_ref| / Σ(1 − κ_ref) (DESIGN.md's shadow metric without the blur)
  double signed_error = 0;      // Σ(κ − κ_ref) / Σ(1 − κ_ref)
  double shadow = 0;            // Σ(1 − κ_ref)
  size_t count = 0, umbra = 0;  // receivers compared; those with κ_ref below the umbra threshold
};

// The κ layer at every second pixel whose ray meets the table plane outside
// the objects, against truth(point) (κ_ref); umbra counts κ_ref < umbra_below.
template <class Truth>
KappaComparison CompareKappaLayer(const InsertLayers& layers, const CameraIntrinsics& camera, const Pose& cam,
                                  double umbra_below, const Truth& truth) {
  KappaComparison c;
  double num = 0, bias = 0;
  for (int y = layers.kappa_rect.y0; y < layers.kappa_rect.y1; y += 2) {
    for (int x = layers.kappa_rect.x0; x < layers.kappa_rect.x1; x += 2) {
      const ObjectGBuffer& g = layers.gbuffer;
      if (g.rect.Contains(x, y) && g.object[g.Index(x, y)] >= 0) continue;
      const Vec3 d(CameraRayDirection(camera, cam, x, y));
      if (d.z >= 0) continue;
      const Vec3 p = cam.translation + d * (-cam.translation.z / d.z);
      const double reference = truth(p);
      const double kappa = layers.kappa.at(x - layers.kappa_rect.x0, y - layers.kappa_rect.y0);
      EXPECT_TRUE(kappa >= 0.0 && kappa <= 1.0) << kappa;
      num += std::abs(kappa - reference);
      bias += kappa - reference;
      c.shadow += 1.0 - reference;
      c.umbra += reference < umbra_below;
      ++c.count;
    }
  }
  c.normalised_error = c.shadow > 0 ? num / c.shadow : 0.0;
  c.signed_error = c.shadow > 0 ? bias / c.shadow : 0.0;
  return c;
}

KappaComparison Compare(const std::vector<InsertObject>& objects, const std::vector<const WorldMesh*>& meshes) {
  const testing::AnalyticScene scene(TableOnly());
  const CameraIntrinsics camera = testing::TestCamera(80, 60);
  const Pose cam = LookAt({0.2, -0.35, 0.4}, {0.0, 0.0, 0.0});
  InsertOptions options;
  options.kappa_step = 1;
  options.shadow_epsilon = 1e-4;
  Inserter inserter(scene, {}, options);
  ImageF frame(camera.width, camera.height, 3, 1.0f);
  InsertLayers layers;
  inserter.Render(camera, cam, objects, frame, &layers);
  const SgMixture light = TestLight();
  const KappaComparison c =
      CompareKappaLayer(layers, camera, cam, 0.5, [&](const Vec3& p) { return BruteForceKappa(light, meshes, p); });
  std::printf("kappa vs ray-traced: normalised error %.3f (signed %.3f) over %zu receivers (%zu in umbra)\n",
              c.normalised_error, c.signed_error, c.count, c.umbra);
  return c;
}

InsertObject Object(const TriangleMesh& mesh, const SsdfVisibility& v, const Pose& T, double scale,
                    const SgMixture* light) {
  InsertObject o;
  o.mesh = &mesh;
  o.T_world_object = T;
  o.scale = scale;
  o.visibility = &v;
  o.light_override = light;
  return o;
}

TEST(KappaMesh, TorusShadowMatchesRayTracedVisibility) {
  const Bakes& b = GetBakes();
  // A torus 16 cm across, tilted 30° and raised so its hole casts a lit spot.
  const Pose T{RotationFromAxisAngle({1, 0, 0}, 0.5), {0.0, 0.0, 0.06}};
  const double scale = 0.08;
  const SsdfVisibility v(b.torus_field, T, scale);
  const WorldMesh world(b.torus, T, scale);
  const SgMixture light = TestLight();
  const KappaComparison c = Compare({Object(b.torus, v, T, scale, &light)}, {&world});
  ASSERT_GT(c.count, 100u);
  ASSERT_GT(c.umbra, 5u);  // the umbra is in view
  // The target for the shadow error is 0.3 (half-strength shadows
  // score ~0.55): κ from a 16³ field with 16² directions, SSD taken at the
  // lobe axes and f_h's half-space model must stay within it against exact
  // visibility.
  EXPECT_LT(c.normalised_error, 0.3) << "shadow " << c.shadow << " over " << c.count << " receivers";
}

TEST(KappaMesh, TwoObjectsShadowAsTheUnionOfTheirFields) {
  const Bakes& b = GetBakes();
  const Pose Tt{RotationFromAxisAngle({1, 0, 0}, 0.5), {-0.05, 0.02, 0.06}};
  const Pose Tb{RotationFromAxisAngle({0, 0, 1}, 0.4), {0.07, -0.03, 0.035}};
  const double st = 0.08, sb = 0.05;
  const SsdfVisibility vt(b.torus_field, Tt, st), vb(b.box_field, Tb, sb);
  const WorldMesh wt(b.torus, Tt, st), wb(b.box, Tb, sb);
  const SgMixture light = TestLight();
  const KappaComparison both =
      Compare({Object(b.torus, vt, Tt, st, &light), Object(b.box, vb, Tb, sb, &light)}, {&wt, &wb});
  const KappaComparison torus_only = Compare({Object(b.torus, vt, Tt, st, &light)}, {&wt});
  ASSERT_GT(both.count, 100u);
  // The box adds its own shadow: more total shadow than the torus alone.
  EXPECT_GT(both.shadow, 1.2 * torus_only.shadow);
  // Same bound as for one object (see above), now against visibility of both
  // meshes together.
  EXPECT_LT(both.normalised_error, 0.3) << "shadow " << both.shadow << " over " << both.count << " receivers";
}

// κ from the light's samples (InsertOptions::kappa_from_samples) under a
// small near area light: a bulb (sphere of radius 3 cm, radiance 200) 25 cm
// from a box 6 cm wide standing on the table, plus a dim sky. The
// reference traces, from every receiver, 60000 Fibonacci directions
// (spacing 0.0145 rad, ~200 on the bulb, whose radius there is ~0.12 rad)
// against the bulb and the box's true triangles: the bulb is seen from the
// receiver itself, so its parallax (it is only 25 cm away) is exact.
struct NearBulb {
  Vec3 center;  // the light centre (the box's bounding-sphere centre)
  Vec3 bulb;
  double bulb_radius = 0.03, radiance = 200.0, sky = 0.05;
  // With panel: a one-sided rectangle at `bulb` instead of the ball (the
  // lamps scene's panel: 12 × 8 cm, facing `panel_normal`).
  bool panel = false;
  Vec3 panel_normal, panel_u, panel_v;
  double panel_half_u = 0.06, panel_half_v = 0.04;
  // Radiance seen from x along d (d unit).
  double Radiance(const Vec3& x, const Vec3& d) const {
    if (panel) {
      const double dn = Dot(d, panel_normal);
      if (dn < 0) {  // only its front (towards +normal) emits
        const double t = Dot(bulb - x, panel_normal) / dn;
        const Vec3 q = x + d * t - bulb;
        if (t > 0 && std::abs(Dot(q, panel_u)) <= panel_half_u && std::abs(Dot(q, panel_v)) <= panel_half_v)
          return radiance;
      }
      return d.z > 0 ? sky : 0.0;
    }
    const Vec3 oc = x - bulb;
    const double b = Dot(oc, d), c = Dot(oc, oc) - bulb_radius * bulb_radius;
    if (b < 0 && b * b > c) return radiance;
    return d.z > 0 ? sky : 0.0;
  }
};

double BruteForceNearKappa(const NearBulb& light, const WorldMesh& mesh, const Vec3& x) {
  static const std::vector<Vec3> dirs = FibonacciSphere(60000);
  double seen = 0, all = 0;
  for (const Vec3& d : dirs) {
    if (d.z <= 0) continue;
    const double w = light.Radiance(x, d) * d.z;
    if (!(w > 0)) continue;
    all += w;
    if (!mesh.Blocks(x, d)) seen += w;
  }
  return all > 0 ? seen / all : 1.0;
}

// `panel`: the rectangle instead of the ball; the light's lobes and samples
// are given `distance_scale` × the true distance (1: exact).
KappaComparison CompareNear(bool from_samples, bool panel = false, double distance_scale = 1.0) {
  const Bakes& b = GetBakes();
  const Pose T{RotationFromAxisAngle({0, 0, 1}, 0.4), {0.0, 0.0, 0.03}};
  const double scale = 0.05;  // the box is 6 cm wide, standing on the table
  const SsdfVisibility v(b.box_field, T, scale);
  const WorldMesh world(b.box, T, scale);
  NearBulb light;
  light.center = world.center;
  const double distance = 0.25;
  light.bulb = light.center + Normalized(Vec3{-0.5, 0.3, 1.0}) * distance;
  if (panel) {
    light.panel = true;
    light.radiance = 60.0;  // about the ball's power: 0.0096 m² against π·0.03²
    light.panel_normal = Normalized(light.center - light.bulb);  // facing the object
    light.panel_u = Normalized(Cross(light.panel_normal, Vec3{0, 0, 1}));
    light.panel_v = Cross(light.panel_u, light.panel_normal);
  }
  // The light at the centre: its samples (what κ from samples reads) and
  // an SG light with the bulb's lobe 25 cm away (what gives the samples
  // their distance, and κ from the SG lobes).
  RadianceSamples samples;
  samples.directions = FibonacciSphere(8192);
  for (const Vec3& d : samples.directions) {
    const double l = light.Radiance(light.center, d);
    samples.radiance.push_back({l, l, l});
    samples.solid_angles.push_back(4.0 * kPi / 8192.0);
  }
  const double bulb_solid = panel ? 4.0 * light.panel_half_u * light.panel_half_v / (distance * distance)
                                  : 2.0 * kPi * (1.0 - std::sqrt(1.0 - std::pow(light.bulb_radius / distance, 2)));
  Sg bulb;
  bulb.axis = Normalized(light.bulb - light.center);
  bulb.sharpness = 1.0 / (bulb_solid / kPi);  // about the bulb's width
  const double a = light.radiance * bulb_solid / SgUnitIntegral(bulb.sharpness);
  bulb.amplitude = {a, a, a};
  Sg sky;
  sky.axis = {0, 0, 1};
  sky.sharpness = 1.0;
  sky.amplitude = {0.08, 0.08, 0.08};
  const SgMixture sg = {bulb, sky};
  const std::vector<double> distances = {distance * distance_scale, std::numeric_limits<double>::infinity()};
  InsertObject o = Object(b.box, v, T, scale, &sg);
  o.light_samples = &samples;
  o.light_distances = &distances;
  o.light_center = light.center;

  const testing::AnalyticScene scene(TableOnly());
  const CameraIntrinsics camera = testing::TestCamera(80, 60);
  const Pose cam = LookAt({0.25, -0.3, 0.35}, {0.03, -0.02, 0.0});
  InsertOptions options;
  options.kappa_step = 1;
  options.shadow_epsilon = 1e-4;
  options.kappa_cache_spacing_radii = 0.0;
  options.kappa_from_samples = from_samples;
  Inserter inserter(scene, {}, options);
  ImageF frame(camera.width, camera.height, 3, 1.0f);
  InsertLayers layers;
  inserter.Render(camera, cam, {o}, frame, &layers);
  const KappaComparison c =
      CompareKappaLayer(layers, camera, cam, 0.3, [&](const Vec3& p) { return BruteForceNearKappa(light, world, p); });
  std::printf(
      "near %s at %.1f x its distance, kappa from %s vs ray-traced: normalised error %.3f (signed %.3f) over %zu "
      "receivers (%zu in umbra)\n",
      panel ? "panel" : "bulb", distance_scale, from_samples ? "samples" : "SG lobes", c.normalised_error,
      c.signed_error, c.count, c.umbra);
  return c;
}

TEST(KappaMesh, NearBulbFromSamplesMatchesRayTracedVisibility) {
  const KappaComparison samples = CompareNear(true), lobes = CompareNear(false);
  ASSERT_GT(samples.count, 300u);
  ASSERT_GT(samples.umbra, 10u);  // the umbra is in view
  // Measured 0.151 (signed −0.024) from samples, 0.264 (signed −0.116)
  // from the SG lobes. Bound 0.2: the target is 0.3 and the
  // field's own error (16² directions, the half-space model of a
  // source's disc) is ~0.15 against exact visibility on this box; the
  // source model must not add more than a third on top.
  EXPECT_LT(samples.normalised_error, 0.2);
  // κ from samples keeps the bulb's true size and re-aims it from each
  // receiver: it must beat the SG lobes here (the reason it exists).
  EXPECT_LT(samples.normalised_error, lobes.normalised_error);
}

// The lamps scene's panel: an extended one-sided source 25 cm away, as
// ground truth the panel seen from each receiver. κ from samples, the
// panel re-aimed from each receiver from its true distance, must stay close
// to the traced κ; given twice that distance (as the lobe distances of the
// ground-truth-input runs do when the NeRF explains only part of a lamp's
// radiance, see BENCHMARKS) it must not: the shadow needs the true
// distance. (A single SG lobe is no model of this panel — λ ≈ 20, one
// lobe for a 12 × 8 cm rectangle — so κ from SG lobes is not held to it.)
TEST(KappaMesh, NearPanelNeedsItsTrueDistance) {
  const KappaComparison exact = CompareNear(true, true), far = CompareNear(true, true, 2.0);
  ASSERT_GT(exact.count, 300u);
  ASSERT_GT(exact.umbra, 10u);  // the umbra is in view
  // Measured 0.122 (signed −0.059). Bound 0.2 as for the bulb above (the
  // field's own error ~0.15 on this box).
  EXPECT_LT(exact.normalised_error, 0.2);
  // Measured 0.233, signed +0.228: twice the distance leaves the shadow
  // too light, the symptom of the lamps scene's ground-truth-input runs.
  // Bounds well inside those figures (the test is deterministic).
  EXPECT_GT(far.normalised_error, exact.normalised_error + 0.08);
  EXPECT_GT(far.signed_error, 0.15);
}

TEST(KappaMesh, DiscVisibleFractionIsTheCircularSegment) {
  // Against counting points of a 401 × 401 grid over the unit disc (area
  // error ~1/401 of the disc's edge: < 2e-3 of the disc).
  for (double s : {-1.5, -1.0, -0.6, -0.2, 0.0, 0.3, 0.7, 1.0, 2.0}) {
    size_t in = 0, seen = 0;
    for (int i = 0; i <= 400; ++i)
      for (int j = 0; j <= 400; ++j) {
        const double u = -1.0 + i / 200.0, w = -1.0 + j / 200.0;
        if (u * u + w * w > 1.0) continue;
        ++in;
        seen += u < s;  // the blocked half-space begins at distance s from the centre
      }
    EXPECT_NEAR(DiscVisibleFraction(s * 0.1, 0.1), double(seen) / double(in), 2e-3) << s;
  }
  EXPECT_EQ(DiscVisibleFraction(0.01, 0.0), 1.0);
  EXPECT_EQ(DiscVisibleFraction(-0.01, 0.0), 0.0);
}

}  // namespace
}  // namespace nerfar
