// render/insert: the work-saving paths against the exact per-pixel ones —
// self-shadow γ per mesh vertex vs an SSDF query per pixel, occlusion from
// coarse corner rays vs a ray per pixel, κ from the world lattice cache vs κ
// at every receiver — and the caches' lifetime (kept while nothing moves,
// rebuilt when an object or the light moves).
#include <gtest/gtest.h>

#include <cmath>

#include "render/insert/inserter.h"
#include "render/sg/sphere.h"
#include "tests/insert/insert_fixtures.h"
#include "tests/insert/kappa_compare.h"
#include "tests/insert/test_camera.h"
#include "tests/support/analytic_scene.h"

namespace nerfar {
namespace {

using testing::OneLobe;
using testing::PlainTable;
using testing::SphereObject;

TEST(FastPath, VertexGammaMatchesPerPixelGamma) {
  // The upper ball half-shadows the lower one under a tilted lobe and a sky:
  // γ varies over the lower ball's surface from 0 to 1.
  const testing::AnalyticScene scene(PlainTable());
  const SphereObject lower({0.0, 0.0, 0.05}, 0.05), upper({0.04, 0.0, 0.19}, 0.05);
  const CameraIntrinsics camera = testing::TestCamera(160, 120);
  const Pose cam = LookAt({0.35, -0.15, 0.15}, lower.center);
  SgMixture light = OneLobe({0.3, 0.0, 1.0}, 30.0, 8.0);
  light.push_back(OneLobe({0, 0, 1}, 1.0, 0.5)[0]);
  InsertOptions exact, fast;
  exact.shadows = fast.shadows = false;
  exact.self_shadow_per_vertex = false;
  fast.self_shadow_per_vertex = true;
  ImageF fa(camera.width, camera.height, 3, 0.f), fb = fa;
  InsertLayers la, lb;
  const std::vector<InsertObject> objects = {lower.Object(&light), upper.Object(&light)};
  Inserter(scene, {}, exact).Render(camera, cam, objects, fa, &la);
  const InsertTimings tb = Inserter(scene, {}, fast).Render(camera, cam, objects, fb, &lb);
  EXPECT_TRUE(tb.gamma_recomputed);
  // Over the lower ball: the relative difference of the shading, and how
  // much the self-shadow changes it at all (without γ the difference would
  // be that large).
  double diff = 0, sum = 0;
  size_t shadowed = 0, n = 0;
  InsertOptions none = exact;
  none.self_shadow = false;
  ImageF fc(camera.width, camera.height, 3, 0.f);
  InsertLayers lc;
  Inserter(scene, {}, none).Render(camera, cam, objects, fc, &lc);
  for (size_t i = 0; i < la.gbuffer.object.size(); ++i) {
    if (la.gbuffer.object[i] != 0) continue;
    const double a = la.object.pixels[i * 3], b = lb.object.pixels[i * 3], c = lc.object.pixels[i * 3];
    diff += std::abs(a - b);
    sum += a;
    shadowed += a < 0.7 * c;
    ++n;
  }
  ASSERT_GT(n, 500u);
  ASSERT_GT(shadowed, 100u);  // γ really darkens part of it
  // Interpolating γ over 48×24-segment triangles blurs the shadow edge over
  // one triangle (~4 pixels here): a few percent of the radiance on average.
  EXPECT_LT(diff / sum, 0.05) << "mean relative difference";
}

TEST(FastPath, CoarseOcclusionMatchesARayPerPixel) {
  // The translucent medium ball and the opaque sphere of the analytic scene
  // partly hide the object: blocks near their silhouettes must be marched.
  testing::AnalyticSceneParams params;
  params.sphere_center = {0.1, 0.06, 0.12};
  const testing::AnalyticScene scene(params);
  const SphereObject object({0.0, -0.02, 0.1}, 0.05);
  const Pose cam = LookAt({0.6, -0.02, 0.1}, object.center);
  const CameraIntrinsics camera = testing::TestCamera(160, 120);
  const SgMixture light = OneLobe({0, 0, 1}, 2.0, 1.0);
  InsertOptions exact, fast;
  exact.shadows = fast.shadows = false;
  exact.occlusion_step = 1;
  fast.occlusion_step = 4;
  ImageF fa(camera.width, camera.height, 3, 0.25f), fb = fa;
  InsertLayers la, lb;
  Inserter(scene, {}, exact).Render(camera, cam, {object.Object(&light)}, fa, &la);
  Inserter(scene, {}, fast).Render(camera, cam, {object.Object(&light)}, fb, &lb);
  size_t occluded = 0, clear = 0;
  double worst = 0;
  for (size_t i = 0; i < la.gbuffer.object.size(); ++i) {
    if (la.gbuffer.object[i] < 0) continue;
    occluded += la.alpha.pixels[i] < 0.9f;
    clear += la.alpha.pixels[i] == 1.0f;
    worst = std::max(worst, double(std::abs(la.alpha.pixels[i] - lb.alpha.pixels[i])));
  }
  ASSERT_GT(occluded, 100u);  // the scene really hides part of the object
  ASSERT_GT(clear, 100u);     // and leaves part of it free
  // A block is taken as free only when its four corner rays (each up to the
  // farthest object depth around it) see less than 1e-3 opacity; between
  // them the smooth medium cannot reach much more: 1e-2 bounds it.
  EXPECT_LT(worst, 1e-2);
  for (size_t i = 0; i < fa.pixels.size(); ++i) ASSERT_NEAR(fa.pixels[i], fb.pixels[i], 1e-2 * (1 + fa.pixels[i]));
}

TEST(FastPath, KappaLatticeMatchesExactKappaAndIsKeptWhileStill) {
  const testing::AnalyticScene scene(PlainTable());
  SphereObject object({0.0, 0.0, 0.06}, 0.05);
  // κ at every pixel: receivers ~1.5 mm apart, denser than the 5 mm lattice
  // (as at 1280x720), so that views share lattice nodes.
  const CameraIntrinsics camera = testing::TestCamera(240, 180);
  const Pose cam = LookAt({0.25, -0.3, 0.35}, {0.02, 0.0, 0.0});
  SgMixture light = OneLobe({0.4, 0.1, 1.0}, 40.0, 5.0);
  light.push_back(OneLobe({0, 0, 1}, 0.5, 0.3)[0]);
  InsertOptions exact, cached;
  exact.kappa_step = cached.kappa_step = 1;
  exact.kappa_coarse_factor = cached.kappa_coarse_factor = 1;
  exact.kappa_cache_spacing_radii = 0.0;
  cached.kappa_cache_spacing_radii = 0.1;
  ImageF frame(camera.width, camera.height, 3, 1.0f);
  InsertLayers la, lb;
  ImageF fa = frame, fb = frame;
  Inserter(scene, {}, exact).Render(camera, cam, {object.Object(&light)}, fa, &la);
  Inserter inserter(scene, {}, cached);
  const InsertTimings first = inserter.Render(camera, cam, {object.Object(&light)}, fb, &lb);
  const testing::KappaDifference d = testing::CompareKappa(lb.kappa, la.kappa);
  const double diff = d.sum, shadow = d.shadow;
  ASSERT_GT(shadow, 10.0);
  // Trilinear κ at 0.1-radius lattice nodes (5 mm) with the normal in a
  // ~4° cell: the shadow's edge (penumbra ~1 cm wide under this λ = 40 lobe
  // from 6 cm) moves by a fraction of a node: under 5% of the shadow.
  EXPECT_LT(diff / shadow, 0.05);
  EXPECT_GT(first.kappa_evaluated, 0u);
  // The same view again, nothing moved: every κ comes from the lattice.
  ImageF f2 = frame;
  EXPECT_EQ(inserter.Render(camera, cam, {object.Object(&light)}, f2).kappa_evaluated, 0u);
  for (size_t i = 0; i < f2.pixels.size(); ++i) ASSERT_EQ(f2.pixels[i], fb.pixels[i]);
  // The camera moved by 1 cm: only nodes the first view did not reach.
  f2 = frame;
  const InsertTimings near =
      inserter.Render(camera, LookAt({0.26, -0.3, 0.35}, {0.02, 0.0, 0.0}), {object.Object(&light)}, f2);
  EXPECT_LE(near.kappa_evaluated, first.kappa_evaluated / 4);
  // The object moved: the lattice is rebuilt and the shadow follows.
  object = SphereObject({0.03, 0.0, 0.06}, 0.05);
  ImageF f3 = frame;
  InsertLayers l3;
  const InsertTimings moved = inserter.Render(camera, cam, {object.Object(&light)}, f3, &l3);
  EXPECT_GT(moved.kappa_evaluated, first.kappa_evaluated / 2);
  ImageF f4 = frame;
  InsertLayers l4;
  Inserter(scene, {}, exact).Render(camera, cam, {object.Object(&light)}, f4, &l4);
  EXPECT_LT(testing::CompareKappa(l3.kappa, l4.kappa).Relative(), 0.05);
}

// A view already passed whole: κ is passed only over the projection of the
// lattice's shadowed nodes, and the κ layer over the whole frame is the same
// value for value (the restricted grid is aligned to the whole one's coarse
// grid, and outside it κ was ≥ 1 − ε).
TEST(FastPath, RepeatedViewPassesOnlyTheShadowedArea) {
  const testing::AnalyticScene scene(PlainTable());
  const SphereObject object({0.0, 0.0, 0.06}, 0.05);
  const CameraIntrinsics camera = testing::TestCamera(240, 180);
  const Pose cam = LookAt({0.25, -0.3, 0.35}, {0.02, 0.0, 0.0});
  const SgMixture light = OneLobe({0.4, 0.1, 1.0}, 40.0, 5.0);  // one sharp lobe: a local shadow
  InsertOptions options;
  options.kappa_cache_spacing_radii = 0.1;
  Inserter inserter(scene, {}, options);
  const ImageF frame(camera.width, camera.height, 3, 1.0f);
  ImageF f1 = frame, f2 = frame;
  InsertLayers l1, l2;
  const InsertTimings first = inserter.Render(camera, cam, {object.Object(&light)}, f1, &l1);
  const InsertTimings second = inserter.Render(camera, cam, {object.Object(&light)}, f2, &l2);
  ASSERT_FALSE(l1.kappa_rect.empty());
  ASSERT_FALSE(l2.kappa_rect.empty());
  // The reach (12 radii) covers the whole 240x180 view; the shadow of the
  // ball under one lobe, seen this close, about 70% of it: a smaller pass.
  EXPECT_LT(l2.kappa_rect.area(), l1.kappa_rect.area());
  EXPECT_LT(second.kappa_marched, first.kappa_marched);
  EXPECT_EQ(second.kappa_evaluated, 0u);
  const ImageF k1 = ExpandLayer(l1.kappa, l1.kappa_rect, camera.width, camera.height, 1.0f);
  const ImageF k2 = ExpandLayer(l2.kappa, l2.kappa_rect, camera.width, camera.height, 1.0f);
  double shadow = 0;
  for (size_t i = 0; i < k1.pixels.size(); ++i) {
    shadow += 1 - k1.pixels[i];
    // Inside the restricted rectangle the same nodes and cells give the same
    // values; outside it the first pass had κ ≥ 1 − ε there (ε = 2e-3).
    ASSERT_NEAR(k1.pixels[i], k2.pixels[i], 2e-3) << "pixel " << i;
  }
  EXPECT_GT(shadow, 10.0);
  for (size_t i = 0; i < f1.pixels.size(); ++i) ASSERT_NEAR(f1.pixels[i], f2.pixels[i], 2e-3f);
  // The same view a third time (same rectangle as the second): the last κ
  // layer is reused, nothing is marched, the frame is the second's exactly.
  ImageF f3 = frame;
  InsertLayers l3;
  const InsertTimings third = inserter.Render(camera, cam, {object.Object(&light)}, f3, &l3);
  EXPECT_EQ(third.kappa_marched, 0u);
  for (size_t i = 0; i < f3.pixels.size(); ++i) ASSERT_EQ(f3.pixels[i], f2.pixels[i]);
  // A new view (1 cm away) is passed again.
  ImageF f4 = frame;
  EXPECT_GT(
      inserter.Render(camera, LookAt({0.26, -0.3, 0.35}, {0.02, 0.0, 0.0}), {object.Object(&light)}, f4).kappa_marched,
      0u);
}

// A hand-held camera (2 mm and a slight turn per frame, object and light
// still): receivers taken from the last frame's (kappa_receiver_reuse) with
// one normal per world cell (receiver_normal_per_cell) against every
// receiver marched with its own normal, frame by frame, with the shadow falling on
// the table and on the scene's sphere (curved: its cells fail the plane test
// and are marched).
TEST(FastPath, HandHeldFramesReuseReceivers) {
  testing::AnalyticSceneParams params = PlainTable();
  params.has_sphere = true;
  const testing::AnalyticScene scene(params);
  const SphereObject object({-0.04, 0.1, 0.05}, 0.04);
  const CameraIntrinsics camera = testing::TestCamera(240, 180);
  SgMixture light = OneLobe({0.8, -0.1, 1.0}, 40.0, 5.0);
  light.push_back(OneLobe({0, 0, 1}, 1.0, 0.3)[0]);
  InsertOptions reuse;  // balanced: κ step 2, coarse factor 4, plane upsampling, lattice 0.15 radii
  InsertOptions marched = reuse;
  marched.kappa_receiver_reuse = false;
  marched.receiver_normal_per_cell = false;  // the exact receivers: a march and a normal query each
  Inserter with_reuse(scene, {}, reuse), without(scene, {}, marched);
  const ImageF frame(camera.width, camera.height, 3, 1.0f);
  size_t marched_reuse = 0, marched_all = 0, reused = 0;
  double worst_mean = 0, worst_max = 0;
  for (int f = 0; f < 6; ++f) {
    const Pose cam = LookAt({0.22 + 0.002 * f, -0.3 + 0.001 * f, 0.35}, {-0.1, 0.1, 0.02});
    ImageF fa = frame, fb = frame;
    InsertLayers la, lb;
    const InsertTimings ta = with_reuse.Render(camera, cam, {object.Object(&light)}, fa, &la);
    const InsertTimings tb = without.Render(camera, cam, {object.Object(&light)}, fb, &lb);
    EXPECT_EQ(tb.kappa_reused, 0u);
    if (f == 0) {
      EXPECT_EQ(ta.kappa_reused, 0u);  // nothing kept yet
    } else {
      marched_reuse += ta.kappa_marched;
      marched_all += tb.kappa_marched;
      reused += ta.kappa_reused;
    }
    const ImageF ka = ExpandLayer(la.kappa, la.kappa_rect, camera.width, camera.height, 1.0f);
    const ImageF kb = ExpandLayer(lb.kappa, lb.kappa_rect, camera.width, camera.height, 1.0f);
    const testing::KappaDifference d = testing::CompareKappa(ka, kb);
    const double diff = d.sum, shadow = d.shadow, max_diff = d.max;
    ASSERT_GT(shadow, 50.0) << "frame " << f;
    worst_mean = std::max(worst_mean, diff / shadow);
    worst_max = std::max(worst_max, max_diff);
  }
  std::printf("hand-held: marched %zu (reuse) vs %zu (all), reused %zu, worst mean %.4f max %.4f\n", marched_reuse,
              marched_all, reused, worst_mean, worst_max);
  EXPECT_GT(reused, 0u);
  // Half the marches saved at least (the table's cells; the sphere's fail
  // the plane test, cells off the table see the eye move 2.2 mm > 0.8 mm).
  EXPECT_LT(marched_reuse, marched_all / 2);
  // A reused receiver lies within 0.02 radii (0.8 mm) of the tangent planes
  // of four marched receivers with normals within 10° and takes one of their
  // normals: κ, trilinear over 6 mm lattice nodes in ~4° normal cells, moves
  // by a fraction of a node at most; a cell's normal is the exact one at a
  // point of the cell (the table's exactly, the 8 cm sphere's within ~4°
  // over a 6 mm cell): under 2% of the shadow per frame and 0.05 at any
  // pixel (an edge pixel's full κ step is ~0.3 here). Measured 1e-4 and
  // 0.008.
  EXPECT_LT(worst_mean, 0.02);
  EXPECT_LT(worst_max, 0.05);
}

TEST(FastPath, VertexGammaIsKeptWhileStillAndRebuiltWhenTheLightChanges) {
  const testing::AnalyticScene scene(PlainTable());
  const SphereObject object({0.0, 0.0, 0.05}, 0.05);
  const CameraIntrinsics camera = testing::TestCamera(96, 72);
  const Pose cam = LookAt({0.3, -0.2, 0.25}, object.center);
  const SgMixture light = OneLobe({0.2, 0.1, 1.0}, 10.0, 3.0), other = OneLobe({-0.5, 0.1, 1.0}, 10.0, 3.0);
  InsertOptions options;
  options.shadows = false;
  Inserter inserter(scene, {}, options);
  ImageF frame(camera.width, camera.height, 3, 0.f);
  EXPECT_TRUE(inserter.Render(camera, cam, {object.Object(&light)}, frame).gamma_recomputed);
  EXPECT_FALSE(inserter.Render(camera, LookAt({0.25, -0.3, 0.2}, object.center), {object.Object(&light)}, frame)
                   .gamma_recomputed);
  EXPECT_TRUE(inserter.Render(camera, cam, {object.Object(&other)}, frame).gamma_recomputed);
}

TEST(FastPath, EdgeCoverageMatchesTheAreaOfADisc) {
  // A flat disc facing the camera (a thin cylinder seen end-on would do; a
  // 96-gon is within 0.05% of a circle's area): the coverage summed over the
  // pixels is its projected area, which a centre test only gets to about
  // its perimeter in pixels.
  TriangleMesh disc;
  const int sides = 96;
  disc.positions.push_back({0, 0, 0});
  for (int k = 0; k < sides; ++k) {
    const double a = 2 * kPi * k / sides;
    disc.positions.push_back({float(std::cos(a)), float(std::sin(a)), 0.0f});
  }
  for (int k = 0; k < sides; ++k) disc.triangles.push_back({0u, uint32_t(1 + k), uint32_t(1 + (k + 1) % sides)});
  CameraIntrinsics camera = testing::TestCamera(128, 96);
  // Camera 1 m in front of the disc (radius 0.1 m), looking along −z.
  const Pose cam = LookAt({0.0013, 0.0021, 1.0}, {0.0013, 0.0021, 0.0});
  RasterOptions options;
  options.coverage_grid = 4;
  const ObjectGBuffer g = Rasterize(camera, cam, {{&disc, Pose{}, 0.1}}, options);
  ASSERT_EQ(g.coverage.size(), g.object.size());
  double area = 0;
  size_t partial = 0;
  for (float c : g.coverage) {
    area += c;
    partial += c > 0.0f && c < 1.0f;
  }
  const double r_px = 0.1 * camera.fx;  // projected radius at 1 m (fx = fy)
  const double expected = kPi * r_px * r_px;
  // 16 sub-samples per edge pixel: each edge pixel's coverage is off by up
  // to 1/16, and these errors are signed and roughly cancel; 1% of the area.
  EXPECT_NEAR(area, expected, 0.01 * expected);
  EXPECT_GT(partial, size_t(4 * r_px));  // the edge pixels are fractional (perimeter 2π r)
}

}  // namespace
}  // namespace nerfar
