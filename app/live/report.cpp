#include "app/live/report.h"

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>

#include "app/live/report_plots.h"
#include "app/live/scene.h"
#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "calib/core/image_io.h"
#include "calib/core/log.h"
#include "calib/core/media.h"
#include "calib/core/random.h"
#include "render/insert/nerf_insert_options.h"
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

// Squared second differences (position m², rotation rad²) at frame k when
// frames k − 1, k, k + 1 are consecutive measured frames; false otherwise.
bool SecondDifference(const std::vector<Json>& frames, size_t k, double& position_sq, double& rotation_sq) {
  if (k == 0 || k + 1 >= frames.size()) return false;
  const Json &a = frames[k - 1], &b = frames[k], &c = frames[k + 1];
  if (!a.value("measured", false) || !b.value("measured", false) || !c.value("measured", false)) return false;
  if (b.at("index").get<long long>() != a.at("index").get<long long>() + 1 ||
      c.at("index").get<long long>() != b.at("index").get<long long>() + 1)
    return false;
  const Pose pa = PoseFromJson(a.at("pose")), pb = PoseFromJson(b.at("pose")), pc = PoseFromJson(c.at("pose"));
  const Vec3 d2 = pa.translation - pb.translation * 2.0 + pc.translation;
  position_sq = Dot(d2, d2);
  // Change of the frame-to-frame rotation (angular acceleration × dt²).
  const Vec3 w0 = AxisAngleFromRotation(pa.rotation.Transposed() * pb.rotation);
  const Vec3 w1 = AxisAngleFromRotation(pb.rotation.Transposed() * pc.rotation);
  const Vec3 dw = w1 - w0;
  rotation_sq = Dot(dw, dw);
  return true;
}

Jitter TrackJitter(const std::vector<Json>& frames) {
  Jitter j;
  double sum_p = 0, sum_r = 0;
  for (size_t k = 1; k + 1 < frames.size(); ++k) {
    double p = 0, r = 0;
    if (!SecondDifference(frames, k, p, r)) continue;
    sum_p += p;
    sum_r += r;
    ++j.triples;
  }
  if (j.triples > 0) {
    j.position_mm = std::sqrt(sum_p / j.triples / 6.0) * 1e3;
    j.rotation_deg = std::sqrt(sum_r / j.triples / 6.0) * 180 / kPi;
  }
  return j;
}

// Stages as the report's plot stacks them (the insertion's six in pairs).
const std::vector<std::pair<std::string, std::vector<std::string>>>& StageGroups() {
  static const std::vector<std::pair<std::string, std::vector<std::string>>> groups = {
      {"track", {"track"}},
      {"expose", {"expose"}},
      {"light+fit", {"light", "fit"}},
      {"raster+shade", {"raster", "shade"}},
      {"occlusion+kappa", {"occlusion", "kappa"}},
      {"views", {"alongside", "layers"}},
      {"display", {"display"}}};
  return groups;
}

// Per-frame series of the session (the report's plots): time, stage groups,
// latency, pose jitter (each frame's second difference / √6, the estimate
// TrackJitter averages), tracking state, light refits; null where a frame
// has no value.
Json SeriesJson(const std::vector<Json>& frames) {
  Json t = Json::array(), latency = Json::array(), jitter = Json::array(), state = Json::array(), refit = Json::array();
  Json stages = Json::object();
  for (const auto& [group, members] : StageGroups()) stages[group] = Json::array();
  for (size_t k = 0; k < frames.size(); ++k) {
    const Json& f = frames[k];
    t.push_back(f.value("t_s", 0.0));
    for (const auto& [group, members] : StageGroups()) {
      double sum = 0;
      for (const std::string& m : members)
        if (f.at("ms").contains(m)) sum += f["ms"][m].get<double>();
      stages[group].push_back(sum);
    }
    latency.push_back(f.at("latency_ms"));
    double p = 0, r = 0;
    jitter.push_back(SecondDifference(frames, k, p, r) ? Json(std::sqrt(p / 6.0) * 1e3) : Json(nullptr));
    state.push_back(f.at("state"));
    refit.push_back(f.contains("light_fit_loss") ? f["light_fit_loss"] : Json(nullptr));
  }
  return {{"t_s", t},       {"stages_ms", stages},    {"latency_ms", latency}, {"jitter_mm", jitter},
          {"state", state}, {"light_fit_loss", refit}};
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
    f["pixels_rewritten"] = r.pixels_rewritten;
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
  const NerfInsertOptions knobs = NerfInsertOptions::Preset(pipeline.preset(), pipeline.options().insert_sets);
  Json session = {{"format", "nerfar-session"},
                  {"version", 1},
                  {"scene", info.scene_dir},
                  {"source", info.source},
                  {"camera", info.camera_path},
                  {"objects", info.objects},
                  {"placements", objects},
                  {"mode", info.mode},
                  {"preset", pipeline.preset()},
                  // The effective options at the end: the preset with --set over it.
                  {"insert_options", Json::parse(knobs.insert.ToJson())},
                  {"nerf_scene_options", Json::parse(knobs.nerf.ToJson())},
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
  report["series"] = SeriesJson(frames);
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

namespace {

using Rows = std::vector<std::pair<std::string, std::string>>;

double Num(const Json& j, const char* key) {
  return j.contains(key) && j[key].is_number() ? j[key].get<double>() : NAN;
}

std::string Printf(const char* format, ...) __attribute__((format(printf, 1, 2)));
std::string Printf(const char* format, ...) {
  char buf[256];
  va_list args;
  va_start(args, format);
  std::vsnprintf(buf, sizeof buf, format, args);
  va_end(args);
  return buf;
}

// The figures table: one (what, value) row per figure, shared by the
// printout, the PNG page and the HTML page.
Rows FigureRows(const Json& report) {
  Rows rows;
  rows.push_back({"session", report.value("session", std::string())});
  rows.push_back({"scene", report.value("scene", std::string())});
  const Json& cal = report["calibration"];
  rows.push_back({"calibration RMS", Fmt(Num(cal, "rms_px"), "%.3f") + " px" +
                                         (cal.contains("note") ? "  (" + cal["note"].get<std::string>() + ")" : "")});
  if (report.contains("tracking")) {
    const Json& t = report["tracking"];
    rows.push_back(
        {"tracking", Printf("%d frames, lost %.1f %% (%d loss events), jitter %s mm / %s deg", t["frames"].get<int>(),
                            100 * Num(t, "lost_fraction"), t["loss_events"].get<int>(),
                            Fmt(Num(t, "jitter_mm"), "%.2f").c_str(), Fmt(Num(t, "jitter_deg"), "%.3f").c_str())});
    rows.push_back({"pose vs truth", Fmt(Num(t, "error_vs_truth_mm"), "%.2f") + " mm RMS (median " +
                                         Fmt(Num(t, "error_vs_truth_median_mm"), "%.2f") + " mm), " +
                                         Fmt(Num(t, "error_vs_truth_deg"), "%.3f") + " deg RMS"});
  }
  if (report.contains("light_fit"))
    rows.push_back({"light fit", Printf("loss %.4f median over %d refits", Num(report["light_fit"], "median_loss"),
                                        report["light_fit"]["refits"].get<int>())});
  const Json& env = report["environment"];
  rows.push_back({"environment energy",
                  Printf("env/near %.3f at surfaces, %.3f at centre, %d lobes%s", Num(env, "env_to_near_surface"),
                         Num(env, "env_to_near_center"), env.contains("lobes") ? env["lobes"].get<int>() : 0,
                         env.value("negligible", false) ? " (negligible: dropped)" : "")});
  for (const Json& s : report["ssdf_error"])
    rows.push_back({"SSDF error", Printf("%s: %.2f deg RMS, %.1f deg max", s.value("object", "").c_str(),
                                         Num(s, "rms_deg"), Num(s, "max_deg"))});
  if (report.contains("performance")) {
    const Json& p = report["performance"];
    rows.push_back({"fps", Printf("%.1f displayed, %.1f captured; latency %.0f ms median, %.0f p90 (%s)",
                                  Num(p, "displayed_fps"), Num(p, "captured_fps"), Num(p["latency_ms"], "median"),
                                  Num(p["latency_ms"], "p90"), p.value("mode", "").c_str())});
    rows.push_back({"load", p.value("load", std::string()) + ", threads " + std::to_string(p.value("threads", 0))});
    if (report.contains("errors")) {
      const Json& e = report["errors"];
      rows.push_back(
          {"errors", Printf("%d frames failed, %d source errors (%d reconnections), %d outputs", e.value("frames", 0),
                            e.value("source", 0), e.value("reconnects", 0), e.value("outputs", 0))});
    }
    rows.push_back({"stage (ms)", "median     p90"});
    for (const auto& [name, v] : p["stages"].items())
      rows.push_back({"  " + name, Printf("%8.2f %8.2f", Num(v, "median_ms"), Num(v, "p90_ms"))});
  }
  return rows;
}

std::vector<double> Values(const Json& array) {
  std::vector<double> v;
  for (const Json& x : array) v.push_back(x.is_number() ? x.get<double>() : NAN);
  return v;
}

// The session's plots from report["series"]: frame time by stage with the
// latency and the 33 ms budget; pose jitter; tracking state; light refits.
Plot NewPlot(const std::string& title, const std::vector<double>& x) {
  Plot plot;
  plot.title = title;
  plot.x = x;
  return plot;
}

std::vector<Plot> SessionPlots(const Json& series) {
  std::vector<Plot> plots;
  const std::vector<double> t = Values(series.at("t_s"));
  static const std::array<std::uint8_t, 3> kColours[] = {{86, 140, 220}, {120, 200, 200}, {240, 190, 70},
                                                         {230, 120, 60}, {200, 80, 140},  {150, 110, 220},
                                                         {120, 200, 100}};
  Plot time = NewPlot("frame time by stage (ms)", t);
  size_t k = 0;
  for (const auto& [group, members] : StageGroups())
    time.stacked.push_back({group, kColours[k++ % 7], Values(series.at("stages_ms").at(group))});
  time.lines.push_back({"latency", {250, 250, 250}, Values(series.at("latency_ms"))});
  time.lines.push_back({"33 ms budget", {255, 60, 60}, std::vector<double>(t.size(), 33.0)});
  plots.push_back(time);
  Plot jitter = NewPlot("pose jitter (mm, second difference / sqrt 6)", t);
  jitter.lines.push_back({"jitter", {120, 200, 250}, Values(series.at("jitter_mm"))});
  plots.push_back(jitter);
  Plot state = NewPlot("tracking state", t);
  state.y_max = 1;
  state.y_axis = false;
  const std::pair<const char*, std::array<std::uint8_t, 3>> states[] = {
      {"tracking", {80, 190, 90}}, {"recovering", {230, 190, 60}}, {"lost", {220, 60, 60}}};
  for (const auto& [name, rgb] : states) {
    std::vector<double> on;
    for (const Json& s : series.at("state")) on.push_back(s.get<std::string>() == name ? 1.0 : 0.0);
    state.stacked.push_back({name, rgb, on});
  }
  plots.push_back(state);
  Plot refits = NewPlot("light fit refits (SG fit loss)", t);
  refits.markers.push_back({"refit", {240, 190, 70}, Values(series.at("light_fit_loss"))});
  plots.push_back(refits);
  return plots;
}

// The last views found in the folder: (caption, path).
std::vector<std::pair<std::string, std::string>> ViewFiles(const std::string& report_dir) {
  std::vector<std::pair<std::string, std::string>> views;
  std::error_code error;
  for (const char* name : {"last_ar.png", "last_alongside.png", "last_layers.png"}) {
    const fs::path p = fs::path(report_dir) / name;
    if (fs::is_regular_file(p, error)) views.push_back({fs::path(name).stem().string().substr(5), p.string()});
  }
  return views;
}

constexpr int kPageWidth = 1000, kPlotHeight = 150;

// One page: the last views on top, the plots, the figures.
void WritePng(const std::string& path, const std::vector<std::pair<std::string, std::string>>& views,
              const std::vector<Plot>& plots, const Rows& rows) {
  std::vector<Image8> tiles;
  std::vector<std::string> captions;
  for (const auto& [caption, file] : views) {
    try {
      tiles.push_back(ReadImage8(file));
      captions.push_back(caption);
    } catch (const std::exception&) {  // an unreadable view leaves a gap, not a failed report
    }
  }
  Image8 sheet = tiles.empty()
                     ? Image8()
                     : ContactSheet(tiles, static_cast<int>(tiles.size()),
                                    std::min(480, (kPageWidth - 16) / static_cast<int>(tiles.size())), captions);
  const int plots_h = kPlotHeight * static_cast<int>(plots.size());
  const int text_y = sheet.height + plots_h + 8;
  Image8 page(kPageWidth, text_y + 16 * static_cast<int>(rows.size()) + 8, 3, 24);
  for (int y = 0; y < sheet.height; ++y)
    for (int x = 0; x < std::min(sheet.width, kPageWidth); ++x)
      for (int c = 0; c < 3; ++c) page.at(x, y, c) = sheet.at(x, y, c);
  for (size_t i = 0; i < plots.size(); ++i)
    DrawPlot(plots[i], page, 0, sheet.height + kPlotHeight * static_cast<int>(i), kPageWidth, kPlotHeight);
  for (size_t i = 0; i < rows.size(); ++i)
    DrawText(page, Printf("%-20s %s", rows[i].first.c_str(), rows[i].second.c_str()), 8,
             text_y + 16 * static_cast<int>(i));
  WriteImage8(path, page);
}

// One self-contained page: the views as data: URIs, the plots as inline SVG.
void WriteHtml(const std::string& path, const std::vector<std::pair<std::string, std::string>>& views,
               const std::vector<Plot>& plots, const Rows& rows) {
  std::string html =
      "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>nerfar session report</title>\n"
      "<style>body{background:#202020;color:#ddd;font-family:sans-serif;margin:16px}"
      "figure{display:inline-block;margin:4px}img{max-width:480px}td{padding:1px 12px 1px 0;"
      "font-family:monospace;white-space:pre}</style></head><body>\n<h1>nerfar session report</h1>\n";
  for (const auto& [caption, file] : views) {
    std::ifstream in(file, std::ios::binary);
    const std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (bytes.empty()) continue;
    html += "<figure><img alt=\"" + HtmlEscape(caption) + "\" src=\"data:image/png;base64," + Base64(bytes) +
            "\"><figcaption>" + HtmlEscape(caption) + "</figcaption></figure>\n";
  }
  for (const Plot& plot : plots) html += "<div>" + PlotSvg(plot, kPageWidth, kPlotHeight) + "</div>\n";
  html += "<table>\n";
  for (const auto& [what, value] : rows)
    html += "<tr><td>" + HtmlEscape(what) + "</td><td>" + HtmlEscape(value) + "</td></tr>\n";
  html += "</table>\n</body></html>\n";
  WriteFileAtomic(path, html);
}

}  // namespace

void WriteReport(const Json& report, const std::string& report_dir) {
  MakeDirectories(report_dir);
  WriteJsonFile((fs::path(report_dir) / "report.json").string(), report);
  const Rows rows = FigureRows(report);
  for (const auto& [what, value] : rows) std::printf("%-20s %s\n", what.c_str(), value.c_str());
  const std::vector<Plot> plots = report.contains("series") ? SessionPlots(report["series"]) : std::vector<Plot>{};
  const auto views = ViewFiles(report_dir);
  WritePng((fs::path(report_dir) / "report.png").string(), views, plots, rows);
  WriteHtml((fs::path(report_dir) / "report.html").string(), views, plots, rows);
}

}  // namespace nerfar
