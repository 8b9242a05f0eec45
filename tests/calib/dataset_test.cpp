// calib/dataset, board, object: the OpenGL <-> OpenCV pose conversion against
// the README's ray formula, write -> read round trips, bad input (each problem
// named with the file and a JSON pointer), the files instant-ngp, nerfstudio
// and their COLMAP conversions write (hand-written here after their writers),
// and the shared scenes as they are.
#include "calib/dataset.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>

#include "calib/board.h"
#include "calib/camera.h"
#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "calib/object.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

namespace fs = std::filesystem;
using testing::InputErrorOf;
using testing::TempDir;
using testing::WriteText;

Mat3 RandomRotation(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  const Vec3 axis{n(rng), n(rng), n(rng)};
  std::uniform_real_distribution<double> angle(0.0, kPi);
  return RotationFromAxisAngle(axis, angle(rng));
}

CameraIntrinsics SceneCamera() {
  CameraIntrinsics c;
  c.width = 400;
  c.height = 300;
  c.fx = c.fy = 346.4101615137755;
  c.cx = 200;
  c.cy = 150;
  return c;
}

// ------------------------------------------------------------------ poses

TEST(Dataset, PoseConversionMatchesReadmeRayFormula) {
  // README: in the OpenGL camera frame a pixel (x, y) lies along
  // ((x - cx)/fl_x, -(y - cy)/fl_y, -1); the world direction is R_gl times
  // that. Our path: OpenCV pose from the matrix, Unproject, rotate.
  std::mt19937 rng(3);
  const CameraIntrinsics c = SceneCamera();
  for (int trial = 0; trial < 20; ++trial) {
    const Mat3 r_gl = RandomRotation(rng);
    const Vec3 centre{0.3 * trial - 2, 0.7, -1.1 + 0.05 * trial};
    std::array<double, 16> m{};
    for (int r = 0; r < 3; ++r) {
      for (int k = 0; k < 3; ++k) m[r * 4 + k] = r_gl(r, k);
      m[r * 4 + 3] = centre[r];
    }
    m[15] = 1;
    const Pose T_world_camera = PoseFromTransformMatrix(m);
    EXPECT_NEAR(Length(T_world_camera.translation - centre), 0.0, 1e-15);
    for (const Vec2& px : {Vec2{0, 0}, Vec2{400, 300}, Vec2{12.5, 250.25}, Vec2{200, 150}}) {
      const Vec3 d_gl{(px.x - c.cx) / c.fx, -(px.y - c.cy) / c.fy, -1};
      const Vec3 expected = Normalized(r_gl * d_gl);
      const Vec3 ours = T_world_camera.Rotate(Unproject(c, px));
      EXPECT_NEAR(Length(ours - expected), 0.0, 1e-12);
    }
    // And back to the same matrix.
    const std::array<double, 16> back = TransformMatrixFromPose(T_world_camera);
    for (int k = 0; k < 16; ++k) EXPECT_NEAR(back[k], m[k], 1e-12);
  }
}

// ------------------------------------------------------------ round trips

Dataset ExampleDataset(const std::string& dir) {
  std::mt19937 rng(11);
  Dataset d;
  d.camera = SceneCamera();
  d.camera.k1 = -0.05;
  d.camera.k2 = 0.01;
  d.camera.p1 = 2e-4;
  d.camera.p2 = -1e-4;
  d.camera.k3 = 0.001;
  d.camera.fy = 345.0;
  d.aabb = Aabb{{-0.62, -0.42, -0.05}, {0.62, 0.42, 0.6}};
  for (int i = 0; i < 3; ++i) {
    DatasetFrame f;
    f.file_path = "images/r_" + std::to_string(i) + ".exr";
    f.image_path = dir + "/" + f.file_path;
    f.T_world_camera = {RandomRotation(rng), {0.1 * i, -0.2, 1.0 + i}};
    d.frames.push_back(f);
  }
  return d;
}

TEST(Dataset, WriteReadRoundTrip) {
  TempDir tmp;
  const std::string dir = tmp.File("scene");
  fs::create_directories(dir + "/images");
  const Dataset d = ExampleDataset(dir);
  const std::string path = dir + "/transforms.json";
  WriteDataset(path, d);
  const Dataset r = ReadDataset(path, /*check_images=*/false);
  EXPECT_EQ(r.camera_model, "OPENCV");
  EXPECT_EQ(r.camera.width, 400);
  EXPECT_EQ(r.camera.height, 300);
  // JSON numbers are written with round-trip precision: exact.
  EXPECT_EQ(r.camera.fx, d.camera.fx);
  EXPECT_EQ(r.camera.fy, d.camera.fy);
  EXPECT_EQ(r.camera.cx, d.camera.cx);
  EXPECT_EQ(r.camera.k1, d.camera.k1);
  EXPECT_EQ(r.camera.k3, d.camera.k3);
  EXPECT_EQ(r.camera.p2, d.camera.p2);
  ASSERT_TRUE(r.aabb.has_value());
  EXPECT_EQ(r.aabb->max.z, 0.6);
  ASSERT_EQ(r.frames.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(r.frames[i].file_path, d.frames[i].file_path);
    EXPECT_EQ(r.frames[i].image_path, (fs::path(dir) / d.frames[i].file_path).lexically_normal().string());
    // Re-orthonormalisation of an orthonormal matrix moves it by rounding only.
    EXPECT_LT(RotationAngleBetween(r.frames[i].T_world_camera.rotation, d.frames[i].T_world_camera.rotation), 1e-12);
    EXPECT_LT(Length(r.frames[i].T_world_camera.translation - d.frames[i].T_world_camera.translation), 1e-15);
  }
  // The file carries camera_angle_x/y consistent with the focal lengths.
  const nlohmann::json doc = nlohmann::json::parse(testing::ReadText(path));
  EXPECT_NEAR(doc["camera_angle_x"].get<double>(), 2 * std::atan(200.0 / d.camera.fx), 1e-15);
  EXPECT_NEAR(doc["camera_angle_y"].get<double>(), 2 * std::atan(150.0 / d.camera.fy), 1e-15);
  EXPECT_EQ(doc["k3"].get<double>(), 0.001);
}

TEST(Dataset, ImagesCheckedRelativeToTheJsonFolder) {
  TempDir tmp;
  const std::string dir = tmp.File("scene");
  fs::create_directories(dir + "/images");
  const std::string path = dir + "/transforms.json";
  WriteDataset(path, ExampleDataset(dir));
  std::string message = InputErrorOf([&] { ReadDataset(path, true); });
  EXPECT_NE(message.find(path + ": /frames/0/file_path: image "), std::string::npos) << message;
  EXPECT_NE(message.find("/frames/2/file_path"), std::string::npos) << message;
  for (int i = 0; i < 3; ++i) WriteText(dir + "/images/r_" + std::to_string(i) + ".exr", "x");
  EXPECT_EQ(ReadDataset(path, true).frames.size(), 3u);
}

TEST(Dataset, SplitPaths) {
  TempDir tmp;
  EXPECT_EQ(DatasetSplitPath(tmp.path(), "train"), tmp.path() + "/transforms.json");
  WriteText(tmp.File("transforms_train.json"), "{}");
  EXPECT_EQ(DatasetSplitPath(tmp.path(), "train"), tmp.path() + "/transforms_train.json");
  EXPECT_EQ(DatasetSplitPath(tmp.path(), "test"), tmp.path() + "/transforms_test.json");
}

TEST(Dataset, FocalFromCameraAngleAlone) {
  TempDir tmp;
  WriteText(tmp.File("t.json"),
            R"({"w": 400, "h": 300, "cx": 200, "cy": 150, "camera_angle_x": 1.0471975511965976, "frames": []})");
  const Dataset d = ReadDataset(tmp.File("t.json"));
  EXPECT_NEAR(d.camera.fx, 200.0 / std::tan(kPi / 6), 1e-9);  // 60 degrees across 400 px
  EXPECT_EQ(d.camera.fy, d.camera.fx);                        // fl_y defaults to fl_x
}

// -------------------------------------------------------------- bad input

class BadDataset : public ::testing::Test {
 protected:
  void SetUp() override {
    good_ = nlohmann::json::parse(R"({
      "camera_model": "OPENCV", "fl_x": 346.41, "fl_y": 346.41, "cx": 200.0, "cy": 150.0, "w": 400, "h": 300,
      "k1": 0, "k2": 0, "p1": 0, "p2": 0, "aabb": [[-1, -1, -1], [1, 1, 1]],
      "frames": [{"file_path": "a.exr", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,2],[0,0,0,1]]},
                 {"file_path": "b.exr", "transform_matrix": [[0,-1,0,0],[1,0,0,0],[0,0,1,2],[0,0,0,1]]}]})");
    path_ = tmp_.File("transforms.json");
  }
  // Writes `doc` (or raw text) and returns the reader's message ("" if accepted).
  std::string Read(const nlohmann::json& doc) {
    WriteText(path_, doc.dump(1));
    return InputErrorOf([&] { ReadDataset(path_, false); });
  }
  std::string ReadText(const std::string& text) {
    WriteText(path_, text);
    return InputErrorOf([&] { ReadDataset(path_, false); });
  }
  // True if `message` names the file and then the pointer.
  bool Names(const std::string& message, const std::string& pointer) const {
    return message.find(path_ + ": " + pointer + ":") != std::string::npos;
  }
  TempDir tmp_;
  nlohmann::json good_;
  std::string path_;
};

TEST_F(BadDataset, GoodFileIsAccepted) { EXPECT_EQ(Read(good_), ""); }

TEST_F(BadDataset, Truncated) {
  const std::string text = good_.dump(1);
  const std::string m = ReadText(text.substr(0, text.size() / 2));
  EXPECT_NE(m.find(path_ + ": line "), std::string::npos) << m;
  EXPECT_NE(m.find("invalid JSON"), std::string::npos) << m;
  EXPECT_NE(ReadText(""), "");
}

TEST_F(BadDataset, WrongTypes) {
  auto doc = good_;
  doc["w"] = "400";
  doc["frames"][1]["file_path"] = 3;
  const std::string m = Read(doc);
  EXPECT_TRUE(Names(m, "/w")) << m;
  EXPECT_NE(m.find("expected an integer"), std::string::npos) << m;
  EXPECT_TRUE(Names(m, "/frames/1/file_path")) << m;  // every problem listed, not only the first
  doc = good_;
  doc["frames"] = nlohmann::json::object();
  EXPECT_TRUE(Names(Read(doc), "/frames"));
  EXPECT_NE(ReadText("[1, 2]"), "");
}

TEST_F(BadDataset, NanAsString) {
  auto doc = good_;
  doc["fl_x"] = "NaN";
  doc["frames"][0]["transform_matrix"][0][3] = "nan";
  const std::string m = Read(doc);
  EXPECT_TRUE(Names(m, "/fl_x")) << m;
  EXPECT_TRUE(Names(m, "/frames/0/transform_matrix/0/3")) << m;
  // A bare NaN token is not JSON at all.
  EXPECT_NE(ReadText(R"({"w": NaN})").find("invalid JSON"), std::string::npos);
}

TEST_F(BadDataset, MissingKeys) {
  auto doc = good_;
  doc.erase("cx");
  doc["frames"][0].erase("transform_matrix");
  const std::string m = Read(doc);
  EXPECT_TRUE(Names(m, "/cx")) << m;
  EXPECT_NE(m.find("/cx: missing"), std::string::npos) << m;
  EXPECT_TRUE(Names(m, "/frames/0/transform_matrix")) << m;
  doc = good_;
  doc.erase("fl_x");
  EXPECT_TRUE(Names(Read(doc), "/fl_x"));
}

TEST_F(BadDataset, AbsurdSizesAndRanges) {
  auto doc = good_;
  doc["w"] = 1000000000;
  doc["h"] = -3;
  doc["fl_y"] = 0;
  doc["k1"] = 1e300;
  const std::string m = Read(doc);
  EXPECT_TRUE(Names(m, "/w")) << m;
  EXPECT_TRUE(Names(m, "/h")) << m;
  EXPECT_TRUE(Names(m, "/fl_y")) << m;
  EXPECT_TRUE(Names(m, "/k1")) << m;
  doc = good_;
  doc["cx"] = 900.0;  // outside a 400-pixel image
  EXPECT_TRUE(Names(Read(doc), "/cx"));
  doc = good_;
  doc["aabb"] = {{1, 1, 1}, {-1, -1, -1}};
  EXPECT_TRUE(Names(Read(doc), "/aabb"));
  doc = good_;
  doc["camera_angle_x"] = 1.2;  // fl_x 346.41 at 400 px is 1.047 rad
  EXPECT_TRUE(Names(Read(doc), "/camera_angle_x"));
}

TEST_F(BadDataset, UnknownKeysAndModels) {
  auto doc = good_;
  doc["fl_z"] = 1.0;
  doc["frames"][0]["trasform_matrix"] = 1;
  doc["camera_model"] = "FISHEYE";
  const std::string m = Read(doc);
  EXPECT_NE(m.find(path_ + ": /fl_z: unknown key"), std::string::npos) << m;
  EXPECT_TRUE(Names(m, "/frames/0/trasform_matrix")) << m;
  EXPECT_TRUE(Names(m, "/camera_model")) << m;
  doc = good_;
  doc["units"] = "metres";  // documentation keys are fine
  EXPECT_EQ(Read(doc), "");
}

TEST_F(BadDataset, NonRigidMatrices) {
  auto doc = good_;
  doc["frames"][0]["transform_matrix"][0][0] = 2.0;                                                  // scale
  doc["frames"][1]["transform_matrix"] = {{-1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}};  // mirror
  const std::string m = Read(doc);
  EXPECT_TRUE(Names(m, "/frames/0/transform_matrix")) << m;
  EXPECT_TRUE(Names(m, "/frames/1/transform_matrix")) << m;
  doc = good_;
  doc["frames"][0]["transform_matrix"][3] = {0, 0, 1, 1};
  EXPECT_TRUE(Names(Read(doc), "/frames/0/transform_matrix/3"));
  doc = good_;
  doc["frames"][0]["transform_matrix"][2] = {0, 0, 1};
  EXPECT_TRUE(Names(Read(doc), "/frames/0/transform_matrix/2"));
}

TEST_F(BadDataset, MissingFileNamesThePath) {
  const std::string m = InputErrorOf([&] { ReadDataset(tmp_.File("nope.json")); });
  EXPECT_NE(m.find(tmp_.File("nope.json")), std::string::npos) << m;
}

// ------------------------------------------------- other tools' dialects

// The file instant-ngp's scripts/colmap2nerf.py writes: sizes as floats, k3/k4
// and is_fisheye, aabb_scale, a sharpness per frame, no aabb, "./" paths.
const char* kInstantNgpFile = R"({
  "camera_angle_x": 1.0471975511965976, "camera_angle_y": 0.8172757101952249,
  "fl_x": 346.41016151377545, "fl_y": 346.41016151377545,
  "k1": 0.0, "k2": 0.0, "k3": 0.0, "k4": 0.0, "p1": 0.0, "p2": 0.0, "is_fisheye": false,
  "cx": 200.0, "cy": 150.0, "w": 400.0, "h": 300.0, "aabb_scale": 4,
  "frames": [
    {"file_path": "./images/0001.jpg", "sharpness": 181.5,
     "transform_matrix": [[1, 0, 0, 0.5], [0, 1, 0, -0.2], [0, 0, 1, 3.0], [0, 0, 0, 1]]},
    {"file_path": "./images/0002.jpg", "sharpness": 160.25,
     "transform_matrix": [[0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 1, 3.0], [0, 0, 0, 1]]}]})";

// nerfstudio's colmap_to_json with two COLMAP cameras: the intrinsics in every
// frame (no shared ones), colmap_im_id, mask_path, applied_transform and
// ply_file_path.
const char* kNerfstudioFile = R"({
  "frames": [
    {"file_path": "images/frame_00001.png", "colmap_im_id": 1, "mask_path": "masks/frame_00001.png",
     "fl_x": 500.5, "fl_y": 501.0, "cx": 320.2, "cy": 239.8, "w": 640, "h": 480,
     "k1": -0.01, "k2": 0.002, "p1": 0.0001, "p2": -0.0002, "camera_model": "OPENCV",
     "transform_matrix": [[1, 0, 0, 0.1], [0, 1, 0, 0.2], [0, 0, 1, 0.3], [0, 0, 0, 1]]},
    {"file_path": "images/frame_00002.png", "colmap_im_id": 2, "mask_path": "masks/frame_00002.png",
     "fl_x": 800.0, "fl_y": 800.0, "cx": 400.0, "cy": 300.0, "w": 800, "h": 600,
     "k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0, "camera_model": "OPENCV",
     "transform_matrix": [[1, 0, 0, 0.4], [0, 1, 0, 0.5], [0, 0, 1, 0.6], [0, 0, 0, 1]]}],
  "applied_transform": [[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0]],
  "ply_file_path": "sparse_pc.ply"})";

TEST(DatasetDialects, InstantNgp) {
  TempDir tmp;
  WriteText(tmp.File("transforms.json"), kInstantNgpFile);
  fs::create_directories(tmp.File("images"));
  for (const char* name : {"images/0001.jpg", "images/0002.jpg"}) WriteText(tmp.File(name), "x");
  const Dataset d = ReadDataset(tmp.File("transforms.json"));
  EXPECT_EQ(d.camera.width, 400);
  EXPECT_EQ(d.camera.height, 300);
  EXPECT_FALSE(d.per_frame_cameras);
  EXPECT_FALSE(d.aabb.has_value());
  ASSERT_EQ(d.frames.size(), 2u);
  EXPECT_EQ(d.frames[1].image_path, tmp.File("images/0002.jpg"));
  EXPECT_EQ(d.ignored_keys, std::vector<std::string>{"frames[].sharpness (in 2 frames)"});
  // instant-ngp's box: 0.5 ± 4/2 in its space, back through its default scale
  // 0.33 and offset 0.5: (0.5 - 2 - 0.5) / 0.33 = -6.0606 .. (0.5 + 2 - 0.5) / 0.33.
  ASSERT_TRUE(d.ngp_box.has_value());
  EXPECT_NEAR(d.ngp_box->min.y, -2.0 / 0.33, 1e-12);
  EXPECT_NEAR(d.ngp_box->max.z, 2.0 / 0.33, 1e-12);
}

TEST(DatasetDialects, InstantNgpScaleAndOffset) {
  TempDir tmp;
  auto doc = nlohmann::json::parse(kInstantNgpFile);
  doc["aabb_scale"] = 1;
  doc["scale"] = 2.0;
  doc["offset"] = {0.5, 0.0, 1.0};
  WriteText(tmp.File("t.json"), doc.dump());
  const Dataset d = ReadDataset(tmp.File("t.json"), false);
  // p · 2 + offset in [0, 1]  <=>  p in [(0 - offset) / 2, (1 - offset) / 2].
  ASSERT_TRUE(d.ngp_box.has_value());
  EXPECT_NEAR(d.ngp_box->min.x, -0.25, 1e-12);
  EXPECT_NEAR(d.ngp_box->max.x, 0.25, 1e-12);
  EXPECT_NEAR(d.ngp_box->min.y, 0.0, 1e-12);
  EXPECT_NEAR(d.ngp_box->max.y, 0.5, 1e-12);
  EXPECT_NEAR(d.ngp_box->min.z, -0.5, 1e-12);
  EXPECT_NEAR(d.ngp_box->max.z, 0.0, 1e-12);
}

TEST(DatasetDialects, NeRFSyntheticPathsWithoutExtension) {
  TempDir tmp;
  auto doc = nlohmann::json::parse(kInstantNgpFile);
  doc["frames"][0]["file_path"] = "./train/r_0";
  doc["frames"][1]["file_path"] = "./train/r_1";
  WriteText(tmp.File("transforms_train.json"), doc.dump());
  fs::create_directories(tmp.File("train"));
  WriteText(tmp.File("train/r_0.png"), "x");
  WriteText(tmp.File("train/r_1.png"), "x");
  const Dataset d = ReadDataset(tmp.File("transforms_train.json"));
  EXPECT_EQ(d.frames[0].image_path, tmp.File("train/r_0.png"));
}

TEST(DatasetDialects, NerfstudioPerFrameCamerasAndMasks) {
  TempDir tmp;
  WriteText(tmp.File("transforms.json"), kNerfstudioFile);
  const Dataset d = ReadDataset(tmp.File("transforms.json"), false);
  EXPECT_TRUE(d.per_frame_cameras);
  ASSERT_EQ(d.frames.size(), 2u);
  const CameraIntrinsics& a = d.CameraOf(d.frames[0]);
  const CameraIntrinsics& b = d.CameraOf(d.frames[1]);
  EXPECT_EQ(a.width, 640);
  EXPECT_EQ(a.fy, 501.0);
  EXPECT_EQ(a.k2, 0.002);
  EXPECT_EQ(b.width, 800);
  EXPECT_EQ(b.fx, 800.0);
  EXPECT_EQ(d.camera.width, 640);  // the shared camera is the first frame's
  EXPECT_EQ(d.frames[1].mask_path, tmp.File("masks/frame_00002.png"));
  const std::vector<std::string> ignored = {"applied_transform", "ply_file_path",
                                            "frames[].colmap_im_id (in 2 frames)"};
  EXPECT_EQ(d.ignored_keys, ignored);
  // Written back, per-frame intrinsics and masks survive.
  WriteDataset(tmp.File("out.json"), d);
  const Dataset r = ReadDataset(tmp.File("out.json"), false);
  EXPECT_TRUE(r.per_frame_cameras);
  EXPECT_EQ(r.CameraOf(r.frames[1]).cx, 400.0);
  EXPECT_EQ(r.frames[0].mask_file, "masks/frame_00001.png");
}

TEST(DatasetDialects, FrameIntrinsicsOverrideSharedOnes) {
  // Shared w, h and camera_angle_x; the second frame gives its own fl_x (the
  // shared angle then says nothing about it, so it is not checked against it).
  TempDir tmp;
  WriteText(tmp.File("t.json"), R"({"w": 400, "h": 300, "cx": 200, "cy": 150, "camera_angle_x": 1.0471975511965976,
    "frames": [{"file_path": "a.png", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,2],[0,0,0,1]], "k1": 0.01},
               {"file_path": "b.png", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,2],[0,0,0,1]], "fl_x": 300}]})");
  const Dataset d = ReadDataset(tmp.File("t.json"), false);
  ASSERT_TRUE(d.per_frame_cameras);
  EXPECT_NEAR(d.CameraOf(d.frames[0]).fx, 200.0 / std::tan(kPi / 6), 1e-9);
  EXPECT_EQ(d.CameraOf(d.frames[0]).k1, 0.01);
  EXPECT_EQ(d.CameraOf(d.frames[1]).fx, 300.0);
  EXPECT_EQ(d.CameraOf(d.frames[1]).fy, 300.0);  // fl_y defaults to the frame's fl_x
  EXPECT_EQ(d.CameraOf(d.frames[1]).width, 400);
}

TEST_F(BadDataset, WholeFloatsAreIntegersOthersAreNot) {
  auto doc = good_;
  doc["w"] = 400.0;
  doc["h"] = 300.0;
  EXPECT_EQ(Read(doc), "");
  doc["w"] = 400.5;
  const std::string m = Read(doc);
  EXPECT_TRUE(Names(m, "/w")) << m;
  EXPECT_NE(m.find("expected an integer"), std::string::npos) << m;
}

TEST_F(BadDataset, OtherToolsKeysAreIgnoredTyposOfOursAreNot) {
  auto doc = good_;
  doc["ply_file_path"] = "x.ply";
  doc["frames"][0]["depth_file_path"] = "d.png";
  EXPECT_EQ(Read(doc), "");
  doc["fl_xx"] = 346.0;
  doc["frames"][1]["mask_pth"] = "m.png";
  doc["frames"][1]["file_paht"] = "m.png";
  const std::string m = Read(doc);
  EXPECT_NE(m.find(path_ + ": /fl_xx: unknown key (a typo of \"fl_x\"?)"), std::string::npos) << m;
  EXPECT_NE(m.find("/frames/1/mask_pth: unknown key (a typo of \"mask_path\"?)"), std::string::npos) << m;
  EXPECT_NE(m.find("/frames/1/file_paht: unknown key (a typo of \"file_path\"?)"), std::string::npos) << m;
  EXPECT_EQ(m.find("ply_file_path"), std::string::npos) << m;
}

TEST_F(BadDataset, FisheyeIsRefusedWithWhatToDo) {
  auto doc = good_;
  doc["camera_model"] = "OPENCV_FISHEYE";
  doc["k4"] = 0.01;
  doc["is_fisheye"] = true;
  const std::string m = Read(doc);
  EXPECT_TRUE(Names(m, "/camera_model")) << m;
  EXPECT_TRUE(Names(m, "/k4")) << m;
  EXPECT_TRUE(Names(m, "/is_fisheye")) << m;
  EXPECT_NE(m.find("undistort the images first"), std::string::npos) << m;
  doc = good_;
  doc["k4"] = 0.0;
  doc["is_fisheye"] = false;
  EXPECT_EQ(Read(doc), "");
}

TEST_F(BadDataset, MissingMaskIsNamed) {
  auto doc = good_;
  doc["frames"][0]["mask_path"] = "masks/a.png";
  WriteText(tmp_.File("a.exr"), "x");
  WriteText(tmp_.File("b.exr"), "x");
  WriteText(path_, doc.dump());
  const std::string m = InputErrorOf([&] { ReadDataset(path_, true); });
  EXPECT_NE(m.find("/frames/0/mask_path: mask " + tmp_.File("masks/a.png") + " does not exist"), std::string::npos)
      << m;
}

// ------------------------------------------------------------- board

std::string BoardJson(double corner_x = 0.06, int second_id = 1) {
  return R"({"family": "tag36h11", "tag_size": 0.06, "units": "meters", "corner_order": "tl tr br bl",
    "tags": [
     {"id": 0, "center": [0.03, 0.03, 0], "yaw_deg": 0, "up_direction": [0, 1, 0],
      "corners": [[0, 0.06, 0], [)" +
         std::to_string(corner_x) + R"(, 0.06, 0], [0.06, 0, 0], [0, 0, 0]]},
     {"id": )" +
         std::to_string(second_id) + R"(, "center": [1.03, 0.03, 0], "up_direction": [0, 1, 0],
      "corners": [[1, 0.06, 0], [1.06, 0.06, 0], [1.06, 0, 0], [1, 0, 0]]}]})";
}

TEST(Board, WriteReadRoundTrip) {
  TempDir tmp;
  WriteText(tmp.File("b.json"), BoardJson());
  const Board b = ReadBoard(tmp.File("b.json"));
  ASSERT_EQ(b.tags.size(), 2u);
  EXPECT_EQ(b.tag_size_m, 0.06);
  ASSERT_NE(b.FindTag(1), nullptr);
  EXPECT_EQ(b.FindTag(1)->corners[2].x, 1.06);
  EXPECT_EQ(b.FindTag(7), nullptr);
  WriteBoard(tmp.File("c.json"), b);
  const Board c = ReadBoard(tmp.File("c.json"));
  ASSERT_EQ(c.tags.size(), 2u);
  for (size_t t = 0; t < 2; ++t)
    for (int k = 0; k < 4; ++k) EXPECT_EQ(c.tags[t].corners[k], b.tags[t].corners[k]);
  EXPECT_EQ(c.tags[1].up_direction, b.tags[1].up_direction);
}

TEST(Board, BadBoards) {
  TempDir tmp;
  const std::string path = tmp.File("b.json");
  WriteText(path, BoardJson(0.07, 0));  // a stretched edge and a duplicate id
  std::string m = InputErrorOf([&] { ReadBoard(path); });
  EXPECT_NE(m.find(path + ": /tags/0/corners: edge from corner 0 to 1"), std::string::npos) << m;
  EXPECT_NE(m.find(path + ": /tags/1/id: is 0 again"), std::string::npos) << m;
  WriteText(path, R"({"family": "tag99", "tag_size": "6cm", "tags": [{"id": 0, "corners": [[0,0,0]]}]})");
  m = InputErrorOf([&] { ReadBoard(path); });
  EXPECT_NE(m.find("/family"), std::string::npos) << m;
  EXPECT_NE(m.find("/tag_size"), std::string::npos) << m;
  EXPECT_NE(m.find("/tags/0/corners"), std::string::npos) << m;
  EXPECT_NE(m.find("/tags/0/center: missing"), std::string::npos) << m;
}

// ----------------------------------------------------- material, placement

TEST(Object, MaterialRoundTripAndPaths) {
  TempDir tmp;
  fs::create_directories(tmp.File("objects"));
  WriteText(tmp.File("objects/m.json"),
            R"({"mesh": "m.obj", "albedo": [0.8, 0.35, 0.2], "roughness": 0.7, "metallic": 0.0, "f0": 0.02,
                "brdf": "text", "bbox_min": [-1, -2, -3], "bbox_max": [1, 2, 3], "center_local": [0, 0, 0],
                "n_vertices": 10, "n_triangles": 12})");
  const Material m = ReadMaterial(tmp.File("objects/m.json"));
  EXPECT_EQ(m.mesh, tmp.File("objects/m.obj"));
  EXPECT_EQ(m.albedo.y, 0.35);
  EXPECT_EQ(m.roughness, 0.7);
  EXPECT_EQ(m.n_triangles, 12);
  ASSERT_TRUE(m.bbox_max.has_value());
  EXPECT_EQ(m.bbox_max->z, 3.0);
  // Written elsewhere, the mesh path still leads to the same file.
  fs::create_directories(tmp.File("other/deeper"));
  WriteMaterial(tmp.File("other/deeper/m.json"), m);
  const Material r = ReadMaterial(tmp.File("other/deeper/m.json"));
  EXPECT_EQ(fs::weakly_canonical(r.mesh), fs::weakly_canonical(m.mesh));
  EXPECT_EQ(r.albedo, m.albedo);
  EXPECT_EQ(r.n_vertices, 10);
}

TEST(Object, BadMaterial) {
  TempDir tmp;
  const std::string path = tmp.File("m.json");
  WriteText(path, R"({"albedo": "red", "roughness": 2, "metallic": -0.1, "bbox_min": [0, 0, 0], "shiny": true})");
  const std::string m = InputErrorOf([&] { ReadMaterial(path); });
  EXPECT_NE(m.find(path + ": /albedo"), std::string::npos) << m;
  EXPECT_NE(m.find(path + ": /roughness"), std::string::npos) << m;
  EXPECT_NE(m.find(path + ": /metallic"), std::string::npos) << m;
  EXPECT_NE(m.find(path + ": /bbox_max: missing"), std::string::npos) << m;
  EXPECT_NE(m.find(path + ": /shiny: unknown key"), std::string::npos) << m;
}

TEST(Object, PlacementWithScaleRoundTrip) {
  TempDir tmp;
  ObjectPlacement p;
  p.T_world_object = {RotationFromAxisAngle({0, 0, 1}, 0.7), {0.1, -0.2, 0.05}};
  p.scale = 2.5;
  p.center_world = Vec3{0.1, -0.2, 0.05};
  p.object = "thing";
  p.placement = PlacementQuality{3.5, 2, 1, 0, 0.25};
  WriteObjectPlacement(tmp.File("pose.json"), p);
  const ObjectPlacement r = ReadObjectPlacement(tmp.File("pose.json"));
  EXPECT_NEAR(r.scale, 2.5, 1e-14);
  EXPECT_LT(RotationAngleBetween(r.T_world_object.rotation, p.T_world_object.rotation), 1e-12);
  EXPECT_EQ(r.T_world_object.translation, p.T_world_object.translation);
  EXPECT_EQ(r.object, "thing");
  ASSERT_TRUE(r.placement.has_value());
  EXPECT_EQ(r.placement->test_views_mostly_hidden, 1);
  // A non-uniform scale is not a placement.
  WriteText(tmp.File("bad.json"),
            R"({"object_to_world": [[1,0,0,0],[0,2,0,0],[0,0,1,0],[0,0,0,1]], "placement": {"score": 1}})");
  const std::string m = InputErrorOf([&] { ReadObjectPlacement(tmp.File("bad.json")); });
  EXPECT_NE(m.find(tmp.File("bad.json") + ": /object_to_world: rotation block"), std::string::npos) << m;
  EXPECT_NE(m.find("/placement/test_views_mostly_hidden: missing"), std::string::npos) << m;
}

// ------------------------------------------------------- shared scenes

TEST(SharedScenes, LoadBothScenes) {
  NERFAR_REQUIRE_SHARED_SCENES(scenes);
  for (const std::string name : {"lamps", "window"}) {
    SCOPED_TRACE(name);
    const std::string dir = scenes + "/" + name;
    const Dataset train = ReadDataset(DatasetSplitPath(dir, "train"));
    const Dataset test = ReadDataset(DatasetSplitPath(dir, "test"));
    const Dataset all = ReadDataset(dir + "/transforms.json");
    EXPECT_EQ(train.frames.size(), 100u);
    EXPECT_EQ(test.frames.size(), 8u);
    EXPECT_EQ(all.frames.size(), 100u);
    for (const Dataset* d : {&train, &test}) {
      EXPECT_EQ(d->camera.width, 400);
      EXPECT_EQ(d->camera.height, 300);
      EXPECT_NEAR(d->camera.fx, 346.41, 0.01);  // README: 346.4102
      EXPECT_NEAR(d->camera.fy, 346.41, 0.01);
      EXPECT_EQ(d->camera.cx, 200.0);
      EXPECT_EQ(d->camera.cy, 150.0);
      EXPECT_FALSE(d->camera.HasDistortion());
      ASSERT_TRUE(d->aabb.has_value());
      EXPECT_EQ(d->aabb->min.x, -0.62);
      EXPECT_EQ(d->aabb->max.z, 0.6);
      for (const DatasetFrame& f : d->frames) {
        // README: cameras 0.8 to 1.3 m from the table centre, looking at points
        // within a few cm of it. In the OpenCV convention the optical axis is
        // the rotation's z column: the centre lies close to that line, ahead.
        const Vec3 c = f.T_world_camera.translation;
        // (Measured from the look-at point, so allow a few cm beyond the range.)
        EXPECT_GT(Length(c), 0.75);
        EXPECT_LT(Length(c), 1.4);
        const Vec3 axis = f.T_world_camera.rotation.Column(2);
        const double along = Dot(-c, axis);
        EXPECT_GT(along, 0.0) << f.file_path;
        EXPECT_LT(Length(-c - axis * along), 0.1) << f.file_path;  // "a few centimetres", with margin
        // No roll: image right (x column) is horizontal.
        EXPECT_NEAR(f.T_world_camera.rotation.Column(0).z, 0.0, 1e-6) << f.file_path;
        // Image down (y) points downwards in the world for a camera above the table.
        EXPECT_LT(f.T_world_camera.rotation.Column(1).z, 0.0) << f.file_path;
      }
    }
    for (const DatasetFrame* f : {&train.frames[0], &train.frames[57], &test.frames[7]}) {
      const ImageF image = ReadExrRgb(f->image_path);
      EXPECT_EQ(image.width, 400);
      EXPECT_EQ(image.height, 300);
    }
    const Board board = ReadBoard(dir + "/board.json");
    EXPECT_EQ(board.family, "tag36h11");
    EXPECT_EQ(board.tag_size_m, 0.06);
    ASSERT_EQ(board.tags.size(), 12u);
    for (int id = 0; id < 12; ++id) {
      const BoardTag* tag = board.FindTag(id);
      ASSERT_NE(tag, nullptr) << id;
      for (int k = 0; k < 4; ++k) {
        // Floats in the file: 1e-6 m is their rounding.
        EXPECT_NEAR(Length(tag->corners[(k + 1) % 4] - tag->corners[k]), 0.06, 1e-6);
        EXPECT_NEAR(tag->corners[k].z, 0.0005, 1e-9);  // printed 0.5 mm above the table
      }
    }
    for (const std::string object : {"sphere_glossy", "monkey_diffuse"}) {
      const ObjectPlacement p = ReadObjectPlacement(dir + "/insert/" + object + "/pose.json");
      EXPECT_EQ(p.object, object);
      EXPECT_NEAR(p.scale, 1.0, 1e-6);
      ASSERT_TRUE(p.center_world.has_value());
      // The local origin is the bounding-box centre: it maps to center_world
      // (float-rounded in the file).
      EXPECT_LT(Length(p.T_world_object.translation - *p.center_world), 1e-6);
      // Rotation about z only.
      EXPECT_NEAR(p.T_world_object.rotation(2, 2), 1.0, 1e-9);
      const Material m = ReadMaterial(ObjectMaterialPath(scenes, object));
      EXPECT_TRUE(fs::is_regular_file(m.mesh)) << m.mesh;
      ASSERT_TRUE(m.bbox_min.has_value() && m.bbox_max.has_value());
      // The object rests on the table: its lowest point at z = 0.
      EXPECT_NEAR(p.center_world->z + m.bbox_min->z * p.scale, 0.0, 1e-6);
    }
  }
  const Material sphere = ReadMaterial(ObjectMaterialPath(scenes, "sphere_glossy"));
  EXPECT_EQ(sphere.roughness, 0.25);
  EXPECT_EQ(sphere.metallic, 1.0);
  EXPECT_EQ(sphere.albedo, (Vec3{0.9, 0.9, 0.9}));
  const Material monkey = ReadMaterial(ObjectMaterialPath(scenes, "monkey_diffuse"));
  EXPECT_EQ(monkey.albedo, (Vec3{0.8, 0.35, 0.2}));
  EXPECT_EQ(monkey.roughness, 0.7);
  EXPECT_EQ(monkey.f0, 0.02);
}

}  // namespace
}  // namespace nerfar
