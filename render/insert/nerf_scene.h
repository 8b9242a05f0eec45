// The HDR NeRF (render/nerf) as the SceneField insertion queries: rays over
// their given [t_near, t_far] through NerfField::RenderRay, normals as
// −∇σ/|∇σ| from the density gradient (averaged over a small neighbourhood,
// since one voxel's gradient is noisy).
#pragma once

#include <atomic>
#include <cstdint>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "calib/core/option_fields.h"
#include "render/lighting/scene_field.h"
#include "render/lighting/seen_radiance.h"
#include "render/nerf/nerf_field.h"

namespace nerfar {

struct NerfSceneOptions {
  NerfRenderOptions render;  // step, early stop of every ray
  // The depth of a ray that gets at least half opaque is where its
  // transmittance crosses 1/2 (NerfRayResult::surface_depth) rather than the
  // opacity-weighted mean: in front of a surface, thin fog pulls the mean
  // towards the camera and a shadow receiver would float off the surface.
  // Rays below 1/2 opacity keep the mean. false: always the mean.
  bool surface_depth = true;
  // Surface normals from the surface itself rather than the density
  // gradient alone: around a point, four short rays along the gradient's
  // normal, offset by this many voxels to either side in its tangent plane,
  // find where their transmittance crosses 1/2, and the normal is that of
  // the four points (cross product of the diagonals), as a depth map's
  // neighbours give it. A trained field's gradient at one point follows its
  // noise (fog, floaters, the trilinear cells); the surface over a few
  // voxels does not. 0: the averaged density gradient only.
  double normal_probe_voxels = 3.0;
  // Incident-light rays (RenderLightRays) that meet a surface from below the
  // capture band take the brightest radiance views from the band see near
  // that point (render/lighting/seen_radiance.h): a lamp's never-photographed
  // underside is otherwise whatever training left there, usually too dark.
  // false: the NeRF's own colour.
  bool light_seen_radiance = true;
  // Capture band, views per point, reach; see-through content on: the
  // light's rays keep only the share of semi-transparent content that views
  // from the band find matter (seen_radiance.h), the rest lets the
  // environment behind it through.
  SeenRadianceOptions seen = [] {
    SeenRadianceOptions s;
    s.see_through = true;
    return s;
  }();
  // Step and early stop of the incident-light rays and of their seen-radiance
  // views (RenderLightRays). Default "live" (2-voxel steps, stop at
  // transmittance 3e-2: ~4.5x fewer samples than `render`): the light is
  // fitted with a few SGs over 1024 directions, far coarser than what a
  // half-voxel step resolves (measured: docs/BENCHMARKS.md "incident light on
  // a real NeRF"). NerfRenderOptions::Preset("full") gives `render`'s march.
  NerfRenderOptions light_render = NerfRenderOptions::Preset("live");
  // Keep the seen-radiance views' answer per cell across frames
  // (SeenRadianceCache): a dragged object's light rays meet the same cells
  // of the scene frame after frame and only the cells met for the first time
  // take views. The cache belongs to the NerfScene (one field, these
  // options); within one light the refined sub-rays also take the answers
  // of the cells the centre rays met. Off in "accurate" (each light's own
  // views, the reference); a field edited in place needs
  // NerfScene::ClearLightCache().
  bool cache_views = true;
  // The insertion presets (render/insert/insert_options.h), as they set the
  // incident light's views: "accurate" is the default above without the
  // cache (the views of each voxel's points their own, every light); "balanced" shares the views of the light
  // rays whose points fall in one 1 cm cell (seen.group_m: a refined
  // direction's 16 sub-rays meet one emitter within a few centimetres),
  // "fast" in one 2 cm cell: the seen radiance varies little within a cell,
  // and the views are the light's largest cost. Fewer views per point leave
  // the brightest view of an emitter to chance. Any other name: InputError.
  static NerfSceneOptions Preset(const std::string& name);
  // Every problem as "field: what is wrong (what was expected)", the field
  // under its Fields() name.
  std::vector<std::string> Validate() const;
  // The knobs under the names `nerfar insert --set` and `nerfar live --set`
  // give them: the marches' step and early stop (nerf_, light_render_), the
  // seen radiance's (seen_), surface_depth, normal_probe_voxels,
  // light_seen_radiance and seen_cache_views (cache_views).
  std::vector<OptionField> Fields();
  // The options as one compact JSON object under the Fields() names.
  std::string ToJson() const;
};

class NerfScene final : public SceneField {
 public:
  // `field` is a loan that must outlive this object.
  explicit NerfScene(const NerfField& field, NerfSceneOptions options = {})
      : field_(field), options_(std::move(options)) {}
  Aabb Box() const override { return field_.aabb; }
  void RenderRays(const SceneRays& rays, SceneSamples& out) const override;
  // Light rays: marched in parallel here (callers pass the whole batch), and
  // the seen-radiance substitution done once for the batch.
  void RenderLightRays(const SceneRays& rays, SceneSamples& out) const override;
  bool ParallelLightRays() const override { return true; }
  // Density samples taken by RenderLightRays since construction, the
  // seen-radiance views included (the cost's floor: samples x ns each).
  uint64_t LightSamples() const { return light_samples_.load(); }
  // Of those, the ones the seen-radiance views took.
  uint64_t LightViewSamples() const { return light_view_samples_.load(); }
  // Cells of seen-radiance views answered from the cache / by new views
  // since construction (NerfSceneOptions::cache_views).
  uint64_t LightCacheHits() const;
  uint64_t LightCacheMisses() const;
  // Forget the cached views' answers (after editing the field in place).
  void ClearLightCache();
  void Normals(const std::vector<Vec3f>& points, std::vector<Vec3f>& normals) const override;
  // Marched as RenderRays marches (the same samples from the same t_near),
  // each ray's level its surface_transmittance.
  void TransmittanceDepths(const SceneRays& rays, const std::vector<float>& transmittance,
                           std::vector<float>& depth) const override;
  const NerfSceneOptions& options() const { return options_; }
  // New options (`nerfar live` switching its preset). The cached views'
  // answers go with the old ones (their key would refuse them anyway; this
  // frees them where the new options cache nothing). Rays read the options
  // unguarded: no other call may be in flight on this scene meanwhile.
  void set_options(const NerfSceneOptions& options);

 private:
  void Render(const SceneRays& rays, SceneSamples& out, bool light) const;
  const NerfField& field_;
  NerfSceneOptions options_;
  mutable std::atomic<uint64_t> light_samples_{0}, light_view_samples_{0};
  mutable std::mutex cache_mutex_;  // the light's batches may come from several objects' threads
  mutable SeenRadianceCache cache_;
};

}  // namespace nerfar
