// render/insert adapters: the NeRF as a SceneField (homogeneous field against
// the closed form, the clipped range, normals from the density gradient) and
// a baked SSDF field posed in the world against the exact sphere occluder,
// inside, near and far outside its grid.
#include <gtest/gtest.h>

#include <cmath>

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
