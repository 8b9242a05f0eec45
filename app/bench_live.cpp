// Bench stage "live": the whole live pipeline as the window runs it
// (app/live/pipeline.h: capture thread, tracking, insertion, display path
// with the HUD; recording off) on frames rendered beforehand by the
// synthetic camera (the demo's window scene, 1280x720), fed at their 30 frames/s time
// stamps, the object covering ~10 % of the frame on the insertion benches'
// NeRF table (BenchTabletopNerf). Three motions: the camera still, hand-held
// (the synthetic camera's trajectory), and the object dragged across the
// table under a still camera, with the light held through the drag (the
// live default, LiveOptions::drag_hold) and, as "dragexact", recomputed
// every frame. Per motion, preset (fast, balanced) and thread
// count (1, 2): displayed fps, frames dropped, per-stage p50/p90 and
// capture-to-display latency p50/p90 over the frames after a warm-up; and the
// floor a display path cannot beat, one 1280x720 RGB frame copied.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>

#include "app/bench.h"
#include "app/live/display.h"
#include "app/live/pipeline.h"
#include "app/live/report.h"
#include "app/live/window.h"
#include "calib/core/log.h"
#include "calib/core/parallel.h"
#include "render/insert/nerf_scene.h"
#include "render/insert/rasterizer.h"
#include "render/mesh/mesh.h"
#include "render/nerf/nerf_field.h"
#include "render/ssdf/ssdf.h"
#include "render/synth/camera_stream.h"

namespace nerfar {

namespace {

constexpr double kFps = 30;
constexpr double kCoverage = 0.10;  // share of the frame the object covers (DESIGN.md budgets)

// Frames rendered beforehand, handed out in order with their time stamps
// (the pipeline paces them); the copy is all the capture costs.
class ReplaySource final : public FrameSource {
 public:
  explicit ReplaySource(const std::vector<Frame>& frames) : frames_(frames) {}
  std::string Describe() const override { return std::to_string(frames_.size()) + " pre-rendered frames"; }
  FrameStatus Next(Frame& frame, int /*timeout_ms*/) override {
    if (next_ >= frames_.size()) return FrameStatus::kEndOfStream;
    frame = frames_[next_++];
    return FrameStatus::kOk;
  }

 private:
  const std::vector<Frame>& frames_;
  size_t next_ = 0;
};

struct Sequence {
  std::unique_ptr<synth::SyntheticCameraSource> camera;  // intrinsics, board, true poses
  std::vector<Frame> frames;
};

Sequence RenderSequence(int width, int height, int frames, bool hand_held) {
  synth::CameraStreamOptions o;
  o.scene = "window";
  o.width = width;
  o.height = height;
  o.samples_per_pixel = 1;
  o.fps = kFps;
  // A still camera is the trajectory slowed 10⁴ times (sub-micrometre moves).
  o.speed = hand_held ? 1.0 : 1e-4;
  Sequence s;
  s.camera = std::make_unique<synth::SyntheticCameraSource>(o);
  for (int i = 0; i < frames; ++i) s.frames.push_back(s.camera->RenderFrame(i / kFps, i));
  return s;
}

// Object 0 on the table under the image centre of the first true pose,
// scaled until its silhouette covers kCoverage of the frame.
LiveObjectState PlaceCovering(const LivePipeline& pipeline, const TriangleMesh& mesh, const Sequence& s,
                              double* coverage) {
  const Pose pose = *s.frames.front().T_world_camera_true;
  const CameraIntrinsics& camera = s.camera->camera();
  const Vec3 d = pose.Rotate(Unproject(camera, {camera.width * 0.5, camera.height * 0.5}));
  LiveObjectState state = pipeline.object(0);
  state.placed = true;
  state.anchor_world = pose.translation + d * (-pose.translation.z / d.z);
  for (int iteration = 0; iteration < 4; ++iteration) {
    const ObjectGBuffer g = Rasterize(camera, pose, {{&mesh, pipeline.ObjectPose(0, state), state.scale}});
    *coverage = double(g.covered) / (double(camera.width) * camera.height);
    if (*coverage <= 0) break;
    state.scale *= std::sqrt(kCoverage / *coverage);
  }
  return state;
}

struct RunSetup {
  const Sequence* sequence = nullptr;
  NerfScene* scene = nullptr;  // its options set by the pipeline from the preset
  const SgMixture* environment = nullptr;
  const TriangleMesh* mesh = nullptr;
  const SsdfField* field = nullptr;
  std::string preset;
  bool drag = false;
  bool drag_hold = true;  // LiveOptions::drag_hold
  int warmup = 15;        // frames left out of the figures (tracking confirms, the first light fit is cold)
};

// One run: the pipeline threaded as in the window, a display loop that takes
// the newest frame and (dragging) moves the object as a mouse would.
std::vector<LiveFrameRecord> RunOnce(const RunSetup& r, LiveCounters* counters, double* coverage) {
  ReplaySource source(r.sequence->frames);
  LiveAsset asset;
  asset.name = "object";
  asset.mesh = r.mesh;
  asset.field = r.field;
  asset.material.base_color = {0.8, 0.35, 0.2};
  asset.material.roughness = 0.7;
  LiveOptions options;
  options.preset = r.preset;
  options.tracker = TrackerOptions::Preset("balanced");  // the live command's default
  options.response = "display";                          // the synthetic camera's encoding
  options.render_divisor = 1;
  options.drag_hold = r.drag_hold;
  LivePipeline pipeline(source, r.sequence->camera->board(), r.sequence->camera->camera(), *r.scene, *r.environment,
                        {asset}, options);
  const LiveObjectState start = PlaceCovering(pipeline, *r.mesh, *r.sequence, coverage);
  pipeline.set_object(0, start);
  // Dragging: 6 cm either way along the camera's horizontal on the table,
  // 3 s a period (up to 13 cm/s), updated at every displayed frame.
  Vec3 along = r.sequence->frames.front().T_world_camera_true->rotation.Column(0);
  along.z = 0;
  along = Normalized(along);
  const auto t0 = LiveClock::now();
  pipeline.Start();
  while (!pipeline.finished()) {
    std::optional<LiveFrame> f = pipeline.TakeLatest(std::chrono::milliseconds(200));
    if (!f) continue;
    pipeline.MarkDisplayed(*f);
    if (r.drag) {
      const double t = std::chrono::duration<double>(LiveClock::now() - t0).count();
      LiveObjectState s = start;
      s.dragging = true;
      s.anchor_world = start.anchor_world + along * (0.06 * std::sin(2 * kPi * t / 3.0));
      pipeline.set_object(0, s);
    }
  }
  pipeline.Stop();
  *counters = pipeline.counters();
  std::vector<LiveFrameRecord> records = pipeline.records();
  const auto posed = std::count_if(records.begin(), records.end(), [](const LiveFrameRecord& f) { return f.has_pose; });
  LogInfo("bench live: " + std::to_string(posed) + " of " + std::to_string(records.size()) + " frames posed");
  return records;
}

// One frame's κ parts and counts (--verbose; for profilers).
void LogKappaCounts(const std::string& label, const LiveFrameRecord& f) {
  const InsertTimings& t = f.times.insert;
  char line[320];
  std::snprintf(line, sizeof line,
                "bench live: %s frame %lld: kappa %.2f ms (receivers %.2f, look-up %.2f, multiply %.2f); "
                "receivers %zu, look-ups %zu, computed %zu, marched %zu, reused %zu, hidden %zu, multiplied %zu px",
                label.c_str(), static_cast<long long>(f.index), t.kappa_ms, t.kappa_receivers_ms, t.kappa_lookup_ms,
                t.kappa_multiply_ms, t.kappa_receivers, t.kappa_lookups, t.kappa_evaluated, t.kappa_marched,
                t.kappa_reused, t.kappa_hidden, t.kappa_multiplied);
  LogVerbose(line);
}

void AddRunFigures(const std::string& label, const std::string& note, const std::vector<LiveFrameRecord>& records,
                   int frames, int warmup, std::vector<BenchFigure>& figures) {
  std::vector<double> latency, track, expose, insert, light, shade, kappa, display, process, rewritten, nodes;
  int displayed = 0, relit = 0;
  for (const LiveFrameRecord& f : records) {
    if (f.index < warmup) continue;
    relit += f.times.insert.lights_recomputed > 0 ? 1 : 0;
    track.push_back(f.times.track_ms);
    expose.push_back(f.times.expose_ms);
    insert.push_back(f.times.insert.total_ms);
    light.push_back(f.times.insert.light_ms + f.times.insert.fit_ms);
    shade.push_back(f.times.insert.shade_ms);
    kappa.push_back(f.times.insert.kappa_ms);
    display.push_back(f.times.display_ms);
    process.push_back(f.times.process_ms);
    rewritten.push_back(static_cast<double>(f.pixels_rewritten));
    nodes.push_back(static_cast<double>(f.times.insert.kappa_evaluated));
    LogKappaCounts(label, f);
    if (f.latency_ms >= 0) {
      latency.push_back(f.latency_ms);
      ++displayed;
    }
  }
  const int fed = std::max(0, frames - warmup);
  figures.push_back({label + "_fps", fed > 0 ? displayed * kFps / fed : 0, "fps", note + ", displayed"});
  figures.push_back({label + "_dropped", double(fed - displayed), "frames", "of " + std::to_string(fed) + " fed"});
  const std::pair<const char*, const std::vector<double>*> stages[] = {
      {"latency", &latency}, {"process", &process}, {"track", &track}, {"expose", &expose},  {"insert", &insert},
      {"light", &light},     {"shade", &shade},     {"kappa", &kappa}, {"display", &display}};
  for (const auto& [name, values] : stages) {
    figures.push_back({label + "_" + name + "_p50_ms", PercentileOf(*values, 0.5), "ms", ""});
    figures.push_back({label + "_" + name + "_p90_ms", PercentileOf(*values, 0.9), "ms", ""});
  }
  figures.push_back({label + "_rewritten_px", PercentileOf(rewritten, 0.5), "px", "median, display path"});
  figures.push_back({label + "_kappa_nodes", PercentileOf(nodes, 0.5), "nodes", "median, κ values computed a frame"});
  figures.push_back({label + "_relit", double(relit), "frames", "processed frames that took the light anew"});
}

// The floor: one 1280x720 RGB frame (2.76 MB) read and written once, as
// the cheapest display path that hands out a new frame would; and the HUD.
void AddFloorAndHud(int width, int height, std::vector<BenchFigure>& figures) {
  const size_t bytes = size_t(width) * height * 3;
  std::vector<std::uint8_t> a(bytes, 7), b(bytes, 0);
  const double copy = MedianMilliseconds([&] { std::memcpy(b.data(), a.data(), bytes); }, 20);
  figures.push_back(
      {"floor_frame_copy_ms", copy, "ms",
       std::to_string(bytes) + " B read + written (" + std::to_string(width) + "x" + std::to_string(height) + " RGB)"});
  // The HUD's share of the display stage: renewing its two lines of text
  // (drawn over black and white, at most 4 times a second) and blending the
  // cached text into a frame (every frame).
  TextOverlay hud;
  int renewals = 0;
  const double renew = MedianMilliseconds(
      [&] {
        const std::string fps = std::to_string(20 + renewals++ % 10) + ".0 fps  latency 29 ms  tracking  tags 2";
        hud.Set({fps, "ms: track 2.8  insert 19.7 (kappa 8.1)  views 0.0"}, width);
      },
      20);
  Image8 frame(width, height, 3, 128);
  const double blend = MedianMilliseconds([&] { hud.Draw(frame); }, 20);
  figures.push_back({"hud_renew_ms", renew, "ms", "new HUD text drawn (at most every 250 ms)"});
  figures.push_back({"hud_blend_ms", blend, "ms", "the cached HUD blended into a frame (every frame)"});
}

// The window's share when a display is there (Xvfb: Mesa's software GL): a
// width x height view presented as a new frame (uploaded to its texture
// once) and presented again unchanged (drawn from the texture, as a redraw
// between frames is). Without a display, nothing.
void AddWindowPresent(int width, int height, std::vector<BenchFigure>& figures) {
  if (!LiveWindow::DisplayAvailable()) {
    LogInfo("bench live: no display, the window's figures skipped (run under xvfb-run for them)");
    return;
  }
  std::unique_ptr<LiveWindow> opened;
  try {
    opened = std::make_unique<LiveWindow>("nerfar bench live", width, height);
  } catch (const std::exception& e) {
    LogInfo(std::string("bench live: the window's figures skipped: ") + e.what());
    return;
  }
  LiveWindow& window = *opened;
  Image8 frames[2] = {Image8(width, height, 3, 60), Image8(width, height, 3, 190)};
  const std::function<void()> no_panel;
  int next = 0;
  const double upload = MedianMilliseconds([&] { window.Present({&frames[next++ % 2]}, no_panel, true); }, 30);
  const double kept = MedianMilliseconds([&] { window.Present({&frames[0]}, no_panel, false); }, 30);
  const std::string size = std::to_string(width) + "x" + std::to_string(height);
  figures.push_back({"window_present_new_ms", upload, "ms", "a new " + size + " frame uploaded once and drawn"});
  figures.push_back({"window_present_kept_ms", kept, "ms", "the same frame drawn again from its texture"});
}

}  // namespace

std::vector<BenchFigure> BenchLive(const BenchOptions& options) {
  std::vector<BenchFigure> figures;
  // NERFAR_BENCH_LIVE_FRAMES=N: frames per run (default 90, 3 s at 30/s).
  const char* frames_env = BenchVariable("NERFAR_BENCH_LIVE_FRAMES");
  const int frames = options.quick ? 8 : std::clamp(frames_env ? std::atoi(frames_env) : 90, 20, 3000);
  const int width = options.quick ? 640 : 1280, height = options.quick ? 360 : 720;
  const int warmup = options.quick ? 2 : 15;
  // NERFAR_BENCH_LIVE_RUNS=TEXT: only the runs whose label holds TEXT.
  const char* runs_env = BenchVariable("NERFAR_BENCH_LIVE_RUNS");
  const std::string only = runs_env ? runs_env : "";
  double t = NowSeconds();
  const Sequence still = RenderSequence(width, height, frames, false);
  const Sequence hand_held = RenderSequence(width, height, frames, true);
  LogInfo("bench live: rendered 2 x " + std::to_string(frames) + " frames in " + FormatDuration(NowSeconds() - t));
  const NerfField nerf = BenchTabletopNerf();
  NerfScene scene(nerf);
  const SgMixture environment = BenchEnvironment();
  std::string mesh_name;
  const TriangleMesh mesh = BenchObjectMesh(options.scenes_dir, &mesh_name);
  SsdfBakeOptions bake = SsdfBakeOptions::Preset("fast");
  if (options.quick) bake.grid = 8;
  t = NowSeconds();
  const SsdfField field = BakeSsdf(mesh, bake, std::nullopt);
  LogInfo("bench live: baked the object's SSDF in " + FormatDuration(NowSeconds() - t));
  AddFloorAndHud(width, height, figures);
  AddWindowPresent(width, height, figures);

  const int threads_before = ThreadCount();
  struct Motion {
    const char* name;
    const Sequence* sequence;
    bool drag, drag_hold;
  };
  // "dragexact": the same drag with the light, γ and κ recomputed every
  // frame (drag_hold off), the comparison within one run.
  const Motion motions[] = {{"still", &still, false, true},
                            {"handheld", &hand_held, false, true},
                            {"drag", &still, true, true},
                            {"dragexact", &still, true, false}};
  const std::vector<std::string> presets =
      options.quick ? std::vector<std::string>{"fast"} : std::vector<std::string>{"fast", "balanced"};
  const std::vector<int> thread_counts = options.quick ? std::vector<int>{1} : std::vector<int>{1, 2};
  for (const int threads : thread_counts)
    for (const std::string& preset : presets)
      for (const Motion& m : motions) {
        const std::string label = std::string(m.name) + "_" + preset + "_t" + std::to_string(threads);
        if (label.find(only) == std::string::npos) continue;
        SetThreadCount(threads);
        RunSetup r{m.sequence, &scene, &environment, &mesh, &field, preset, m.drag, m.drag_hold, warmup};
        LiveCounters counters;
        double coverage = 0;
        const std::vector<LiveFrameRecord> records = RunOnce(r, &counters, &coverage);
        char note[160];
        std::snprintf(note, sizeof note, "%dx%d, %s, object %.0f %% of the frame, %d threads", width, height,
                      mesh_name.c_str(), coverage * 100, threads);
        AddRunFigures(label, note, records, frames, warmup, figures);
        LogInfo("bench live: " + label + " done (" + std::to_string(counters.displayed) + " displayed)");
      }
  SetThreadCount(threads_before);
  return figures;
}

}  // namespace nerfar
