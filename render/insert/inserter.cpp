#include "render/insert/inserter.h"

#include <cmath>

#include "calib/core/error.h"
#include "calib/core/parallel.h"
#include "render/insert/cache_keys.h"
#include "render/insert/drag_hold.h"
#include "render/insert/insert_common.h"
#include "render/insert/light_prep.h"
#include "render/insert/object_shading.h"
#include "render/insert/occlusion.h"
#include "render/insert/shadow_pass.h"
#include "render/insert/shadow_terms.h"
#include "render/insert/vertex_gamma.h"

namespace nerfar {

// The objects' prepared lights and what they were prepared for.
struct LightPrepCache {
  std::vector<LightPrepKey> key;  // per object
  std::vector<LightPrep> preps;
  std::vector<PrefilteredRadiance> specular;  // per object (InsertOptions::prefiltered_specular), same key
  std::vector<ShadowSources> shadow_sources;  // per object (InsertOptions::kappa_from_samples), same key
};

namespace {
// The lobes beside an object's light samples: the incident light's analytic
// ones, or those given with an override (a probe's compact sources).
const SgMixture& CompactLobes(const InsertObject& object, const IncidentLight& light) {
  static const SgMixture kNone;
  if (!object.light_override) return light.compact();
  return object.light_compact ? *object.light_compact : kNone;
}

// World bounding spheres of the objects (radius 0 without a mesh).
std::vector<WorldSphere> WorldSpheres(const std::vector<InsertObject>& objects) {
  std::vector<WorldSphere> spheres(objects.size());
  for (size_t i = 0; i < objects.size(); ++i) {
    if (objects[i].mesh == nullptr || objects[i].mesh->positions.empty()) continue;
    const BoundingSphere bs = ComputeBoundingSphere(*objects[i].mesh);
    spheres[i].center = Vec3f(objects[i].T_world_object * (bs.center * objects[i].scale));
    spheres[i].radius = static_cast<float>(bs.radius * std::abs(objects[i].scale));
  }
  return spheres;
}

// Covered pixels (G-buffer indices), in scan order.
std::vector<uint32_t> CoveredPixels(const ObjectGBuffer& g) {
  std::vector<uint32_t> covered;
  covered.reserve(g.covered);
  for (size_t i = 0; i < g.object.size(); ++i)
    if (g.object[i] >= 0) covered.push_back(static_cast<uint32_t>(i));
  return covered;
}

// The incident-light samples prefiltered for the specular term, per object,
// made again when the preps were (`specular` emptied with them).
void UpdatePrefilteredSpecular(const InsertOptions& options, const std::vector<InsertObject>& objects,
                               const std::vector<LightParallax>& parallax, const std::vector<IncidentLight>& lights,
                               std::vector<PrefilteredRadiance>& specular) {
  const size_t n_objects = objects.size();
  if (!options.prefiltered_specular) specular.clear();
  if (!options.prefiltered_specular || specular.size() == n_objects) return;
  specular.assign(n_objects, PrefilteredRadiance());
  for (size_t o = 0; o < n_objects; ++o) {
    const RadianceSamples* samples = objects[o].light_override ? objects[o].light_samples : &lights[o].samples();
    // The compact lobes given beside the samples reach the map as lobes.
    if (samples != nullptr)
      specular[o] = PrefilteredRadiance(*samples, options.specular_levels, CompactLobes(objects[o], lights[o]));
    // Parallax-corrected reflections: the distances the samples' light comes from.
    if (!options.specular_parallax || specular[o].empty()) continue;
    if (objects[o].light_override && objects[o].light_sample_distances)
      specular[o].SetParallax(parallax[o].center, *objects[o].light_sample_distances,
                              options.specular_parallax_iterations);
    else if (!objects[o].light_override)
      specular[o].SetParallax(
          parallax[o].center,
          ReflectionDistances(lights[o].samples().directions, lights[o].opacity(), lights[o].depth()),
          options.specular_parallax_iterations);
  }
}

// κ's light as sources from the same samples, per object, made again when
// the preps were (`sources` emptied with them).
void UpdateShadowSources(const InsertOptions& options, const std::vector<InsertObject>& objects,
                         const std::vector<SgMixture>& used_lights, const std::vector<LightParallax>& parallax,
                         const std::vector<IncidentLight>& lights, std::vector<ShadowSources>& sources) {
  const size_t n_objects = objects.size();
  if (!options.kappa_from_samples) sources.clear();
  if (!options.kappa_from_samples || sources.size() == n_objects) return;
  sources.resize(n_objects);
  for (size_t o = 0; o < n_objects; ++o) {
    const RadianceSamples* samples = objects[o].light_override ? objects[o].light_samples : &lights[o].samples();
    if (samples != nullptr)
      sources[o] = BuildShadowSources(*samples, used_lights[o], parallax[o], objects, options.kappa_sample_bins,
                                      options.kappa_sample_min_radius, CompactLobes(objects[o], lights[o]));
  }
}
}  // namespace

ImageF ExpandLayer(const ImageF& layer, const PixelRect& rect, int width, int height, float fill) {
  const int channels = layer.channels > 0 ? layer.channels : 1;
  ImageF full(width, height, channels, fill);
  if (layer.empty()) return full;
  for (int y = rect.y0; y < rect.y1; ++y)
    for (int x = rect.x0; x < rect.x1; ++x)
      for (int c = 0; c < channels; ++c) full.at(x, y, c) = layer.at(x - rect.x0, y - rect.y0, c);
  return full;
}

Inserter::~Inserter() = default;
Inserter::Inserter(Inserter&&) noexcept = default;

Inserter::Inserter(const SceneField& scene, SgMixture environment, InsertOptions options,
                   std::vector<double> environment_distance_m)
    : scene_(scene),
      environment_(std::move(environment)),
      environment_distance_m_(std::move(environment_distance_m)),
      options_(std::move(options)),
      drag_(std::make_unique<DragHold>()) {
  Problems problems("insert options");
  for (const std::string& p : options_.Validate()) problems.Add("", p);
  problems.ThrowIfAny();
}

const SgMixture& Inserter::Light(size_t object) const { return used_lights_.at(object); }

ImageF Inserter::RenderBackground(const CameraIntrinsics& camera, const Pose& T_world_camera) const {
  ImageF image(camera.width, camera.height, 3, 0.0f);
  const Aabb box = scene_.Box();
  const Vec3 eye = T_world_camera.translation;
  ParallelFor(
      static_cast<size_t>(camera.height),
      [&](size_t row) {
        const int y = static_cast<int>(row);
        SceneRays rays;
        SceneSamples out;
        rays.Reserve(camera.width);
        for (int x = 0; x < camera.width; ++x) {
          const Vec3f d = CameraRayDirection(camera, T_world_camera, x, y);
          const auto range = IntersectBox(box, eye, Vec3(d));
          rays.Add(Vec3f(eye), d, range ? static_cast<float>(range->first) : 0.0f,
                   range ? static_cast<float>(range->second) : 0.0f);
        }
        scene_.RenderRays(rays, out);
        for (int x = 0; x < camera.width; ++x) {
          const Vec3f c = Finite(out.colour[x]) ? out.colour[x] : Vec3f{};
          image.at(x, y, 0) = c.x;
          image.at(x, y, 1) = c.y;
          image.at(x, y, 2) = c.z;
        }
      },
      1);
  return image;
}

std::vector<LightParallax> Inserter::UpdateLights(const std::vector<InsertObject>& objects,
                                                  const std::vector<WorldSphere>& spheres, const DragFrame& drag,
                                                  InsertTimings& times) {
  const size_t n_objects = objects.size();
  std::vector<LightParallax> parallax(n_objects);
  if (drag.phase == DragPhase::kHeld) {
    for (size_t i = 0; i < n_objects; ++i) {
      used_lights_[i] = drag_->light(i);
      parallax[i] = drag_->Parallax(i, drag.shift);
    }
    times.lights_held = static_cast<int>(n_objects);
    return parallax;
  }
  for (size_t i = 0; i < n_objects; ++i) {
    const Vec3 at = objects[i].light_center.value_or(Vec3(spheres[i].center));
    parallax[i].center = at;
    parallax[i].min_sharpness = options_.light.parallax_min_sharpness;
    const LightObjectVolume volume{objects[i].mesh, objects[i].T_world_object, objects[i].scale};
    if (objects[i].light_override) {
      used_lights_[i] = *objects[i].light_override;
      if (objects[i].light_distances && options_.light.parallax)
        parallax[i].distance = *objects[i].light_distances;
      else
        parallax[i].distance = lights_[i].DistancesFor(scene_, used_lights_[i], at, options_.light, &volume);
      continue;
    }
    const IncidentLight::Update u =
        lights_[i].Refresh(scene_, environment_, at, options_.light, &volume, environment_distance_m_);
    times.light_ms += u.sample_ms;
    times.fit_ms += u.fit_ms;
    times.lights_recomputed += u.recomputed ? 1 : 0;
    used_lights_[i] = lights_[i].light();
    parallax[i].distance = lights_[i].lobe_distances();
  }
  if (drag.phase == DragPhase::kStart) drag_->Take(used_lights_, parallax);
  return parallax;
}

std::vector<LightPrep>& Inserter::PrepareLights(const std::vector<InsertObject>& objects,
                                                const std::vector<LightParallax>& parallax, const DragFrame& drag) {
  const size_t n_objects = objects.size();
  // Every object's light (the shadow pass needs those of objects not seen
  // too), prepared again only when a light, its parallax or an object (its
  // field's queries are posed) changed.
  {
    std::vector<LightPrepKey> key;
    key.reserve(n_objects);
    for (size_t o = 0; o < n_objects; ++o)
      key.push_back({.object = ObjectKeyOf(objects[o]),
                     .light = used_lights_[o],
                     .parallax_center = parallax[o].center,
                     .lobes = ReaimedLobesKeyOf(parallax[o])});
    if (!preps_) preps_ = std::make_unique<LightPrepCache>();
    if (key != preps_->key) {
      // A held light keeps its samples, so their prefiltered map holds.
      if (drag.phase != DragPhase::kHeld) preps_->specular.clear();
      preps_->shadow_sources.clear();
      preps_->preps = std::vector<LightPrep>(n_objects);
      preps_->key = std::move(key);
    }
  }
  std::vector<LightPrep>& preps = preps_->preps;
  for (size_t o = 0; o < n_objects; ++o) PrepareLight(used_lights_[o], objects, preps[o], &parallax[o]);
  return preps;
}

void Inserter::HeldKappaLights(const std::vector<InsertObject>& objects, const DragFrame& drag,
                               std::vector<SgMixture>& lights, std::vector<LightPrep>& preps) const {
  lights.resize(objects.size());
  preps = std::vector<LightPrep>(objects.size());
  for (size_t o = 0; o < objects.size(); ++o) {
    lights[o] = drag_->kappa_light(o);
    const LightParallax parallax = drag_->KappaParallax(o, drag.kappa_shift);
    PrepareLight(lights[o], objects, preps[o], &parallax);
  }
}

InsertTimings Inserter::Render(const CameraIntrinsics& camera, const Pose& T_world_camera,
                               const std::vector<InsertObject>& objects, ImageF& frame, InsertLayers* layers_out,
                               const ReceiverOverride& receivers) {
  const auto t_start = InsertClock::now();
  InsertTimings times;
  if (frame.width != camera.width || frame.height != camera.height || frame.channels != 3) {
    ThrowInputError("frame", "size " + std::to_string(frame.width) + "x" + std::to_string(frame.height) + "x" +
                                 std::to_string(frame.channels) + " does not match the camera (expected " +
                                 std::to_string(camera.width) + "x" + std::to_string(camera.height) + "x3)");
  }
  InsertLayers local_layers;
  InsertLayers& layers = layers_out ? *layers_out : local_layers;
  layers = InsertLayers{};
  const size_t n_objects = objects.size();
  lights_.resize(n_objects);
  used_lights_.resize(n_objects);

  const std::vector<WorldSphere> spheres = WorldSpheres(objects);
  const DragFrame drag = drag_->Begin(objects, spheres, !options_.kappa_from_samples);

  // 1. Incident light per object (cached while it stands still, held while
  // it is dragged), with its lobes' distances for the parallax of near light.
  const std::vector<LightParallax> parallax = UpdateLights(objects, spheres, drag, times);

  // 2. G-buffer.
  auto t0 = InsertClock::now();
  std::vector<RasterObject> raster(n_objects);
  for (size_t i = 0; i < n_objects; ++i) raster[i] = {objects[i].mesh, objects[i].T_world_object, objects[i].scale};
  RasterOptions raster_options;
  raster_options.coverage_grid = options_.antialias_edges ? 4 : 0;
  layers.gbuffer = Rasterize(camera, T_world_camera, raster, raster_options);
  const ObjectGBuffer& g = layers.gbuffer;
  times.raster_ms = MsSince(t0);

  const std::vector<uint32_t> covered = CoveredPixels(g);
  // 3. Shading with self-shadows: lobes of each object's light, SSD of every
  // shadow-casting object at those axes (the union takes the minimum).
  t0 = InsertClock::now();
  layers.object = ImageF(g.rect.width(), g.rect.height(), 3, 0.0f);
  layers.alpha = ImageF(g.rect.width(), g.rect.height(), 1, 0.0f);
  std::vector<LightPrep>& preps = PrepareLights(objects, parallax, drag);
  std::vector<PrefilteredRadiance>& specular = preps_->specular;
  UpdatePrefilteredSpecular(options_, objects, parallax, lights_, specular);
  std::vector<ShadowSources>& shadow_sources = preps_->shadow_sources;
  UpdateShadowSources(options_, objects, used_lights_, parallax, lights_, shadow_sources);
  // Self-shadow γ per mesh vertex, kept while the objects and the light
  // stand still (it does not depend on the view).
  const bool per_vertex = options_.self_shadow && options_.self_shadow_per_vertex;
  std::vector<std::vector<Vec3f>> vertex_normals(n_objects);
  if (per_vertex)
    times.gamma_recomputed = UpdateVertexGamma(objects, spheres, used_lights_, preps, options_, vertex_gamma_,
                                               vertex_normals, drag.dragged() ? drag.key : nullptr);
  ShadeObjects(objects, spheres, preps, per_vertex ? &vertex_gamma_ : nullptr, vertex_normals, options_, g, covered,
               Vec3f(T_world_camera.translation), layers.object, specular);
  times.shade_ms = MsSince(t0);

  // 4. Occlusion and composite on object pixels (paper eq. 7 and Fig. "sample").
  t0 = InsertClock::now();
  OccludeAndComposite(scene_, options_, camera, T_world_camera, covered, receivers, frame, layers);
  times.occlusion_ms = MsSince(t0);

  // 5. Shadows κ on the scene where an object can shadow (through a drag,
  // with the light it began with: DragFrame::kappa_apart).
  t0 = InsertClock::now();
  std::vector<SgMixture> kappa_lights;
  std::vector<LightPrep> kappa_preps;
  if (drag.kappa_apart) HeldKappaLights(objects, drag, kappa_lights, kappa_preps);
  RenderShadows(
      {scene_, options_, camera, T_world_camera, objects, spheres, drag.kappa_apart ? kappa_lights : used_lights_, g,
       receivers, options_.kappa_from_samples ? &shadow_sources : nullptr, support_ ? &*support_ : nullptr, &drag},
      drag.kappa_apart ? kappa_preps : preps, kappa_cache_, frame, layers, times);
  times.kappa_ms = MsSince(t0);

  // Pixels partly covered by an object whose centre misses it.
  CompositeEdges(receivers, frame, layers);
  times.total_ms = MsSince(t_start);
  return times;
}

}  // namespace nerfar
