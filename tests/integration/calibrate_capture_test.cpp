// The offline jobs a user runs before training, end to end through the
// `nerfar` executable, on the synthetic camera of render/synth (known
// intrinsics and poses): calibrate recovers the intrinsics; capture turns a
// tracked stream into a dataset whose poses match the truth and which the
// dataset reader (the trainer's input) accepts.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>

#include "calib/board.h"
#include "calib/camera_file.h"
#include "calib/core/atomic_file.h"
#include "calib/core/exr.h"
#include "calib/core/image_io.h"
#include "calib/core/json.h"
#include "calib/dataset.h"
#include "render/nerf/nerf_train.h"
#include "render/synth/camera_stream.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

int RunNerfar(const std::string& arguments, std::string* output = nullptr) {
  testing::CommandResult result = testing::RunCommand(std::string(NERFAR_BINARY) + " " + arguments);
  if (output != nullptr) *output = std::move(result.output);
  return result.exit_code;
}

synth::CameraStreamOptions StreamOptions() {
  synth::CameraStreamOptions options;
  options.scene = "lamps";
  options.width = 640;
  options.height = 480;
  options.samples_per_pixel = 2;
  options.speed = 4;  // cover more of the trajectory in few frames
  return options;
}

// Board images of the synthetic stream at times t_s, as frame_NNN.png in dir.
void WriteBoardViews(const synth::SyntheticCameraSource& source, const std::vector<double>& t_s,
                     const std::string& dir) {
  MakeDirectories(dir);
  for (size_t i = 0; i < t_s.size(); ++i) {
    const Frame frame = source.RenderFrame(t_s[i], static_cast<std::int64_t>(i));
    char name[32];
    std::snprintf(name, sizeof name, "frame_%03zu.png", i);
    WriteImage8(dir + "/" + name, frame.image);
  }
}

TEST(Calibrate, RecoversTheSyntheticCamerasIntrinsics) {
  testing::TempDir dir;
  const synth::SyntheticCameraSource source(StreamOptions());
  WriteBoard(dir.File("board.json"), source.board());
  // 60 views spread over 30 s of the handheld trajectory (about 5 orbits at speed 4).
  std::vector<double> times;
  for (int i = 0; i < 60; ++i) times.push_back(0.5 * i);
  WriteBoardViews(source, times, dir.File("frames"));
  std::string output;
  const int code = RunNerfar("calibrate --board " + dir.File("board.json") + " --images " + dir.File("frames") +
                                 " -o " + dir.File("camera.json") + " --min-tags 2 --no-tangential --square-pixels",
                             &output);
  ASSERT_EQ(code, 0) << "good views must pass the gate\n" << output;
  EXPECT_NE(output.find("calibration good"), std::string::npos) << output;
  const CameraFile file = ReadCameraFile(dir.File("camera.json"));
  const CameraIntrinsics& truth = source.camera();
  ASSERT_TRUE(file.calibration.has_value());
  const CalibrationRecord& record = *file.calibration;
  // Focal length: the 0.5 %. The principal point of these frames
  // (small tags, a camera that always looks at the table centre) is only
  // determined to a few pixels, and the calibration says so: it must lie
  // within 3 of its own reported sigmas (plus 0.5 px of detector bias). The
  // issue's 1 px on exact correspondences is tested in calib_test.
  EXPECT_LT(std::abs(file.camera.fx / truth.fx - 1), 0.005) << output;
  EXPECT_LT(std::abs(file.camera.fy / truth.fy - 1), 0.005) << output;
  EXPECT_LT(std::abs(file.camera.cx - truth.cx), 3 * record.sigma_cx + 0.5) << output;
  EXPECT_LT(std::abs(file.camera.cy - truth.cy), 3 * record.sigma_cy + 0.5) << output;
  EXPECT_LT(record.sigma_cy, 5.0) << output;
  EXPECT_LT(record.rms_px, 0.5) << output;
}

// Seven views from 0.3 s of the trajectory (around a view that sees seven
// tags) see the board from nearly one place: its corners fill a small part of
// the image, below the gate's 60 % coverage. The calibration is still
// written, with its verdict, and the exit code is 1.
TEST(Calibrate, ViewsFromOnePlaceFailTheGateWithExitOne) {
  testing::TempDir dir;
  const synth::SyntheticCameraSource source(StreamOptions());
  WriteBoard(dir.File("board.json"), source.board());
  WriteBoardViews(source, {12.85, 12.9, 12.95, 13.0, 13.05, 13.1, 13.15}, dir.File("frames"));
  std::string output;
  const int code = RunNerfar("calibrate --board " + dir.File("board.json") + " --images " + dir.File("frames") +
                                 " -o " + dir.File("camera.json") + " --min-tags 2 --no-tangential --square-pixels",
                             &output);
  EXPECT_EQ(code, 1) << output;
  EXPECT_NE(output.find("take more views"), std::string::npos) << output;
  const CameraFile file = ReadCameraFile(dir.File("camera.json"));
  ASSERT_TRUE(file.calibration.has_value());
  EXPECT_LT(file.calibration->coverage, 0.6) << output;
}

TEST(Capture, SyntheticStreamBecomesADatasetWithTruePoses) {
  testing::TempDir dir;
  synth::CameraStreamOptions options = StreamOptions();
  const synth::SyntheticCameraSource truth(options);
  WriteBoard(dir.File("board.json"), truth.board());
  CameraFile camera;
  camera.camera = truth.camera();
  WriteCameraFile(dir.File("camera.json"), camera);
  std::string output;
  const std::string source = "synthetic:lamps,size=640x480,spp=2,speed=4,frames=240";
  ASSERT_EQ(RunNerfar("capture --source " + source + " --board " + dir.File("board.json") + " --camera " +
                          dir.File("camera.json") + " -o " + dir.File("ds") + " --views 12 --test-every 4",
                      &output),
            0)
      << output;
  const Dataset train = ReadDataset(dir.File("ds/transforms_train.json"));
  const Dataset test = ReadDataset(dir.File("ds/transforms_test.json"));
  EXPECT_EQ(train.frames.size() + test.frames.size(), 12u) << output;
  EXPECT_EQ(test.frames.size(), 3u);
  ASSERT_TRUE(train.aabb.has_value());

  // Each view's pose against the true pose of the frame it came from.
  const Json log = ReadJsonFile(dir.File("ds/capture_log.json"));
  ASSERT_EQ(log["views"].size(), 12u);
  std::vector<double> rotation_deg, translation_mm;
  for (const Json& view : log["views"]) {
    const std::string file_path = view["file_path"].get<std::string>();
    const Dataset& split = file_path.rfind("test/", 0) == 0 ? test : train;
    const DatasetFrame* frame = nullptr;
    for (const DatasetFrame& f : split.frames)
      if (f.file_path == file_path) frame = &f;
    ASSERT_NE(frame, nullptr) << file_path;
    const Pose expected = truth.PoseAt(view["t_ns"].get<double>() * 1e-9);
    rotation_deg.push_back(RotationAngleBetween(frame->T_world_camera.rotation, expected.rotation) * 180 / kPi);
    translation_mm.push_back(Length(frame->T_world_camera.translation - expected.translation) * 1e3);
  }
  std::sort(rotation_deg.begin(), rotation_deg.end());
  std::sort(translation_mm.begin(), translation_mm.end());
  // Capture stores the tracker's per-frame poses; the tracker's own targets
  // (0.2 deg, 2 mm) are measured in tracking_test. On this 640x480 stream with
  // 2-4 px tag cells the tracker measures about 0.15 deg and 3 mm, so the
  // dataset must be within 0.3 deg and 5 mm of the truth (median).
  EXPECT_LT(rotation_deg[rotation_deg.size() / 2], 0.3);
  EXPECT_LT(translation_mm[translation_mm.size() / 2], 5.0);
  std::printf("capture poses: median rotation %.3f deg, translation %.2f mm\n", rotation_deg[rotation_deg.size() / 2],
              translation_mm[translation_mm.size() / 2]);
}

// Brackets end to end: the synthetic stream with simulated exposure control
// (its frames' display response, 10 ms base) -> `nerfar capture --brackets 3`
// -> an HDR dataset whose poses match the truth, whose merged views agree
// with the response, and which the NeRF trainer loads and trains on.
TEST(Capture, BracketsBecomeAnHdrDatasetTheTrainerAccepts) {
  testing::TempDir dir;
  const synth::SyntheticCameraSource truth(StreamOptions());
  WriteBoard(dir.File("board.json"), truth.board());
  CameraFile camera;
  camera.camera = truth.camera();
  camera.response = CameraResponse::Display8(3);
  WriteCameraFile(dir.File("camera.json"), camera);
  std::string output;
  const std::string source = "synthetic:lamps,size=640x480,spp=2,speed=4,frames=200,exposure-control";
  ASSERT_EQ(RunNerfar("capture --source " + source + " --board " + dir.File("board.json") + " --camera " +
                          dir.File("camera.json") + " -o " + dir.File("ds") +
                          " --views 6 --test-every 3 --brackets 3 --ev-step 1",
                      &output),
            0)
      << output;
  EXPECT_EQ(output.find("cannot set its exposure"), std::string::npos) << output;
  const Dataset train = ReadDataset(dir.File("ds/transforms_train.json"));
  const Dataset test = ReadDataset(dir.File("ds/transforms_test.json"));
  ASSERT_EQ(train.frames.size() + test.frames.size(), 6u) << output;

  // Poses: as in the single-exposure test (0.3 deg, 5 mm median).
  const Json log = ReadJsonFile(dir.File("ds/capture_log.json"));
  std::vector<double> rotation_deg, translation_mm;
  for (const Json& view : log["views"]) {
    const std::string file_path = view["file_path"].get<std::string>();
    const Dataset& split = file_path.rfind("test/", 0) == 0 ? test : train;
    for (const DatasetFrame& f : split.frames) {
      if (f.file_path != file_path) continue;
      const Pose expected = truth.PoseAt(view["t_ns"].get<double>() * 1e-9);
      rotation_deg.push_back(RotationAngleBetween(f.T_world_camera.rotation, expected.rotation) * 180 / kPi);
      translation_mm.push_back(Length(f.T_world_camera.translation - expected.translation) * 1e3);
    }
  }
  ASSERT_EQ(rotation_deg.size(), 6u);
  std::sort(rotation_deg.begin(), rotation_deg.end());
  std::sort(translation_mm.begin(), translation_mm.end());
  EXPECT_LT(rotation_deg[3], 0.3);
  EXPECT_LT(translation_mm[3], 5.0);

  // The merged HDR view against the base frame read through the response:
  // where the base frame is well exposed (20..235) both are the same linear
  // radiance up to one scale.
  const DatasetFrame& first = train.frames.front();
  const ImageF merged = ReadExrRgb(first.image_path);
  const Frame base = truth.RenderFrame(log["views"][0]["t_ns"].get<double>() * 1e-9, 0);
  std::vector<double> ratios;
  for (size_t p = 0; p < base.image.PixelCount(); ++p)
    for (int c = 0; c < 3; ++c) {
      const int z = base.image.pixels[p * 3 + c];
      const double m = merged.pixels[p * 3 + c];
      if (z >= 20 && z <= 235 && m > 0) ratios.push_back(m / camera.response->Linear(c, z));
    }
  ASSERT_GT(ratios.size(), 1000u);
  std::sort(ratios.begin(), ratios.end());
  const double median = ratios[ratios.size() / 2];
  const double q1 = ratios[ratios.size() / 4] / median, q3 = ratios[ratios.size() * 3 / 4] / median;
  std::printf("merged / base-through-response: quartiles %.3f %.3f of the median\n", q1, q3);
  // The camera moves between a bracket's frames (speed 4), so edges
  // disagree (the 10th-90th percentiles span 0.81-1.16); the quartiles are
  // flat areas: within 10 %.
  EXPECT_GT(q1, 0.9);
  EXPECT_LT(q3, 1.1);

  // The trainer takes the dataset as it is: a few steps, finite and falling loss.
  const NerfTrainData data = ReadNerfTrainData(dir.File("ds"));
  EXPECT_EQ(data.train.size(), train.frames.size());
  NerfTrainOptions options = NerfTrainOptions::Preset("fast");
  options.steps = 40;
  options.rays_per_step = 1024;
  options.levels = 1;
  options.eval_views = 0;
  NerfTrainer trainer(data, options);
  double first_loss = 0, last_loss = 0;
  for (int i = 0; i < 40; ++i) {
    const double loss = trainer.Step();
    ASSERT_TRUE(std::isfinite(loss)) << "step " << i;
    if (i < 5) first_loss += loss / 5;
    if (i >= 35) last_loss += loss / 5;
  }
  EXPECT_LT(last_loss, first_loss) << "40 steps of Adam from fog lower the loss";
}

TEST(Capture, BadInputExitsTwoWithAMessage) {
  testing::TempDir dir;
  std::string output;
  EXPECT_EQ(
      RunNerfar("capture --source synthetic --board " + dir.File("missing.json") + " --camera x -o " + dir.File("ds"),
                &output),
      2);
  EXPECT_NE(output.find("missing.json"), std::string::npos) << output;
  EXPECT_EQ(RunNerfar("calibrate --board b.json -o c.json", &output), 2);
  EXPECT_NE(output.find("--images DIR or --source S"), std::string::npos) << output;
}

}  // namespace
}  // namespace nerfar
