// Bench stage "nerf": trains the NeRF of each shared scene with the presets in
// $NERFAR_BENCH_NERF_PRESETS (default "fast"; e.g. "fast,balanced,accurate")
// and reports training time, psnr_tm of the test views against the low-noise
// insert/bg_XXX.exr, depth error on surfaces, model size, and the query
// throughput (density and radiance samples/s, 1280x720 and 320x180 colour+depth
// frames at quality full, live and preview - from the compact render copy, and live from the
// float arrays too - with the mean samples per ray of the 720p frame) on 1 thread and on
// all threads. --quick: a 20-step run on one scene.
// $NERFAR_BENCH_NERF_MODELS="lamps=A.nerf,window=B.nerf": no training; the
// given saved models are scored and timed instead.
#include <cstdlib>
#include <filesystem>
#include <random>
#include <sstream>

#include "app/bench.h"
#include "calib/core/error.h"
#include "calib/core/log.h"
#include "calib/core/parallel.h"
#include "calib/dataset.h"
#include "render/nerf/nerf_eval.h"
#include "render/nerf/nerf_file.h"
#include "render/nerf/nerf_train.h"

namespace nerfar {
namespace {

std::vector<std::string> Split(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ','))
    if (!item.empty()) out.push_back(item);
  return out;
}

void Throughput(const NerfField& field, const std::string& dataset, const std::string& tag,
                std::vector<BenchFigure>& figures) {
  const Dataset test = ReadDataset(DatasetSplitPath(dataset, "test"), false);
  const Pose pose = test.frames.at(0).T_world_camera;
  // Query points: the samples a 400x300 view's rays take (coherent, as the live path queries).
  const std::vector<NerfRay> rays = CameraRays(test.camera, pose, field.aabb);
  std::vector<Vec3f> points, dirs;
  for (size_t n = 0; n < rays.size() && points.size() < 2000000; n += 1) {
    const NerfRay& r = rays[n];
    for (float t = r.t_near; t < r.t_far && points.size() < 2000000; t += 4 * field.voxel_m) {
      points.push_back(r.origin + r.dir * t);
      dirs.push_back(r.dir);
    }
  }
  std::vector<float> sigma(points.size());
  std::vector<Vec3f> radiance(points.size());
  const int all = ThreadCount();
  for (int threads : {1, all}) {
    SetThreadCount(threads);
    const std::string cond = tag + ", " + std::to_string(threads) + " thread" + (threads > 1 ? "s" : "");
    const double d_ms = MedianMilliseconds([&] { field.QueryDensity(points.data(), points.size(), sigma.data()); }, 3);
    figures.push_back({"density_msamples_per_s", points.size() / d_ms / 1e3, "M/s", cond + ", along camera rays"});
    const double r_ms =
        MedianMilliseconds([&] { field.QueryRadiance(points.data(), dirs.data(), points.size(), radiance.data()); }, 3);
    figures.push_back({"radiance_msamples_per_s", points.size() / r_ms / 1e3, "M/s", cond + ", along camera rays"});
    for (const auto& [w, h] : {std::pair{1280, 720}, std::pair{320, 180}}) {
      const CameraIntrinsics cam = test.camera.Scaled(w, h);
      const double ms = MedianMilliseconds([&] { RenderView(field, cam, pose, {}); }, 3, 0.5);
      figures.push_back(
          {"frame_" + std::to_string(w) + "x" + std::to_string(h) + "_ms", ms, "ms", cond + ", colour+depth+opacity"});
      // The live setting (NerfRenderOptions::Preset("live")): 2-voxel steps, rays stop at transmittance 3e-2.
      const NerfRenderOptions live = NerfRenderOptions::Preset("live");
      const double live_ms = MedianMilliseconds([&] { RenderView(field, cam, pose, live); }, 3, 0.5);
      figures.push_back({"frame_" + std::to_string(w) + "x" + std::to_string(h) + "_live_ms", live_ms, "ms",
                         cond + ", quality live (step 2 voxels, min transmittance 3e-2)"});
      const double preview_ms =
          MedianMilliseconds([&] { RenderView(field, cam, pose, NerfRenderOptions::Preset("preview")); }, 3, 0.5);
      figures.push_back({"frame_" + std::to_string(w) + "x" + std::to_string(h) + "_preview_ms", preview_ms, "ms",
                         cond + ", quality preview (step 3 voxels, min transmittance 3e-2)"});
      // The live frame from the float arrays (no render copy), for comparison.
      NerfRenderOptions live_float = live;
      live_float.use_render_copy = false;
      const double float_ms = MedianMilliseconds([&] { RenderView(field, cam, pose, live_float); }, 3, 0.5);
      figures.push_back({"frame_" + std::to_string(w) + "x" + std::to_string(h) + "_live_float_ms", float_ms, "ms",
                         cond + ", quality live, float arrays (no render copy)"});
    }
  }
  for (const std::string quality : {"full", "live"}) {
    // What a 720p frame's rays cost: density samples and colour evaluations per ray (all rays, misses included).
    const std::vector<NerfRay> hd = CameraRays(test.camera.Scaled(1280, 720), pose, field.aabb);
    std::vector<NerfRayResult> out(hd.size());
    field.RenderRays(hd.data(), hd.size(), out.data(), NerfRenderOptions::Preset(quality));
    double samples = 0, colour = 0;
    for (const NerfRayResult& r : out) samples += r.samples, colour += r.color_samples;
    const std::string suffix = quality == "full" ? "" : "_live";
    figures.push_back(
        {"samples_per_ray" + suffix, samples / double(hd.size()), "", tag + ", 1280x720 frame, all rays, " + quality});
    figures.push_back(
        {"colour_samples_per_ray" + suffix, colour / double(hd.size()), "", tag + ", 1280x720 frame, " + quality});
  }
  SetThreadCount(all);
}

}  // namespace

std::vector<BenchFigure> BenchNerf(const BenchOptions& options) {
  std::vector<BenchFigure> figures;
  if (options.scenes_dir.empty()) {
    LogWarning("bench nerf: ../shared/scenes not found; nothing measured");
    return figures;
  }
  const char* env = BenchVariable("NERFAR_BENCH_NERF_PRESETS");
  const std::vector<std::string> presets = options.quick ? std::vector<std::string>{"fast"} : Split(env ? env : "fast");
  std::vector<std::string> scenes = {"lamps", "window"};
  if (options.quick) scenes.resize(1);
  const std::string tmp = std::filesystem::temp_directory_path() / "nerfar_bench_nerf";
  std::filesystem::create_directories(tmp);
  if (const char* models = BenchVariable("NERFAR_BENCH_NERF_MODELS")) {
    for (const std::string& item : Split(models)) {
      const size_t eq = item.find('=');
      if (eq == std::string::npos) throw InputError("NERFAR_BENCH_NERF_MODELS: '" + item + "' (expected SCENE=FILE)");
      const std::string scene = item.substr(0, eq), path = item.substr(eq + 1), dir = options.scenes_dir + "/" + scene;
      NerfField field = LoadNerf(path);
      field.UpdateRenderCopy();  // what nerfar render reads (NerfRenderCopy)
      const std::string tag = scene + " " + std::filesystem::path(path).filename().string();
      const NerfEvaluation eval = EvaluateNerf(field, dir, NerfEvalOptions{});
      figures.push_back({"psnr_tm_reference_db", eval.mean_psnr_reference, "dB", tag + ", 8 test views vs insert/bg"});
      figures.push_back({"surface_depth_median_error_mm", eval.surface_depth_median_m * 1e3, "mm",
                         tag + ", surfaces, object masked"});
      figures.push_back({"model_mb", double(std::filesystem::file_size(path)) / 1e6, "MB", tag});
      Throughput(field, dir, tag, figures);
    }
    return figures;
  }
  for (const std::string& scene : scenes) {
    const std::string dir = options.scenes_dir + "/" + scene;
    const NerfTrainData data = ReadNerfTrainData(dir);
    for (const std::string& preset : presets) {
      NerfTrainOptions o = NerfTrainOptions::Preset(preset);
      if (options.quick) o.steps = 20;
      o.eval_views = 0;
      NerfTrainer trainer(data, o);
      while (!trainer.Done()) trainer.Step();
      NerfField field = trainer.FinalField();
      field.UpdateRenderCopy();
      const std::string path = tmp + "/" + scene + "_" + preset + ".nerf";
      SaveNerf(path, field);
      const std::string tag = scene + " " + preset;
      figures.push_back(
          {"train_s", trainer.elapsed_seconds(), "s", tag + ", " + std::to_string(trainer.step()) + " steps"});
      NerfEvalOptions eval_options;
      const NerfEvaluation eval = EvaluateNerf(field, dir, eval_options);
      figures.push_back({"psnr_tm_reference_db", eval.mean_psnr_reference, "dB", tag + ", 8 test views vs insert/bg"});
      figures.push_back({"psnr_tm_dataset_db", eval.mean_psnr_dataset, "dB", tag + ", 8 test views vs test/ (noisy)"});
      figures.push_back({"depth_median_error_mm", eval.depth_median_m * 1e3, "mm", tag + ", surfaces, object masked"});
      figures.push_back({"model_mb", double(std::filesystem::file_size(path)) / 1e6, "MB", tag});
      Throughput(field, dir, tag, figures);
    }
  }
  std::filesystem::remove_all(tmp);
  return figures;
}

}  // namespace nerfar
