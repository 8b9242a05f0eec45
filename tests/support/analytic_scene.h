// The tests' exact scene: an opaque horizontal plane z = 0 (Lambertian-looking
// checker radiance, bounded by the box), an opaque sphere and a ball of
// constant density σ (an absorbing and emitting medium, as a NeRF models glass
// or smoke), rendered in closed form through render/lighting's SceneField.
// World frame, metres.
#pragma once

#include <vector>

#include "render/lighting/scene_field.h"

namespace nerfar::testing {

// The scene's parts (defaults: a checker table, a blue sphere, a white medium).
struct AnalyticSceneParams {
  Aabb box{{-0.6, -0.4, -0.05}, {0.6, 0.4, 0.6}};
  Vec3f plane_radiance{0.5f, 0.45f, 0.4f};  // mean radiance of the table (checker ±20%)
  float checker_size_m = 0.05f;             // 0: plain
  bool has_sphere = true;
  Vec3 sphere_center{-0.2, 0.1, 0.08};
  double sphere_radius = 0.08;
  Vec3f sphere_radiance{0.2f, 0.3f, 0.6f};
  bool has_medium = true;
  Vec3 medium_center{0.2, -0.1, 0.1};
  double medium_radius = 0.07;
  double medium_density = 20.0;  // σ, 1/m
  Vec3f medium_radiance{0.9f, 0.9f, 0.9f};
};

class AnalyticScene final : public SceneField {
 public:
  explicit AnalyticScene(AnalyticSceneParams params = {}) : params_(params) {}
  Aabb Box() const override { return params_.box; }
  void RenderRays(const SceneRays& rays, SceneSamples& out) const override;
  void Normals(const std::vector<Vec3f>& points, std::vector<Vec3f>& normals) const override;
  void TransmittanceDepths(const SceneRays& rays, const std::vector<float>& transmittance,
                           std::vector<float>& depth) const override;
  const AnalyticSceneParams& params() const { return params_; }

  // One ray, double precision; depth here is the unnormalised D̂ = Σ T α t.
  void RenderOne(const Vec3& origin, const Vec3& direction, double t0, double t1, Vec3& colour, double& opacity,
                 double& depth) const;

 private:
  Vec3f PlaneRadiance(const Vec3& point) const;
  // The first opaque surface (plane or sphere) on o + t·d within [t0, t1]:
  // its distance (infinity if none) and radiance.
  double FirstHit(const Vec3& o, const Vec3& d, double t0, double t1, Vec3f* radiance) const;
  AnalyticSceneParams params_;
};

}  // namespace nerfar::testing
