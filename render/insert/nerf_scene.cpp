#include "render/insert/nerf_scene.h"

#include <cmath>

#include "calib/core/error.h"
#include "calib/core/parallel.h"

namespace nerfar {

NerfSceneOptions NerfSceneOptions::Preset(const std::string& name) {
  NerfSceneOptions o;
  if (name == "fast") {
    o.seen.group_m = 0.02;
  } else if (name == "balanced") {
    o.seen.group_m = 0.01;
  } else if (name == "accurate") {
    o.cache_views = false;
  } else {
    ThrowInputError("preset", "unknown preset '" + name + "' (expected fast, balanced or accurate)");
  }
  return o;
}

std::vector<OptionField> NerfSceneOptions::Fields() {
  return {FieldOf("nerf_step_voxels", &render.step_voxels),
          FieldOf("nerf_min_transmittance", &render.min_transmittance),
          FieldOf("light_render_step_voxels", &light_render.step_voxels),
          FieldOf("light_render_min_transmittance", &light_render.min_transmittance),
          FieldOf("surface_depth", &surface_depth),
          FieldOf("normal_probe_voxels", &normal_probe_voxels),
          FieldOf("light_seen_radiance", &light_seen_radiance),
          FieldOf("seen_min_elevation_deg", &seen.min_elevation_deg),
          FieldOf("seen_max_elevation_deg", &seen.max_elevation_deg),
          FieldOf("seen_views", &seen.views),
          FieldOf("seen_reach_m", &seen.reach_m),
          FieldOf("seen_min_opacity", &seen.min_opacity),
          FieldOf("seen_see_through", &seen.see_through),
          FieldOf("seen_see_through_min_opacity", &seen.see_through_min_opacity),
          FieldOf("seen_see_through_reach_m", &seen.see_through_reach_m),
          FieldOf("seen_group_m", &seen.group_m),
          FieldOf("seen_face_views", &seen.face_views),
          FieldOf("seen_face_min_cosine", &seen.face_min_cosine),
          FieldOf("seen_face_reach_m", &seen.face_reach_m),
          FieldOf("seen_agree_fraction", &seen.agree_fraction),
          FieldOf("seen_cache_views", &cache_views)};
}

std::string NerfSceneOptions::ToJson() const {
  NerfSceneOptions copy = *this;
  return OptionFieldsJson(copy.Fields());
}

std::vector<std::string> NerfSceneOptions::Validate() const {
  std::vector<std::string> problems;
  const auto check = [&](bool ok, const std::string& what) {
    if (!ok) problems.push_back(what);
  };
  check(render.step_voxels > 0.0f && std::isfinite(render.step_voxels),
        "nerf_step_voxels: must be a finite number > 0");
  check(render.min_transmittance >= 0.0f && render.min_transmittance < 1.0f,
        "nerf_min_transmittance: must be in [0, 1)");
  check(light_render.step_voxels > 0.0f && std::isfinite(light_render.step_voxels),
        "light_render_step_voxels: must be a finite number > 0");
  check(light_render.min_transmittance >= 0.0f && light_render.min_transmittance < 1.0f,
        "light_render_min_transmittance: must be in [0, 1)");
  check(normal_probe_voxels >= 0.0 && normal_probe_voxels <= 64.0,
        "normal_probe_voxels: out of range (expected 0 to 64)");
  if (light_seen_radiance) {
    check(seen.min_elevation_deg >= -90.0 && seen.min_elevation_deg < seen.max_elevation_deg &&
              seen.max_elevation_deg <= 90.0,
          "seen_min_elevation_deg, seen_max_elevation_deg: expected -90 <= min < max <= 90 degrees");
    check(seen.views >= 1 && seen.views <= 1024, "seen_views: out of range (expected 1 to 1024)");
    check(seen.reach_m > 0.0 && std::isfinite(seen.reach_m), "seen_reach_m: must be a finite number > 0");
    check(seen.min_opacity >= 0.0 && seen.min_opacity <= 1.0, "seen_min_opacity: must be in [0, 1]");
    check(seen.see_through_min_opacity >= 0.0 && seen.see_through_min_opacity <= 1.0,
          "seen_see_through_min_opacity: must be in [0, 1]");
    check(seen.see_through_reach_m > 0.0 && std::isfinite(seen.see_through_reach_m),
          "seen_see_through_reach_m: must be a finite number > 0");
    check(seen.group_m >= 0.0 && seen.group_m <= 1.0, "seen_group_m: out of range (expected 0 to 1 metre)");
    check(seen.agree_fraction >= 0.0 && seen.agree_fraction <= 1.0,
          "seen_agree_fraction: out of range (expected 0 to 1)");
    check(seen.face_min_cosine >= -1.0 && seen.face_min_cosine <= 1.0, "seen_face_min_cosine: must be in [-1, 1]");
    check(seen.face_reach_m > 0.0 && std::isfinite(seen.face_reach_m),
          "seen_face_reach_m: must be a finite number > 0");
  }
  return problems;
}

void NerfScene::RenderRays(const SceneRays& rays, SceneSamples& out) const { Render(rays, out, false); }

void NerfScene::RenderLightRays(const SceneRays& rays, SceneSamples& out) const { Render(rays, out, true); }

void NerfScene::Render(const SceneRays& rays, SceneSamples& out, bool light) const {
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
  std::vector<NerfRayResult> results(n);
  if (light) {
    // The light's callers hand over the whole batch (ParallelLightRays).
    ParallelFor(
        n, [&](size_t i) { results[i] = field_.RenderRay(nerf_rays[i], options_.light_render); }, 32);
    uint64_t samples = 0;
    for (const NerfRayResult& r : results) samples += r.samples;
    uint64_t view_samples = 0;
    if (options_.light_seen_radiance && n > 0) {
      if (options_.cache_views) {
        const std::lock_guard<std::mutex> lock(cache_mutex_);
        ApplySeenRadiance(field_, nerf_rays, results, options_.seen, options_.light_render, &view_samples, &cache_);
      } else {
        ApplySeenRadiance(field_, nerf_rays, results, options_.seen, options_.light_render, &view_samples);
      }
    }
    light_samples_ += samples + view_samples;
    light_view_samples_ += view_samples;
  } else {
    // The callers already split work over threads: render serially here.
    for (size_t i = 0; i < n; ++i) results[i] = field_.RenderRay(nerf_rays[i], options_.render);
  }
  for (size_t i = 0; i < n; ++i) {
    const NerfRayResult& r = results[i];
    out.colour[i] = r.color;
    out.opacity[i] = r.opacity;
    // surface_depth is the mean already where the ray stays under 1/2.
    out.depth[i] = options_.surface_depth && r.opacity >= 0.5f ? r.surface_depth : r.depth;
  }
}

void NerfScene::TransmittanceDepths(const SceneRays& rays, const std::vector<float>& transmittance,
                                    std::vector<float>& depth) const {
  NERFAR_CHECK_EQ(transmittance.size(), rays.size());
  depth.resize(rays.size());
  for (size_t i = 0; i < rays.size(); ++i) {
    NerfRenderOptions options = options_.render;
    options.surface_transmittance = transmittance[i];
    options.min_transmittance = std::min(options.min_transmittance, 0.5f * transmittance[i]);
    const NerfRay ray{rays.origins[i], rays.directions[i], rays.t_near[i], std::max(rays.t_near[i], rays.t_far[i])};
    const NerfRayResult r = field_.RenderRay(ray, options);
    depth[i] = r.opacity >= 1.0f - transmittance[i] ? r.surface_depth : rays.t_far[i];
  }
}

uint64_t NerfScene::LightCacheHits() const {
  const std::lock_guard<std::mutex> lock(cache_mutex_);
  return cache_.hits;
}

uint64_t NerfScene::LightCacheMisses() const {
  const std::lock_guard<std::mutex> lock(cache_mutex_);
  return cache_.misses;
}

void NerfScene::ClearLightCache() {
  const std::lock_guard<std::mutex> lock(cache_mutex_);
  cache_.Clear();
}

void NerfScene::set_options(const NerfSceneOptions& options) {
  options_ = options;
  ClearLightCache();
}

void NerfScene::Normals(const std::vector<Vec3f>& points, std::vector<Vec3f>& normals) const {
  normals.assign(points.size(), Vec3f{});
  const float h = static_cast<float>(options_.normal_probe_voxels) * field_.voxel_m;
  for (size_t i = 0; i < points.size(); ++i) {
    const Vec3f n0 = AveragedGradientNormal(field_, points[i]);
    normals[i] = n0;
    if (!(h > 0.0f) || Dot(n0, n0) < 0.5f) continue;
    // Tangent basis of the gradient's plane.
    const Vec3f a = std::abs(n0.x) < 0.9f ? Vec3f{1, 0, 0} : Vec3f{0, 1, 0};
    const Vec3f t1 = Normalized(Cross(n0, a)), t2 = Cross(n0, t1);
    // Four rays down along −n0 from 2h above the tangent plane, over 4h:
    // surfaces tilted up to ~60° from the gradient's plane are found.
    const Vec3f offsets[4] = {t1 * h, t1 * -h, t2 * h, t2 * -h};
    Vec3f found[4];
    bool ok = true;
    for (int k = 0; k < 4 && ok; ++k) {
      NerfRay ray;
      ray.origin = points[i] + offsets[k] + n0 * (2.0f * h);
      ray.dir = -n0;
      ray.t_near = 0.0f;
      ray.t_far = 4.0f * h;
      const NerfRayResult r = field_.RenderRay(ray, options_.render);
      ok = r.opacity >= 0.5f && std::isfinite(r.surface_depth);
      found[k] = ray.origin + ray.dir * r.surface_depth;
    }
    if (!ok) continue;  // an edge or a hole nearby: keep the gradient's normal
    Vec3f n = Cross(found[0] - found[1], found[2] - found[3]);
    const float len = Length(n);
    if (!(len > 0.0f) || !std::isfinite(len)) continue;
    n = n * (1.0f / len);
    normals[i] = Dot(n, n0) >= 0.0f ? n : -n;
  }
}

}  // namespace nerfar
