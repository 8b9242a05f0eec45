// Bench stage "insert": per-stage time of a 1280x720 AR frame with the object
// covering about 10% of the frame, per preset (paper §4.4, budgets of
// DESIGN.md), and, where ../shared/scenes is present, quality with
// ground-truth inputs (true probe fitted with SGs as the light, true depth as
// the receivers): object psnr_tm, shadow error and the SG fit's lighting error.
//
// The scene is a NeRF grid (render/nerf's NerfField, 1 cm voxels) filled
// from an exact tabletop (table slab, a sphere), so the occlusion and κ stages
// pay the real cost of marching a NeRF with empty-space skipping.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <string>

#include "app/bench.h"
#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "calib/core/image_io.h"
#include "calib/core/log.h"
#include "calib/core/parallel.h"
#include "calib/dataset.h"
#include "calib/object.h"
#include "render/insert/inserter.h"
#include "render/insert/nerf_scene.h"
#include "render/insert/quality.h"
#include "render/insert/rasterizer.h"
#include "render/insert/ssdf_visibility.h"
#include "render/mesh/mesh.h"
#include "render/nerf/nerf_field.h"
#include "render/sg/fit.h"
#include "render/sg/sphere.h"
#include "render/ssdf/ssdf.h"

namespace nerfar {

namespace fs = std::filesystem;

// The shared scenes' box, a 4 cm table slab (albedo-like radiance 0.4) and a
// sphere (r = 8 cm) standing on it, as a 1 cm NeRF grid.
NerfField BenchTabletopNerf() {
  const Aabb box{{-0.62, -0.42, -0.05}, {0.62, 0.42, 0.60}};
  NerfField field =
      NerfField::Dense(box, 0.01, kNerfEmptyDensityRaw, {std::log(0.4f), std::log(0.35f), std::log(0.3f)});
  const Vec3 sphere_center{-0.2, 0.12, 0.08};
  for (int k = 0; k < field.res[2]; ++k)
    for (int j = 0; j < field.res[1]; ++j)
      for (int i = 0; i < field.res[0]; ++i) {
        const int32_t slot = field.Slot(i, j, k);
        if (slot < 0) continue;
        const Vec3 p = Vec3(field.origin) + Vec3(i, j, k) * double(field.voxel_m);
        const bool table = p.z <= 0.0 && p.z >= -0.04 && std::abs(p.x) <= 0.6 && std::abs(p.y) <= 0.4;
        const bool sphere = Length(p - sphere_center) <= 0.08;
        if (table || sphere) field.density[slot] = std::log(3000.0f);  // σ = 3000/m: opaque within ~2 mm
        if (sphere) field.color[size_t(slot) * kNerfColorCoeffs + 8] = std::log(0.8f);
      }
  field.UpdateOccupancy(1.0f);
  return field;
}

// The shared scenes' monkey where present, else a torus (4 cm ring).
TriangleMesh BenchObjectMesh(const std::string& scenes_dir, std::string* name) {
  if (!scenes_dir.empty()) {
    const std::string path = scenes_dir + "/objects/monkey_diffuse.obj";
    std::error_code error;
    if (fs::is_regular_file(path, error)) {
      *name = "monkey_diffuse (3936 triangles)";
      return ReadMesh(path);
    }
  }
  *name = "torus (2304 triangles)";
  return MakeTorus(0.04, 0.015, 48, 24);
}

// A sky from above and a bright window lobe.
SgMixture BenchEnvironment() {
  Sg sky;
  sky.axis = {0, 0, 1};
  sky.sharpness = 1.0;
  sky.amplitude = {0.3, 0.35, 0.4};
  Sg window;
  window.axis = Normalized(Vec3{0.6, 0.5, 0.6});
  window.sharpness = 60.0;
  window.amplitude = {30.0, 28.0, 25.0};
  SgMixture environment = {sky, window};
  // NERFAR_BENCH_INSERT_SUN=λ: also a small, very bright sun of that
  // sharpness (the sunroom's energy), which the incident light passes on
  // analytically when it is sharper than its directions resolve.
  if (const char* sun_env = BenchVariable("NERFAR_BENCH_INSERT_SUN")) {
    Sg sun;
    sun.axis = Normalized(Vec3{-0.66, -0.36, 0.65});
    sun.sharpness = std::clamp(std::atof(sun_env), 1.0, 1e4);
    const double mu = 8.7 / SgUnitIntegral(sun.sharpness);
    sun.amplitude = {mu, 0.93 * mu, 0.83 * mu};
    environment.push_back(sun);
  }
  return environment;
}

namespace {

struct StageMedians {
  double light = 0, fit_warm = 0, raster = 0, shade = 0, occlusion = 0, kappa = 0, frame_still = 0, frame_moving = 0;
  double coverage = 0;
  double kappa_rect_px = 0, kappa_marched = 0;            // a still frame's κ rectangle and receiver rays marched
  double kappa_camera_moved = 0, frame_camera_moved = 0;  // object still, camera moved 1 mm
  // A hand-held sequence (object still, camera 3 mm per frame): medians over
  // its frames after the first, with the preset's options and with exact receivers.
  double handheld_kappa = 0, handheld_frame = 0, handheld_marched = 0, handheld_reused = 0;
  // Its parts (medians): κ's receivers / look-ups / multiply (ms), occlusion +
  // composite (ms), receivers whose κ was taken, shared-lattice look-ups,
  // pixels passed by the multiply.
  double handheld_receivers_ms = 0, handheld_lookup_ms = 0, handheld_multiply_ms = 0, handheld_occlusion = 0;
  double handheld_receivers = 0, handheld_lookups = 0, handheld_multiplied = 0;
  double handheld_hidden = 0;  // κ grid nodes under the object that no background pixel needs
  double handheld_evaluated = 0, handheld_raster = 0, handheld_shade = 0;  // new lattice nodes; raster, shade ms
  double handheld_kappa_marched_all = 0, handheld_frame_marched_all = 0, handheld_marched_all = 0;
  // κ of the preset against exact receivers: worst frame's Σ|Δκ| / Σ(1 − κ), worst pixel |Δκ|.
  double handheld_error_mean = 0, handheld_error_max = 0;
  // Exact receivers against themselves with the camera 0.1 mm further (the
  // NeRF receivers' own frame-to-frame noise), same measures.
  double handheld_noise_mean = 0, handheld_noise_max = 0;
  // κ with the bench scene's true geometry as receivers (table top z = 0 and
  // the sphere, true normals) against the preset and against exact NeRF
  // receivers, same measures.
  double handheld_truth_preset_mean = 0, handheld_truth_exact_mean = 0;
};

// The bench NeRF's geometry (BenchTabletopNerf) as true receivers: ray distance
// and world normal per pixel (table top z = 0 within |x| ≤ 0.6, |y| ≤ 0.4, the
// sphere of 8 cm), 0 where a ray meets neither.
void TabletopReceivers(const CameraIntrinsics& camera, const Pose& T_world_camera, ImageF& distance, ImageF& normal) {
  distance = ImageF(camera.width, camera.height, 1, 0.0f);
  normal = ImageF(camera.width, camera.height, 3, 0.0f);
  const Vec3 eye = T_world_camera.translation, c{-0.2, 0.12, 0.08};
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) {
      const Vec3 d(CameraRayDirection(camera, T_world_camera, x, y));
      double best = std::numeric_limits<double>::infinity();
      Vec3 n;
      if (d.z < 0) {
        const double t = -eye.z / d.z;
        const Vec3 p = eye + d * t;
        if (std::abs(p.x) <= 0.6 && std::abs(p.y) <= 0.4) {
          best = t;
          n = {0, 0, 1};
        }
      }
      const Vec3 oc = eye - c;
      const double b = Dot(oc, d), disc = b * b - (Dot(oc, oc) - 0.08 * 0.08);
      if (disc >= 0) {
        const double t = -b - std::sqrt(disc);
        if (t > 0 && t < best) {
          best = t;
          n = Normalized(eye + d * t - c);
        }
      }
      if (!std::isfinite(best)) continue;
      distance.at(x, y) = float(best);
      for (int ch = 0; ch < 3; ++ch) normal.at(x, y, ch) = float(n[ch]);
    }
}

// Worst |Δκ| and Σ|Δκ| / Σ(1 − κ_b) of two κ layers, as full frames.
void KappaDifference(const InsertLayers& la, const InsertLayers& lb, const CameraIntrinsics& camera, double& mean,
                     double& max) {
  const ImageF ka = ExpandLayer(la.kappa, la.kappa_rect, camera.width, camera.height, 1.0f);
  const ImageF kb = ExpandLayer(lb.kappa, lb.kappa_rect, camera.width, camera.height, 1.0f);
  double diff = 0, shadow = 0;
  for (size_t i = 0; i < ka.pixels.size(); ++i) {
    const double d = std::abs(double(ka.pixels[i]) - kb.pixels[i]);
    diff += d;
    shadow += 1.0 - kb.pixels[i];
    max = std::max(max, d);
  }
  if (shadow > 0) mean = std::max(mean, diff / shadow);
}

// One hand-held frame after the first (a function of its own so that
// `valgrind --tool=callgrind --toggle-collect='*RenderHandHeldFrame*'` counts
// exactly these frames' instructions).
__attribute__((noinline)) InsertTimings RenderHandHeldFrame(Inserter& inserter, const CameraIntrinsics& camera,
                                                            const Pose& cam, const InsertObject& object, ImageF& frame,
                                                            InsertLayers& layers) {
  return inserter.Render(camera, cam, {object}, frame, &layers);
}

// Object still, the camera translated by 3 mm (and 1 mm sideways) per frame
// from T_world_camera: `frames` frames with the options given and the same
// ones with the exact receivers (kappa_receiver_reuse and
// receiver_normal_per_cell off: a march and a NeRF normal each).
void TimeHandHeld(const NerfScene& scene, const SgMixture& environment, const InsertObject& object,
                  const CameraIntrinsics& camera, const Pose& T_world_camera, const InsertOptions& options, int frames,
                  StageMedians& m) {
  InsertOptions marched_options = options;
  marched_options.kappa_receiver_reuse = false;
  marched_options.receiver_normal_per_cell = false;
  Inserter reuse(scene, environment, options), marched(scene, environment, marched_options),
      jitter(scene, environment, marched_options), truth(scene, environment, marched_options);
  const ImageF background(camera.width, camera.height, 3, 0.3f);
  std::vector<double> kappa, frame_ms, n_marched, n_reused, kappa_all, frame_all, n_marched_all;
  std::vector<double> part_receivers, part_lookup, part_multiply, part_occlusion, n_receivers, n_lookups, n_multiplied;
  std::vector<double> n_evaluated, part_raster, part_shade, n_hidden;
  // NERFAR_BENCH_INSERT_HANDHELD_ONLY=1 (for profiling): the preset's
  // hand-held frames alone, no reference renders (error rows stay 0).
  const char* only_env = BenchVariable("NERFAR_BENCH_INSERT_HANDHELD_ONLY");
  const bool handheld_only = only_env != nullptr && std::string(only_env) == "1";
  for (int f = 0; f < frames; ++f) {
    Pose cam = T_world_camera;
    cam.translation.x += 3e-3 * f;
    cam.translation.y += 1e-3 * f;
    ImageF fa = background, fb = background;
    InsertLayers la, lb;
    const InsertTimings ta =
        f == 0 ? reuse.Render(camera, cam, {object}, fa, &la) : RenderHandHeldFrame(reuse, camera, cam, object, fa, la);
    if (f > 0) {
      part_receivers.push_back(ta.kappa_receivers_ms);
      part_lookup.push_back(ta.kappa_lookup_ms);
      part_multiply.push_back(ta.kappa_multiply_ms);
      part_occlusion.push_back(ta.occlusion_ms);
      n_receivers.push_back(double(ta.kappa_receivers));
      n_lookups.push_back(double(ta.kappa_lookups));
      n_multiplied.push_back(double(ta.kappa_multiplied));
      n_evaluated.push_back(double(ta.kappa_evaluated));
      n_hidden.push_back(double(ta.kappa_hidden));
      part_raster.push_back(ta.raster_ms);
      part_shade.push_back(ta.shade_ms);
    }
    if (handheld_only) {
      if (f > 0)
        LogInfo("hand-held frame " + std::to_string(f) + ": κ " + std::to_string(ta.kappa_ms) + " ms, receivers " +
                std::to_string(ta.kappa_receivers) + ", look-ups " + std::to_string(ta.kappa_lookups) + ", new nodes " +
                std::to_string(ta.kappa_evaluated) + ", marched " + std::to_string(ta.kappa_marched) + ", rect " +
                std::to_string(la.kappa_rect.area()) + " px, multiplied " + std::to_string(ta.kappa_multiplied) +
                " px");
      if (f > 0) kappa.push_back(ta.kappa_ms), frame_ms.push_back(ta.total_ms);
      if (f > 0) n_marched.push_back(double(ta.kappa_marched)), n_reused.push_back(double(ta.kappa_reused));
      continue;
    }
    const InsertTimings tb = marched.Render(camera, cam, {object}, fb, &lb);
    if (f == 0) continue;  // the first frame builds the caches
    kappa.push_back(ta.kappa_ms);
    frame_ms.push_back(ta.total_ms);
    n_marched.push_back(double(ta.kappa_marched));
    n_reused.push_back(double(ta.kappa_reused));
    kappa_all.push_back(tb.kappa_ms);
    frame_all.push_back(tb.total_ms);
    n_marched_all.push_back(double(tb.kappa_marched));
    KappaDifference(la, lb, camera, m.handheld_error_mean, m.handheld_error_max);
    Pose jittered = cam;
    jittered.translation.x += 1e-4;
    ImageF fc = background;
    InsertLayers lc;
    jitter.Render(camera, jittered, {object}, fc, &lc);
    KappaDifference(lc, lb, camera, m.handheld_noise_mean, m.handheld_noise_max);
    ImageF true_distance, true_normal;
    TabletopReceivers(camera, cam, true_distance, true_normal);
    ReceiverOverride truth_receivers;
    truth_receivers.distance = &true_distance;
    truth_receivers.normal = &true_normal;
    ImageF fd = background;
    InsertLayers ld;
    truth.Render(camera, cam, {object}, fd, &ld, truth_receivers);
    double unused = 0;
    KappaDifference(la, ld, camera, m.handheld_truth_preset_mean, unused);
    KappaDifference(lb, ld, camera, m.handheld_truth_exact_mean, unused);
  }
  m.handheld_kappa = MedianOf(kappa);
  m.handheld_receivers_ms = MedianOf(part_receivers);
  m.handheld_lookup_ms = MedianOf(part_lookup);
  m.handheld_multiply_ms = MedianOf(part_multiply);
  m.handheld_occlusion = MedianOf(part_occlusion);
  m.handheld_receivers = MedianOf(n_receivers);
  m.handheld_lookups = MedianOf(n_lookups);
  m.handheld_multiplied = MedianOf(n_multiplied);
  m.handheld_evaluated = MedianOf(n_evaluated);
  m.handheld_hidden = MedianOf(n_hidden);
  m.handheld_raster = MedianOf(part_raster);
  m.handheld_shade = MedianOf(part_shade);
  m.handheld_frame = MedianOf(frame_ms);
  m.handheld_marched = MedianOf(n_marched);
  m.handheld_reused = MedianOf(n_reused);
  m.handheld_kappa_marched_all = MedianOf(kappa_all);
  m.handheld_frame_marched_all = MedianOf(frame_all);
  m.handheld_marched_all = MedianOf(n_marched_all);
}

StageMedians TimePreset(const NerfScene& scene, const SgMixture& environment, const InsertObject& object_template,
                        const CameraIntrinsics& camera, const Pose& T_world_camera, const InsertOptions& options,
                        int repeats) {
  Inserter inserter(scene, environment, options);
  ImageF background(camera.width, camera.height, 3, 0.3f);
  InsertObject object = object_template;
  std::vector<double> light, fit, raster, shade, occlusion, kappa, still, moving, kappa_cam, still_cam;
  InsertLayers layers;
  // Warm-up: the cold fit and allocations.
  {
    ImageF frame = background;
    inserter.Render(camera, T_world_camera, {object}, frame, &layers);
  }
  StageMedians m;
  m.coverage = double(layers.gbuffer.covered) / (double(camera.width) * camera.height);
  const char* only_env = BenchVariable("NERFAR_BENCH_INSERT_HANDHELD_ONLY");
  if (only_env != nullptr && std::string(only_env) == "1") repeats = 0;  // profiling the hand-held frames
  for (int r = 0; r < repeats; ++r) {
    // The object still: the incident light is reused.
    ImageF frame = background;
    InsertTimings t = inserter.Render(camera, T_world_camera, {object}, frame, &layers);
    raster.push_back(t.raster_ms);
    shade.push_back(t.shade_ms);
    occlusion.push_back(t.occlusion_ms);
    kappa.push_back(t.kappa_ms);
    still.push_back(t.total_ms);
    m.kappa_rect_px = double(layers.kappa_rect.area());
    m.kappa_marched = double(t.kappa_marched);
    // The object still, the camera moved by 1 mm (a hand-held AR frame): the
    // lattice holds, the receivers are marched again.
    {
      Pose moved_camera = T_world_camera;
      moved_camera.translation.y += (r % 2 ? -1e-3 : 1e-3);
      ImageF moved_frame = background;
      const InsertTimings tc = inserter.Render(camera, moved_camera, {object}, moved_frame);
      kappa_cam.push_back(tc.kappa_ms);
      still_cam.push_back(tc.total_ms);
    }
    // The object moved by 1 mm: new rays from its centre and a warm-started fit.
    object.T_world_object.translation.x += (r % 2 ? -1e-3 : 1e-3);
    frame = background;
    t = inserter.Render(camera, T_world_camera, {object}, frame, &layers);
    light.push_back(t.light_ms);
    fit.push_back(t.fit_ms);
    moving.push_back(t.total_ms);
  }
  m.light = MedianOf(light);
  m.fit_warm = MedianOf(fit);
  m.raster = MedianOf(raster);
  m.shade = MedianOf(shade);
  m.occlusion = MedianOf(occlusion);
  m.kappa = MedianOf(kappa);
  m.frame_still = MedianOf(still);
  m.frame_moving = MedianOf(moving);
  m.kappa_camera_moved = MedianOf(kappa_cam);
  m.frame_camera_moved = MedianOf(still_cam);
  // NERFAR_BENCH_INSERT_HANDHELD_FRAMES=N: N hand-held frames (default 6,
  // the first builds the caches; more give a profiler more samples).
  const char* frames_env = BenchVariable("NERFAR_BENCH_INSERT_HANDHELD_FRAMES");
  const int frames = frames_env != nullptr ? std::clamp(std::atoi(frames_env), 2, 1000) : 6;
  TimeHandHeld(scene, environment, object, camera, T_world_camera, options, frames, m);
  return m;
}

// Quality with ground-truth inputs for one scene and object; appends figures.
void GroundTruthQuality(const std::string& scenes_dir, const std::string& scene_name, const std::string& object_name,
                        std::vector<BenchFigure>& figures) {
  const fs::path scene_dir = fs::path(scenes_dir) / scene_name;
  const fs::path truth = scene_dir / "insert" / object_name;
  const Dataset dataset = ReadDataset((scene_dir / "transforms_test.json").string(), false);
  const Material material = ReadMaterial((fs::path(scenes_dir) / "objects" / (object_name + ".json")).string());
  const TriangleMesh mesh = ReadMesh(material.mesh);
  const ObjectPlacement placement = ReadObjectPlacement((truth / "pose.json").string());
  const SsdfField field = BakeSsdf(mesh, SsdfBakeOptions::Preset("fast"), material);
  const SsdfVisibility visibility(field, placement.T_world_object, placement.scale);
  InsertOptions options = InsertOptions::Preset("balanced");
  const ImageF probe = ReadExrRgb((truth / "probe.exr").string());
  const SgMixture light = FitSg(SamplesFromEquirect(probe, 64, 32), options.light.fit);
  InsertObject object;
  object.mesh = &mesh;
  object.T_world_object = placement.T_world_object;
  object.scale = placement.scale;
  object.material.base_color = material.albedo;
  object.material.roughness = material.roughness;
  object.material.metallic = material.metallic;
  object.visibility = &visibility;
  object.light_override = &light;
  const EmptyScene scene(*dataset.aabb);
  Inserter inserter(scene, {}, options);
  double psnr_sum = 0, shadow_sum = 0;
  int psnr_n = 0, shadow_n = 0;
  for (size_t v = 0; v < dataset.frames.size(); ++v) {
    char index[24];
    std::snprintf(index, sizeof index, "%03zu", v);
    const ImageF bg = ReadExrRgb((scene_dir / "insert" / ("bg_" + std::string(index) + ".exr")).string());
    const ImageF gt = ReadExrRgb((truth / ("rgb_" + std::string(index) + ".exr")).string());
    const ImageF depth = ReadExrChannel((truth / ("depth_" + std::string(index) + ".exr")).string());
    const Image8 mask8 = ReadImage8((truth / ("mask_" + std::string(index) + ".png")).string());
    ImageF mask(mask8.width, mask8.height, 1);
    for (size_t p = 0; p < mask.pixels.size(); ++p) mask.pixels[p] = mask8.pixels[p * mask8.channels] / 255.0f;
    ImageF distance, normal;
    ReceiversFromDepth(depth, dataset.camera, dataset.frames[v].T_world_camera, distance, normal);
    ImageF frame = bg;
    inserter.Render(dataset.camera, dataset.frames[v].T_world_camera, {object}, frame, nullptr,
                    {&distance, &normal, true});
    const double psnr = ObjectPsnrTm(frame, gt, mask);
    const ShadowError se = ComputeShadowError(frame, bg, gt, bg, mask);
    if (std::isfinite(psnr)) psnr_sum += psnr, ++psnr_n;
    if (std::isfinite(se.error)) shadow_sum += se.error, ++shadow_n;
  }
  const std::string key = scene_name + "_" + object_name;
  const std::string note =
      "balanced, SSDF baked fast; GT inputs: true probe fitted (32 SGs), true depth as receivers and occluder, "
      "bg_XXX frames";
  figures.push_back({"psnr_obj_" + key + "_db", psnr_n ? psnr_sum / psnr_n : NAN, "dB", note});
  figures.push_back({"shadow_err_" + key, shadow_n ? shadow_sum / shadow_n : NAN, "", note});
  figures.push_back({"light_err_fit_" + key, LightingError(light, probe), "", "32-SG fit of the true probe"});
}

// The object's SSDF, baked with the fast preset. NERFAR_BENCH_INSERT_SSDF_CACHE=PATH
// (for profiling under valgrind): read from PATH when it exists, else baked and written there.
SsdfField BenchObjectSsdf(const TriangleMesh& mesh) {
  const double t_bake = NowSeconds();
  const char* ssdf_cache = BenchVariable("NERFAR_BENCH_INSERT_SSDF_CACHE");
  std::error_code exists_error;
  const bool cached_ssdf = ssdf_cache != nullptr && fs::is_regular_file(ssdf_cache, exists_error);
  SsdfField field = cached_ssdf ? ReadSsdf(ssdf_cache) : BakeSsdf(mesh, SsdfBakeOptions::Preset("fast"), std::nullopt);
  if (ssdf_cache != nullptr && !cached_ssdf) WriteSsdf(ssdf_cache, field);
  LogInfo("bench insert: " + std::string(cached_ssdf ? "read" : "baked") + " the object's SSDF (fast) in " +
          FormatDuration(NowSeconds() - t_bake));
  return field;
}

// The camera of the timed frames: 60° horizontal view, its distance set so
// the object covers about 10% of the frame.
struct BenchView {
  CameraIntrinsics camera;
  Pose T_world_camera;
};

BenchView FrameTheObject(const TriangleMesh& mesh, const Pose& T_world_object, int width, int height) {
  BenchView view;
  CameraIntrinsics& camera = view.camera;
  camera.width = width;
  camera.height = height;
  camera.fx = camera.fy = 0.5 * width / std::tan(kPi / 6);
  camera.cx = width / 2.0;
  camera.cy = height / 2.0;
  const Vec3 target = T_world_object.translation;
  const Vec3 direction = Normalized(Vec3{0.7, -0.6, 0.5});
  double distance = 0.4;
  view.T_world_camera = LookAt(target + direction * distance, target);
  for (int iteration = 0; iteration < 4; ++iteration) {
    const ObjectGBuffer g = Rasterize(camera, view.T_world_camera, {{&mesh, T_world_object, 1.0}});
    const double coverage = double(g.covered) / (double(width) * height);
    if (coverage <= 0) break;
    distance *= std::sqrt(coverage / 0.10);
    view.T_world_camera = LookAt(target + direction * distance, target);
  }
  return view;
}

// The non-empty items of a comma-separated list (none for nullptr).
std::vector<std::string> SplitList(const char* text) {
  std::vector<std::string> items;
  const std::string list = text ? text : "";
  for (size_t begin = 0; begin <= list.size();) {
    const size_t end = std::min(list.find(',', begin), list.size());
    if (end > begin) items.push_back(list.substr(begin, end - begin));
    begin = end + 1;
  }
  return items;
}

// The preset's options with the NERFAR_BENCH_INSERT_{PARALLAX,OFF,KNOBS}
// overrides (to attribute a part's cost).
InsertOptions PresetWithOverrides(const char* preset) {
  InsertOptions insert_options = InsertOptions::Preset(preset);
  // NERFAR_BENCH_INSERT_PARALLAX=0: near-light parallax off (to attribute its cost).
  const char* parallax_env = BenchVariable("NERFAR_BENCH_INSERT_PARALLAX");
  if (parallax_env != nullptr && std::string(parallax_env) == "0") insert_options.light.parallax = false;
  // NERFAR_BENCH_INSERT_OFF="snap,skip_covered" (either): κ's ε snap /
  // the skipped nodes under the object off (to attribute their savings).
  for (const std::string& item : SplitList(BenchVariable("NERFAR_BENCH_INSERT_OFF"))) {
    if (item == "snap") {
      insert_options.shadow_epsilon_snap = false;
    } else if (item == "skip_covered") {
      insert_options.kappa_skip_covered = false;
    } else {
      ThrowInputError("NERFAR_BENCH_INSERT_OFF", "'" + item + "' (expected snap, skip_covered or both)");
    }
  }
  // NERFAR_BENCH_INSERT_KNOBS="kappa_step=4,shadow_reach_radii=8,...": any
  // of `nerfar insert --set`'s keys set over the preset (to attribute one
  // preset's cost against another's), through the same InsertOptions::Set:
  // an unknown name or a bad value stops the bench.
  for (const std::string& item : SplitList(BenchVariable("NERFAR_BENCH_INSERT_KNOBS")))
    insert_options.Set(item, "NERFAR_BENCH_INSERT_KNOBS");
  return insert_options;
}

// One preset's figures: the still and moving frames' stages, then the
// hand-held sequence's.
void AddPresetFigures(const char* preset, const StageMedians& m, const InsertOptions& insert_options,
                      const std::string& size, std::vector<BenchFigure>& figures) {
  const std::string note = std::string(preset) + ", " + size + ", object " +
                           std::to_string(int(std::round(m.coverage * 100))) + "% of the frame";
  const std::string p = std::string(preset) + "_";
  figures.push_back({p + "light_ms", m.light, "ms", note + "; N=" + std::to_string(insert_options.light.directions)});
  figures.push_back(
      {p + "fit_warm_ms", m.fit_warm, "ms", note + "; M=" + std::to_string(insert_options.light.fit.lobes)});
  figures.push_back({p + "raster_ms", m.raster, "ms", note});
  figures.push_back({p + "shade_ms", m.shade, "ms", note + " (with self-shadow)"});
  figures.push_back({p + "occlusion_ms", m.occlusion, "ms", note + " (incl. composite)"});
  figures.push_back({p + "kappa_ms", m.kappa, "ms", note + "; step " + std::to_string(insert_options.kappa_step)});
  figures.push_back({p + "kappa_rect_still_px", m.kappa_rect_px, "px", note + "; where κ was passed, still frame"});
  figures.push_back({p + "kappa_marched_still", m.kappa_marched, "rays", note + "; κ receivers marched, still frame"});
  figures.push_back({p + "frame_still_ms", m.frame_still, "ms", note + "; light cached"});
  figures.push_back({p + "frame_moving_ms", m.frame_moving, "ms", note + "; light + warm fit"});
  figures.push_back({p + "kappa_camera_moved_ms", m.kappa_camera_moved, "ms", note + "; object still, camera 1 mm"});
  figures.push_back({p + "frame_camera_moved_ms", m.frame_camera_moved, "ms", note + "; object still, camera 1 mm"});
  const std::string hh = note + "; hand-held: object still, camera 3 mm per frame, median of 5 frames";
  figures.push_back({p + "handheld_kappa_ms", m.handheld_kappa, "ms", hh + ", options of the preset"});
  figures.push_back({p + "handheld_frame_ms", m.handheld_frame, "ms", hh + ", options of the preset"});
  figures.push_back({p + "handheld_marched", m.handheld_marched, "rays", hh + ", options of the preset"});
  figures.push_back({p + "handheld_occlusion_ms", m.handheld_occlusion, "ms", hh + ", occlusion + composite"});
  figures.push_back({p + "handheld_kappa_receivers_ms", m.handheld_receivers_ms, "ms",
                     hh + ", κ part: receivers (reuse, marches, cell normals)"});
  figures.push_back({p + "handheld_kappa_lookup_ms", m.handheld_lookup_ms, "ms",
                     hh + ", κ part: κ at the receivers (lattice look-ups, new nodes)"});
  figures.push_back(
      {p + "handheld_kappa_multiply_ms", m.handheld_multiply_ms, "ms", hh + ", κ part: layer + background multiply"});
  figures.push_back({p + "handheld_receivers", m.handheld_receivers, "", hh + ", receivers whose κ was taken"});
  figures.push_back({p + "handheld_lookups", m.handheld_lookups, "", hh + ", shared-lattice look-ups"});
  figures.push_back({p + "handheld_multiplied_px", m.handheld_multiplied, "px", hh + ", pixels the multiply passed"});
  figures.push_back({p + "handheld_evaluated", m.handheld_evaluated, "", hh + ", lattice nodes evaluated (new)"});
  figures.push_back(
      {p + "handheld_hidden", m.handheld_hidden, "", hh + ", κ grid nodes under the object not needed (skipped)"});
  figures.push_back({p + "handheld_raster_ms", m.handheld_raster, "ms", hh + ", raster"});
  figures.push_back({p + "handheld_shade_ms", m.handheld_shade, "ms", hh + ", shade + self-shadow"});
  figures.push_back({p + "handheld_reused", m.handheld_reused, "rays", hh + ", options of the preset"});
  figures.push_back(
      {p + "handheld_kappa_all_marched_ms", m.handheld_kappa_marched_all, "ms", hh + ", exact receivers"});
  figures.push_back(
      {p + "handheld_frame_all_marched_ms", m.handheld_frame_marched_all, "ms", hh + ", exact receivers"});
  figures.push_back({p + "handheld_marched_all", m.handheld_marched_all, "rays", hh + ", exact receivers"});
  figures.push_back({p + "handheld_kappa_error_mean", m.handheld_error_mean, "",
                     hh + ", preset vs exact receivers: worst frame's sum |dκ| / sum (1 - κ)"});
  figures.push_back(
      {p + "handheld_kappa_error_max", m.handheld_error_max, "", hh + ", preset vs exact receivers: worst pixel |dκ|"});
  figures.push_back(
      {p + "handheld_kappa_noise_mean", m.handheld_noise_mean, "",
       hh + ", exact receivers vs exact receivers from 0.1 mm away: worst frame's sum |dκ| / sum (1 - κ)"});
  figures.push_back({p + "handheld_kappa_vs_truth_mean", m.handheld_truth_preset_mean, "",
                     hh + ", preset vs κ with the true geometry as receivers: worst frame's sum |dκ| / sum (1 - κ)"});
  figures.push_back({p + "handheld_kappa_exact_vs_truth_mean", m.handheld_truth_exact_mean, "",
                     hh + ", exact receivers vs κ with the true geometry: worst frame's sum |dκ| / sum (1 - κ)"});
  figures.push_back({p + "handheld_kappa_noise_max", m.handheld_noise_max, "",
                     hh + ", exact receivers vs exact receivers from 0.1 mm away: worst pixel |dκ|"});
}

}  // namespace

// The incident light on a real NeRF (bench_insert_light.cpp; NERFAR_BENCH_INSERT_NERF).
void BenchInsertRealNerfLight(const BenchOptions& options, std::vector<BenchFigure>& figures);

std::vector<BenchFigure> BenchInsert(const BenchOptions& options) {
  // A bad NERFAR_BENCH_INSERT_OFF, _KNOBS or scene override stops the bench before any work.
  PresetWithOverrides("fast");
  BenchInsertSceneOptions("fast");
  std::vector<BenchFigure> figures;
  BenchInsertRealNerfLight(options, figures);
  // NERFAR_BENCH_INSERT_GT=0 skips the ground-truth quality part;
  // NERFAR_BENCH_INSERT_PRESETS="fast,balanced" times only those presets.
  const char* gt_env = BenchVariable("NERFAR_BENCH_INSERT_GT");
  const bool with_gt = gt_env == nullptr || std::string(gt_env) != "0";
  const char* presets_env = BenchVariable("NERFAR_BENCH_INSERT_PRESETS");
  const std::string presets = presets_env ? presets_env : "fast,balanced,accurate";
  if (with_gt && !options.quick && !options.scenes_dir.empty()) {
    for (const char* scene_name : {"lamps", "window"})
      for (const char* object_name : {"monkey_diffuse", "sphere_glossy"})
        GroundTruthQuality(options.scenes_dir, scene_name, object_name, figures);
  }
  const int width = options.quick ? 320 : 1280, height = options.quick ? 180 : 720;
  const int repeats = options.quick ? 2 : 3;
  const NerfField nerf = BenchTabletopNerf();
  const SgMixture environment = BenchEnvironment();
  std::string mesh_name;
  const TriangleMesh mesh = BenchObjectMesh(options.scenes_dir, &mesh_name);
  const SsdfField field = BenchObjectSsdf(mesh);
  const BoundingSphere bs = ComputeBoundingSphere(mesh);
  const Pose T_world_object{Mat3::Identity(), {0.1, -0.05, -bs.center.z + (ComputeBounds(mesh).max.z - bs.center.z)}};
  const SsdfVisibility visibility(field, T_world_object, 1.0);
  InsertObject object;
  object.mesh = &mesh;
  object.T_world_object = T_world_object;
  object.material.base_color = {0.8, 0.35, 0.2};
  object.material.roughness = 0.7;
  object.visibility = &visibility;
  const BenchView view = FrameTheObject(mesh, T_world_object, width, height);
  const std::string size = std::to_string(width) + "x" + std::to_string(height) + ", " + mesh_name;
  for (const char* preset : {"fast", "balanced", "accurate"}) {
    if (presets.find(preset) == std::string::npos) continue;
    const InsertOptions insert_options = PresetWithOverrides(preset);
    const NerfScene scene(nerf, BenchInsertSceneOptions(preset));  // as `nerfar insert --preset` builds it
    const StageMedians m =
        TimePreset(scene, environment, object, view.camera, view.T_world_camera, insert_options, repeats);
    AddPresetFigures(preset, m, insert_options, size, figures);
  }
  return figures;
}

}  // namespace nerfar
