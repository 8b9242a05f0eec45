// The `nerfar` executable as a user meets it: help, exit codes 0/1/2 and
// messages that name what is wrong.
#include <gtest/gtest.h>

#include <cctype>
#include <cmath>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>

#include "app/cli.h"
#include "calib/board.h"
#include "calib/camera_file.h"
#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "calib/core/image_io.h"
#include "calib/core/json.h"
#include "render/lighting/env_light.h"
#include "render/mesh/mesh.h"
#include "render/nerf/nerf_field.h"
#include "render/nerf/nerf_file.h"
#include "render/synth/scenes.h"
#include "tests/support/nerfar_command.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

using Result = testing::CommandResult;
using testing::RunNerfar;

TEST(App, HelpListsTheCommands) {
  const Result result = RunNerfar("help");
  EXPECT_EQ(result.exit_code, 0);
  EXPECT_NE(result.output.find("bench"), std::string::npos) << result.output;
  EXPECT_EQ(RunNerfar("").exit_code, 0);
}

TEST(App, EveryCommandHasHelp) {
  for (const char* command : {"bench", "version", "board", "import"}) {
    const Result result = RunNerfar(std::string(command) + " --help");
    EXPECT_EQ(result.exit_code, 0) << command;
    EXPECT_NE(result.output.find("usage: nerfar"), std::string::npos) << command << ": " << result.output;
  }
}

// A user reading `calibrate --help` must learn which detector preset runs
// when --detector is left out.
TEST(App, CalibrateHelpStatesTheDetectorDefault) {
  const Result result = RunNerfar("calibrate --help");
  EXPECT_EQ(result.exit_code, 0);
  EXPECT_NE(result.output.find("(default accurate)"), std::string::npos) << result.output;
}

TEST(App, UnknownCommandAndBadFlagsExitTwo) {
  Result result = RunNerfar("frobnicate");
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_NE(result.output.find("unknown command 'frobnicate'"), std::string::npos);
  result = RunNerfar("bench --no-such-flag");
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_NE(result.output.find("unknown option --no-such-flag"), std::string::npos) << result.output;
  result = RunNerfar("bench --threads two");
  EXPECT_EQ(result.exit_code, 2);
  result = RunNerfar("bench nosuchstage");
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_NE(result.output.find("unknown stage 'nosuchstage'"), std::string::npos);
}

TEST(App, BenchWritesTableAndJson) {
  testing::TempDir dir;
  const Result result = RunNerfar("bench core --quick --threads 1 --json " + dir.File("b.json"));
  ASSERT_EQ(result.exit_code, 0) << result.output;
  EXPECT_NE(result.output.find("exr_read_half_ms"), std::string::npos);
  const std::string json = testing::ReadText(dir.File("b.json"));
  EXPECT_NE(json.find("\"threads\": 1"), std::string::npos) << json;
  EXPECT_NE(json.find("exr_write_float_ms"), std::string::npos);
}

// bench live with its smallest settings (--quick: 640x360, 8 frames a run,
// fast preset, 1 thread): it runs the three motions through the threaded
// pipeline and reports fps, drops, stage and latency percentiles for each.
TEST(App, BenchLiveQuickReportsEveryMotion) {
  testing::TempDir dir;
  const Result result = RunNerfar("bench live --quick --json " + dir.File("b.json"));
  ASSERT_EQ(result.exit_code, 0) << result.output;
  const Json report = ReadJsonFile(dir.File("b.json"));
  std::map<std::string, double> figures;
  for (const Json& f : report.at("stages").at("live").at("figures"))
    figures[f.at("name").get<std::string>()] = f.at("value").is_number() ? f["value"].get<double>() : NAN;
  EXPECT_GT(figures.count("floor_frame_copy_ms"), 0u);
  for (const char* motion : {"still", "handheld", "drag"}) {
    const std::string label = std::string(motion) + "_fast_t1";
    for (const char* figure : {"_fps", "_dropped", "_latency_p50_ms", "_latency_p90_ms", "_process_p50_ms",
                               "_track_p90_ms", "_insert_p50_ms", "_display_p90_ms"})
      EXPECT_EQ(figures.count(label + figure), 1u) << label + figure << "\n" << result.output;
    // Frames fed after the warm-up are either displayed or dropped.
    const double fps = figures[label + "_fps"], dropped = figures[label + "_dropped"];
    EXPECT_GE(fps, 0);
    EXPECT_GE(dropped, 0);
    EXPECT_NEAR(fps / 30.0 * 6 + dropped, 6.0, 1e-9) << label;
  }
}

// A tiny SCENE folder built here: an opaque slab NeRF whose top is the table
// plane z = 0 (dense grid, 2 cm voxels), the synthetic board, a one-lobe
// environment and a 6 cm cube mesh (no .ssdf: no shadows).
void WriteTinyScene(const std::string& dir) {
  const Aabb slab{{-0.6, -0.4, -0.04}, {0.6, 0.4, 0.0}};
  NerfField nerf = NerfField::Dense(slab, 0.02, std::log(5000.0f), Vec3f{-1.0f, -1.0f, -1.0f});
  nerf.UpdateOccupancy(1.0f);
  SaveNerf(dir + "/scene.nerf", nerf);
  WriteBoard(dir + "/board.json", synth::MakeTagBoard());
  EnvLight env;
  env.lobes.push_back(Sg{{0, 0, 1}, 4.0, {2.0, 2.0, 2.0}});
  WriteEnvLight(dir + "/env.json", env);
  WriteMeshObj(dir + "/cube.obj", MakeBox({0.03, 0.03, 0.03}));
}

TEST(App, LiveDemoReportRejectBadArgumentsWithExitTwo) {
  testing::TempDir dir;
  Result r = RunNerfar("live");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("--source"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("--scene"), std::string::npos) << r.output;
  r = RunNerfar("live --source synthetic --scene " + dir.File("nothing"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("not a folder"), std::string::npos) << r.output;
  r = RunNerfar("live --source synthetic --scene " + dir.path() + " --preset turbo --views ar,sideways");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("turbo"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("sideways"), std::string::npos) << r.output;
  r = RunNerfar("live --source synthetic --scene " + dir.path());  // a folder without scene.nerf
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("scene.nerf"), std::string::npos) << r.output;
  r = RunNerfar("live --source synthetic --scene " + dir.path() + " --anchor 1,2");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("--anchor"), std::string::npos) << r.output;
  r = RunNerfar("report " + dir.File("nothing"));
  EXPECT_EQ(r.exit_code, 2);
  r = RunNerfar("report");
  EXPECT_EQ(r.exit_code, 2);
  r = RunNerfar("demo --minutes -1 --size 10x10 -o " + dir.File("d"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("--minutes"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("--size"), std::string::npos) << r.output;
  for (const char* command : {"live", "demo", "report"})
    EXPECT_EQ(RunNerfar(std::string(command) + " --help").exit_code, 0);
}

TEST(App, LiveHeadlessWritesVideoSheetSessionAndReport) {
  testing::TempDir dir;
  WriteTinyScene(dir.path());
  const std::string session = dir.File("session");
  const Result r =
      RunNerfar("live --headless --threads 2 --source synthetic:lamps,size=640x480,spp=1,frames=40 --scene " +
                dir.path() + " --object " + dir.File("cube.obj") + " -o " + session + " --frames 8" +
                " --set kappa_step=3 --set light_source=near --set seen_group_m=0.03");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* name : {"live.mp4", "contact_sheet.png", "session.json", "report.json", "report.png", "report.html",
                           "last_ar.png", "last_alongside.png", "last_layers.png"})
    EXPECT_TRUE(std::filesystem::is_regular_file(session + "/" + name)) << name << "\n" << r.output;
  const Json s = ReadJsonFile(session + "/session.json");
  ASSERT_EQ(s.at("frames").size(), 8u);
  // --set holds over the fast preset (kappa_step 4, light source full).
  EXPECT_EQ(s.at("insert_options").at("kappa_step"), 3);
  EXPECT_EQ(s.at("insert_options").at("light_source"), "near");
  EXPECT_EQ(s.at("insert_options").at("occlusion_step"), 4) << "the fast preset's, untouched";
  // The NeRF scene's knobs take --set too, over the same preset's (fast: 2 cm cells, cached).
  EXPECT_EQ(s.at("nerf_scene_options").at("seen_group_m"), 0.03);
  EXPECT_EQ(s.at("nerf_scene_options").at("seen_cache_views"), true) << "the fast preset's, untouched";
  const Json report = ReadJsonFile(session + "/report.json");
  EXPECT_EQ(report.at("tracking").at("frames").get<int>(), 8);
  // The synthetic stream knows its poses: the report compares against them.
  // Tracking 640x480 frames of the lamps mat from ~0.85 m: within 2 cm (the
  // tracker's own tests hold it to a few mm; this checks that the truth
  // reaches the report and that the frames were tracked, not their accuracy).
  ASSERT_TRUE(report["tracking"]["error_vs_truth_mm"].is_number()) << report.dump();
  EXPECT_LT(report["tracking"]["error_vs_truth_mm"].get<double>(), 20.0);
  EXPECT_GT(report["tracking"]["tracking"].get<int>() + report["tracking"]["recovering"].get<int>(), 0);
  // Re-reporting the session is the `report` command.
  const Result again = RunNerfar("report " + session);
  EXPECT_EQ(again.exit_code, 0) << again.output;
  EXPECT_NE(again.output.find("tracking"), std::string::npos) << again.output;
  // A SCENE without sessions/ reports its scene items only.
  const Result scene = RunNerfar("report " + dir.path());
  EXPECT_EQ(scene.exit_code, 0) << scene.output;
  EXPECT_NE(scene.output.find("environment energy"), std::string::npos) << scene.output;
  EXPECT_TRUE(std::filesystem::is_regular_file(dir.File("report.png")));
}

// A video that cannot be written (its folder is a file) is reported and the
// run goes on: the session and report are written, the exit code is 1.
// --loop: an image folder of two frames feeds five; without it the stream
// ends after its two.
TEST(App, LiveLoopStartsAnImageFolderOver) {
  testing::TempDir dir;
  WriteTinyScene(dir.path());
  MakeDirectories(dir.File("frames"));
  for (const char* name : {"a.png", "b.png"}) WriteImage8(dir.File("frames/") + name, Image8(64, 48, 3, 120));
  CameraFile camera;
  camera.camera.width = 64;
  camera.camera.height = 48;
  camera.camera.fx = camera.camera.fy = 60;
  camera.camera.cx = 32;
  camera.camera.cy = 24;
  WriteCameraFile(dir.File("camera.json"), camera);
  const std::string common = "live --headless --threads 2 --source images:" + dir.File("frames") + " --camera " +
                             dir.File("camera.json") + " --scene " + dir.path() + " --object " + dir.File("cube.obj") +
                             " --views ar --frames 5 -o ";
  for (const bool loop : {true, false}) {
    const std::string session = dir.File(loop ? "looped" : "once");
    const Result r = RunNerfar(common + session + (loop ? " --loop" : ""));
    ASSERT_EQ(r.exit_code, 0) << r.output;
    const Json counters = ReadJsonFile(session + "/session.json").at("counters");
    EXPECT_EQ(counters.at("captured").get<int>(), loop ? 5 : 2) << counters.dump();
  }
}

TEST(App, LiveHeadlessReportsAVideoItCannotWriteAndStillWritesTheSession) {
  testing::TempDir dir;
  WriteTinyScene(dir.path());
  testing::WriteText(dir.File("a_file"), "not a folder");
  const std::string session = dir.File("session");
  const std::string video = dir.File("a_file/live.mp4");
  const Result r = RunNerfar(
      "live --headless --threads 2 --source synthetic:lamps,size=640x480,spp=1,frames=40 --scene " + dir.path() +
      " --object " + dir.File("cube.obj") + " -o " + session + " --frames 3 --views ar --video " + video);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find(video), std::string::npos) << r.output;
  for (const char* name : {"session.json", "report.json", "report.png", "last_ar.png"})
    EXPECT_TRUE(std::filesystem::is_regular_file(session + "/" + name)) << name << "\n" << r.output;
  const Json report = ReadJsonFile(session + "/report.json");
  EXPECT_EQ(report.at("errors").at("outputs").get<int>(), 1) << report.dump();
  EXPECT_EQ(report.at("tracking").at("frames").get<int>(), 3);
}

// `nerfar env` on the tiny scene's slab: bad --truth or --report are usage
// errors (exit 2, the file named) found before the estimate runs; a small
// estimate with a truth states the fit residual and the irradiance error and
// writes the report picture beside env.json, or into the folder --report names.
TEST(App, EnvReportsTheFitAndRejectsBadTruth) {
  testing::TempDir dir;
  WriteTinyScene(dir.path());
  const std::string env = "env " + dir.File("scene.nerf") + " -o " + dir.File("e.json");
  Result r = RunNerfar(env + " --truth " + dir.File("nope.exr"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find(dir.File("nope.exr")), std::string::npos) << r.output;
  WriteExrRgb(dir.File("square.exr"), ImageF(16, 16, 3, 1.0f));
  r = RunNerfar(env + " --truth " + dir.File("square.exr"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find(dir.File("square.exr") + ": is 16x16 (expected an equirect panorama"), std::string::npos)
      << r.output;
  r = RunNerfar(env + " --report " + dir.File("report.txt"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("report.txt"), std::string::npos) << r.output;
  EXPECT_EQ(RunNerfar(env + " --report " + dir.File("r.png") + " --no-report").exit_code, 2);
  EXPECT_FALSE(std::filesystem::exists(dir.File("e.json")));

  WriteExrRgb(dir.File("truth.exr"), ImageF(64, 32, 3, 0.5f), ExrPixelType::kFloat);
  const std::string small = " --preset fast --set views=6 --set pixels_per_view=32 --set rays_per_point=32 --threads 2";
  r = RunNerfar(env + " --truth " + dir.File("truth.exr") + small);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("fit residual over"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("irradiance error against " + dir.File("truth.exr")), std::string::npos) << r.output;
  const Image8 picture = ReadImage8(dir.File("e_report.png"));
  EXPECT_GT(picture.width, 1000);
  EXPECT_GT(picture.height, picture.width);  // panoramas, views, legend and text stacked
  const Json written = ReadJsonFile(dir.File("e.json"));
  EXPECT_GT(written.at("fit").at("samples").get<int>(), 0) << written.dump();
  r = RunNerfar("env " + dir.File("scene.nerf") + " -o " + dir.File("e2.json") + " --report " + dir.File("pics") + "/" +
                small);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(std::filesystem::is_regular_file(dir.File("pics/e2_report.png")));
  EXPECT_FALSE(std::filesystem::exists(dir.File("e2_report.png")));
}

TEST(ArgParser, ParsesOptionsPositionalsAndRejectsMisuse) {
  std::string input, output;
  int count = 3;
  double scale = 1.0;
  bool flag = false;
  ArgParser parser("test", "a test command");
  parser.Positional("INPUT", &input, "input");
  parser.Option("-o", &output, "FILE", "output");
  parser.Option("--count", &count, "N", "count");
  parser.Option("--scale", &scale, "S", "scale");
  parser.Flag("--flag", &flag, "a flag");
  ASSERT_TRUE(parser.Parse({"in.json", "-o", "out", "--count=7", "--scale", "-0.5", "--flag", "--threads", "1"}));
  EXPECT_EQ(input, "in.json");
  EXPECT_EQ(output, "out");
  EXPECT_EQ(count, 7);
  EXPECT_EQ(scale, -0.5);
  EXPECT_TRUE(flag);
  EXPECT_THROW(ArgParser("t", "").Parse({"extra"}), InputError);
  ArgParser missing("t", "");
  missing.Positional("X", &input, "x");
  EXPECT_THROW(missing.Parse({}), InputError);
  ArgParser twice("t", "");
  twice.Option("--count", &count, "N", "");
  EXPECT_THROW(twice.Parse({"--count", "1", "--count", "2"}), InputError);
  EXPECT_THROW(twice.Parse({"--count", "1x"}), InputError);
  EXPECT_THROW(twice.Parse({"--quiet", "--verbose"}), InputError);
}

TEST(ArgParser, RequiredOptionsAreMarkedInHelpAndEnforced) {
  std::string output, board;
  ArgParser parser("test", "a test command");
  parser.Option("-o", &output, "FILE", "output");
  parser.Option("--board", &board, "B", "board");
  parser.Required("-o");
  const std::string help = parser.Help();
  EXPECT_NE(help.find("output (required)\n"), std::string::npos) << help;
  EXPECT_EQ(help.find("board (required)"), std::string::npos) << help;
  const auto message = [](ArgParser& p, const std::vector<std::string>& args) {
    try {
      p.Parse(args);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("(no error)");
  };
  EXPECT_NE(message(parser, {"--board", "b.json"}).find("missing -o FILE (required)"), std::string::npos);
  EXPECT_NE(message(parser, {"-o", ""}).find("-o is empty"), std::string::npos);
  EXPECT_THROW(parser.Required("--nothing"), std::logic_error);
  ASSERT_TRUE(parser.Parse({"-o", "out.json"}));
  EXPECT_EQ(output, "out.json");
  // --help needs no required option.
  ArgParser helped("test", "");
  helped.Option("-o", &output, "FILE", "output");
  helped.Required("-o");
  EXPECT_FALSE(helped.Parse({"--help"}));
}

// The guide's option tables and every command's --help agree on which
// options are required: a row of a command's section whose default is
// "required" is marked "(required)" by the parser in that command's --help,
// and no other option is.
TEST(App, GuideTablesAndHelpAgreeOnRequiredOptions) {
  std::istringstream guide(testing::ReadText(testing::SourcePath("docs/USER_GUIDE.md")));
  std::map<std::string, std::set<std::string>> guide_required;
  std::string command, line;
  while (std::getline(guide, line)) {
    if (line.rfind("## ", 0) == 0) {
      const size_t at = line.find("(`nerfar ");
      command = at == std::string::npos ? "" : line.substr(at + 9, line.find('`', at + 9) - at - 9);
      if (!command.empty()) guide_required[command];
    }
    if (command.empty() || line.rfind("| `-", 0) != 0) continue;
    const std::string flag = line.substr(3, line.find_first_of(" `", 3) - 3);
    const size_t cell = line.find('|', 1) + 1;
    const std::string default_cell = line.substr(cell, line.find('|', cell) - cell);
    if (default_cell == " required ") guide_required[command].insert(flag);
  }
  ASSERT_GE(guide_required.size(), 12u) << "commands with a section in the guide";
  for (const auto& [name, expected] : guide_required) {
    const Result result = RunNerfar(name + " --help");
    ASSERT_EQ(result.exit_code, 0) << name;
    std::set<std::string> marked;
    std::istringstream help(result.output);
    while (std::getline(help, line))
      if (line.rfind("  -", 0) == 0 && line.size() > 11 && line.substr(line.size() - 11) == " (required)")
        marked.insert(line.substr(2, line.find(' ', 2) - 2));
    EXPECT_EQ(marked, expected) << "nerfar " << name << " --help against docs/USER_GUIDE.md:\n" << result.output;
  }
}

// train and env take --set through the one parser (calib/core/option_fields.h):
// an unknown key or a bad value stops either with exit code 2 naming them, and
// env's echo of its float options is the number as written (the balanced
// preset's 1e-3 and 0.03 of the guide's table, not the floats' binary digits).
TEST(App, TrainAndEnvSetKnobsThroughOneParser) {
  testing::TempDir dir;
  for (const std::string& command : {"train " + dir.path() + " -o " + dir.File("m.nerf"),
                                     "env " + dir.File("m.nerf") + " -o " + dir.File("e.json")}) {
    Result r = RunNerfar(command + " --set stpes=3");
    EXPECT_EQ(r.exit_code, 2) << command << ": " << r.output;
    EXPECT_NE(r.output.find("--set stpes=3: unknown option 'stpes' (expected one of: "), std::string::npos) << r.output;
    r = RunNerfar(command + " --set seed=abc");
    EXPECT_EQ(r.exit_code, 2) << command << ": " << r.output;
    EXPECT_NE(r.output.find("'abc' is not a valid value of seed"), std::string::npos) << r.output;
  }
  const Result help = RunNerfar("env --help");
  EXPECT_NE(help.output.find(R"("min_transmittance":0.001,)"), std::string::npos) << help.output;
  EXPECT_NE(help.output.find(R"("shadow_min_transmittance":0.03,)"), std::string::npos) << help.output;
}

// The environment variables of `nerfar bench`: each one a stage reads
// (BenchVariable("...") in app/bench_*.cpp, and no getenv of one besides) is
// listed by `nerfar bench --help` and tabled in the guide's bench section,
// and a NERFAR_BENCH_* name not listed stops the bench before any stage runs,
// naming it.
TEST(App, BenchVariablesAreReadListedDocumentedAndChecked) {
  const auto names_after = [](const std::string& text, const std::string& marker, std::set<std::string>& into) {
    for (size_t at = text.find(marker); at != std::string::npos; at = text.find(marker, at + 1)) {
      const size_t begin = at + marker.size() - std::string("NERFAR_BENCH_").size();
      size_t end = begin;
      while (end < text.size() && (std::isupper(static_cast<unsigned char>(text[end])) || text[end] == '_')) ++end;
      if (end > at + marker.size()) into.insert(text.substr(begin, end - begin));  // not the family NERFAR_BENCH_*
    }
  };
  std::set<std::string> read, read_directly, listed, tabled;
  for (const auto& entry : std::filesystem::directory_iterator(testing::SourcePath("app"))) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("bench_", 0) != 0 || entry.path().extension() != ".cpp") continue;
    const std::string source = testing::ReadText(entry.path().string());
    names_after(source, "BenchVariable(\"NERFAR_BENCH_", read);
    names_after(source, "getenv(\"NERFAR_BENCH_", read_directly);
  }
  const Result help = RunNerfar("bench --help");
  ASSERT_EQ(help.exit_code, 0);
  names_after(help.output, "\n  NERFAR_BENCH_", listed);
  names_after(testing::ReadText(testing::SourcePath("docs/USER_GUIDE.md")), "| `NERFAR_BENCH_", tabled);
  EXPECT_GE(read.size(), 30u);
  EXPECT_TRUE(read_directly.empty()) << *read_directly.begin() << " read without BenchVariable";
  EXPECT_EQ(listed, read) << help.output;
  EXPECT_EQ(tabled, read) << "the guide's table of bench variables";

  const Result r = testing::RunCommand("NERFAR_BENCH_INSERT_NREF=m.nerf NERFAR_BENCH_LIVE_FRAMES=30 " +
                                       std::string(NERFAR_BINARY) + " bench insert --quick");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("unknown environment variable NERFAR_BENCH_INSERT_NREF ("), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("nerfar bench  "), std::string::npos) << "no stage ran: " << r.output;
  // The insert stage's knobs go through the --set parser: a misspelt knob
  // stops the stage before it measures anything, naming the knob.
  const Result knob = testing::RunCommand("NERFAR_BENCH_INSERT_KNOBS=kappa_step=4,shade_stp=2 " +
                                          std::string(NERFAR_BINARY) + " bench insert --quick");
  EXPECT_EQ(knob.exit_code, 2) << knob.output;
  EXPECT_NE(knob.output.find("NERFAR_BENCH_INSERT_KNOBS shade_stp=2: unknown option 'shade_stp'"), std::string::npos)
      << knob.output;
  EXPECT_EQ(knob.output.find("insert     "), std::string::npos) << "no figure: " << knob.output;
}

}  // namespace
}  // namespace nerfar
