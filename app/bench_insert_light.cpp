// Part of `nerfar bench insert`: the incident light's first (cold) frame on a
// real trained NeRF, where the analytic stand-in of the rest of the stage
// says little (its rays are closed-form; a NeRF's are marched and its
// surfaces seen from below get the seen-radiance views). Runs when
// NERFAR_BENCH_INSERT_NERF names a .nerf model.
#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "app/bench.h"
#include "calib/core/error.h"
#include "calib/core/log.h"
#include "calib/core/parallel.h"
#include "calib/object.h"
#include "render/insert/insert_options.h"
#include "render/insert/nerf_scene.h"
#include "render/lighting/incident_light.h"
#include "render/mesh/mesh.h"
#include "render/nerf/nerf_file.h"

namespace nerfar {

NerfSceneOptions BenchInsertSceneOptions(const std::string& preset) {
  NerfSceneOptions o = NerfSceneOptions::Preset(preset);
  // NERFAR_BENCH_INSERT_LIGHT_RENDER=full|live|preview: the light rays' march
  // (NerfSceneOptions::light_render; default live).
  if (const char* render_env = BenchVariable("NERFAR_BENCH_INSERT_LIGHT_RENDER"))
    o.light_render = NerfRenderOptions::Preset(render_env);
  // NERFAR_BENCH_INSERT_SEE_THROUGH=0: semi-transparent content kept whole
  // (no views aimed at it; seen radiance of surfaces only).
  if (const char* see_env = BenchVariable("NERFAR_BENCH_INSERT_SEE_THROUGH"))
    o.seen.see_through = std::string(see_env) != "0";
  // NERFAR_BENCH_INSERT_SEEN_VIEWS=V, NERFAR_BENCH_INSERT_SEEN_GROUP_CM=C:
  // views per point, cell of shared views (nerfar insert --seen-views, --seen-group-cm).
  if (const char* views_env = BenchVariable("NERFAR_BENCH_INSERT_SEEN_VIEWS")) o.seen.views = std::atoi(views_env);
  if (const char* group_env = BenchVariable("NERFAR_BENCH_INSERT_SEEN_GROUP_CM"))
    o.seen.group_m = std::atof(group_env) / 100.0;
  // NERFAR_BENCH_INSERT_VIEWS_CACHE=0|1: the views' cache across frames (NerfSceneOptions::cache_views).
  if (const char* c = BenchVariable("NERFAR_BENCH_INSERT_VIEWS_CACHE")) o.cache_views = std::string(c) != "0";
  Problems problems("NERFAR_BENCH_INSERT_* light options");
  for (const std::string& p : o.Validate()) problems.Add("", p);
  problems.ThrowIfAny();
  return o;
}

namespace {

// The object the light is taken for: monkey_diffuse posed by
// NERFAR_BENCH_INSERT_NERF_POSE (default scenes/lamps/insert/monkey_diffuse/pose.json);
// the torus at the scene's centre where neither is there.
struct LitObject {
  TriangleMesh mesh;
  std::string name = "monkey_diffuse";
  Pose T_world_object;
  double scale = 1.0;
  Vec3 center;  // of its bounding sphere, world frame
};

LitObject PlaceLitObject(const BenchOptions& options, const NerfField& nerf) {
  LitObject object;
  const std::string obj = options.scenes_dir + "/objects/monkey_diffuse.obj";
  std::error_code error;
  if (!options.scenes_dir.empty() && std::filesystem::is_regular_file(obj, error)) {
    object.mesh = ReadMesh(obj);
  } else {
    object.mesh = MakeTorus(0.04, 0.015, 48, 24);
    object.name = "torus";
  }
  const char* pose_env = BenchVariable("NERFAR_BENCH_INSERT_NERF_POSE");
  const std::string pose_path = pose_env ? pose_env : options.scenes_dir + "/lamps/insert/monkey_diffuse/pose.json";
  object.T_world_object = Pose{Mat3::Identity(), Vec3(nerf.aabb.min + nerf.aabb.max) * 0.5};
  if (std::filesystem::is_regular_file(pose_path, error)) {
    const ObjectPlacement placement = ReadObjectPlacement(pose_path);
    object.T_world_object = placement.T_world_object;
    object.scale = placement.scale;
  }
  const BoundingSphere bs = ComputeBoundingSphere(object.mesh);
  object.center = object.T_world_object * (bs.center * object.scale);
  return object;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// One preset's run: the model, the object, the light's options and the figures' note.
struct LightRun {
  const NerfField& nerf;
  const LitObject& object;
  const SgMixture& environment;
  const InsertOptions& insert_options;
  const NerfSceneOptions& scene_options;
  std::string prefix;  // real_PRESET_
  std::string note;
};

// The cold light: the median over 3 refreshes, each with a fresh cache (the
// object just placed or moved).
void AddColdLight(const LightRun& run, const std::string& preset, std::vector<BenchFigure>& figures) {
  const LightObjectVolume volume{&run.object.mesh, run.object.T_world_object, run.object.scale};
  std::vector<double> sample_ms, fit_ms, samples, view_samples, refined;
  for (int r = 0; r < 3; ++r) {
    const NerfScene scene(run.nerf, run.scene_options);
    IncidentLight light;
    const IncidentLight::Update u =
        light.Refresh(scene, run.environment, run.object.center, run.insert_options.light, &volume);
    sample_ms.push_back(u.sample_ms);
    fit_ms.push_back(u.fit_ms);
    samples.push_back(static_cast<double>(scene.LightSamples()));
    view_samples.push_back(static_cast<double>(scene.LightViewSamples()));
    refined.push_back(static_cast<double>(light.refined()));
  }
  const std::string cold_note = run.note + ", cold (first frame), median of 3";
  const std::string& p = run.prefix;
  figures.push_back({p + "light_ms", Median(sample_ms), "ms", cold_note});
  figures.push_back({p + "fit_cold_ms", Median(fit_ms), "ms",
                     cold_note + "; M=" + std::to_string(run.insert_options.light.fit.lobes)});
  figures.push_back({p + "light_samples", Median(samples), "samples", cold_note + "; density samples, views included"});
  figures.push_back({p + "light_view_samples", Median(view_samples), "samples",
                     cold_note + "; of light_samples, the seen-radiance views"});
  figures.push_back({p + "light_refined", Median(refined), "directions", cold_note});
  LogInfo("bench insert: real NeRF light (" + preset + "): " + std::to_string(Median(sample_ms)) + " ms, " +
          std::to_string(Median(samples)) + " samples");
}

// The object dragged: NERFAR_BENCH_INSERT_DRAG_FRAMES frames, moved
// NERFAR_BENCH_INSERT_DRAG_MM per frame along +x, one NerfScene and one
// IncidentLight for the whole drag; the first frame (cold) apart, the median
// of the others.
void AddDrag(const LightRun& run, const std::string& preset, std::vector<BenchFigure>& figures) {
  const char* frames_env = BenchVariable("NERFAR_BENCH_INSERT_DRAG_FRAMES");
  const char* step_env = BenchVariable("NERFAR_BENCH_INSERT_DRAG_MM");
  const int frames = frames_env ? std::max(2, std::atoi(frames_env)) : 20;
  const double step_m = (step_env ? std::atof(step_env) : 5.0) / 1000.0;
  const LitObject& object = run.object;
  const NerfScene scene(run.nerf, run.scene_options);
  IncidentLight light;
  std::vector<double> drag_ms, drag_fit_ms, drag_refresh_ms, drag_samples, drag_view_samples;
  double first_ms = 0, first_samples = 0;
  uint64_t last_samples = 0, last_views = 0;
  for (int f = 0; f < frames; ++f) {
    const Vec3 offset{step_m * f, 0.0, 0.0};
    const LightObjectVolume moved{
        &object.mesh, Pose{object.T_world_object.rotation, object.T_world_object.translation + offset}, object.scale};
    const auto t0 = std::chrono::steady_clock::now();
    const IncidentLight::Update u =
        light.Refresh(scene, run.environment, object.center + offset, run.insert_options.light, &moved);
    const double refresh_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    const double frame_samples = static_cast<double>(scene.LightSamples() - last_samples);
    const double frame_views = static_cast<double>(scene.LightViewSamples() - last_views);
    last_samples = scene.LightSamples();
    last_views = scene.LightViewSamples();
    if (f == 0) {
      first_ms = u.sample_ms;
      first_samples = frame_samples;
      continue;
    }
    drag_ms.push_back(u.sample_ms);
    drag_refresh_ms.push_back(refresh_ms);
    drag_fit_ms.push_back(u.fit_ms);
    drag_samples.push_back(frame_samples);
    drag_view_samples.push_back(frame_views);
  }
  const std::string drag_note = run.note + "; dragged " + std::to_string(frames) + " frames of " +
                                std::to_string(step_m * 1000.0).substr(0, 4) + " mm along +x, views cache " +
                                (run.scene_options.cache_views ? "on" : "off");
  const double cells = static_cast<double>(scene.LightCacheHits() + scene.LightCacheMisses());
  const std::string& p = run.prefix;
  figures.push_back({p + "drag_light_ms", Median(drag_ms), "ms", drag_note + "; median over frames 2.."});
  figures.push_back({p + "drag_refresh_ms", Median(drag_refresh_ms), "ms",
                     drag_note + "; the whole Refresh: the rays' starts on the moved mesh, light, warm fit, lobe "
                                 "distances"});
  figures.push_back({p + "drag_first_light_ms", first_ms, "ms", drag_note + "; the drag's first frame (cold)"});
  figures.push_back({p + "drag_fit_warm_ms", Median(drag_fit_ms), "ms", drag_note});
  figures.push_back({p + "drag_light_samples", Median(drag_samples), "samples",
                     drag_note + "; per frame, views included (first frame " +
                         std::to_string(static_cast<long long>(first_samples)) + ")"});
  figures.push_back({p + "drag_light_view_samples", Median(drag_view_samples), "samples", drag_note});
  figures.push_back({p + "drag_cache_hit_share", cells > 0 ? scene.LightCacheHits() / cells : 0.0, "",
                     drag_note + "; cells answered from the cache, whole drag"});
  LogInfo("bench insert: real NeRF light dragged (" + preset + "): " + std::to_string(Median(drag_ms)) + " ms, " +
          std::to_string(Median(drag_samples)) + " samples");
}

}  // namespace

// NERFAR_BENCH_INSERT_NERF=model.nerf: per preset (NERFAR_BENCH_INSERT_LIGHT_PRESETS,
// default "fast,balanced"), the median over 3 cold refreshes (a fresh cache each:
// the object just placed or moved) of the light's sampling time, the cold SG fit,
// the density samples taken (light rays and seen-radiance views) and the
// directions refined (AddColdLight). Then the object DRAGGED (AddDrag; the
// per-frame cost the 10 ms budget is for: the light is recomputed only when the
// object moved): NERFAR_BENCH_INSERT_DRAG_FRAMES (default 20) frames, the object
// moved NERFAR_BENCH_INSERT_DRAG_MM (default 5: 15 cm/s at 30 fps) per frame
// along +x from its pose, as in nerfar live (the seen-radiance views' cache and
// the warm fit carry over).
void BenchInsertRealNerfLight(const BenchOptions& options, std::vector<BenchFigure>& figures) {
  const char* model = BenchVariable("NERFAR_BENCH_INSERT_NERF");
  if (model == nullptr || std::string(model).empty()) return;
  NerfField nerf = LoadNerf(model);
  // NERFAR_BENCH_INSERT_NERF_COPY=0: the exact float arrays (no render copy).
  const char* copy_env = BenchVariable("NERFAR_BENCH_INSERT_NERF_COPY");
  const bool copy = copy_env == nullptr || std::string(copy_env) != "0";
  if (copy) nerf.UpdateRenderCopy();  // what nerfar render reads (NerfRenderCopy)
  const LitObject object = PlaceLitObject(options, nerf);
  SgMixture environment;  // the timing does not depend on it (one SG look-up per direction)
  {
    Sg sky;
    sky.axis = {0, 0, 1};
    sky.sharpness = 1.0;
    sky.amplitude = {0.3, 0.35, 0.4};
    environment = {sky};
  }
  const char* presets_env = BenchVariable("NERFAR_BENCH_INSERT_LIGHT_PRESETS");
  const std::string presets = presets_env ? presets_env : "fast,balanced";
  const Vec3& center = object.center;
  const std::string where = std::filesystem::path(model).filename().string() + ", " + object.name + " at (" +
                            std::to_string(center.x).substr(0, 6) + ", " + std::to_string(center.y).substr(0, 6) +
                            ", " + std::to_string(center.z).substr(0, 6) + "), " +
                            (copy ? "render copy, " : "float arrays, ") + std::to_string(ThreadCount()) + " threads";
  for (const char* preset : {"fast", "balanced", "accurate"}) {
    if (presets.find(preset) == std::string::npos) continue;
    InsertOptions insert_options = InsertOptions::Preset(preset);
    // NERFAR_BENCH_INSERT_LIGHT_DIRECTIONS=N, NERFAR_BENCH_INSERT_LIGHT_REFINE=K:
    // the light's directions and sub-rays per refined direction (--light-directions, --light-refine-rays).
    if (const char* d = BenchVariable("NERFAR_BENCH_INSERT_LIGHT_DIRECTIONS"))
      insert_options.light.directions = std::atoi(d);
    if (const char* k = BenchVariable("NERFAR_BENCH_INSERT_LIGHT_REFINE"))
      insert_options.light.refine_rays = std::atoi(k);
    const NerfSceneOptions scene_options = BenchInsertSceneOptions(preset);
    const std::string note = std::string(preset) + ", " + where +
                             "; N=" + std::to_string(insert_options.light.directions) +
                             ", refine_rays=" + std::to_string(insert_options.light.refine_rays) +
                             ", views=" + std::to_string(scene_options.seen.views) +
                             ", group=" + std::to_string(scene_options.seen.group_m * 100.0).substr(0, 4) + " cm" +
                             (scene_options.seen.see_through ? "" : ", no see-through");
    const LightRun run{nerf, object, environment, insert_options, scene_options, std::string("real_") + preset + "_",
                       note};
    AddColdLight(run, preset, figures);
    AddDrag(run, preset, figures);
  }
}

}  // namespace nerfar
