#include "app/live/report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>

#include "app/live/scene.h"
#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "calib/core/image_io.h"
#include "calib/core/log.h"
#include "calib/core/media.h"
#include "calib/core/random.h"
#include "render/sg/sg.h"

namespace nerfar {

namespace fs = std::filesystem;

namespace {

Json Number(double v) { return std::isfinite(v) ? Json(v) : Json(nullptr); }

Json PoseJson(const Pose& pose) {
  const Mat3& r = pose.rotation;
  Json rot = Json::array();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) rot.push_back(r(i, j));
  return {{"t", {pose.translation.x, pose.translation.y, pose.translation.z}}, {"R", rot}};
}

Pose PoseFromJson(const Json& j) {
  Pose pose;
  for (int i = 0; i < 3; ++i) pose.translation[i] = j.at("t").at(i).get<double>();
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) pose.rotation(i, k) = j.at("R").at(i * 3 + k).get<double>();
  return pose;
}

std::string ReadLoad() {
  std::ifstream file("/proc/loadavg");
  std::string a, b, c;
  if (!(file >> a >> b >> c)) return "";
  return a + " " + b + " " + c + " (1, 5, 15 min)";
}

// RMS of the second differences of a track over runs of consecutive
// measured frames, divided by √6: for a smooth path plus white noise of
// standard deviation σ, E[(x₋ − 2x₀ + x₊)²] = 6σ², so this estimates σ
// (the path's own curvature at 30 fps adds ~a·dt², well under a millimetre).
struct Jitter {
  double position_mm = NAN, rotation_deg = NAN;
  int triples = 0;
};

Jitter TrackJitter(const std::vector<Json>& frames) {
  Jitter j;
  double sum_p = 0, sum_r = 0;
  for (size_t k = 1; k + 1 < frames.size(); ++k) {
    const Json &a = frames[k - 1], &b = frames[k], &c = frames[k + 1];
    if (!a.value("measured", false) || !b.value("measured", false) || !c.value("measured", false)) continue;
    if (b.at("index").get<long long>() != a.at("index").get<long long>() + 1 ||
        c.at("index").get<long long>() != b.at("index").get<long long>() + 1)
      continue;
    const Pose pa = PoseFromJson(a.at("pose")), pb = PoseFromJson(b.at("pose")), pc = PoseFromJson(c.at("pose"));
    const Vec3 d2 = pa.translation - pb.translation * 2.0 + pc.translation;
    sum_p += Dot(d2, d2);
    // Change of the frame-to-frame rotation (angular acceleration × dt²).
    const Vec3 w0 = AxisAngleFromRotation(pa.rotation.Transposed() * pb.rotation);
    const Vec3 w1 = AxisAngleFromRotation(pb.rotation.Transposed() * pc.rotation);
    const Vec3 dw = w1 - w0;
    sum_r += Dot(dw, dw);
    ++j.triples;
  }
  if (j.triples > 0) {
    j.position_mm = std::sqrt(sum_p / j.triples / 6.0) * 1e3;
    j.rotation_deg = std::sqrt(sum_r / j.triples / 6.0) * 180 / kPi;
  }
  return j;
}

// SSDF error estimate: the field against brute-force ray casting of its mesh
// at `samples` random (point, direction) pairs on shells 1.1-2 bounding radii
// from the centre (where shadows and self-shadows are queried).
Json SsdfErrorEstimate(const LiveObjectAsset& asset, int samples) {
  if (!asset.field) return {{"object", asset.name}, {"note", "no .ssdf (no shadows)"}};
  const SsdfField& field = *asset.field;
  const SsdReference reference(asset.mesh);
  Rng rng(7, 0x55df, 0, 0);
  double sum = 0, worst = 0;
  for (int i = 0; i < samples; ++i) {
    const double z = rng.Uniform(-1, 1), phi = rng.Uniform(0, 2 * kPi), s = std::sqrt(1 - z * z);
    const Vec3 dir_out{s * std::cos(phi), s * std::sin(phi), z};
    const Vec3 x = field.center() + dir_out * (field.radius() * rng.Uniform(1.1, 2.0));
    const double z2 = rng.Uniform(-1, 1), phi2 = rng.Uniform(0, 2 * kPi), s2 = std::sqrt(1 - z2 * z2);
    const Vec3 d{s2 * std::cos(phi2), s2 * std::sin(phi2), z2};
    // 24 great circles at 0.02 rad steps: the reference itself is good to
    // about a step where the direction is blocked (exact where it misses).
    const double truth = reference.Ssd(x, d, 24, 0.02);
    const double value = field.Query(Vec3f(x), Vec3f(d));
    const double e = std::abs(value - truth);
    sum += e * e;
    worst = std::max(worst, e);
  }
  return {{"object", asset.name},
          {"samples", samples},
          {"rms_deg", std::sqrt(sum / samples) * 180 / kPi},
          {"max_deg", worst * 180 / kPi},
          {"note", "field vs brute-force ray casting at points 1.1-2 radii from the centre, random directions"}};
}

Json EnvironmentJson(const std::string& env_path) {
  if (env_path.empty()) return {{"note", "no env.json (no distant light)"}};
  const EnvLight env = ReadEnvLight(env_path);
  const Vec3 integral = Integral(env.lobes);
  return {{"file", env_path},
          {"lobes", env.lobes.size()},
          {"negligible", env.negligible},
          {"env_to_near_surface", env.env_to_near_surface},
          {"env_to_near_center", env.env_to_near_center},
          {"radiant_integral_luminance", 0.2126 * integral.x + 0.7152 * integral.y + 0.0722 * integral.z}};
}

Json CalibrationJson(const std::string& camera_path) {
  if (camera_path.empty())
    return {{"rms_px", nullptr}, {"note", "the source's own intrinsics (synthetic camera: exact, not calibrated)"}};
  const CameraFile file = ReadCameraFile(camera_path);
  if (!file.calibration)
    return {{"file", camera_path},
            {"rms_px", nullptr},
            {"note", "no calibration record in the file (exact or external intrinsics)"}};
  const CalibrationRecord& c = *file.calibration;
  return {{"file", camera_path},
          {"rms_px", c.rms_px},
          {"views_used", c.views_used},
          {"views_rejected", c.views_rejected},
          {"coverage", c.coverage}};
}

std::string NewestSession(const std::string& scene_dir) {
  std::error_code error;
  const fs::path sessions = fs::path(scene_dir) / "sessions";
  std::string newest;
  if (!fs::is_directory(sessions, error)) return newest;
  for (const auto& entry : fs::directory_iterator(sessions, error))
    if (fs::is_regular_file(entry.path() / "session.json", error) && entry.path().string() > newest)
      newest = entry.path().string();
  return newest;
}

// A number for the page, "n/a" when not available.
std::string Fmt(double v, const char* format) {
  if (!std::isfinite(v)) return "n/a";
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

}  // namespace

double PercentileOf(std::vector<double> values, double q) {
  values.erase(std::remove_if(values.begin(), values.end(), [](double v) { return !std::isfinite(v); }), values.end());
  if (values.empty()) return NAN;
  std::sort(values.begin(), values.end());
  const double pos = q * (values.size() - 1);
  const size_t lo = static_cast<size_t>(std::floor(pos));
  const size_t hi = std::min(values.size() - 1, lo + 1);
  return values[lo] + (values[hi] - values[lo]) * (pos - lo);
}

void WriteSession(const std::string& session_dir, const SessionInfo& info, const LivePipeline& pipeline) {
  const LiveCounters c = pipeline.counters();
  Json frames = Json::array();
  for (const LiveFrameRecord& r : pipeline.records()) {
    Json f = {{"index", r.index},
              {"state", TrackingStateName(r.state)},
              {"measured", r.measured},
              {"t_s", r.t_s},
              {"latency_ms", r.latency_ms >= 0 ? Json(r.latency_ms) : Json(nullptr)}};
    if (r.has_pose) f["pose"] = PoseJson(r.T_world_camera);
    if (r.T_world_camera_true) f["true_pose"] = PoseJson(*r.T_world_camera_true);
    Json ms = Json::object();
    for (const auto& [name, value] : StageList(r.times)) ms[name] = value;
    f["ms"] = ms;
    if (r.light_fit_loss >= 0) f["light_fit_loss"] = r.light_fit_loss;
    // The inserter's caches at work: κ values computed this frame (cache
    // misses) and whether the per-vertex self-shadow was rebuilt.
    f["kappa_evaluated"] = r.times.insert.kappa_evaluated;
    f["gamma_recomputed"] = r.times.insert.gamma_recomputed;
    f["lights_recomputed"] = r.times.insert.lights_recomputed;
    frames.push_back(f);
  }
  Json objects = Json::array();
  for (size_t i = 0; i < pipeline.object_count(); ++i) {
    const LiveObjectState o = pipeline.object(i);
    Json j = {{"file", i < info.objects.size() ? info.objects[i] : std::string()},
              {"placed", o.placed},
              {"yaw_rad", o.yaw_rad},
              {"scale", o.scale},
              {"material",
               {{"base_color", {o.material.base_color.x, o.material.base_color.y, o.material.base_color.z}},
                {"roughness", o.material.roughness},
                {"metallic", o.material.metallic}}}};
    if (o.placed) {
      j["anchor_world"] = {o.anchor_world.x, o.anchor_world.y, o.anchor_world.z};
      j["T_world_object"] = PoseJson(pipeline.ObjectPose(i, o));
    }
    if (i == 0 && info.auto_placed_frame >= 0) j["auto_placed_frame"] = info.auto_placed_frame;
    objects.push_back(j);
  }
  Json errors = Json::array();
  for (const LiveError& e : pipeline.errors())
    errors.push_back({{"frame", e.frame >= 0 ? Json(e.frame) : Json(nullptr)}, {"stage", e.stage}, {"what", e.what}});
  Json session = {{"format", "nerfar-session"},
                  {"version", 1},
                  {"scene", info.scene_dir},
                  {"source", info.source},
                  {"camera", info.camera_path},
                  {"objects", info.objects},
                  {"placements", objects},
                  {"mode", info.mode},
                  {"preset", pipeline.preset()},
                  {"wall_s", info.wall_s},
                  {"threads", info.threads},
                  {"load", info.load.empty() ? ReadLoad() : info.load},
                  {"counters",
                   {{"captured", c.captured},
                    {"dropped_before_process", c.dropped_before_process},
                    {"processed", c.processed},
                    {"dropped_before_display", c.dropped_before_display},
                    {"displayed", c.displayed},
                    {"source_errors", c.source_errors},
                    {"reconnects", c.reconnects},
                    {"frame_errors", c.frame_errors},
                    {"output_errors", c.output_errors}}},
                  {"errors", errors},
                  {"frames", frames}};
  MakeDirectories(session_dir);
  WriteJsonFile((fs::path(session_dir) / "session.json").string(), session);
}

Json BuildReport(const std::string& dir, std::string* report_dir) {
  std::error_code error;
  if (!fs::is_directory(dir, error))
    ThrowInputError(dir, "not a folder (expected a session folder with session.json, or a SCENE folder)");
  std::string session_dir;
  std::string scene_dir;
  if (fs::is_regular_file(fs::path(dir) / "session.json", error)) {
    session_dir = dir;
  } else {
    scene_dir = dir;
    session_dir = NewestSession(dir);
  }
  Json session;
  if (!session_dir.empty()) {
    session = ReadJsonFile((fs::path(session_dir) / "session.json").string());
    if (!session.is_object() || session.value("format", "") != "nerfar-session")
      ThrowInputError(session_dir + "/session.json", "not a nerfar session (expected \"format\": \"nerfar-session\")");
    if (scene_dir.empty()) scene_dir = session.value("scene", "");
  }
  if (report_dir) *report_dir = session_dir.empty() ? dir : session_dir;
  Json report = {{"format", "nerfar-report"}, {"scene", scene_dir}, {"session", session_dir}};

  // Scene items.
  LiveScenePaths paths;
  if (!scene_dir.empty() && fs::is_directory(scene_dir, error)) paths = FindLiveScene(scene_dir);
  std::string camera_path = session.is_object() ? session.value("camera", "") : paths.camera;
  report["calibration"] = CalibrationJson(camera_path);
  report["environment"] = EnvironmentJson(paths.env);
  std::vector<std::string> objects = paths.objects;
  if (session.is_object() && session.contains("objects")) objects = session["objects"].get<std::vector<std::string>>();
  Json ssdf = Json::array();
  for (const std::string& o : objects) {
    try {
      ssdf.push_back(SsdfErrorEstimate(LoadLiveObject(o), 64));
    } catch (const std::exception& e) {
      ssdf.push_back({{"object", o}, {"note", std::string("not evaluated: ") + e.what()}});
    }
  }
  report["ssdf_error"] = ssdf;
  std::vector<std::string> inputs = {camera_path, paths.env};
  if (!session_dir.empty()) inputs.push_back((fs::path(session_dir) / "session.json").string());
  inputs.insert(inputs.end(), objects.begin(), objects.end());
  report["inputs"] = inputs;
  if (!session.is_object()) {
    report["note"] = "no session: scene items only (run `nerfar live` for tracking, light and timing figures)";
    return report;
  }

  // Tracking.
  std::vector<Json> frames;
  for (const Json& f : session.at("frames")) frames.push_back(f);
  int counts[3] = {0, 0, 0}, loss_events = 0;
  std::string previous;
  double err_t = 0, err_r = 0;
  std::vector<double> errors_mm;
  int err_n = 0;
  std::vector<double> fit_losses, latencies;
  std::map<std::string, std::vector<double>> stages;
  for (const Json& f : frames) {
    const std::string state = f.at("state").get<std::string>();
    counts[state == "tracking" ? 0 : (state == "recovering" ? 1 : 2)]++;
    if (state == "lost" && !previous.empty() && previous != "lost") ++loss_events;
    previous = state;
    if (f.contains("pose") && f.contains("true_pose") && state != "lost") {
      const Pose a = PoseFromJson(f["pose"]), b = PoseFromJson(f["true_pose"]);
      const Vec3 d = a.translation - b.translation;
      err_t += Dot(d, d);
      errors_mm.push_back(Length(d) * 1e3);
      const double angle = RotationAngleBetween(a.rotation, b.rotation);
      err_r += angle * angle;
      ++err_n;
    }
    if (f.contains("light_fit_loss")) fit_losses.push_back(f["light_fit_loss"].get<double>());
    if (!f.at("latency_ms").is_null()) latencies.push_back(f["latency_ms"].get<double>());
    for (const auto& [name, value] : f.at("ms").items()) stages[name].push_back(value.get<double>());
  }
  const Jitter jitter = TrackJitter(frames);
  const double n = std::max<size_t>(1, frames.size());
  report["tracking"] = {{"frames", frames.size()},
                        {"tracking", counts[0]},
                        {"recovering", counts[1]},
                        {"lost", counts[2]},
                        {"lost_fraction", counts[2] / n},
                        {"loss_events", loss_events},
                        {"jitter_mm", Number(jitter.position_mm)},
                        {"jitter_deg", Number(jitter.rotation_deg)},
                        {"jitter_note", "RMS second difference over consecutive measured frames / sqrt(6)"},
                        {"error_vs_truth_mm", err_n ? Json(std::sqrt(err_t / err_n) * 1e3) : Json(nullptr)},
                        {"error_vs_truth_median_mm", Number(PercentileOf(errors_mm, 0.5))},
                        {"error_vs_truth_deg", err_n ? Json(std::sqrt(err_r / err_n) * 180 / kPi) : Json(nullptr)}};
  report["light_fit"] = {
      {"refits", fit_losses.size()},
      {"median_loss", Number(PercentileOf(fit_losses, 0.5))},
      {"max_loss", fit_losses.empty() ? Json(nullptr) : Json(*std::max_element(fit_losses.begin(), fit_losses.end()))},
      {"note", "SG fit loss of object 0's incident light (render/sg SgFitLoss, per sr, normalised)"}};
  const Json& counters = session.at("counters");
  const double wall = session.value("wall_s", 0.0);
  Json stage_json = Json::object();
  for (const auto& [name, values] : stages)
    stage_json[name] = {{"median_ms", Number(PercentileOf(values, 0.5))},
                        {"p90_ms", Number(PercentileOf(values, 0.9))}};
  report["performance"] = {
      {"mode", session.value("mode", "")},
      {"wall_s", wall},
      {"threads", session.value("threads", 0)},
      {"load", session.value("load", "")},
      {"displayed_fps", wall > 0 ? Json(counters.value("displayed", 0) / wall) : Json(nullptr)},
      {"captured_fps", wall > 0 ? Json(counters.value("captured", 0) / wall) : Json(nullptr)},
      {"latency_ms", {{"median", Number(PercentileOf(latencies, 0.5))}, {"p90", Number(PercentileOf(latencies, 0.9))}}},
      {"counters", counters},
      {"stages", stage_json}};
  // What the loop went on after (a failing frame, camera or recording).
  report["errors"] = {{"frames", counters.value("frame_errors", 0)},
                      {"source", counters.value("source_errors", 0)},
                      {"reconnects", counters.value("reconnects", 0)},
                      {"outputs", counters.value("output_errors", 0)},
                      {"recent", session.value("errors", Json::array())}};
  return report;
}

void WriteReport(const Json& report, const std::string& report_dir) {
  MakeDirectories(report_dir);
  WriteJsonFile((fs::path(report_dir) / "report.json").string(), report);
  // The text of the page, also printed.
  std::vector<std::string> lines;
  char buf[256];
  const auto num = [](const Json& j, const char* key) {
    return j.contains(key) && j[key].is_number() ? j[key].get<double>() : NAN;
  };
  lines.push_back("nerfar session report  " + report.value("session", std::string()));
  lines.push_back("scene " + report.value("scene", std::string()));
  std::snprintf(buf, sizeof buf, "calibration RMS      %s px",
                Fmt(num(report["calibration"], "rms_px"), "%.3f").c_str());
  lines.push_back(std::string(buf) + (report["calibration"].contains("note")
                                          ? "  (" + report["calibration"]["note"].get<std::string>() + ")"
                                          : ""));
  if (report.contains("tracking")) {
    const Json& t = report["tracking"];
    std::snprintf(buf, sizeof buf,
                  "tracking             %d frames, lost %.1f %% (%d loss events), jitter %s mm / %s deg",
                  t["frames"].get<int>(), 100 * num(t, "lost_fraction"), t["loss_events"].get<int>(),
                  Fmt(num(t, "jitter_mm"), "%.2f").c_str(), Fmt(num(t, "jitter_deg"), "%.3f").c_str());
    lines.push_back(buf);
    std::snprintf(buf, sizeof buf, "pose vs truth        %s mm RMS (median %s mm), %s deg RMS",
                  Fmt(num(t, "error_vs_truth_mm"), "%.2f").c_str(),
                  Fmt(num(t, "error_vs_truth_median_mm"), "%.2f").c_str(),
                  Fmt(num(t, "error_vs_truth_deg"), "%.3f").c_str());
    lines.push_back(buf);
  }
  if (report.contains("light_fit")) {
    std::snprintf(buf, sizeof buf, "light fit            loss %.4f median over %d refits",
                  num(report["light_fit"], "median_loss"), report["light_fit"]["refits"].get<int>());
    lines.push_back(buf);
  }
  const Json& env = report["environment"];
  std::snprintf(buf, sizeof buf, "environment energy   env/near %.3f at surfaces, %.3f at centre, %d lobes%s",
                num(env, "env_to_near_surface"), num(env, "env_to_near_center"),
                env.contains("lobes") ? env["lobes"].get<int>() : 0,
                env.value("negligible", false) ? " (negligible: dropped)" : "");
  lines.push_back(buf);
  for (const Json& s : report["ssdf_error"]) {
    std::snprintf(buf, sizeof buf, "SSDF error           %s: %.2f deg RMS, %.1f deg max", s.value("object", "").c_str(),
                  num(s, "rms_deg"), num(s, "max_deg"));
    lines.push_back(buf);
  }
  if (report.contains("performance")) {
    const Json& p = report["performance"];
    std::snprintf(buf, sizeof buf,
                  "fps                  %.1f displayed, %.1f captured; latency %.0f ms median, %.0f p90 (%s)",
                  num(p, "displayed_fps"), num(p, "captured_fps"), num(p["latency_ms"], "median"),
                  num(p["latency_ms"], "p90"), p.value("mode", "").c_str());
    lines.push_back(buf);
    lines.push_back("load " + p.value("load", std::string()) + ", threads " + std::to_string(p.value("threads", 0)));
    if (report.contains("errors")) {
      const Json& e = report["errors"];
      std::snprintf(buf, sizeof buf,
                    "errors               %d frames failed, %d source errors (%d reconnections), %d outputs",
                    e.value("frames", 0), e.value("source", 0), e.value("reconnects", 0), e.value("outputs", 0));
      lines.push_back(buf);
    }
    lines.push_back("stage (ms)           median     p90");
    for (const auto& [name, v] : p["stages"].items()) {
      std::snprintf(buf, sizeof buf, "  %-18s %8.2f %8.2f", name.c_str(), num(v, "median_ms"), num(v, "p90_ms"));
      lines.push_back(buf);
    }
  }
  for (const std::string& l : lines) std::printf("%s\n", l.c_str());

  // One page: the last views on top, the text below.
  std::vector<Image8> tiles;
  std::vector<std::string> captions;
  std::error_code error;
  for (const char* name : {"last_ar.png", "last_alongside.png", "last_layers.png"}) {
    const fs::path p = fs::path(report_dir) / name;
    if (!fs::is_regular_file(p, error)) continue;
    try {
      tiles.push_back(ReadImage8(p.string()));
      captions.push_back(fs::path(name).stem().string().substr(5));
    } catch (const std::exception&) {
    }
  }
  const int page_w = 1000;
  Image8 sheet = tiles.empty() ? Image8()
                               : ContactSheet(tiles, static_cast<int>(tiles.size()),
                                              (page_w - 16) / static_cast<int>(tiles.size()), captions);
  const int text_h = 16 * static_cast<int>(lines.size()) + 16;
  Image8 page(page_w, sheet.height + text_h, 3, 24);
  for (int y = 0; y < sheet.height; ++y)
    for (int x = 0; x < std::min(sheet.width, page_w); ++x)
      for (int c = 0; c < 3; ++c) page.at(x, y, c) = sheet.at(x, y, c);
  for (size_t i = 0; i < lines.size(); ++i) DrawText(page, lines[i], 8, sheet.height + 8 + 16 * static_cast<int>(i));
  WriteImage8((fs::path(report_dir) / "report.png").string(), page);
}

}  // namespace nerfar
