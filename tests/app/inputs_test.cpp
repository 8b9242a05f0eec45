// Inputs are never written: each command that writes files refuses, before
// any work, an output that is one of its inputs (exit 2, both paths named,
// the input's bytes unchanged): the same path, a symbolic link to it, a
// relative spelling of it, or a file of an input folder that the command
// would write by name. The model, field and mesh files given here are not
// valid (except where a command reads them first): a command that did any
// work before the check would fail on them with another message.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "calib/board.h"
#include "calib/camera_file.h"
#include "calib/core/atomic_file.h"
#include "calib/core/exr.h"
#include "calib/core/image_io.h"
#include "calib/core/json.h"
#include "calib/dataset.h"
#include "render/mesh/mesh.h"
#include "render/synth/scenes.h"
#include "tests/support/nerfar_command.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

namespace fs = std::filesystem;
using Result = testing::CommandResult;

using testing::Nerfar;
using testing::RunNerfar;

// Runs the command line and checks the refusal: exit 2, the output and the
// input named as the command spells them (the input when given), the input
// file's bytes unchanged.
void ExpectRefusedLine(const std::string& command_line, const std::string& output, const std::string& input,
                       const std::string& input_file) {
  const std::string before = testing::ReadText(input_file);
  ASSERT_FALSE(before.empty()) << input_file;
  const Result r = testing::RunCommand(command_line);
  EXPECT_EQ(r.exit_code, 2) << command_line << "\n" << r.output;
  EXPECT_NE(r.output.find("would overwrite the input"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(output + ": "), std::string::npos) << "output " << output << " not named:\n" << r.output;
  if (!input.empty()) {
    EXPECT_NE(r.output.find("input " + input + " "), std::string::npos) << "input " << input << " not named:\n"
                                                                        << r.output;
  }
  EXPECT_EQ(testing::ReadText(input_file), before) << input_file << " was written";
}

void ExpectRefused(const std::string& arguments, const std::string& output, const std::string& input,
                   const std::string& input_file) {
  ExpectRefusedLine(Nerfar(arguments), output, input, input_file);
}

void ExpectRefused(const std::string& arguments, const std::string& output, const std::string& input) {
  ExpectRefused(arguments, output, input, input);
}

// DIR/transforms_{train,test}.json with two 16x12 views each ({train,test}/r_00N.exr) and an aabb.
void WriteTinyDataset(const std::string& dir) {
  for (const char* split : {"train", "test"}) {
    Dataset dataset;
    dataset.dir = dir;
    dataset.camera.width = 16;
    dataset.camera.height = 12;
    dataset.camera.fx = dataset.camera.fy = 14;
    dataset.camera.cx = 8;
    dataset.camera.cy = 6;
    dataset.aabb = Aabb{{-0.5, -0.5, -0.1}, {0.5, 0.5, 0.5}};
    MakeDirectories(dir + "/" + split);
    for (int i = 0; i < 2; ++i) {
      DatasetFrame frame;
      frame.file_path = std::string(split) + "/r_00" + std::to_string(i) + ".exr";
      frame.image_path = dir + "/" + frame.file_path;
      frame.T_world_camera = LookAt({0.3 * i, -1.0, 0.8}, {0, 0, 0});
      WriteExrRgb(frame.image_path, ImageF(16, 12, 3, 0.25f + 0.1f * i));
      dataset.frames.push_back(frame);
    }
    WriteDataset(dir + "/transforms_" + split + ".json", dataset);
  }
}

// The case: composites are named like the frames they are made from.
TEST(InputsAreNeverWritten, InsertIntoItsOwnFramesFolder) {
  testing::TempDir dir;
  WriteTinyDataset(dir.File("ds"));
  MakeDirectories(dir.File("frames"));
  for (const char* name : {"r_000.exr", "r_001.exr"}) WriteExrRgb(dir.File("frames/") + name, ImageF(16, 12, 3, 0.5f));
  testing::WriteText(dir.File("scene.nerf"), "not a model");
  testing::WriteText(dir.File("o.ssdf"), "not a field");
  testing::WriteText(dir.File("pose.json"), "{}");
  const std::string common = "insert --nerf " + dir.File("scene.nerf") + " --object " + dir.File("o.ssdf") +
                             " --pose " + dir.File("pose.json") + " --dataset " + dir.File("ds");
  ExpectRefused(common + " --frames " + dir.File("frames") + " -o " + dir.File("frames"),
                dir.File("frames") + "/r_000.exr", dir.File("frames") + "/r_000.exr");
  EXPECT_EQ(ReadExrRgb(dir.File("frames/r_001.exr")).pixels.front(), 0.5f);
  // The dataset's own test images, and a symbolic link to their folder.
  ExpectRefused(common + " -o " + dir.File("ds/test"), dir.File("ds/test") + "/r_000.exr", "",
                dir.File("ds/test/r_000.exr"));
  fs::create_directory_symlink(dir.File("ds/test"), dir.File("linked"));
  ExpectRefused(common + " -o " + dir.File("linked"), dir.File("linked") + "/r_000.exr", "",
                dir.File("ds/test/r_000.exr"));
  // Another folder passes the check and the command goes on to read its
  // inputs (and stops at the model, which is not one).
  const Result other = RunNerfar(common + " --frames " + dir.File("frames") + " -o " + dir.File("out"));
  EXPECT_EQ(other.exit_code, 2) << other.output;
  EXPECT_EQ(other.output.find("would overwrite"), std::string::npos) << other.output;
  EXPECT_NE(other.output.find(dir.File("scene.nerf")), std::string::npos) << other.output;
}

TEST(InputsAreNeverWritten, EnvTrainRenderBake) {
  testing::TempDir dir;
  WriteTinyDataset(dir.File("ds"));
  testing::WriteText(dir.File("scene.nerf"), "not a model");
  ExpectRefused("env " + dir.File("scene.nerf") + " -o " + dir.File("scene.nerf"), dir.File("scene.nerf"),
                dir.File("scene.nerf"));
  const Result twice =
      RunNerfar("env " + dir.File("scene.nerf") + " -o " + dir.File("e.json") + " --preview " + dir.File("e.json"));
  EXPECT_EQ(twice.exit_code, 2);
  EXPECT_NE(twice.output.find("two outputs"), std::string::npos) << twice.output;

  // train: a training image, through a symbolic link, and spelled relative to the current folder.
  const std::string image = dir.File("ds/train/r_001.exr");
  ExpectRefused("train " + dir.File("ds") + " -o " + image, image, "", image);
  fs::create_symlink(image, dir.File("link.nerf"));
  ExpectRefused("train " + dir.File("ds") + " -o " + dir.File("link.nerf"), dir.File("link.nerf"), "", image);
  ExpectRefusedLine("cd " + dir.path() + " && " + Nerfar("train ds -o ds/test/../train/r_001.exr"),
                    "ds/test/../train/r_001.exr", "", image);

  // render into the split's own folder.
  ExpectRefused("render " + dir.File("scene.nerf") + " --dataset " + dir.File("ds") + " -o " + dir.File("ds/test"),
                dir.File("ds/test") + "/r_000.exr", "", dir.File("ds/test/r_000.exr"));

  // bake over its mesh.
  WriteMeshObj(dir.File("cube.obj"), MakeBox({0.03, 0.03, 0.03}));
  ExpectRefused("bake " + dir.File("cube.obj") + " -o " + dir.File("cube.obj"), dir.File("cube.obj"),
                dir.File("cube.obj"));
}

TEST(InputsAreNeverWritten, CalibrateTrackCapture) {
  testing::TempDir dir;
  WriteTinyDataset(dir.File("ds"));
  WriteBoard(dir.File("board.json"), synth::MakeTagBoard());
  CameraFile camera;
  camera.camera = ReadDataset(dir.File("ds/transforms_train.json")).camera;
  WriteCameraFile(dir.File("camera.json"), camera);
  MakeDirectories(dir.File("frames"));
  WriteImage8(dir.File("frames/view.png"), Image8(16, 12, 3, 90));

  ExpectRefused("calibrate --board " + dir.File("board.json") + " --images " + dir.File("frames") + " -o " +
                    dir.File("board.json"),
                dir.File("board.json"), dir.File("board.json"));
  ExpectRefused("calibrate --board " + dir.File("board.json") + " --images " + dir.File("frames") + " -o " +
                    dir.File("frames/view.png"),
                dir.File("frames/view.png"), dir.File("frames") + "/view.png", dir.File("frames/view.png"));
  ExpectRefused("track --source images:" + dir.File("frames") + " --board " + dir.File("board.json") + " --camera " +
                    dir.File("camera.json") + " -o " + dir.File("camera.json"),
                dir.File("camera.json"), dir.File("camera.json"));
  // capture into the dataset whose views it reads as its source.
  ExpectRefused("capture --source images:" + dir.File("ds/train") + " --board " + dir.File("board.json") +
                    " --camera " + dir.File("camera.json") + " -o " + dir.File("ds"),
                dir.File("ds") + "/train/r_000.exr", dir.File("ds/train") + "/r_000.exr",
                dir.File("ds/train/r_000.exr"));
}

// import into its own source folder: its split files are the ones it would write.
TEST(InputsAreNeverWritten, ImportIntoItsSource) {
  testing::TempDir dir;
  WriteTinyDataset(dir.File("ds"));
  ExpectRefused("import " + dir.File("ds") + " -o " + dir.File("ds"), dir.File("ds") + "/transforms_train.json",
                dir.File("ds") + "/transforms_train.json", dir.File("ds/transforms_train.json"));
}

TEST(InputsAreNeverWritten, LiveAndReport) {
  testing::TempDir dir;
  MakeDirectories(dir.File("scene"));
  testing::WriteText(dir.File("scene/scene.nerf"), "not a model");
  WriteBoard(dir.File("scene/board.json"), synth::MakeTagBoard());
  WriteMeshObj(dir.File("cube.obj"), MakeBox({0.03, 0.03, 0.03}));
  ExpectRefused("live --headless --source synthetic --scene " + dir.File("scene") + " --object " +
                    dir.File("cube.obj") + " -o " + dir.File("session") + " --contact-sheet " +
                    dir.File("scene/board.json"),
                dir.File("scene/board.json"), dir.File("scene/board.json"));

  // A session that lists its own report page among its objects.
  MakeDirectories(dir.File("session"));
  WriteImage8(dir.File("session/report.png"), Image8(8, 8, 3, 50));
  WriteJsonFile(dir.File("session/session.json"), Json{{"format", "nerfar-session"},
                                                       {"objects", {dir.File("session/report.png")}},
                                                       {"frames", Json::array()},
                                                       {"counters", Json::object()},
                                                       {"wall_s", 1.0}});
  ExpectRefused("report " + dir.File("session"), dir.File("session") + "/report.png", dir.File("session/report.png"));
}

}  // namespace
}  // namespace nerfar
