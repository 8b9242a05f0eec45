// The HDR NeRF (render/nerf) as the SceneField insertion queries: rays over
// their given [t_near, t_far] through NerfField::RenderRays, normals as
// −∇σ/|∇σ| from the density gradient (averaged over a small neighbourhood,
// since one voxel's gradient is noisy).
#pragma once

#include "render/insert/scene_field.h"
#include "render/nerf/nerf_field.h"

namespace nerfar {

class NerfScene final : public SceneField {
 public:
  // `field` is a loan that must outlive this object.
  explicit NerfScene(const NerfField& field, NerfRenderOptions options = {}) : field_(field), options_(options) {}
  Aabb Box() const override { return field_.aabb; }
  void RenderRays(const SceneRays& rays, SceneSamples& out) const override;
  void Normals(const std::vector<Vec3f>& points, std::vector<Vec3f>& normals) const override;

 private:
  const NerfField& field_;
  NerfRenderOptions options_;
};

}  // namespace nerfar
