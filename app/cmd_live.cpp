// nerfar live --source S --scene SCENE [--object OBJ] [--camera C --board B]
//             [--headless -o DIR] [--frames N]
// The live AR view: frames from a camera (or the synthetic stream) tracked
// from the board's AprilTags, the object inserted with the pose of that same
// frame (app/live/pipeline.h). With a display: the window (click to place,
// drag to move, keys and panel for the rest; app/live/live_ui.h). Without
// one, or with --headless: the same views written to files. Every run ends
// with the session report (SESSION/report.json, report.png and report.html),
// also after SIGINT / SIGTERM. A camera that disappears is opened again;
// frames that fail and views that cannot be written are counted in the
// report (exit 1 when a view could not be written), never the end of the run.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <utility>

#include "app/cli.h"
#include "app/command_files.h"
#include "app/commands.h"
#include "app/live/live_ui.h"
#include "app/live/pipeline.h"
#include "app/live/report.h"
#include "app/live/scene.h"
#include "app/live/window.h"
#include "app/sources.h"
#include "app/stop_signal.h"
#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "calib/core/image_io.h"
#include "calib/core/log.h"
#include "calib/core/media.h"
#include "calib/core/parallel.h"
#include "render/insert/nerf_insert_options.h"
#include "render/lighting/seen_radiance.h"
#include "render/synth/camera_stream.h"
#include "tracking/frame_sources.h"
#include "tracking/reconnecting_source.h"

namespace nerfar {

namespace fs = std::filesystem;

namespace {

std::string SessionName() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char name[64];
  std::strftime(name, sizeof name, "%Y%m%d-%H%M%S", &tm);
  return name;
}

bool ParseVec3(const std::string& text, Vec3& out) {
  double v[3];
  char tail = 0;
  if (std::sscanf(text.c_str(), "%lf,%lf,%lf%c", &v[0], &v[1], &v[2], &tail) != 3) return false;
  out = {v[0], v[1], v[2]};
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

struct LiveArgs {
  std::string source_name, scene_dir, camera_path, board_path, output, preset = "fast", tracker_preset = "balanced";
  std::string response, views_text, anchor_text, video_path, sheet_path;
  std::vector<std::string> object_paths, sets;
  int frames = 0, render_divisor = 0;
  double scale = 1.0;
  bool headless = false, realtime = false, auto_place = false, no_hud = false, loop = false;
  Vec3 anchor;    // parsed --anchor
  int views = 0;  // parsed --views (LiveView flags; 0: the default)
};

// "ar,alongside,layers" -> view flags; unknown names go to `usage`.
int ParseViews(const std::string& text, Problems& usage) {
  int views = 0;
  if (text.empty()) return views;
  size_t start = 0;
  while (start <= text.size()) {
    const size_t comma = text.find(',', start);
    const std::string v = text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    if (v == "ar")
      views |= kViewAr;
    else if (v == "alongside")
      views |= kViewAlongside;
    else if (v == "layers")
      views |= kViewLayers;
    else
      usage.Add("--views", "'" + v + "' (expected ar, alongside or layers)");
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return views;
}

// The command line, checked: every problem at once (exit 2); nullopt after --help.
std::optional<LiveArgs> ParseLiveArgs(const CommandArgs& args) {
  LiveArgs a;
  ArgParser parser("live", "The live AR view: tracked camera frames with the object inserted.");
  parser.Option("--source", &a.source_name, "S", "frames: synthetic:SCENE,..., v4l2:/dev/videoN, video:FILE, ...");
  parser.Required("--source");
  parser.Option("--scene", &a.scene_dir, "SCENE",
                "folder with scene.nerf, env.json, board.json, camera and *.ssdf (a `nerfar demo` output)");
  parser.Required("--scene");
  parser.Option("--object", &a.object_paths, "OBJ",
                "object .ssdf (or a mesh: no shadows); repeatable (default: SCENE/*.ssdf)");
  parser.Option("--camera", &a.camera_path, "C",
                "camera.json or transforms.json (default: SCENE's, or the synthetic stream's)");
  parser.Option("--board", &a.board_path, "B", "board.json (default: SCENE's, or the synthetic stream's)");
  parser.Flag("--headless", &a.headless, "no window even with a display: write the views to files");
  parser.Option("-o", &a.output, "DIR", "session folder (default SCENE/sessions/<UTC time>)");
  parser.Option("--frames", &a.frames, "N", "stop after N frames (headless default 60; window: until closed)");
  parser.Option("--preset", &a.preset, "P", "insertion preset: fast (default) | balanced | accurate");
  parser.Option("--set", &a.sets, "KEY=VALUE",
                "set one knob over the preset, also the one switched to (repeatable; the keys of `nerfar insert "
                "--set`, the insertion's and the NeRF scene's, but support_plane)");
  // balanced by default: on noisy 640x480 frames the fast detector (decimated)
  // lost 8 of 60 frames of the demo stream where balanced lost none.
  parser.Option("--tracker-preset", &a.tracker_preset, "P",
                "tag detector preset: fast | balanced (default) | accurate");
  parser.Option("--response", &a.response, "R",
                "camera response: display (synthetic default) | srgb (cameras default)");
  parser.Option("--views", &a.views_text, "LIST", "ar[,alongside][,layers] (window default ar; headless: all three)");
  parser.Option("--anchor", &a.anchor_text, "X,Y,Z", "place the first object on this world point (metres) at start");
  parser.Option("--render-divisor", &a.render_divisor, "D",
                "composite at 1/D of the frame size, tracking at full size (1-4; default 1 up to 1280x720, "
                "2 for larger frames)");
  parser.Option("--scale", &a.scale, "S", "object scale at start (default 1)");
  parser.Flag("--auto-place", &a.auto_place,
              "place the first object on the surface under the image centre at the first tracked frame "
              "(default in headless runs without --anchor)");
  parser.Flag("--realtime", &a.realtime,
              "headless: capture and processing threads with frame dropping, as in the window "
              "(default: every frame processed in order)");
  parser.Flag("--no-hud", &a.no_hud, "no HUD text in the AR view");
  parser.Flag("--loop", &a.loop, "images:DIR sources: start over after the last frame (soak runs, unattended demos)");
  parser.Option("--video", &a.video_path, "FILE", "headless: the AR video (default SESSION/live.mp4)");
  parser.Option("--contact-sheet", &a.sheet_path, "FILE",
                "headless: views of four frames (default SESSION/contact_sheet.png)");
  parser.Epilog(
      "window keys: click place, drag move, Tab next object, A/D rotate, W/S scale, 1/2/3 preset, N alongside,\n"
      "L layers, "
      "H HUD, R record (SESSION/recording.mp4), P screenshot, Esc quit.\n"
      "session files: session.json, report.json, report.png, report.html, last_ar.png [, last_alongside.png, "
      "last_layers.png]\n"
      "example:\n"
      "  nerfar live --source synthetic:window,spp=1 --scene demo_out\n\n" +
      SourceHelp());
  if (!parser.Parse(args)) return std::nullopt;

  Problems usage("nerfar live");
  if (a.render_divisor < 0 || a.render_divisor > 4)
    usage.Add("--render-divisor", std::to_string(a.render_divisor) + " (expected 1..4)");
  if (a.frames < 0) usage.Add("--frames", std::to_string(a.frames) + " (expected >= 0)");
  if (!(a.scale > 0 && a.scale < 100)) usage.Add("--scale", std::to_string(a.scale) + " (expected (0, 100))");
  if (!a.response.empty() && a.response != "display" && a.response != "srgb")
    usage.Add("--response", "'" + a.response + "' (expected display or srgb)");
  if (!a.anchor_text.empty() && !ParseVec3(a.anchor_text, a.anchor))
    usage.Add("--anchor", "'" + a.anchor_text + "' (expected X,Y,Z in metres)");
  a.views = ParseViews(a.views_text, usage);
  if (a.preset != "fast" && a.preset != "balanced" && a.preset != "accurate")
    usage.Add("--preset", "'" + a.preset + "' (expected fast, balanced or accurate)");
  if (a.tracker_preset != "fast" && a.tracker_preset != "balanced" && a.tracker_preset != "accurate")
    usage.Add("--tracker-preset", "'" + a.tracker_preset + "' (expected fast, balanced or accurate)");
  usage.ThrowIfAny();
  // An unknown key or a bad value stops here (InputError); one out of range too.
  for (const std::string& problem : NerfInsertOptions::Preset(a.preset, a.sets).Validate()) usage.Add("--set", problem);
  usage.ThrowIfAny();
  return a;
}

using WriteView = std::function<bool(const std::function<void()>&)>;

// Headless: the AR video, the contact sheet (AR, alongside and layers of
// four frames), every frame processed in order or (--realtime) as the window
// takes them; returns the last frame.
std::optional<LiveFrame> RunHeadless(LivePipeline& pipeline, const LiveArgs& a, const std::string& video_file,
                                     const std::string& sheet_file, int requested_views,
                                     const std::function<void(const LiveFrame&)>& try_auto_place,
                                     const WriteView& write_view) {
  std::optional<LiveFrame> last;
  const int limit = a.frames > 0 ? a.frames : 60;
  std::unique_ptr<VideoWriter> video;
  bool video_failed = false;
  std::vector<Image8> sheet_tiles;
  std::vector<std::string> captions;
  const int sheet_every = std::max(1, limit / 4);
  int n = 0;
  const auto consume = [&](LiveFrame f) {
    pipeline.MarkDisplayed(f);
    try_auto_place(f);
    if (!video_failed) {
      video_failed = !write_view([&] {
        if (!video) video = std::make_unique<VideoWriter>(video_file, f.ar.width, f.ar.height, 30.0);
        video->Write(f.ar);
      });
      if (video_failed) video.reset();
    }
    if (n % sheet_every == sheet_every - 1 && sheet_tiles.size() < 12) {
      const std::string label = "frame " + std::to_string(f.index) + " " + TrackingStateName(f.state);
      sheet_tiles.push_back(f.ar);
      captions.push_back(label);
      sheet_tiles.push_back(f.alongside.empty() ? Image8(f.ar.width / 2, f.ar.height / 2, 3, 30) : f.alongside);
      captions.push_back("alongside (NeRF)");
      sheet_tiles.push_back(f.layers.empty() ? Image8(f.ar.width, f.ar.height / 2, 3, 30) : f.layers);
      captions.push_back("kappa | alpha | light");
    }
    ++n;
    last = std::move(f);
  };
  if (a.realtime) {
    pipeline.Start();
    while (n < limit && !StopRequested()) {
      std::optional<LiveFrame> f = pipeline.TakeLatest(std::chrono::milliseconds(200));
      if (f)
        consume(std::move(*f));
      else if (pipeline.finished())
        break;
    }
    pipeline.Stop();
  } else {
    while (n < limit && !StopRequested()) {
      // The extra views cost more than the AR frame: made for the frames
      // that go into the contact sheet (the video holds the AR view).
      pipeline.set_views(n % sheet_every == sheet_every - 1 ? requested_views : kViewAr);
      std::optional<LiveFrame> f = pipeline.Step();
      if (f)
        consume(std::move(*f));
      else if (pipeline.source_ended())
        break;
    }
  }
  if (video) write_view([&] { video->Close(); });
  if (!sheet_tiles.empty()) write_view([&] { WriteImage8(sheet_file, ContactSheet(sheet_tiles, 3, 320, captions)); });
  if (!video_failed) LogInfo("live: wrote " + std::to_string(n) + " frames to " + video_file);
  return last;
}

// --camera, else the synthetic stream's exact intrinsics, else SCENE's;
// `used` names the file ("" for the stream's own).
CameraIntrinsics ChooseCamera(const LiveArgs& a, const synth::SyntheticCameraSource* synthetic,
                              const LiveSceneData& scene, const LiveScenePaths& paths, std::string* used) {
  if (!a.camera_path.empty()) {
    *used = a.camera_path;
    return ReadCameraFile(a.camera_path).camera;
  }
  if (synthetic != nullptr) return synthetic->camera();
  if (scene.camera) {
    *used = paths.camera;
    return scene.camera->camera;
  }
  throw InputError("nerfar live: no camera: give --camera C (camera.json from `nerfar calibrate`)");
}

// --board, else SCENE's, else the synthetic stream's.
Board ChooseBoard(const LiveArgs& a, const synth::SyntheticCameraSource* synthetic, const LiveSceneData& scene) {
  if (!a.board_path.empty()) return ReadBoard(a.board_path);
  if (scene.board) return *scene.board;
  if (synthetic != nullptr) return synthetic->board();
  throw InputError("nerfar live: no board: give --board B (board.json), or put one into " + a.scene_dir);
}

// The last views, session.json and the report; the exit code (the signal's
// after SIGINT / SIGTERM, 1 when a view could not be written).
int FinishSession(const LivePipeline& pipeline, const std::string& session_dir, const SessionInfo& info,
                  const std::optional<LiveFrame>& last, const WriteView& write_view) {
  if (last) {
    const std::pair<const char*, const Image8*> last_views[] = {
        {"last_ar.png", &last->ar}, {"last_alongside.png", &last->alongside}, {"last_layers.png", &last->layers}};
    for (const auto& [name, image] : last_views)
      if (!image->empty()) write_view([&] { WriteImage8((fs::path(session_dir) / name).string(), *image); });
  }
  WriteSession(session_dir, info, pipeline);
  std::string report_dir;
  const Json report = BuildReport(session_dir, &report_dir);
  WriteReport(report, report_dir);
  LogInfo("live: session report " + report_dir + "/report.json, report.png and report.html");
  if (StopRequested()) return StopExitCode();
  if (const std::uint64_t failed = pipeline.counters().output_errors; failed > 0) {
    std::fprintf(stderr, "error: live: %llu views could not be written (see %s/report.json)\n",
                 static_cast<unsigned long long>(failed), report_dir.c_str());
    return 1;
  }
  return 0;
}

// The pipeline's options from the command line and the camera.
LiveOptions LiveOptionsFor(const LiveArgs& a, const CameraIntrinsics& camera, bool synthetic) {
  LiveOptions options;
  options.preset = a.preset;
  options.insert_sets = a.sets;
  options.tracker = TrackerOptions::Preset(a.tracker_preset);
  options.response = !a.response.empty() ? a.response : (synthetic ? "display" : "srgb");
  options.hud = !a.no_hud;
  // The display path rewrites only what the insertion changed, so a 1280x720
  // frame composites at its own size within the frame budget (bench live).
  options.render_divisor =
      a.render_divisor > 0 ? a.render_divisor : (camera.width > 1280 || camera.height > 720 ? 2 : 1);
  // The alongside and layers views (a NeRF rendering: its cost grows with
  // its pixels) keep the size they had when frames wider than 480 px were
  // composited at half size: a quarter of the frame, not half of it.
  if (a.render_divisor == 0 && options.render_divisor == 1 && camera.width > 480) options.alongside_scale = 0.25;
  return options;
}

// The loaded objects as the pipeline borrows them.
std::vector<LiveAsset> AssetsOf(const std::vector<LiveObjectAsset>& objects) {
  std::vector<LiveAsset> assets;
  for (const LiveObjectAsset& o : objects) {
    const auto map = [](const std::optional<ImageF>& m) { return m ? &*m : nullptr; };
    assets.push_back({o.name, &o.mesh, o.field ? &*o.field : nullptr, o.material, map(o.maps.albedo),
                      map(o.maps.roughness), map(o.maps.metallic)});
  }
  return assets;
}

}  // namespace

int RunLive(const CommandArgs& args) {
  const std::optional<LiveArgs> parsed = ParseLiveArgs(args);
  if (!parsed) return 0;
  LiveArgs a = *parsed;

  // Scene, objects, source, camera, board.
  const LiveScenePaths paths = FindLiveScene(a.scene_dir);
  if (a.object_paths.empty()) a.object_paths = paths.objects;
  const std::string session_dir =
      !a.output.empty() ? a.output : (fs::path(a.scene_dir) / "sessions" / SessionName()).string();
  const std::string video_file = !a.video_path.empty() ? a.video_path : (fs::path(session_dir) / "live.mp4").string();
  const std::string sheet_file =
      !a.sheet_path.empty() ? a.sheet_path : (fs::path(session_dir) / "contact_sheet.png").string();
  CheckOutputsSpareInputs(Paths(LiveSessionOutputs(session_dir), video_file, sheet_file),
                          Paths(paths.nerf, paths.env, paths.board, paths.camera, a.camera_path, a.board_path,
                                a.object_paths, SourceInputs(a.source_name)));
  LiveSceneData scene = LoadLiveScene(paths);
  if (a.object_paths.empty())
    throw InputError("nerfar live: no object: give --object OBJ (.ssdf or mesh), or bake one into " + a.scene_dir);
  std::vector<LiveObjectAsset> objects;
  for (const std::string& o : a.object_paths) objects.push_back(LoadLiveObject(o));
  SourceOptions source_options;
  source_options.loop = a.loop;
  std::unique_ptr<FrameSource> source = OpenSource(a.source_name, source_options);
  const auto* synthetic = dynamic_cast<const synth::SyntheticCameraSource*>(source.get());
  std::string used_camera;
  const CameraIntrinsics camera = ChooseCamera(a, synthetic, scene, paths, &used_camera);
  const Board board = ChooseBoard(a, synthetic, scene);
  const LiveOptions options = LiveOptionsFor(a, camera, synthetic != nullptr);
  const std::vector<LiveAsset> assets = AssetsOf(objects);
  source =
      ReconnectOnLoss(std::move(source), [&a, source_options] { return OpenSource(a.source_name, source_options); });
  LivePipeline pipeline(*source, board, camera, *scene.field, scene.env.lobes, assets, options, scene.env.distance_m);
  // A view that cannot be written (a full disk, a folder gone) is reported, not the end of the run.
  const auto write_view = [&pipeline](const std::function<void()>& write) {
    try {
      write();
      return true;
    } catch (const std::exception& e) {
      pipeline.ReportOutputError(e.what());
      return false;
    }
  };
  if (!a.anchor_text.empty() || a.scale != 1.0) {
    LiveObjectState s = pipeline.object(0);
    s.placed = !a.anchor_text.empty();
    s.anchor_world = a.anchor;
    s.scale = a.scale;
    pipeline.set_object(0, s);
  }

  const bool window_mode = !a.headless && LiveWindow::DisplayAvailable();
  if (!window_mode && !a.headless) LogInfo("live: no display: running headless (views written to files)");
  if (!window_mode && a.anchor_text.empty()) a.auto_place = true;
  MakeDirectories(session_dir);
  const int requested_views =
      a.views != 0 ? (a.views | kViewAr) : (window_mode ? kViewAr : (kViewAr | kViewAlongside | kViewLayers));
  pipeline.set_views(requested_views);
  LogInfo("live: " + source->Describe() + ", scene " + paths.nerf + ", " + std::to_string(objects.size()) +
          " object(s), preset " + a.preset + ", response " + options.response + ", threads " +
          std::to_string(ThreadCount()) + ", session " + session_dir + ", light's seen radiance " +
          SeenViewsNote(scene.nerf, NerfInsertOptions::Preset(options.preset, options.insert_sets).nerf.seen));

  // Places object 0 under the image centre once a frame has a pose.
  std::int64_t auto_placed_frame = -1;
  const auto try_auto_place = [&](const LiveFrame& f) {
    if (!a.auto_place || pipeline.object(0).placed || !f.has_pose) return;
    if (const auto hit = pipeline.PickSurface(f, f.ar.width * 0.5, f.ar.height * 0.5)) {
      LiveObjectState s = pipeline.object(0);
      s.placed = true;
      s.anchor_world = *hit;
      pipeline.set_object(0, s);
      auto_placed_frame = f.index;
      LogInfo("live: placed " + objects[0].name + " at the surface under the image centre of frame " +
              std::to_string(f.index));
    }
  };

  const auto t_start = LiveClock::now();
  const StopScope stop_scope;  // a signal ends the loop; the session files are written as after any run
  std::optional<LiveFrame> last;
  if (window_mode) {
    LiveWindow window("nerfar live - " + paths.dir, 1280, 720);
    LiveUi ui(window, pipeline, session_dir);
    pipeline.Start();
    while (ui.Tick(std::chrono::milliseconds(30)) && !StopRequested()) {
      if (ui.shown()) try_auto_place(*ui.shown());
      if (a.frames > 0 && ui.frames_shown() >= a.frames) break;
    }
    pipeline.Stop();
    ui.StopRecording();
    last = ui.shown();
  } else {
    last = RunHeadless(pipeline, a, video_file, sheet_file, requested_views, try_auto_place, write_view);
  }
  SessionInfo info;
  info.scene_dir = a.scene_dir;
  info.source = a.source_name;
  info.camera_path = used_camera;
  info.objects = a.object_paths;
  info.mode = window_mode ? "window" : (a.realtime ? "headless-realtime" : "headless");
  info.wall_s = std::chrono::duration<double>(LiveClock::now() - t_start).count();
  info.threads = ThreadCount();
  info.auto_placed_frame = auto_placed_frame;
  return FinishSession(pipeline, session_dir, info, last, write_view);
}

}  // namespace nerfar
