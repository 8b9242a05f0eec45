// SIGINT and SIGTERM end `nerfar train`, `capture`, `env` and `live` cleanly
// (app/stop_signal.h): the command is started as a child process, signalled
// once it is at work, and must exit with 128 + the signal's number having
// written what it keeps (train: the checkpoint of the step it stopped at,
// which the same command resumes; capture: a consistent dataset; live: the
// session, report and video) and leaving no temporary file; env, which has
// nothing to keep, leaves an earlier env.json as it was.
#include <gtest/gtest.h>

#include <cmath>
#include <csignal>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <regex>
#include <string>
#include <thread>

#include "calib/board.h"
#include "calib/camera_file.h"
#include "calib/core/atomic_file.h"
#include "calib/core/exr.h"
#include "calib/core/json.h"
#include "calib/dataset.h"
#include "render/lighting/env_light.h"
#include "render/mesh/mesh.h"
#include "render/nerf/nerf_field.h"
#include "render/nerf/nerf_file.h"
#include "render/synth/camera_stream.h"
#include "render/synth/scenes.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

namespace fs = std::filesystem;

// Temporary files (".NAME.tmpPID_N.EXT") anywhere under dir.
std::vector<std::string> TemporaryFiles(const std::string& dir) {
  std::vector<std::string> found;
  for (const auto& entry : fs::recursive_directory_iterator(dir))
    if (entry.path().filename().string().find(".tmp") != std::string::npos) found.push_back(entry.path().string());
  return found;
}

std::string SignalName(int signal) { return signal == SIGINT ? "SIGINT" : "SIGTERM"; }

// A dataset of four 24x18 views of a grey box (enough for training steps).
void WriteSmallDataset(const std::string& dir) {
  Dataset dataset;
  dataset.dir = dir;
  dataset.camera.width = 24;
  dataset.camera.height = 18;
  dataset.camera.fx = dataset.camera.fy = 20;
  dataset.camera.cx = 12;
  dataset.camera.cy = 9;
  dataset.aabb = Aabb{{-0.3, -0.3, -0.1}, {0.3, 0.3, 0.3}};
  MakeDirectories(dir + "/train");
  for (int i = 0; i < 4; ++i) {
    DatasetFrame frame;
    frame.file_path = "train/r_00" + std::to_string(i) + ".exr";
    frame.image_path = dir + "/" + frame.file_path;
    const double a = 1.5 * i;
    frame.T_world_camera = LookAt({std::cos(a), std::sin(a), 0.6}, {0, 0, 0});
    ImageF image(24, 18, 3, 0.2f);
    for (int y = 6; y < 12; ++y)
      for (int x = 8; x < 16; ++x) image.at(x, y, 0) = image.at(x, y, 1) = image.at(x, y, 2) = 0.8f;
    WriteExrRgb(frame.image_path, image);
    dataset.frames.push_back(frame);
  }
  WriteDataset(dir + "/transforms_train.json", dataset);
}

std::vector<std::string> TrainArguments(const std::string& dir) {
  // Endless (a million steps), a checkpoint every 0.2 s of training, a coarse grid.
  return {NERFAR_BINARY,
          "train",
          dir + "/ds",
          "-o",
          dir + "/m.nerf",
          "--preset",
          "fast",
          "--set",
          "steps=1000000",
          "--set",
          "levels=1",
          "--set",
          "coarse_voxel_m=0.05",
          "--set",
          "rays_per_step=256",
          "--set",
          "eval_views=0",
          "--checkpoint-seconds",
          "0.2",
          "--threads",
          "1"};
}

TEST(Signals, TrainWritesTheCheckpointOfTheStepItStoppedAtAndResumesFromIt) {
  for (const int signal : {SIGTERM, SIGINT}) {
    SCOPED_TRACE(SignalName(signal));
    testing::TempDir dir;
    WriteSmallDataset(dir.File("ds"));
    testing::ChildProcess train(TrainArguments(dir.path()));
    // A periodic checkpoint proves the loop is running.
    ASSERT_TRUE(testing::WaitUntil([&] { return fs::exists(dir.File("m.nerf.ckpt")); }, 60)) << train.output();
    train.Signal(signal);
    ASSERT_EQ(train.Wait(60), 128 + signal) << train.output();
    std::smatch stopped;
    const std::string output = train.output();
    ASSERT_TRUE(std::regex_search(output, stopped, std::regex("stopped at step ([0-9]+); checkpoint"))) << output;
    EXPECT_TRUE(TemporaryFiles(dir.path()).empty());
    EXPECT_FALSE(fs::exists(dir.File("m.nerf"))) << "an interrupted run writes no model";

    // The same command resumes at that very step (one more step, then the model).
    const int step = std::stoi(stopped[1]);
    std::vector<std::string> again = TrainArguments(dir.path());
    again.push_back("--stop-at-step");
    again.push_back(std::to_string(step + 1));
    testing::ChildProcess resumed(again);
    EXPECT_EQ(resumed.Wait(120), 0) << resumed.output();
    EXPECT_NE(resumed.output().find("at step " + std::to_string(step) + " ("), std::string::npos) << resumed.output();
    EXPECT_TRUE(fs::exists(dir.File("m.nerf")));
  }
}

TEST(Signals, CaptureEndsAfterTheViewInProgressWithAConsistentDataset) {
  for (const int signal : {SIGINT, SIGTERM}) {
    SCOPED_TRACE(SignalName(signal));
    testing::TempDir dir;
    synth::CameraStreamOptions stream;
    stream.scene = "lamps";
    stream.width = 640;
    stream.height = 480;
    const synth::SyntheticCameraSource truth(stream);
    WriteBoard(dir.File("board.json"), truth.board());
    CameraFile camera;
    camera.camera = truth.camera();
    WriteCameraFile(dir.File("camera.json"), camera);
    testing::ChildProcess capture({NERFAR_BINARY, "capture", "--source", "synthetic:lamps,size=640x480,spp=1,speed=4",
                                   "--board", dir.File("board.json"), "--camera", dir.File("camera.json"), "-o",
                                   dir.File("ds"), "--views", "1000", "--test-every", "2", "--threads", "1"});
    ASSERT_TRUE(testing::WaitUntil([&] { return fs::exists(dir.File("ds/capture_log.json")); }, 60))
        << capture.output();
    capture.Signal(signal);
    ASSERT_EQ(capture.Wait(60), 128 + signal) << capture.output();
    EXPECT_TRUE(TemporaryFiles(dir.path()).empty());
    // Every view in the log is in a split and on disk, and the other way round.
    const Json log = ReadJsonFile(dir.File("ds/capture_log.json"));
    const Dataset train = ReadDataset(dir.File("ds/transforms_train.json"));
    const Dataset test = ReadDataset(dir.File("ds/transforms_test.json"));
    EXPECT_GE(log.at("views").size(), 1u);
    EXPECT_EQ(log.at("views").size(), train.frames.size() + test.frames.size());
  }
}

TEST(Signals, EnvEndsAtOnceLeavingAnEarlierResultWhole) {
  testing::TempDir dir;
  // An opaque slab (table top z = 0), as the live tests' scene.
  NerfField nerf = NerfField::Dense({{-0.6, -0.4, -0.04}, {0.6, 0.4, 0.0}}, 0.02, std::log(5000.0f), {-1, -1, -1});
  nerf.UpdateOccupancy(1.0f);
  SaveNerf(dir.File("scene.nerf"), nerf);
  testing::WriteText(dir.File("env.json"), "an earlier estimate");
  for (const int signal : {SIGTERM, SIGINT}) {
    SCOPED_TRACE(SignalName(signal));
    testing::ChildProcess env({NERFAR_BINARY, "env", dir.File("scene.nerf"), "-o", dir.File("env.json"), "--preset",
                               "accurate", "--threads", "1"});
    ASSERT_TRUE(env.WaitForOutput("env: " + dir.File("scene.nerf"), 60)) << env.output();
    env.Signal(signal);
    ASSERT_EQ(env.Wait(60), 128 + signal) << env.output();
    EXPECT_EQ(testing::ReadText(dir.File("env.json")), "an earlier estimate");
    EXPECT_TRUE(TemporaryFiles(dir.path()).empty());
  }
}

TEST(Signals, LiveWritesItsSessionReportAndVideo) {
  for (const int signal : {SIGTERM, SIGINT}) {
    SCOPED_TRACE(SignalName(signal));
    testing::TempDir dir;
    NerfField nerf = NerfField::Dense({{-0.6, -0.4, -0.04}, {0.6, 0.4, 0.0}}, 0.02, std::log(5000.0f), {-1, -1, -1});
    nerf.UpdateOccupancy(1.0f);
    SaveNerf(dir.File("scene.nerf"), nerf);
    WriteBoard(dir.File("board.json"), synth::MakeTagBoard());
    WriteMeshObj(dir.File("cube.obj"), MakeBox({0.03, 0.03, 0.03}));
    const std::string session = dir.File("session");
    testing::ChildProcess live({NERFAR_BINARY, "live", "--headless", "--source", "synthetic:lamps,size=640x480,spp=1",
                                "--scene", dir.path(), "--object", dir.File("cube.obj"), "-o", session, "--frames",
                                "100000", "--views", "ar", "--threads", "1"});
    // The video's temporary file appears with the first frame.
    ASSERT_TRUE(testing::WaitUntil([&] { return fs::is_directory(session) && !TemporaryFiles(session).empty(); }, 60))
        << live.output();
    live.Signal(signal);
    ASSERT_EQ(live.Wait(60), 128 + signal) << live.output();
    for (const char* name : {"session.json", "report.json", "report.png", "live.mp4", "last_ar.png"})
      EXPECT_TRUE(fs::is_regular_file(session + "/" + name)) << name << "\n" << live.output();
    EXPECT_TRUE(TemporaryFiles(dir.path()).empty());
    EXPECT_GE(ReadJsonFile(session + "/session.json").at("frames").size(), 1u);
  }
}

}  // namespace
}  // namespace nerfar
