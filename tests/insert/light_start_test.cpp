// render/insert/incident_light: rays of the incident light start where they
// leave the object's own volume. ObjectExitDistances against the closed-form
// exit of a ray from a posed box (slab method, no triangles involved), and
// the light taken inside a box that encloses a fog ball against the same
// scene without the fog: whatever lies inside the object neither lights it
// nor hides the light, and everything outside is unchanged.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "render/lighting/incident_light.h"
#include "render/mesh/mesh.h"
#include "render/sg/sphere.h"
#include "render/sg/visibility.h"
#include "tests/support/analytic_scene.h"

namespace nerfar {
namespace {

// Exit distance of o + t·d from the box |x_i| <= h_i (o inside), slab method.
double BoxExit(const Vec3& o, const Vec3& d, const Vec3& h) {
  double t = 1e300;
  const double oc[3] = {o.x, o.y, o.z}, dc[3] = {d.x, d.y, d.z}, hc[3] = {h.x, h.y, h.z};
  for (int i = 0; i < 3; ++i)
    if (dc[i] != 0.0) t = std::min(t, ((dc[i] > 0 ? hc[i] : -hc[i]) - oc[i]) / dc[i]);
  return t;
}

TEST(LightStart, ExitDistancesOfAPosedBoxMatchTheSlabMethod) {
  const Vec3 half{0.5, 0.3, 0.2};
  const TriangleMesh box = MakeBox(half);
  LightObjectVolume volume;
  volume.mesh = &box;
  volume.T_world_object.rotation = Mat3::FromColumns(Normalized(Vec3{1, 1, 0}), Normalized(Vec3{-1, 1, 0}), {0, 0, 1});
  volume.T_world_object.translation = {0.2, -0.1, 0.05};
  volume.scale = 0.1;  // a 10 × 6 × 4 cm box
  const Vec3 local_start{0.1, -0.05, 0.02};
  const Vec3 center = volume.T_world_object * (local_start * volume.scale);
  const std::vector<Vec3> dirs = FibonacciSphere(200);
  const std::vector<float> exit = ObjectExitDistances(volume, center, dirs);
  ASSERT_EQ(exit.size(), dirs.size());
  for (size_t i = 0; i < dirs.size(); ++i) {
    const Vec3 d_local = volume.T_world_object.rotation.Transposed() * dirs[i];
    const double expected = BoxExit(local_start, d_local, half) * volume.scale;
    // Float result of a double computation on centimetre distances: 1 µm.
    EXPECT_NEAR(exit[i], expected, 1e-6) << i;
  }
  // From outside the box, looking away from it: no crossing, start at 0.
  const Vec3 outside = volume.T_world_object * (Vec3{2.0, 0, 0} * volume.scale);
  const Vec3 away = volume.T_world_object.Rotate({1, 0, 0});
  EXPECT_EQ(ObjectExitDistances(volume, outside, {away})[0], 0.0f);
  // Towards it: the far face, 2.5 half-widths away.
  EXPECT_NEAR(ObjectExitDistances(volume, outside, {-away})[0], 2.5 * volume.scale, 1e-6);
}

TEST(LightStart, ExitDistancesOfAFineSphereMatchTheAnalyticSphere) {
  // 64 × 32 facets (4096 triangles, each a small part of the sky seen from
  // inside): the triangles are culled by their cones, which must keep every
  // crossing. Exit of o + t·d from the sphere |x| = R: t = −o·d + √((o·d)² − |o|² + R²).
  const double radius = 0.05, scale = 1.5, R = radius * scale;
  const TriangleMesh ball = MakeUvSphere(radius, 64, 32);
  LightObjectVolume volume;
  volume.mesh = &ball;
  volume.T_world_object.rotation = Mat3::FromColumns(Normalized(Vec3{1, 0, 1}), {0, 1, 0}, Normalized(Vec3{-1, 0, 1}));
  volume.T_world_object.translation = {0.3, 0.2, 0.1};
  volume.scale = scale;
  const Vec3 offset{0.02, -0.01, 0.015};  // world metres from the ball's centre, inside it
  const Vec3 center = volume.T_world_object.translation + offset;
  const std::vector<Vec3> dirs = FibonacciSphere(2000);
  const std::vector<float> exit = ObjectExitDistances(volume, center, dirs);
  for (size_t i = 0; i < dirs.size(); ++i) {
    const double od = Dot(offset, dirs[i]);
    const double expected = -od + std::sqrt(od * od - Dot(offset, offset) + R * R);
    // The facets lie inside the true sphere by at most R·(1 − cos²(π/64))
    // ≈ 0.18 mm, a little more along oblique rays: 0.3 mm.
    EXPECT_NEAR(exit[i], expected, 3e-4) << i;
  }
}

// A table, an opaque sphere and a fog ball (absorbing and emitting) whose
// centre the object's light is taken at.
testing::AnalyticSceneParams FogScene(bool with_fog) {
  testing::AnalyticSceneParams p;
  p.has_medium = with_fog;
  p.medium_center = {0.2, -0.1, 0.1};
  p.medium_radius = 0.03;
  p.medium_density = 40.0;                    // 1 − e^{−40·0.03} ≈ 70 % opacity from the centre out
  p.medium_radiance = {0.05f, 0.05f, 0.05f};  // dark grey fog: it mostly hides light
  return p;
}

TEST(LightStart, FogInsideTheObjectNeitherLightsNorHidesIt) {
  const testing::AnalyticScene foggy(FogScene(true)), clear(FogScene(false));
  const Vec3 center = FogScene(true).medium_center;
  // A 4 cm cube around the fog ball (radius 3 cm) at the light's centre,
  // clear of the table (z from 6 to 14 cm) and of the opaque sphere.
  const TriangleMesh cube = MakeBox({0.04, 0.04, 0.04});
  LightObjectVolume volume;
  volume.mesh = &cube;
  volume.T_world_object.translation = center;
  const SgMixture env = {Sg{{0.3, 0.2, 1.0}, 4.0, {3.0, 2.5, 2.0}}};
  const std::vector<Vec3> dirs = FibonacciSphere(512);
  const std::vector<float> start = ObjectExitDistances(volume, center, dirs);
  std::vector<float> opacity_skip, opacity_clear, depth_skip, depth_clear, opacity_fog;
  const RadianceSamples skip =
      SampleIncidentLight(foggy, env, center, dirs, LightSource::kFull, &opacity_skip, &depth_skip, &start);
  const RadianceSamples reference =
      SampleIncidentLight(clear, env, center, dirs, LightSource::kFull, &opacity_clear, &depth_clear);
  const RadianceSamples from_centre = SampleIncidentLight(foggy, env, center, dirs, LightSource::kFull, &opacity_fog);
  size_t fogged = 0;
  for (size_t i = 0; i < dirs.size(); ++i) {
    // The analytic scene integrates in closed form (double, stored as
    // float): the same rays outside the cube give the same light to 1e-5.
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(skip.radiance[i][c], reference.radiance[i][c], 1e-5 * (1 + reference.radiance[i][c])) << i;
    EXPECT_NEAR(opacity_skip[i], opacity_clear[i], 1e-6) << i;
    // Depths are distances from the centre either way.
    EXPECT_NEAR(depth_skip[i], depth_clear[i], 1e-5) << i;
    if (opacity_fog[i] > 0.5f) ++fogged;
  }
  // Without the start, the fog hides most of the light in every direction.
  EXPECT_EQ(fogged, dirs.size());

  // Through IncidentLight: the fit with the object's volume equals the fit
  // of the fog-free scene (same samples, same cold start).
  IncidentLightOptions options;
  options.directions = 512;
  options.fit = SgFitOptions::Preset("fast");
  IncidentLight with_volume, without_fog, off;
  with_volume.Refresh(foggy, env, center, options, &volume);
  without_fog.Refresh(clear, env, center, options);
  ASSERT_EQ(with_volume.light().size(), without_fog.light().size());
  for (const Vec3& n : FibonacciSphere(16)) {
    const Vec3 a = Irradiance(with_volume.light(), n), b = Irradiance(without_fog.light(), n);
    // Same samples up to 1e-5 relative; the fit's iterations amplify float
    // noise, so allow 0.1 % of the irradiance.
    EXPECT_NEAR(a.y, b.y, 1e-3 * b.y + 1e-6);
  }
  // The knob off: the dark fog is back and hides most of the light above.
  options.start_outside_object = false;
  off.Refresh(foggy, env, center, options, &volume);
  EXPECT_LT(Irradiance(off.light(), {0, 0, 1}).y, 0.8 * Irradiance(without_fog.light(), {0, 0, 1}).y);

  // Turning the object (same centre) refits: the cube turned by 45° about z
  // starts its rays elsewhere.
  options.start_outside_object = true;
  IncidentLight::Update u = with_volume.Refresh(foggy, env, center, options, &volume);
  EXPECT_FALSE(u.recomputed);
  LightObjectVolume turned = volume;
  turned.T_world_object.rotation = Mat3::FromColumns(Normalized(Vec3{1, 1, 0}), Normalized(Vec3{-1, 1, 0}), {0, 0, 1});
  u = with_volume.Refresh(foggy, env, center, options, &turned);
  EXPECT_TRUE(u.recomputed);
}

TEST(LightStart, ATurnThatLeavesEveryStartInPlaceKeepsTheLight) {
  const testing::AnalyticScene scene(FogScene(true));
  const Vec3 center = FogScene(true).medium_center;
  // A 4 cm ball of 32 × 16 facets around the centre: turned about its
  // vertical axis, each ray's exit moves only by the facets' sagitta,
  // r·(1 − cos(π/32))·2 ≈ 0.4 mm at most, under the 1 mm tolerance.
  const TriangleMesh ball = MakeUvSphere(0.04, 32, 16);
  LightObjectVolume volume;
  volume.mesh = &ball;
  volume.T_world_object.translation = center;
  const SgMixture env = {Sg{{0.3, 0.2, 1.0}, 4.0, {3.0, 2.5, 2.0}}};
  IncidentLightOptions options;
  options.directions = 512;
  options.fit = SgFitOptions::Preset("fast");
  IncidentLight light;
  ASSERT_TRUE(light.Refresh(scene, env, center, options, &volume).recomputed);
  LightObjectVolume turned = volume;
  const double a = 0.3;
  turned.T_world_object.rotation =
      Mat3::FromColumns({std::cos(a), std::sin(a), 0}, {-std::sin(a), std::cos(a), 0}, {0, 0, 1});
  // The turn does move the starts (not a no-op test), but by less than 1 mm.
  const std::vector<Vec3> dirs = FibonacciSphere(options.directions);
  const std::vector<float> before = ObjectExitDistances(volume, center, dirs);
  const std::vector<float> after = ObjectExitDistances(turned, center, dirs);
  float largest = 0.0f;
  for (size_t i = 0; i < dirs.size(); ++i) largest = std::max(largest, std::abs(after[i] - before[i]));
  EXPECT_GT(largest, 1e-5f);
  EXPECT_LT(largest, 1e-3f);
  EXPECT_FALSE(light.Refresh(scene, env, center, options, &turned).recomputed);
  // With no tolerance the same turn refits.
  // (The light is still the one fitted unturned.)
  options.start_tolerance_m = 0.0;
  EXPECT_TRUE(light.Refresh(scene, env, center, options, &turned).recomputed);
  // A negative or non-finite tolerance is reported.
  options.start_tolerance_m = -1.0;
  EXPECT_FALSE(options.Validate().empty());
}

}  // namespace
}  // namespace nerfar
