// render/insert: the shadow κ (paper eqs. 8-9) of a small distant source —
// a sun of angular radius r, a uniform disc — cast by a box on the table,
// against brute force: visibility ray-traced against the box's true
// triangles from each receiver, integrated over the sun's disc itself (800
// points). No sky: a broad lobe's κ is f_h's half-space model bounded by the
// occluder's cap (ShadowRatioCapped), an approximation of its own that would
// hide the sun's shadow in this comparison. The light given to
// the inserter is the disc's moment-matched SG (equal integral, λ = 4/r²:
// the disc's mean squared angle r²/2 is the SG's 2/λ), as an environment
// estimate or the incident light's analytic lobes carry it. A hard edge for
// a small sun (r = 0.02 rad: λ = 1e4, the sharpest lobe DESIGN.md allows),
// a wide penumbra for a large one (r = 0.2 rad: λ = 100).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "render/insert/inserter.h"
#include "render/insert/ssdf_visibility.h"
#include "render/sg/sphere.h"
#include "render/ssdf/ssdf.h"
#include "tests/insert/test_camera.h"
#include "tests/support/analytic_scene.h"

namespace nerfar {
namespace {

// The box posed in the world: its true faces for the reference.
struct WorldBox {
  std::vector<std::array<Vec3, 3>> triangles;
  WorldBox(const TriangleMesh& mesh, const Pose& T, double scale) {
    const TriangleMesh world = TransformMesh(mesh, T, scale);
    for (const auto& f : world.triangles)
      triangles.push_back({Vec3(world.positions[f[0]]), Vec3(world.positions[f[1]]), Vec3(world.positions[f[2]])});
  }
  // Does x + t·d (t > 0) cross a face (Möller–Trumbore)?
  bool Blocks(const Vec3& x, const Vec3& d) const {
    for (const auto& t : triangles) {
      const Vec3 e1 = t[1] - t[0], e2 = t[2] - t[0], p = Cross(d, e2);
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

struct Sun {
  Vec3 axis = Normalized(Vec3{0.5, 0.2, 0.75});
  double radius = 0.02;  // angular radius of the disc, radians
  double radiance = 2000.0;
  double SolidAngle() const { return 2.0 * kPi * (1.0 - std::cos(radius)); }
  // The disc's moment-matched SG.
  SgMixture Light() const {
    Sg sun;
    sun.axis = axis;
    sun.sharpness = 4.0 / (radius * radius);
    const double mu = radiance * SolidAngle() / SgUnitIntegral(sun.sharpness);
    sun.amplitude = {mu, mu, mu};
    return {sun};
  }
};

// κ at table point x (normal +z) under the true disc.
double BruteForceKappa(const Sun& sun, const WorldBox& box, const Vec3& x) {
  constexpr int kDisc = 800;
  const Vec3 a = std::abs(sun.axis.x) < 0.9 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
  const Vec3 t1 = Normalized(Cross(sun.axis, a)), t2 = Cross(sun.axis, t1);
  double seen = 0, all = 0;
  const double w_disc = sun.radiance * sun.SolidAngle() / kDisc;
  for (int k = 0; k < kDisc; ++k) {  // Vogel points, equal area
    const double rho = std::tan(sun.radius) * std::sqrt((k + 0.5) / kDisc);
    const double phi = k * kPi * (3.0 - std::sqrt(5.0));
    const Vec3 d = Normalized(sun.axis + (t1 * std::cos(phi) + t2 * std::sin(phi)) * rho);
    const double w = w_disc * std::max(d.z, 0.0);
    all += w;
    if (!box.Blocks(x, d)) seen += w;
  }
  return all > 0 ? seen / all : 1.0;
}

struct Bake {
  TriangleMesh box = MakeBox({0.5, 0.5, 0.5});
  SsdfField field;
  Bake() { field = BakeSsdf(box, SsdfBakeOptions(), std::nullopt); }  // nerfar bake's defaults
};
const Bake& GetBake() {
  static const Bake bake;
  return bake;
}

struct Profile {
  double normalised_error = 0;           // Σ|κ − κ_ref| / Σ(1 − κ_ref) over the receivers
  double umbra_ours = 0, umbra_ref = 0;  // mean κ where κ_ref is in the sun's umbra
  double width_ours = 0, width_ref = 0;  // penumbra: receivers with κ in (0.2, 0.8), as a share of those in shadow
  size_t count = 0;
};

// κ of the inserter (exact per receiver, or from its lattice) against
// brute force at every table pixel of a 120 × 90 view from above.
Profile Measure(const Sun& sun, bool lattice) {
  const Bake& b = GetBake();
  const Pose T{RotationFromAxisAngle({0, 0, 1}, 0.3), {0.0, 0.0, 0.03}};
  const double scale = 0.06;  // a 6 cm cube standing on the table
  const SsdfVisibility visibility(b.field, T, scale);
  const WorldBox world(b.box, T, scale);
  const SgMixture light = sun.Light();
  InsertObject object;
  object.mesh = &b.box;
  object.T_world_object = T;
  object.scale = scale;
  object.visibility = &visibility;
  object.light_override = &light;
  std::vector<double> no_distances(light.size(), std::numeric_limits<double>::infinity());
  object.light_distances = &no_distances;  // a distant light
  const testing::AnalyticScene scene([] {
    testing::AnalyticSceneParams p;
    p.has_sphere = p.has_medium = false;
    p.checker_size_m = 0;
    return p;
  }());
  const CameraIntrinsics camera = testing::TestCamera(120, 90);
  const Pose cam = LookAt({-0.05, -0.12, 0.35}, {-0.06, -0.03, 0.0});
  InsertOptions options;
  options.kappa_step = 1;
  options.shadow_epsilon = 1e-4;
  if (!lattice) options.kappa_cache_spacing_radii = 0.0;
  Inserter inserter(scene, {}, options);
  ImageF frame(camera.width, camera.height, 3, 1.0f);
  InsertLayers layers;
  inserter.Render(camera, cam, {object}, frame, &layers);
  // Every table pixel outside the box: (ours, truth).
  std::vector<std::pair<double, double>> pairs;
  double lowest = 1.0;
  for (int y = layers.kappa_rect.y0; y < layers.kappa_rect.y1; ++y)
    for (int x = layers.kappa_rect.x0; x < layers.kappa_rect.x1; ++x) {
      const ObjectGBuffer& g = layers.gbuffer;
      if (g.rect.Contains(x, y) && g.object[g.Index(x, y)] >= 0) continue;
      const Vec3 d(CameraRayDirection(camera, cam, x, y));
      if (d.z >= 0) continue;
      const Vec3 q = cam.translation + d * (-cam.translation.z / d.z);
      pairs.push_back(
          {layers.kappa.at(x - layers.kappa_rect.x0, y - layers.kappa_rect.y0), BruteForceKappa(sun, world, q)});
      lowest = std::min(lowest, pairs.back().second);
    }
  // The step from the deepest shadow (the sun wholly hidden) to 1: umbra
  // within 5 % of its bottom, penumbra between 20 % and 80 % of it.
  const auto step = [&](double k) { return (k - lowest) / std::max(1.0 - lowest, 1e-9); };
  Profile p;
  double diff = 0, shadow = 0, umbra_n = 0;
  size_t shadowed = 0, pen_ours = 0, pen_ref = 0;
  for (const auto& [ours, ref] : pairs) {
    diff += std::abs(ours - ref);
    shadow += 1.0 - ref;
    ++p.count;
    shadowed += step(ref) < 0.95;
    pen_ref += step(ref) > 0.2 && step(ref) < 0.8;
    pen_ours += step(ours) > 0.2 && step(ours) < 0.8;
    if (step(ref) < 0.05) p.umbra_ours += ours, p.umbra_ref += ref, ++umbra_n;
  }
  p.normalised_error = shadow > 0 ? diff / shadow : 0.0;
  if (umbra_n > 0) p.umbra_ours /= umbra_n, p.umbra_ref /= umbra_n;
  p.width_ours = shadowed ? double(pen_ours) / shadowed : 0.0;
  p.width_ref = shadowed ? double(pen_ref) / shadowed : 0.0;
  std::printf(
      "sun r %.3f rad (λ %.0f), %s: normalised error %.3f over %zu receivers; umbra κ %.3f (truth %.3f); "
      "penumbra share %.3f (truth %.3f)\n",
      sun.radius, 4.0 / (sun.radius * sun.radius), lattice ? "lattice" : "exact", p.normalised_error, p.count,
      p.umbra_ours, p.umbra_ref, p.width_ours, p.width_ref);
  return p;
}

// Tolerances. Normalised error 0.25 (the target for the blurred
// metric is 0.40): beyond the SSDF grid (1.5 radii from the centre) its
// radial re-mapping, exact for a sphere, rounds a box's far shadow corners
// (measured 0.17 for the small sun, 0.13 for the large one). Umbra depth
// within 0.05 of κ (the strength). Penumbra, as a share of the shadowed
// receivers: within 0.1 of the truth's (the SG's erf edge against the
// disc's circular segment; measured 0.05 vs 0.09 and 0.33 vs 0.42). The
// lattice (InsertOptions::kappa_cache_spacing_radii, 0.15 radii ≈ 8 mm
// here) widens a hard edge to its spacing, below the metric's 5×5 blur
// (GT-input shadow error within 0.007 with and without it on sunroom): it
// is held to the error, the umbra within 0.08 and the hard/soft order.
TEST(CompactShadow, SmallSunCastsAHardShadowLargeOneASoftOne) {
  Sun small, large;
  small.radius = 0.02;                                                        // λ = 1e4
  large.radius = 0.2;                                                         // λ = 100
  large.radiance = small.radiance * small.SolidAngle() / large.SolidAngle();  // the same energy
  for (bool lattice : {false, true}) {
    const Profile hard = Measure(small, lattice), soft = Measure(large, lattice);
    ASSERT_GT(hard.count, 2000u);
    for (const Profile& p : {hard, soft}) {
      EXPECT_LT(p.normalised_error, 0.25);
      EXPECT_NEAR(p.umbra_ours, p.umbra_ref, lattice ? 0.08 : 0.05);
      if (!lattice) {
        EXPECT_NEAR(p.width_ours, p.width_ref, 0.1);
      }
    }
    EXPECT_LT(hard.width_ours, 0.9 * soft.width_ours);
  }
}

}  // namespace
}  // namespace nerfar
