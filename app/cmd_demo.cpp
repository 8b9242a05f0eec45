// nerfar demo [-o DIR] [--headless] [--quick]
// From nothing to a running AR sequence on the built-in synthetic 'window'
// scene: synth (small dataset with ground truth) -> train (fast NeRF) -> env
// -> bake (the torus's SSDF) -> live on the synthetic camera stream, tracked
// from its own rendered tags. Each stage is the ordinary subcommand run in
// process; a finished stage leaves DIR/stages/NAME.done and is skipped when
// the demo is run again (training also resumes from its checkpoint). DIR is a
// SCENE folder for `nerfar live` afterwards. With a display the last stage
// opens the window; without one (or with --headless) it writes DIR/demo.mp4,
// DIR/contact_sheet.png, DIR/timing.json and DIR/session/report.{json,png}.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "app/cli.h"
#include "app/commands.h"
#include "app/live/report.h"
#include "app/live/window.h"
#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "calib/core/json.h"
#include "calib/core/log.h"
#include "calib/core/parallel.h"

namespace nerfar {

namespace fs = std::filesystem;

namespace {

struct DemoStage {
  std::string name;
  std::string what;
  int (*run)(const CommandArgs&);
  CommandArgs args;
  std::string output;  // must exist after the stage
};

// The demo's command line, checked, with the defaults that depend on it filled in.
struct DemoSettings {
  std::string output = "demo_out";
  bool headless = false, quick = false, restart = false;
  double minutes = 3.0;  // only with --minutes
  bool minutes_given = false;
  int frames = 0;
  std::string size;
  bool window_mode = false;
};

// Parses and checks the command line; false when --help was given.
bool ParseDemoSettings(const CommandArgs& args, DemoSettings* settings) {
  DemoSettings& d = *settings;
  ArgParser parser("demo", "From nothing to a running AR sequence on the built-in synthetic scene.");
  parser.Option("-o", &d.output, "DIR", "output folder, a SCENE for `nerfar live` afterwards (default demo_out)");
  parser.Flag("--headless", &d.headless,
              "no window even with a display: write demo.mp4, contact_sheet.png, timing.json");
  parser.Flag("--quick", &d.quick,
              "tiny everything (tests, a first look): 100x75 views, a 2 cm NeRF trained 300 steps, the whole demo "
              "in about a minute");
  parser.Option("--minutes", &d.minutes, "M",
                "cap training at M minutes (default: the whole schedule, 44 CPU-s, ~22 s on a quiet 2-core machine; "
                "a cap on a busy machine trains fewer steps)");
  parser.Option("--frames", &d.frames, "N", "live frames (headless default 60, --quick 12; window: until closed)");
  parser.Option("--size", &d.size, "WxH",
                "synthetic camera size (default 640x480: tracked at that size, composited at half)");
  parser.Flag("--restart", &d.restart, "run every stage again (ignore DIR/stages/*.done)");
  parser.Epilog(
      "stages: synth (window scene, 200x150, 60 views) -> train (fast, from 2 cm voxels) -> env (fast) -> bake (torus, "
      "fast)\n"
      "-> live (synthetic camera at 640x480 tracked from its tags, composited at 320x240, the torus placed under the "
      "image centre).\n"
      "outputs: DIR/dataset, DIR/scene.nerf, DIR/env.json, DIR/torus.ssdf, DIR/board.json,\n"
      "DIR/session/ (session.json, report.json, report.png) and, headless, DIR/demo.mp4,\n"
      "DIR/contact_sheet.png, DIR/timing.json. Run again to reuse finished stages.\n"
      "--quick: synth 100x75 x 24 views, train 300 steps at 2 cm (about 25 CPU-s), env 12 views without BRISQUE,\n"
      "bake 8^3 grid, 12 live frames at 480x360: the whole demo in about a minute on 2 cores.\n"
      "example:\n"
      "  nerfar demo -o demo_out && nerfar live --source synthetic:window,spp=1 --scene demo_out\n");
  if (!parser.Parse(args)) return false;
  {
    Problems usage("nerfar demo");
    if (!(d.minutes > 0 && d.minutes <= 600))
      usage.Add("--minutes", std::to_string(d.minutes) + " (expected (0, 600])");
    if (d.frames < 0) usage.Add("--frames", std::to_string(d.frames) + " (expected >= 0)");
    int w = 0, h = 0;
    char tail = 0;
    if (!d.size.empty() &&
        (std::sscanf(d.size.c_str(), "%dx%d%c", &w, &h, &tail) != 2 || w < 64 || h < 48 || w > 4096 || h > 4096))
      usage.Add("--size", "'" + d.size + "' (expected WxH, 64x48 to 4096x4096)");
    usage.ThrowIfAny();
  }
  // A step count, not a time budget, for --quick: the same model on a busy
  // machine as on a quiet one (tests assert on its picture).
  // Training runs the preset's whole step count unless --minutes is given:
  // a time budget on a busy machine is a worse model (a 3-minute budget at
  // load 10 on 2 cores ended after 28 of 700 steps, nothing pruned: a
  // 148 MB fog in which the torus floated), and tests assert on the picture.
  for (const std::string& a : args) d.minutes_given |= a == "--minutes" || a.rfind("--minutes=", 0) == 0;
  if (d.size.empty()) d.size = d.quick ? "480x360" : "640x480";
  d.window_mode = !d.headless && LiveWindow::DisplayAvailable();
  if (d.frames == 0 && !d.window_mode) d.frames = d.quick ? 12 : 60;
  return true;
}

// The training stage's arguments.
CommandArgs TrainArgs(const DemoSettings& d) {
  const fs::path dir(d.output);
  char minutes_text[32];
  std::snprintf(minutes_text, sizeof minutes_text, "%g", d.minutes);
  // The fast preset from 2 cm voxels (-> 1 cm) instead of 1 cm (-> 5 mm):
  // on the demo's dataset its 1100 steps take 44 CPU-s and give 25.2 dB on
  // the held-out views and a 0.9 MB model, where 5 mm voxels cost twice the
  // samples and the demo's 200x150 views do not resolve them. --quick: 300
  // steps of 2048 rays (~12 CPU-s).
  CommandArgs train_args = {
      (dir / "dataset").string(), "-o", (dir / "scene.nerf").string(), "--preset", "fast", "--set",
      "coarse_voxel_m=0.02"};
  if (d.quick) train_args.insert(train_args.end(), {"--set", "rays_per_step=2048", "--set", "steps=300"});
  if (d.minutes_given) train_args.insert(train_args.end(), {"--minutes", minutes_text});
  return train_args;
}

// The live stage: headless to files, or the window.
DemoStage LiveStage(const DemoSettings& d) {
  const fs::path dir(d.output);
  CommandArgs live_args = {"--source",    "synthetic:window,size=" + d.size + ",spp=1",
                           "--scene",     d.output,
                           "--object",    (dir / "torus.ssdf").string(),
                           "-o",          (dir / "session").string(),
                           "--auto-place"};
  if (!d.window_mode) {
    live_args.insert(live_args.end(),
                     {"--headless", "--frames", std::to_string(d.frames), "--video", (dir / "demo.mp4").string(),
                      "--contact-sheet", (dir / "contact_sheet.png").string()});
  } else if (d.frames > 0) {
    live_args.insert(live_args.end(), {"--frames", std::to_string(d.frames)});
  }
  return {"live",
          d.window_mode ? "the AR window on the synthetic camera (close it to finish)"
                        : "the AR sequence on the synthetic camera, written to files",
          RunLive, live_args, (dir / "session" / "report.json").string()};
}

// synth -> train -> env -> bake -> live, each the ordinary subcommand's arguments.
std::vector<DemoStage> DemoStages(const DemoSettings& d) {
  const fs::path dir(d.output);
  const std::string dataset = (dir / "dataset").string();
  const bool quick = d.quick;
  std::vector<DemoStage> stages = {
      {"synth", "a tabletop with a hidden window light, ground truth and an AprilTag mat", RunSynth,
       quick ? CommandArgs{"--scene", "window", "-o", dataset, "--res", "100x75", "--views", "24", "--test-views", "2",
                           "--preset", "fast", "--contact-sheet", "0"}
             : CommandArgs{"--scene", "window", "-o", dataset, "--res", "200x150", "--views", "60", "--test-views", "4",
                           "--preset", "fast"},
       (dir / "dataset" / "transforms_train.json").string()},
      {"train", "the HDR NeRF, fast preset", RunTrain, TrainArgs(d), (dir / "scene.nerf").string()},
      {"env", "the distant light the NeRF does not hold", RunEnv,
       quick ? CommandArgs{(dir / "scene.nerf").string(), "-o", (dir / "env.json").string(), "--preview",
                           (dir / "env.exr").string(), "--preset", "fast", "--set", "views=12", "--set",
                           "pixels_per_view=32", "--set", "rays_per_point=64", "--set", "iterations=4", "--set",
                           "brisque_max=100"}
             : CommandArgs{(dir / "scene.nerf").string(), "-o", (dir / "env.json").string(), "--preview",
                           (dir / "env.exr").string(), "--preset", "fast"},
       (dir / "env.json").string()},
      {"bake", "the torus's visibility field (shadows)", RunBake,
       quick ? CommandArgs{(dir / "dataset" / "objects" / "torus_diffuse.obj").string(), "--material",
                           (dir / "dataset" / "objects" / "torus_diffuse.json").string(), "-o",
                           (dir / "torus.ssdf").string(), "--preset", "fast", "--grid", "8", "--dirs", "12",
                           "--components", "8"}
             : CommandArgs{(dir / "dataset" / "objects" / "torus_diffuse.obj").string(), "--material",
                           (dir / "dataset" / "objects" / "torus_diffuse.json").string(), "-o",
                           (dir / "torus.ssdf").string(), "--preset", "fast"},
       (dir / "torus.ssdf").string()},
  };
  stages.push_back(LiveStage(d));
  return stages;
}

// Runs the stages in order, reusing those finished before (but live); each
// stage's wall time goes into `timing`. Returns the first failing stage's
// exit code, 0 when all ran.
int RunStages(const std::vector<DemoStage>& stages, const DemoSettings& d, Json* timing) {
  const fs::path dir(d.output);
  for (size_t i = 0; i < stages.size(); ++i) {
    const DemoStage& s = stages[i];
    const fs::path done = dir / "stages" / (s.name + ".done");
    std::error_code error;
    const bool reuse =
        !d.restart && s.name != "live" && fs::is_regular_file(done, error) && fs::is_regular_file(s.output, error);
    std::printf("== %zu/%zu %s: %s%s\n", i + 1, stages.size(), s.name.c_str(), s.what.c_str(),
                reuse ? " (done before: reused)" : "");
    std::fflush(stdout);
    const auto t0 = std::chrono::steady_clock::now();
    if (!reuse) {
      const int code = s.run(s.args);
      if (code != 0) {
        LogWarning("demo: stage " + s.name + " failed with exit code " + std::to_string(code));
        return code;
      }
      if (!fs::is_regular_file(s.output, error))
        throw std::runtime_error("demo: stage " + s.name + " did not write " + s.output);
      WriteFileAtomic(done.string(), s.output + "\n");
    }
    // The board of the dataset beside the NeRF makes DIR a SCENE folder.
    if (s.name == "synth") {
      const fs::path board = dir / "board.json";
      if (!fs::is_regular_file(board, error))
        WriteFileAtomic(board.string(), ReadFileBytes((dir / "dataset" / "board.json").string()));
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    timing->push_back({{"stage", s.name}, {"seconds", seconds}, {"reused", reuse}});
  }
  return 0;
}

// The timing report: stage wall times and the live session's figures,
// printed and written to DIR/timing.json.
void ReportTiming(const DemoSettings& d, const Json& timing, double total) {
  const fs::path dir(d.output);
  Json live_summary = Json::object();
  std::error_code error;
  if (fs::is_regular_file(dir / "session" / "report.json", error)) {
    const Json report = ReadJsonFile((dir / "session" / "report.json").string());
    if (report.contains("performance")) live_summary = report["performance"];
  }
  std::printf("\n%-8s %10s  %s\n", "stage", "seconds", "");
  for (const Json& t : timing)
    std::printf("%-8s %10.1f  %s\n", t["stage"].get<std::string>().c_str(), t["seconds"].get<double>(),
                t["reused"].get<bool>() ? "reused" : "");
  std::printf("%-8s %10.1f\n", "total", total);
  if (live_summary.contains("stages")) {
    std::printf("\nlive, per frame (ms)   median      p90\n");
    for (const auto& [name, v] : live_summary["stages"].items())
      if (v["median_ms"].is_number())
        std::printf("  %-18s %8.2f %8.2f\n", name.c_str(), v["median_ms"].get<double>(),
                    v["p90_ms"].is_number() ? v["p90_ms"].get<double>() : 0.0);
  }
  const Json document = {{"total_seconds", total}, {"threads", ThreadCount()},
                         {"quick", d.quick},       {"mode", d.window_mode ? "window" : "headless"},
                         {"stages", timing},       {"live", live_summary}};
  WriteJsonFile((dir / "timing.json").string(), document);
}

}  // namespace

int RunDemo(const CommandArgs& args) {
  DemoSettings d;
  if (!ParseDemoSettings(args, &d)) return 0;
  MakeDirectories((fs::path(d.output) / "stages").string());
  const std::vector<DemoStage> stages = DemoStages(d);
  Json timing = Json::array();
  const auto t_demo = std::chrono::steady_clock::now();
  if (const int code = RunStages(stages, d, &timing); code != 0) return code;
  const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_demo).count();
  ReportTiming(d, timing, total);
  const std::string& output = d.output;
  if (!d.window_mode)
    std::printf("\ndemo: %s/demo.mp4, %s/contact_sheet.png, %s/timing.json, report %s/session/report.png\n",
                output.c_str(), output.c_str(), output.c_str(), output.c_str());
  std::printf("then: nerfar live --source synthetic:window,size=%s,spp=1 --scene %s\n", d.size.c_str(), output.c_str());
  return 0;
}

}  // namespace nerfar
