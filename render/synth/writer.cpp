#include "render/synth/writer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "calib/board.h"
#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "calib/core/image_io.h"
#include "calib/core/json.h"
#include "calib/core/log.h"
#include "calib/core/parallel.h"
#include "calib/core/random.h"
#include "calib/dataset.h"
#include "calib/object.h"
#include "render/synth/renderer.h"

namespace nerfar::synth {

namespace fs = std::filesystem;

namespace {

constexpr double kDeg = kPi / 180.0;
constexpr int kEnvWidth = 256, kEnvHeight = 128;  // env.exr and probe.exr (README)
// Streams of the random numbers: train views use their index, the others are offset.
constexpr uint64_t kTestStream = 1u << 20, kInsertStream = 2u << 20;

double Now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }

std::string Numbered(const std::string& prefix, int index, const std::string& ext) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%03d", index);
  return prefix + buffer + ext;
}

Json ToJson(const Vec3f& v) { return Json::array({v.x, v.y, v.z}); }
Json ToJson(const Vec3& v) { return Json::array({v.x, v.y, v.z}); }

Json LightsJson(const SynthScene& synth) {
  const Scene& scene = synth.scene;
  Json doc = Json::object();
  doc["units"] =
      "radiance in the same linear units as the image pixels: a directly viewed emitter of radiance L has "
      "pixel value L";
  Json env = Json::object();
  env["present"] = scene.environment.Present();
  env["visible_to_camera"] = false;
  if (!scene.environment.Present()) {
    env["description"] = "no environment light: escaping rays see black";
  } else {
    env["file"] = "env.exr";
  }
  if (synth.sky) {
    const SkyWithWindow& sky = *synth.sky;
    env["description"] =
        "distant environment: smooth sky gradient plus a bright rectangular 'window' patch of constant radiance that "
        "replaces the sky inside |azimuth - azimuth_deg| <= width_deg/2 and elev_min_deg <= elevation <= elev_max_deg "
        "(azimuth = atan2(d_y, d_x), elevation = asin(d_z), degrees); rendered from a 512 x 256 equirect map of it";
    env["sky"] = Json{{"zenith", ToJson(sky.zenith)},
                      {"horizon", ToJson(sky.horizon)},
                      {"ground", ToJson(sky.ground)},
                      {"formula",
                       "for a direction d (unit vector, z up): L(d) = horizon + (zenith - horizon) * "
                       "sqrt(d_z) if d_z >= 0, else ground (constant lower hemisphere)"}};
    env["window_patch"] = Json{{"azimuth_deg", sky.window_azimuth_deg},
                               {"width_deg", sky.window_width_deg},
                               {"elev_min_deg", sky.window_elev_min_deg},
                               {"elev_max_deg", sky.window_elev_max_deg},
                               {"radiance", ToJson(sky.window_radiance)}};
  }
  if (!scene.environment.lobes.empty()) {
    env["description"] = "distant environment given as spherical Gaussians: L(d) = sum mu * exp(lambda (d.p - 1))";
    Json lobes = Json::array();
    for (const EnvLobe& lobe : scene.environment.lobes)
      lobes.push_back(
          Json{{"axis", ToJson(lobe.axis)}, {"sharpness", lobe.sharpness}, {"amplitude", ToJson(lobe.amplitude)}});
    env["sg_lobes"] = lobes;
  }
  doc["environment"] = env;
  Json emitters = Json::array();
  for (size_t i = 0; i < scene.sphere_lights.size(); ++i) {
    const SphereLight& l = scene.sphere_lights[i];
    emitters.push_back(
        Json{{"name", "bulb_" + std::to_string(i)},
             {"shape", "sphere"},
             {"center", ToJson(l.center)},
             {"radius", l.radius},
             {"radiance", ToJson(l.radiance)},
             {"emits", "all directions (uniform radiance over its surface)"},
             {"visible_in_images", true},
             {"inside_aabb", true},
             {"note", "stands on a dark pole (radius 5 mm) with a round base (radius 45 mm, 12 mm high)"}});
  }
  for (size_t i = 0; i < scene.rectangle_lights.size(); ++i) {
    const RectangleLight& l = scene.rectangle_lights[i];
    emitters.push_back(Json{{"name", "panel_" + std::to_string(i)},
                            {"shape", "rectangle"},
                            {"center", ToJson(l.center)},
                            {"size", Json::array({2 * l.half_u, 2 * l.half_v})},
                            {"normal", ToJson(Cross(l.u_axis, l.v_axis))},
                            {"u_axis", ToJson(l.u_axis)},
                            {"v_axis", ToJson(l.v_axis)},
                            {"radiance", ToJson(l.radiance)},
                            {"emits", l.two_sided ? "both sides" : "front side only (towards +normal)"},
                            {"visible_in_images", true},
                            {"inside_aabb", true},
                            {"note", "its back is black; on a dark pole with a round base"}});
  }
  for (size_t i = 0; i < scene.box_lights.size(); ++i) {
    const BoxLight& l = scene.box_lights[i];
    emitters.push_back(Json{{"name", "glow_cube_" + std::to_string(i)},
                            {"shape", "box"},
                            {"center", ToJson(l.center)},
                            {"size", ToJson(l.half_size * 2.0f)},
                            {"yaw_deg", l.yaw_rad / kDeg},
                            {"radiance", ToJson(l.radiance)},
                            {"emits", "all faces"},
                            {"visible_in_images", true},
                            {"inside_aabb", true}});
  }
  doc["emitters"] = emitters;
  doc["note"] =
      "Emitters have constant radiance and do not reflect; nothing else emits. Escaping camera rays always "
      "see black. Scene: " +
      synth.description + ".";
  return doc;
}

Dataset MakeDataset(const SynthScene& synth, const CameraIntrinsics& camera, const std::vector<Pose>& poses,
                    const std::string& folder) {
  Dataset dataset;
  dataset.camera = camera;
  dataset.aabb = synth.aabb;
  for (size_t i = 0; i < poses.size(); ++i) {
    DatasetFrame frame;
    frame.file_path = Numbered(folder + "/r_", static_cast<int>(i), ".exr");
    frame.T_world_camera = poses[i];
    dataset.frames.push_back(frame);
  }
  return dataset;
}

// What every part of the dataset is rendered from: the scene, its cameras and the render settings.
struct SynthPlan {
  SynthScene synth;
  CameraIntrinsics camera;
  std::vector<Pose> train, test;
  Dataset train_set;     // the training views' file names and poses
  RenderOptions render;  // train and test views; insert renders and probes change the spp
};

// The progress log, with work counted in pixel-samples so that the ETA weighs each render by its spp.
class WorkMeter {
 public:
  WorkMeter(const SynthOptions& options, size_t n_objects) : progress_("synth " + options.scene, 1000) {
    view_cost_ = static_cast<double>(options.width) * options.height;
    total_ = view_cost_ * options.spp * (options.views + options.test_views) +
             view_cost_ * options.insert_spp * options.test_views * (1 + n_objects) +
             static_cast<double>(kEnvWidth) * kEnvHeight * options.probe_spp * n_objects;
  }
  void View(int spp) { Advance(view_cost_ * spp); }
  void Probe(int spp) { Advance(static_cast<double>(kEnvWidth) * kEnvHeight * spp); }
  void Finish(const std::string& line) { progress_.Finish(line); }

 private:
  void Advance(double cost) {
    done_ += cost;
    progress_.Update(static_cast<size_t>(std::min(1000.0, 1000.0 * done_ / total_)));
  }
  Progress progress_;
  double view_cost_ = 0, total_ = 0, done_ = 0;
};

SynthPlan MakePlan(const SynthOptions& options) {
  SynthPlan plan;
  plan.synth = MakeSynthScene(options.scene, options.seed);
  plan.camera = SynthCamera(options.width, options.height);
  plan.train = HemisphereCameras(options.views, options.seed, 1, plan.synth.aabb);
  plan.test = HemisphereCameras(options.test_views, options.seed, 2, plan.synth.aabb);
  plan.train_set = MakeDataset(plan.synth, plan.camera, plan.train, "train");
  plan.render.spp = options.spp;
  plan.render.bounce = options.bounce;
  plan.render.seed = options.seed;
  return plan;
}

// The small files first, so that a folder is usable for its metadata at once.
void WriteMetadata(const std::string& dir, const SynthPlan& plan) {
  WriteDataset(dir + "/transforms_train.json", plan.train_set);
  WriteDataset(dir + "/transforms.json", plan.train_set);
  WriteDataset(dir + "/transforms_test.json", MakeDataset(plan.synth, plan.camera, plan.test, "test"));
  WriteBoard(dir + "/board.json", plan.synth.board);
  WriteJsonFile(dir + "/lights.json", LightsJson(plan.synth));
  WriteExrRgb(dir + "/env.exr", RenderEnvironment(plan.synth.scene, kEnvWidth, kEnvHeight, 4), ExrPixelType::kFloat);
}

// train/ and test/ views and the contact sheet of the first training views; returns the images written.
int WriteTrainTestViews(const std::string& dir, const SynthOptions& options, const SynthPlan& plan, WorkMeter& meter) {
  int images = 0;
  std::vector<ImageF> sheet_images;
  for (int i = 0; i < options.views; ++i) {
    ImageF image = RenderView(plan.synth.scene, plan.camera, plan.train[i], plan.render, static_cast<uint64_t>(i));
    WriteExrRgb(dir + "/" + plan.train_set.frames[i].file_path, image);
    if (static_cast<int>(sheet_images.size()) < options.contact_sheet_views) sheet_images.push_back(std::move(image));
    ++images;
    meter.View(options.spp);
  }
  for (int i = 0; i < options.test_views; ++i) {
    const ImageF image =
        RenderView(plan.synth.scene, plan.camera, plan.test[i], plan.render, kTestStream + static_cast<uint64_t>(i));
    WriteExrRgb(dir + Numbered("/test/r_", i, ".exr"), image);
    ++images;
    meter.View(options.spp);
  }
  if (!sheet_images.empty()) WriteImage8(dir + "/contact_sheet.png", ContactSheet(sheet_images, 4));
  return images;
}

// objects/NAME.obj and NAME.json (the material with its bounds and counts) and insert/NAME/pose.json.
void WriteObjectFiles(const std::string& dir, const InsertObject& object) {
  const std::string mesh_path = dir + "/objects/" + object.name + ".obj";
  WriteMeshObj(mesh_path, object.mesh);
  Material material = object.material;
  material.mesh = mesh_path;
  material.brdf =
      "simplified Disney: Lambert diffuse (1 - metallic) albedo / pi plus GGX specular (alpha = roughness^2, "
      "Smith G, Schlick Fresnel), F0 = mix(f0, albedo, metallic)";
  const Bounds bounds = ComputeBounds(object.mesh);
  material.bbox_min = bounds.min;
  material.bbox_max = bounds.max;
  material.center_local = Vec3{0, 0, 0};
  material.n_vertices = static_cast<long long>(object.mesh.VertexCount());
  material.n_triangles = static_cast<long long>(object.mesh.TriangleCount());
  WriteMaterial(dir + "/objects/" + object.name + ".json", material);
  ObjectPlacement placement = object.placement;
  placement.object = object.name;
  placement.mesh = "objects/" + object.name + ".obj (relative to the scene directory)";
  WriteObjectPlacement(dir + "/insert/" + object.name + "/pose.json", placement);
}

// insert/: the test views without any object (bg), then per object its files, the probe at its
// centre without it, and the test views with it (rgb, mask, depth). The renders with and without
// an object use the same random numbers. Returns the images written; `frames` gets each
// render's seconds.
int WriteInsertGroundTruth(const std::string& dir, const SynthOptions& options, const SynthPlan& plan, WorkMeter& meter,
                           Json& frames) {
  MakeDirectories(dir + "/insert");
  MakeDirectories(dir + "/objects");
  RenderOptions insert_render = plan.render;
  insert_render.spp = options.insert_spp;
  int images = 0;
  for (int i = 0; i < options.test_views; ++i) {
    const double t0 = Now();
    WriteExrRgb(dir + Numbered("/insert/bg_", i, ".exr"),
                RenderView(plan.synth.scene, plan.camera, plan.test[i], insert_render,
                           kInsertStream + static_cast<uint64_t>(i)));
    frames[Numbered("bg_", i, ".exr")] = Now() - t0;
    ++images;
    meter.View(options.insert_spp);
  }
  for (size_t k = 0; k < plan.synth.objects.size(); ++k) {
    const InsertObject& object = plan.synth.objects[k];
    const std::string object_dir = dir + "/insert/" + object.name;
    MakeDirectories(object_dir);
    WriteObjectFiles(dir, object);
    RenderOptions probe_render = plan.render;
    probe_render.spp = options.probe_spp;
    WriteExrRgb(object_dir + "/probe.exr",
                RenderProbe(plan.synth.scene, *object.placement.center_world, kEnvWidth, kEnvHeight, probe_render),
                ExrPixelType::kFloat);
    meter.Probe(options.probe_spp);
    const Scene with_object = SceneWithObject(plan.synth, static_cast<int>(k));
    for (int i = 0; i < options.test_views; ++i) {
      const double t0 = Now();
      WriteExrRgb(
          object_dir + Numbered("/rgb_", i, ".exr"),
          RenderView(with_object, plan.camera, plan.test[i], insert_render, kInsertStream + static_cast<uint64_t>(i)));
      frames[object.name + Numbered("/rgb_", i, ".exr")] = Now() - t0;
      ImageF depth;
      Image8 mask;
      RenderFirstHit(with_object, plan.camera, plan.test[i], static_cast<int>(k), depth, mask);
      WriteImage8(object_dir + Numbered("/mask_", i, ".png"), mask);
      WriteExr(object_dir + Numbered("/depth_", i, ".exr"), depth, {"Y"}, ExrPixelType::kFloat);
      images += 2;
      meter.View(options.insert_spp);
    }
  }
  return images;
}

// insert/timing.json: the insert renders' seconds and how they were made.
void WriteInsertTiming(const std::string& dir, const SynthOptions& options, const Json& frames, double seconds) {
  Json timing = Json::object();
  timing["frames"] = frames;
  timing["device"] = "CPU";
  timing["threads"] = ThreadCount();
  timing["resolution"] = Json::array({options.width, options.height});
  timing["samples_per_pixel"] = options.insert_spp;
  timing["train_test_samples_per_pixel"] = options.spp;
  timing["probe_samples_per_pixel"] = options.probe_spp;
  timing["bounce"] = options.bounce;
  timing["engine"] = "nerfar synth (next-event estimation, box pixel filter)";
  timing["total_seconds"] = seconds;
  WriteJsonFile(dir + "/insert/timing.json", timing);
}

}  // namespace

std::vector<std::string> SynthOptions::Validate() const {
  std::vector<std::string> p;
  const std::vector<std::string> names = SynthSceneNames();
  if (std::find(names.begin(), names.end(), scene) == names.end()) {
    std::string known;
    for (const std::string& n : names) known += (known.empty() ? "" : ", ") + n;
    p.push_back("scene: '" + scene + "' (expected one of " + known + ")");
  }
  if (output_dir.empty()) p.push_back("output_dir: empty (expected a folder)");
  if (width < 8 || width > 8192 || height < 8 || height > 8192)
    p.push_back("res: " + std::to_string(width) + "x" + std::to_string(height) + " (expected 8..8192 each)");
  if (views < 1 || views > 100000) p.push_back("views: " + std::to_string(views) + " (expected 1..100000)");
  if (test_views < 1 || test_views > 100000)
    p.push_back("test_views: " + std::to_string(test_views) + " (expected 1..100000)");
  for (auto [name, value] : {std::pair{"spp", spp}, {"insert_spp", insert_spp}, {"probe_spp", probe_spp}})
    if (value < 1 || value > 65536)
      p.push_back(std::string(name) + ": " + std::to_string(value) + " (expected 1..65536)");
  if (contact_sheet_views < 0 || contact_sheet_views > 1000)
    p.push_back("contact_sheet_views: " + std::to_string(contact_sheet_views) + " (expected 0..1000)");
  return p;
}

bool SynthOptions::ApplyPreset(const std::string& name) {
  if (name == "fast") {
    spp = 4, insert_spp = 16, probe_spp = 4;
  } else if (name == "balanced") {
    spp = 16, insert_spp = 64, probe_spp = 16;
  } else if (name == "accurate") {
    spp = 64, insert_spp = 256, probe_spp = 64;
  } else {
    return false;
  }
  return true;
}

CameraIntrinsics SynthCamera(int width, int height) {
  CameraIntrinsics camera;
  camera.width = width;
  camera.height = height;
  camera.fx = camera.fy = 0.5 * width / std::tan(30.0 * kDeg);
  camera.cx = 0.5 * width;
  camera.cy = 0.5 * height;
  return camera;
}

std::vector<Pose> HemisphereCameras(int count, uint64_t seed, uint64_t stream, const Aabb& aabb) {
  Rng rng(seed, stream ^ 0xca3e7a5ull, 0, 0);
  // Stratified elevations in a shuffled order so that any prefix covers the range.
  std::vector<int> strata(count);
  for (int i = 0; i < count; ++i) strata[i] = i;
  for (int i = count - 1; i > 0; --i) std::swap(strata[i], strata[static_cast<int>(rng.Uniform(0, i + 1))]);
  const double golden = kPi * (3.0 - std::sqrt(5.0));
  const double azimuth0 = rng.Uniform(0, 2 * kPi);
  std::vector<Pose> poses;
  for (int i = 0; i < count; ++i) {
    for (int attempt = 0;; ++attempt) {
      NERFAR_CHECK_LT(attempt, 1000);
      const double elevation = (15.0 + 55.0 * (strata[i] + rng.UniformDouble()) / count) * kDeg;
      const double azimuth = azimuth0 + golden * i + rng.Uniform(-0.1, 0.1);
      const double distance = rng.Uniform(0.8, 1.3);
      const Vec3 target{rng.Uniform(-0.03, 0.03), rng.Uniform(-0.03, 0.03), rng.Uniform(0.0, 0.03)};
      const Vec3 eye = target + Vec3{std::cos(elevation) * std::cos(azimuth), std::cos(elevation) * std::sin(azimuth),
                                     std::sin(elevation)} *
                                    distance;
      const bool inside = eye.x > aabb.min.x && eye.x < aabb.max.x && eye.y > aabb.min.y && eye.y < aabb.max.y &&
                          eye.z > aabb.min.z && eye.z < aabb.max.z;
      if (inside) continue;
      poses.push_back(LookAt(eye, target));
      break;
    }
  }
  return poses;
}

Image8 ContactSheet(const std::vector<ImageF>& images, int columns) {
  NERFAR_CHECK(!images.empty() && columns > 0);
  const int w = images[0].width, h = images[0].height, gap = 4;
  const int cols = std::min<int>(columns, static_cast<int>(images.size()));
  const int rows = (static_cast<int>(images.size()) + cols - 1) / cols;
  Image8 sheet(cols * w + (cols - 1) * gap, rows * h + (rows - 1) * gap, 3, 255);
  for (size_t k = 0; k < images.size(); ++k) {
    NERFAR_CHECK(images[k].width == w && images[k].height == h);
    // Expose so that the 99th percentile maps to 2 (Reinhard shows it at 2/3).
    const Image8 tile = ToneMapToDisplay(images[k], 2.0f * ExposureForPercentile(images[k]));
    const int ox = static_cast<int>(k % cols) * (w + gap), oy = static_cast<int>(k / cols) * (h + gap);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < 3; ++c) sheet.at(ox + x, oy + y, c) = tile.at(x, y, std::min(c, tile.channels - 1));
  }
  return sheet;
}

SynthReport WriteSynthDataset(const SynthOptions& options) {
  {
    Problems problems("nerfar synth");
    for (const std::string& p : options.Validate()) problems.Add("", p);
    problems.ThrowIfAny();
  }
  const double start = Now();
  SynthReport report;
  const std::string dir = options.output_dir;
  MakeDirectories(dir + "/train");
  MakeDirectories(dir + "/test");
  const SynthPlan plan = MakePlan(options);
  WriteMetadata(dir, plan);
  WorkMeter meter(options, options.insert ? plan.synth.objects.size() : 0);
  report.images += WriteTrainTestViews(dir, options, plan, meter);
  report.seconds_train_test = Now() - start;
  if (options.insert) {
    const double insert_start = Now();
    Json frames = Json::object();
    report.images += WriteInsertGroundTruth(dir, options, plan, meter, frames);
    report.seconds_insert = Now() - insert_start;
    WriteInsertTiming(dir, options, frames, report.seconds_insert);
  }
  report.seconds_total = Now() - start;
  meter.Finish(std::to_string(report.images) + " images in " + FormatDuration(report.seconds_total));
  return report;
}

}  // namespace nerfar::synth
