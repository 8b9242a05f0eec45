#include "render/insert/nerf_scene.h"

#include <cmath>

#include "calib/core/error.h"

namespace nerfar {

void NerfScene::RenderRays(const SceneRays& rays, SceneSamples& out) const {
  NERFAR_CHECK_EQ(rays.directions.size(), rays.size());
  const size_t n = rays.size();
  out.Resize(n);
  std::vector<NerfRay> nerf_rays(n);
  for (size_t i = 0; i < n; ++i) {
    nerf_rays[i].origin = rays.origins[i];
    nerf_rays[i].dir = rays.directions[i];
    nerf_rays[i].t_near = rays.t_near[i];
    nerf_rays[i].t_far = std::max(rays.t_near[i], rays.t_far[i]);
  }
  // The callers already split work over threads: render serially here.
  for (size_t i = 0; i < n; ++i) {
    const NerfRayResult r = field_.RenderRay(nerf_rays[i], options_);
    out.colour[i] = r.color;
    out.opacity[i] = r.opacity;
    out.depth[i] = r.depth;
  }
}

void NerfScene::Normals(const std::vector<Vec3f>& points, std::vector<Vec3f>& normals) const {
  normals.assign(points.size(), Vec3f{});
  // Unit gradients averaged at the point and ±1 voxel along each axis:
  // smooths the trilinear field's piecewise gradient, and normalising each
  // first keeps σ's range (1e-13 to 1e6 per metre) from letting one sample
  // decide alone.
  const float h = field_.voxel_m;
  const Vec3f offsets[7] = {{0, 0, 0}, {h, 0, 0}, {-h, 0, 0}, {0, h, 0}, {0, -h, 0}, {0, 0, h}, {0, 0, -h}};
  for (size_t i = 0; i < points.size(); ++i) {
    Vec3f g{};
    for (const Vec3f& o : offsets) {
      const Vec3f d = field_.DensityGradient(points[i] + o);
      const float len = Length(d);
      if (len > 0.0f && std::isfinite(len)) g += d * (1.0f / len);
    }
    const float len = Length(g);
    if (len > 0.0f && std::isfinite(len)) normals[i] = g * (-1.0f / len);
  }
}

}  // namespace nerfar
