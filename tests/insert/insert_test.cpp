// render/insert: rasteriser against brute-force ray casting of the same mesh,
// the analytic scene against numerical volume rendering, compositing with the
// clipped range, κ and object shading against quadrature, the incident light,
// and the stability cases of the issue (object far away, inside geometry,
// behind the camera, half out of frame, grazing light, a 1e5 sun, extreme
// materials): finite, plausible output.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "calib/core/parallel.h"
#include "render/insert/rasterizer.h"
#include "render/lighting/scene_field.h"
#include "render/mesh/mesh.h"
#include "tests/insert/test_camera.h"
#include "tests/support/analytic_scene.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

// Möller-Trumbore; the reference the rasteriser is checked against.
struct Hit {
  double t = std::numeric_limits<double>::infinity();
  uint32_t triangle = 0;
  double b1 = 0, b2 = 0;
  double margin = 0;  // smallest barycentric: how far inside the triangle the ray is
};

Hit CastRay(const std::vector<Vec3>& p, const TriangleMesh& mesh, const Vec3& o, const Vec3& d) {
  Hit best;
  for (uint32_t t = 0; t < mesh.triangles.size(); ++t) {
    const auto& idx = mesh.triangles[t];
    const Vec3 e1 = p[idx[1]] - p[idx[0]], e2 = p[idx[2]] - p[idx[0]];
    const Vec3 q = Cross(d, e2);
    const double det = Dot(e1, q);
    if (std::abs(det) < 1e-18) continue;
    const Vec3 s = o - p[idx[0]];
    const double u = Dot(s, q) / det;
    const Vec3 r = Cross(s, e1);
    const double v = Dot(d, r) / det;
    const double dist = Dot(e2, r) / det;
    if (u < 0 || v < 0 || u + v > 1 || dist <= 1e-9) continue;
    if (dist < best.t) best = {dist, t, u, v, std::min({u, v, 1 - u - v})};
  }
  return best;
}

struct RasterCase {
  TriangleMesh mesh;
  Pose T_world_object;
  double scale = 1.0;
  Pose T_world_camera;
};

// Every pixel: covered iff the ray hits (except within a hair of an edge),
// and then the same distance, position, normal and triangle.
void CompareWithRayCasting(const RasterCase& c, const CameraIntrinsics& camera, size_t* covered_out = nullptr) {
  const ObjectGBuffer g = Rasterize(camera, c.T_world_camera, {{&c.mesh, c.T_world_object, c.scale}});
  std::vector<Vec3> p(c.mesh.positions.size());
  for (size_t i = 0; i < p.size(); ++i) p[i] = c.T_world_object * (Vec3(c.mesh.positions[i]) * c.scale);
  size_t covered = 0, checked = 0;
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      const Vec3 d(CameraRayDirection(camera, c.T_world_camera, x, y));
      const Hit hit = CastRay(p, c.mesh, c.T_world_camera.translation, d);
      const bool raster = g.rect.Contains(x, y) && g.object[g.Index(x, y)] >= 0;
      const bool cast = std::isfinite(hit.t);
      // Pixel centres within 1e-4 (barycentric) of a triangle edge may go
      // either way (float set-up, shared edges); everything else must agree.
      if (cast && hit.margin < 1e-4) continue;
      if (!cast) {
        EXPECT_FALSE(raster) << "pixel " << x << "," << y << " drawn but the ray misses";
        continue;
      }
      ++checked;
      ASSERT_TRUE(raster) << "pixel " << x << "," << y << " hit at t=" << hit.t << " but not drawn";
      ++covered;
      const size_t i = g.Index(x, y);
      // Depth is interpolated as 1/z in double and stored in float: relative 1e-5.
      EXPECT_NEAR(g.t[i], hit.t, 1e-5 * hit.t + 1e-6) << x << "," << y;
      const Vec3 hit_p = c.T_world_camera.translation + d * hit.t;
      EXPECT_NEAR(g.position[i].x, hit_p.x, 1e-5) << x << "," << y;
      EXPECT_NEAR(g.position[i].y, hit_p.y, 1e-5) << x << "," << y;
      EXPECT_NEAR(g.position[i].z, hit_p.z, 1e-5) << x << "," << y;
      if (!c.mesh.normals.empty()) {
        const auto& idx = c.mesh.triangles[hit.triangle];
        const Vec3 n_local = Vec3(c.mesh.normals[idx[0]]) * (1 - hit.b1 - hit.b2) +
                             Vec3(c.mesh.normals[idx[1]]) * hit.b1 + Vec3(c.mesh.normals[idx[2]]) * hit.b2;
        Vec3 n = Normalized(c.T_world_object.Rotate(n_local));
        const Vec3 face = Cross(p[idx[1]] - p[idx[0]], p[idx[2]] - p[idx[0]]);
        if (Dot(face, d) > 0) n = -n;
        // Perspective-correct barycentrics in float: 1e-4 on a unit normal.
        EXPECT_NEAR(Dot(Vec3(g.normal[i]), n), 1.0, 1e-4) << x << "," << y;
      }
    }
  }
  EXPECT_GT(checked, 0u);
  size_t raster_covered = 0;
  for (int32_t o : g.object) raster_covered += o >= 0;
  EXPECT_EQ(raster_covered, g.covered);
  if (covered_out) *covered_out = covered;
}

TEST(Rasterizer, TorusMatchesRayCasting) {
  RasterCase c;
  c.mesh = MakeTorus(0.08, 0.03, 24, 12);
  c.T_world_object = {RotationFromAxisAngle({1, 0.3, 0}, 0.7), {0.02, -0.01, 0.05}};
  c.T_world_camera = LookAt({0.25, -0.3, 0.2}, {0, 0, 0.05});
  size_t covered = 0;
  CompareWithRayCasting(c, testing::TestCamera(160, 120), &covered);
  EXPECT_GT(covered, 500u);  // the torus fills a good part of the frame
}

TEST(Rasterizer, ScaledSphereHalfOutOfFrame) {
  RasterCase c;
  c.mesh = MakeUvSphere(1.0, 24, 12);
  c.scale = 0.05;
  c.T_world_camera = LookAt({0.4, 0, 0.1}, {0, 0, 0.1});
  // The camera looks past the sphere: it straddles the image's right border
  // (camera x is world +y here; half the view is 0.4·80/144 = 0.222 m wide).
  c.T_world_object = {Mat3::Identity(), {0, 0.22, 0.1}};
  const CameraIntrinsics camera = testing::TestCamera(160, 120);
  const ObjectGBuffer g = Rasterize(camera, c.T_world_camera, {{&c.mesh, c.T_world_object, c.scale}});
  ASSERT_FALSE(g.rect.empty());
  EXPECT_EQ(g.rect.x1, camera.width);  // clipped at the border
  EXPECT_GT(g.rect.x0, camera.width / 2);
  CompareWithRayCasting(c, camera);
}

TEST(Rasterizer, NearPlaneClippingWithCameraInsideTheObject) {
  // A box around the camera: every pixel sees an inner face; the triangles
  // crossing the camera plane are clipped, never dropped or drawn wrapped.
  RasterCase c;
  c.mesh = MakeBox({0.5, 0.4, 0.3});
  c.T_world_object = {RotationFromAxisAngle({0, 0, 1}, 0.3), {0.05, 0.02, 0.0}};
  c.T_world_camera = LookAt({0.0, 0.0, 0.0}, {1.0, 0.2, -0.1});
  size_t covered = 0;
  CompareWithRayCasting(c, testing::TestCamera(160, 120), &covered);
  const CameraIntrinsics camera = testing::TestCamera(160, 120);
  EXPECT_GT(covered, static_cast<size_t>(camera.width * camera.height * 9 / 10));
}

TEST(Rasterizer, BehindTheCameraDrawsNothing) {
  const TriangleMesh mesh = MakeUvSphere(0.05, 16, 8);
  const Pose cam = LookAt({0.5, 0, 0.1}, {1.0, 0, 0.1});  // looks away from the origin
  const ObjectGBuffer g = Rasterize(testing::TestCamera(160, 120), cam, {{&mesh, Pose::Identity(), 1.0}});
  EXPECT_TRUE(g.rect.empty());
  EXPECT_EQ(g.covered, 0u);
}

TEST(Rasterizer, NearestObjectWinsAndThreadCountDoesNotMatter) {
  const TriangleMesh a = MakeUvSphere(0.05, 24, 12);
  const TriangleMesh b = MakeBox({0.04, 0.04, 0.04});
  const Pose cam = LookAt({0.5, -0.1, 0.15}, {0, 0, 0.05});
  const std::vector<RasterObject> objects = {{&a, {Mat3::Identity(), {0.0, 0.0, 0.05}}, 1.0},
                                             {&b, {Mat3::Identity(), {0.1, 0.0, 0.05}}, 1.0}};
  const CameraIntrinsics camera = testing::TestCamera(160, 120);
  SetThreadCount(1);
  const ObjectGBuffer g1 = Rasterize(camera, cam, objects);
  SetThreadCount(2);
  const ObjectGBuffer g2 = Rasterize(camera, cam, objects);
  SetThreadCount(0);
  EXPECT_EQ(g1.object, g2.object);
  EXPECT_EQ(g1.t, g2.t);
  // Check the depth order against casting both meshes.
  std::vector<Vec3> pa, pb;
  for (const auto& v : a.positions) pa.push_back(objects[0].T_world_object * Vec3(v));
  for (const auto& v : b.positions) pb.push_back(objects[1].T_world_object * Vec3(v));
  size_t both = 0;
  for (int y = g1.rect.y0; y < g1.rect.y1; ++y) {
    for (int x = g1.rect.x0; x < g1.rect.x1; ++x) {
      const Vec3 d(CameraRayDirection(camera, cam, x, y));
      const Hit ha = CastRay(pa, a, cam.translation, d), hb = CastRay(pb, b, cam.translation, d);
      if (!std::isfinite(ha.t) || !std::isfinite(hb.t) || ha.margin < 1e-4 || hb.margin < 1e-4) continue;
      ++both;
      EXPECT_EQ(g1.object[g1.Index(x, y)], ha.t < hb.t ? 0 : 1) << x << "," << y;
    }
  }
  EXPECT_GT(both, 20u);  // the box is partly behind the sphere in this view
}

TEST(Rasterizer, ProjectBallHoldsTheSphere) {
  const CameraIntrinsics camera = testing::TestCamera(160, 120);
  const TriangleMesh sphere = MakeUvSphere(0.06, 32, 16);
  for (const Vec3& center : {Vec3{0, 0, 0.05}, Vec3{0.15, 0.1, 0.0}, Vec3{-0.2, 0.3, 0.1}}) {
    const Pose cam = LookAt({0.5, -0.2, 0.3}, {0, 0, 0});
    const ObjectGBuffer g = Rasterize(camera, cam, {{&sphere, {Mat3::Identity(), center}, 1.0}});
    const PixelRect r = ProjectBall(camera, cam, center, 0.06);
    for (int y = g.rect.y0; y < g.rect.y1; ++y) {
      for (int x = g.rect.x0; x < g.rect.x1; ++x) {
        if (g.object[g.Index(x, y)] >= 0) {
          EXPECT_TRUE(r.Contains(x, y)) << x << "," << y;
        }
      }
    }
  }
  // Behind the camera: empty; around the camera: the whole image.
  const Pose cam = LookAt({0, 0, 0}, {1, 0, 0});
  EXPECT_TRUE(ProjectBall(camera, cam, {-1, 0, 0}, 0.1).empty());
  EXPECT_EQ(ProjectBall(camera, cam, {0.01, 0, 0}, 0.1).area(), static_cast<size_t>(camera.width * camera.height));
}

TEST(Rasterizer, DegenerateAndNonFiniteTrianglesAreSkipped) {
  TriangleMesh mesh = MakeUvSphere(0.05, 12, 6);
  mesh.positions.push_back({0, 0, 0});
  mesh.positions.push_back({0, 0, 0});
  mesh.positions.push_back({std::numeric_limits<float>::quiet_NaN(), 0, 0});
  mesh.normals.resize(mesh.positions.size(), {0, 0, 1});
  const uint32_t n = static_cast<uint32_t>(mesh.positions.size());
  mesh.triangles.push_back({n - 3, n - 2, n - 3});  // zero area
  mesh.triangles.push_back({n - 3, n - 2, n - 1});  // NaN corner
  mesh.triangles.push_back({0, 1, n + 5});          // index out of range
  const Pose cam = LookAt({0.3, 0, 0.1}, {0, 0, 0});
  const ObjectGBuffer g = Rasterize(testing::TestCamera(160, 120), cam, {{&mesh, Pose::Identity(), 1.0}});
  EXPECT_GT(g.covered, 100u);
  for (size_t i = 0; i < g.t.size(); ++i) {
    EXPECT_TRUE(std::isfinite(g.t[i]));
    EXPECT_TRUE(std::isfinite(g.normal[i].x));
  }
}

// ------------------------------------------------------------ scene field

TEST(SceneField, IntersectBox) {
  const Aabb box{{-1, -1, -1}, {1, 1, 1}};
  auto r = IntersectBox(box, {-3, 0, 0}, {1, 0, 0});
  ASSERT_TRUE(r);
  EXPECT_DOUBLE_EQ(r->first, 2.0);
  EXPECT_DOUBLE_EQ(r->second, 4.0);
  r = IntersectBox(box, {0, 0, 0}, {0, 0, 1});  // inside: starts at 0
  ASSERT_TRUE(r);
  EXPECT_DOUBLE_EQ(r->first, 0.0);
  EXPECT_DOUBLE_EQ(r->second, 1.0);
  EXPECT_FALSE(IntersectBox(box, {-3, 2, 0}, {1, 0, 0}));  // parallel outside
  EXPECT_FALSE(IntersectBox(box, {3, 0, 0}, {1, 0, 0}));   // box behind
  EXPECT_FALSE(IntersectBox(box, {0, 0, 0}, {std::nan(""), 0, 0}));
}

// Numerical volume rendering of the analytic scene (midpoint rule on a fine
// grid; the surfaces as a hard stop), an independent check of the closed form.
void MarchReference(const testing::AnalyticScene& scene, const Vec3& o, const Vec3& d, double t0, double t1,
                    Vec3& colour, double& opacity, double& depth) {
  const auto& p = scene.params();
  const int steps = 200000;
  const double dt = (t1 - t0) / steps;
  double transmittance = 1.0;
  colour = {};
  opacity = depth = 0;
  for (int k = 0; k < steps; ++k) {
    const double t = t0 + (k + 0.5) * dt;
    const Vec3 x = o + d * t;
    // Opaque surfaces: the plane within the box, the sphere.
    const bool on_plane = (o.z + d.z * (t - 0.5 * dt)) * (o.z + d.z * (t + 0.5 * dt)) <= 0 && x.x >= p.box.min.x &&
                          x.x <= p.box.max.x && x.y >= p.box.min.y && x.y <= p.box.max.y;
    const bool in_sphere = p.has_sphere && Length(x - p.sphere_center) < p.sphere_radius;
    if (on_plane || in_sphere) {
      // Radiance of the surface: sample the field itself with a zero-length look-up.
      Vec3 c;
      double a = 0, dd = 0;
      scene.RenderOne(x - d * dt, d, 0, 2 * dt, c, a, dd);
      colour += c * transmittance;
      opacity += transmittance;
      depth += transmittance * t;
      return;
    }
    if (p.has_medium && Length(x - p.medium_center) < p.medium_radius) {
      const double alpha = -std::expm1(-p.medium_density * dt);
      colour += Vec3(p.medium_radiance) * (transmittance * alpha);
      opacity += transmittance * alpha;
      depth += transmittance * alpha * t;
      transmittance *= 1 - alpha;
    }
  }
}

TEST(SceneField, AnalyticMatchesNumericalVolumeRendering) {
  const testing::AnalyticScene scene;
  const auto& p = scene.params();
  struct Ray {
    Vec3 o, d;
  };
  const std::vector<Ray> rays = {
      {{0.2, -0.1, 0.5}, Normalized(Vec3{0, 0, -1})},  // through the medium onto the table
      {{0.5, -0.4, 0.3}, Normalized(p.medium_center - Vec3{0.5, -0.4, 0.3})},
      {{-0.2, 0.5, 0.3}, Normalized(p.sphere_center - Vec3{-0.2, 0.5, 0.3})},  // the opaque sphere
      {{0.0, 0.0, 0.5}, Normalized(Vec3{0.1, 0.05, -1})},                      // the table
  };
  for (const Ray& r : rays) {
    const auto range = IntersectBox(p.box, r.o, r.d);
    ASSERT_TRUE(range);
    Vec3 c, c_ref;
    double a, a_ref, dep, dep_ref;
    scene.RenderOne(r.o, r.d, range->first, range->second, c, a, dep);
    MarchReference(scene, r.o, r.d, range->first, range->second, c_ref, a_ref, dep_ref);
    // Midpoint rule with 2e5 steps over < 1 m: error ~ σ·dt ≈ 1e-4 relative,
    // plus the surface located within one step (5e-6 m).
    EXPECT_NEAR(a, a_ref, 2e-4);
    EXPECT_NEAR(c.x, c_ref.x, 2e-4);
    EXPECT_NEAR(c.z, c_ref.z, 2e-4);
    EXPECT_NEAR(dep, dep_ref, 2e-4);
    EXPECT_GT(a, 0.5);
  }
  // Homogeneous ball through its centre: 1 − exp(−σ·2r) exactly.
  Vec3 c;
  double a, dep;
  const Vec3 o = p.medium_center + Vec3{0, 0, 0.3};
  scene.RenderOne(o, {0, 0, -1}, 0.0, 0.3 + p.medium_radius + 0.01, c, a, dep);  // stop before the table
  EXPECT_NEAR(a, 1 - std::exp(-p.medium_density * 2 * p.medium_radius), 1e-12);
}

TEST(SceneField, ClippedRangeRemovesWhatLiesBehind) {
  const testing::AnalyticScene scene;
  const auto& p = scene.params();
  const Vec3 o{p.medium_center.x, p.medium_center.y, 0.4};
  const Vec3 d{0, 0, -1};
  Vec3 c;
  double a, dep;
  // Range ending at the medium's centre: half the chord, the table never seen.
  const double mid = o.z - p.medium_center.z;
  scene.RenderOne(o, d, 0.0, mid, c, a, dep);
  EXPECT_NEAR(a, 1 - std::exp(-p.medium_density * p.medium_radius), 1e-12);
  // Empty range: nothing.
  scene.RenderOne(o, d, mid, mid, c, a, dep);
  EXPECT_EQ(a, 0.0);
}

}  // namespace
}  // namespace nerfar
