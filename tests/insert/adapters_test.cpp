// render/insert adapters: the NeRF as a SceneField (homogeneous field against
// the closed form, the clipped range, normals from the density gradient) and
// a baked SSDF field posed in the world against the exact sphere occluder,
// inside, near and far outside its grid.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "render/insert/nerf_scene.h"
#include "render/insert/object_visibility.h"
#include "render/insert/ssdf_visibility.h"
#include "render/mesh/mesh.h"
#include "render/ssdf/ssdf.h"

namespace nerfar {
namespace {

TEST(NerfScene, HomogeneousFieldMatchesTheClosedForm) {
  const Aabb box{{0, 0, 0}, {1, 1, 1}};
  const float sigma = 2.0f;
  const NerfField field =
      NerfField::Dense(box, 0.05, std::log(sigma), {std::log(0.5f), std::log(0.5f), std::log(0.5f)});
  const NerfScene scene(field);
  SceneRays rays;
  rays.Add({0.0f, 0.5f, 0.5f}, {1, 0, 0}, 0.0f, 1.0f);
  rays.Add({0.0f, 0.5f, 0.5f}, {1, 0, 0}, 0.0f, 0.5f);  // the clipped range: half the slab
  rays.Add({0.0f, 0.5f, 0.5f}, {1, 0, 0}, 0.3f, 0.3f);  // empty range
  SceneSamples out;
  scene.RenderRays(rays, out);
  const double o1 = 1 - std::exp(-sigma * 1.0), o2 = 1 - std::exp(-sigma * 0.5);
  // The renderer's step is half a voxel (2.5 cm): σ·dt = 0.05, and its
  // quadrature errs by well under 1e-3 in opacity.
  EXPECT_NEAR(out.opacity[0], o1, 2e-3);
  EXPECT_NEAR(out.opacity[1], o2, 2e-3);
  EXPECT_NEAR(out.opacity[2], 0.0, 1e-6);
  EXPECT_NEAR(out.colour[0].x, 0.5 * o1, 2e-3);
  // Expected termination distance ∫ tσe^{−σt} dt / O over [0, 1].
  const double depth = ((1 - std::exp(-sigma)) / sigma - std::exp(-sigma)) / o1;
  EXPECT_NEAR(out.depth[0], depth, 5e-3);
}

TEST(NerfScene, NormalsPointOutOfADenseSlab) {
  const Aabb box{{0, 0, 0}, {1, 1, 1}};
  NerfField field = NerfField::Dense(box, 0.05, kNerfEmptyDensityRaw, {0, 0, 0});
  for (int k = 0; k < field.res[2]; ++k)
    for (int j = 0; j < field.res[1]; ++j)
      for (int i = 0; i < field.res[0]; ++i)
        if (k <= 9) field.density[field.Slot(i, j, k)] = std::log(1000.0f);
  field.UpdateOccupancy(1.0f);
  const NerfScene scene(field);
  std::vector<Vec3f> normals;
  // The slab's top is between the vertices at z = 0.45 (dense) and 0.5 (empty).
  scene.Normals({{0.5f, 0.5f, 0.46f}, {0.31f, 0.72f, 0.48f}, {0.5f, 0.5f, 0.9f}}, normals);
  EXPECT_NEAR(normals[0].z, 1.0f, 1e-3);
  // Off the vertex columns the averaged trilinear gradients tilt it by a few
  // degrees (measured 12.5° at most here: cos > 0.97).
  EXPECT_GT(normals[1].z, 0.97f);
  // Far above the slab the gradient is zero: no normal.
  EXPECT_EQ(normals[2], Vec3f{});
}

// A half-space below the tilted plane z = 0.2 + 0.3·(x − 0.2) (σ = 1000/m),
// its vertices within 1.5 voxels of the plane perturbed by a hash by up to
// e^{±2} in density: a trained field's noisy surface. Normals at points on
// the plane against the plane's own normal (−0.3, 0, 1)/|·|.
TEST(NerfScene, SurfaceProbeNormalsFollowANoisyTiltedSurface) {
  const Aabb box{{0, 0, 0}, {0.4, 0.4, 0.4}};
  const double voxel = 0.01;
  NerfField field = NerfField::Dense(box, voxel, kNerfEmptyDensityRaw, {0, 0, 0});
  const auto plane = [](double x) { return 0.2 + 0.3 * (x - 0.2); };
  for (int k = 0; k < field.res[2]; ++k)
    for (int j = 0; j < field.res[1]; ++j)
      for (int i = 0; i < field.res[0]; ++i) {
        const double x = i * voxel, z = k * voxel;
        const double below = plane(x) - z;  // > 0 inside
        if (below < -1.5 * voxel) continue;
        float raw = below > 0 ? std::log(1000.0f) : kNerfEmptyDensityRaw;
        if (std::abs(below) <= 1.5 * voxel) {
          const uint32_t hash = (static_cast<uint32_t>(i) * 73856093u) ^ (static_cast<uint32_t>(j) * 19349663u) ^
                                (static_cast<uint32_t>(k) * 83492791u);
          const float u = static_cast<float>(hash % 1000u) / 999.0f;  // [0, 1]
          raw = (below > 0 ? std::log(1000.0f) : std::log(30.0f)) + 4.0f * (u - 0.5f);
        }
        field.density[field.Slot(i, j, k)] = raw;
      }
  field.UpdateOccupancy(1.0f);
  const Vec3f truth = Normalized(Vec3f{-0.3f, 0.0f, 1.0f});
  std::vector<Vec3f> points;
  for (int a = 0; a < 6; ++a)
    for (int b = 0; b < 6; ++b) {
      const float x = 0.12f + 0.031f * a, y = 0.11f + 0.033f * b;
      points.push_back({x, y, static_cast<float>(plane(x))});
    }
  NerfSceneOptions gradient_only;
  gradient_only.normal_probe_voxels = 0.0;
  std::vector<Vec3f> probe, gradient;
  NerfScene(field).Normals(points, probe);
  NerfScene(field, gradient_only).Normals(points, gradient);
  double worst_probe = 0, worst_gradient = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    worst_probe = std::max(worst_probe, std::acos(std::clamp<double>(Dot(probe[i], truth), -1, 1)));
    worst_gradient = std::max(worst_gradient, std::acos(std::clamp<double>(Dot(gradient[i], truth), -1, 1)));
  }
  // Four surface points 6 voxels apart across: the noise (σ from 135 to
  // 7400/m) moves where T crosses 1/2 by at most ln 2/135 m ≈ 0.5 voxel, a
  // tilt of at most atan(0.5·√2 / 6) ≈ 6.7° (measured 7.5° worst: the
  // trilinear cells add a little); allow 10°.
  EXPECT_LT(worst_probe, 10.0 * kPi / 180.0) << "gradient normals: worst " << worst_gradient * 180 / kPi << "°";
  // The single-point gradient follows the noise far more (measured 47°).
  EXPECT_GT(worst_gradient, 3.0 * worst_probe);
}

// A small bake of a unit UV sphere, posed at 5 cm radius in the world.
class SsdfVisibilityTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    SsdfBakeOptions options;
    options.grid = 8;
    options.dirs = 24;
    options.components = 16;
    options.bisection_steps = 4;
    mesh_ = new TriangleMesh(MakeUvSphere(1.0, 48, 24));
    field_ = new SsdfField(BakeSsdf(*mesh_, options, std::nullopt));
  }
  static void TearDownTestSuite() {
    delete field_;
    delete mesh_;
  }
  static TriangleMesh* mesh_;
  static SsdfField* field_;
};
TriangleMesh* SsdfVisibilityTest::mesh_ = nullptr;
SsdfField* SsdfVisibilityTest::field_ = nullptr;

TEST_F(SsdfVisibilityTest, PosedFieldMatchesTheExactSphereInsideAndFarOutsideTheGrid) {
  const Pose T_world_object{RotationFromAxisAngle({0.2, 1, 0.3}, 1.1), {0.1, -0.2, 0.05}};
  const double scale = 0.05;
  const SsdfVisibility field(*field_, T_world_object, scale);
  EXPECT_NEAR(field.Radius(), 0.05, 1e-3);
  EXPECT_LT(Length(field.Center() - T_world_object.translation), 1e-3);
  const Vec3 c = T_world_object.translation;
  std::vector<Vec3f> dirs;
  for (int k = 0; k < 24; ++k) {
    const double z = 1 - (2 * k + 1) / 24.0, phi = 2.4 * k;
    dirs.push_back(Vec3f(Vec3{std::sqrt(1 - z * z) * std::cos(phi), std::sqrt(1 - z * z) * std::sin(phi), z}));
  }
  const auto query = field.Prepare(dirs);
  ASSERT_EQ(query->direction_count(), 24);
  // Points at 1.3 radii (inside the 3-radius grid), 4, 10 and 100 radii.
  for (double radii : {1.3, 4.0, 10.0, 100.0}) {
    const Vec3 x = c + Normalized(Vec3{0.3, -0.8, 0.5}) * (radii * scale);
    const Vec3f xf(x);
    std::vector<float> ssd(dirs.size());
    query->Ssd(&xf, 1, ssd.data());
    double worst = 0;
    for (size_t k = 0; k < dirs.size(); ++k) {
      ASSERT_TRUE(std::isfinite(ssd[k]));
      const double exact = SphereVisibility::SsdAt(c, scale, x, Normalized(Vec3(dirs[k])));
      worst = std::max(worst, std::abs(ssd[k] - exact));
    }
    // An 8³ grid with a 24² direction map and 16 components: a few degrees;
    // outside the grid the geometric re-mapping is exact for a sphere.
    EXPECT_LT(worst, 0.12) << radii << " radii";
  }
}

TEST_F(SsdfVisibilityTest, InsideAndOnTheObjectValuesAreFiniteAndInRange) {
  // (Inside the mesh the field is interpolated between grid points, some of
  // which lie outside it: the value is finite and in range, not always −π.)
  const SsdfVisibility field(*field_, Pose::Identity(), 0.05);
  const std::vector<Vec3f> dirs = {{0, 0, 1}, {1, 0, 0}, {0, -1, 0}};
  const auto query = field.Prepare(dirs);
  for (const Vec3f& x : {Vec3f{0.0f, 0.01f, 0.0f}, Vec3f{0.0f, 0.0f, 0.05f}, Vec3f{0.05f, 0.0f, 0.0f}}) {
    float ssd[3];
    query->Ssd(&x, 1, ssd);
    for (float s : ssd) {
      EXPECT_TRUE(std::isfinite(s));
      EXPECT_GE(s, -static_cast<float>(kPi));
      EXPECT_LE(s, static_cast<float>(kPi));
    }
  }
}

}  // namespace
}  // namespace nerfar
