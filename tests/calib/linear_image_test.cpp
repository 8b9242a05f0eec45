// calib/linear_image: 8- and 16-bit PNG and JPEG frames (written here by
// OpenCV from known values) come back as the linear values the sRGB curve or a
// camera response says, with the sensor's clipped channels flagged; EXR as
// stored; masks at their image's size; a dataset's camera.json chooses the
// response. calib/scene_box: the look-at point of cameras aimed at a known
// point, the box of a board and of a capture without one, instant-ngp's box.
#include "calib/linear_image.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>

#include "calib/camera_file.h"
#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "calib/scene_box.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

namespace fs = std::filesystem;
using testing::TempDir;
using testing::WriteText;

// The sRGB decoding curve written out (IEC 61966-2-1), independent of ours.
double SrgbDecode(double v) { return v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4); }

// A 4x2 BGR image whose pixel (x, y) has values from `levels` (RGB order).
template <typename T>
cv::Mat Frame(const std::vector<std::array<int, 3>>& levels, int depth) {
  cv::Mat m(2, 4, CV_MAKETYPE(depth, 3));
  for (int i = 0; i < 8; ++i) {
    const auto& l = levels[i % levels.size()];
    m.at<cv::Vec<T, 3>>(i / 4, i % 4) = cv::Vec<T, 3>(T(l[2]), T(l[1]), T(l[0]));
  }
  return m;
}

TEST(LinearImage, Png8ThroughSrgbWithClippedChannelsFlagged) {
  TempDir tmp;
  const std::vector<std::array<int, 3>> levels = {{0, 10, 128}, {255, 200, 60}, {255, 255, 255}, {254, 1, 77}};
  ASSERT_TRUE(cv::imwrite(tmp.File("a.png"), Frame<std::uint8_t>(levels, CV_8U)));
  const LinearImage image = ReadLinearImage(tmp.File("a.png"), Linearisation{});
  ASSERT_EQ(image.rgb.width, 4);
  EXPECT_TRUE(image.display_referred);
  for (int i = 0; i < 8; ++i) {
    const auto& l = levels[i % levels.size()];
    std::uint8_t flags = 0;
    for (int c = 0; c < 3; ++c) {
      // float sRGB against the double formula: 1e-6 relative.
      EXPECT_NEAR(image.rgb.at(i % 4, i / 4, c), SrgbDecode(l[c] / 255.0), 1e-6) << i << " " << c;
      if (l[c] == 255) flags |= std::uint8_t(1u << c);
    }
    EXPECT_EQ(image.clipped.at(i % 4, i / 4), flags) << i;
  }
  EXPECT_EQ(image.ClippedPixels(), 4u);  // pixels 1, 2 and their repeats 5, 6
}

TEST(LinearImage, Png16ClipsOnlyAtItsTop) {
  TempDir tmp;
  const std::vector<std::array<int, 3>> levels = {{65535, 65534, 0}, {32768, 1000, 65535}};
  ASSERT_TRUE(cv::imwrite(tmp.File("a.png"), Frame<std::uint16_t>(levels, CV_16U)));
  const LinearImage image = ReadLinearImage(tmp.File("a.png"), Linearisation{});
  EXPECT_EQ(image.clipped.at(0, 0), 1u);       // red only: 65534 is not the top
  EXPECT_EQ(image.clipped.at(1, 0), 1u << 2);  // blue
  EXPECT_NEAR(image.rgb.at(1, 0, 0), SrgbDecode(32768 / 65535.0), 1e-6);
  EXPECT_NEAR(image.rgb.at(1, 0, 1), SrgbDecode(1000 / 65535.0), 1e-6);
}

TEST(LinearImage, JpegNearItsTopCountsAsClipped) {
  // A flat frame: JPEG keeps flat areas within a level, so 252 reads 251..253
  // (within 5 of the top: clipped) and 200 reads 199..201 (not).
  TempDir tmp;
  cv::Mat m(16, 16, CV_8UC3, cv::Scalar(200, 252, 200));
  ASSERT_TRUE(cv::imwrite(tmp.File("a.jpg"), m, {cv::IMWRITE_JPEG_QUALITY, 100}));
  const LinearImage image = ReadLinearImage(tmp.File("a.jpg"), Linearisation{});
  EXPECT_EQ(image.clipped.at(5, 5), 1u << 1);  // green (BGR order in OpenCV's scalar)
  EXPECT_NEAR(image.rgb.at(5, 5, 0), SrgbDecode(200 / 255.0), 0.01);
}

TEST(LinearImage, ThroughTheCameraResponse) {
  // g(z) = ln((z + 1) / 64) per channel, scaled per channel: linear values
  // exp(g) exactly at levels, interpolated in g between 16-bit levels.
  CameraResponse response;
  for (int c = 0; c < 3; ++c) {
    std::array<float, kResponseLevels> g{};
    for (int z = 0; z < kResponseLevels; ++z) g[z] = float(std::log((z + 1) / 64.0) + c);
    response.log_exposure.push_back(g);
  }
  const Linearisation linearisation{response, "camera.json"};
  EXPECT_EQ(LinearValue(linearisation, 0, 0.0f), 0.0f);  // black
  EXPECT_NEAR(LinearValue(linearisation, 0, 63.0f), 1.0, 1e-6);
  EXPECT_NEAR(LinearValue(linearisation, 2, 127.0f), 2.0 * std::exp(2.0), 1e-5);
  // Halfway between levels 63 and 64 in g: the geometric mean of 1 and 65/64.
  EXPECT_NEAR(LinearValue(linearisation, 0, 63.5f), std::sqrt(65.0 / 64.0), 1e-6);
  TempDir tmp;
  ASSERT_TRUE(cv::imwrite(tmp.File("a.png"), Frame<std::uint8_t>({{63, 63, 127}}, CV_8U)));
  const LinearImage image = ReadLinearImage(tmp.File("a.png"), linearisation);
  EXPECT_NEAR(image.rgb.at(0, 0, 1), std::exp(1.0), 1e-5);
  EXPECT_NEAR(image.rgb.at(0, 0, 2), 2.0 * std::exp(2.0), 1e-5);
}

TEST(LinearImage, ExrAsStoredAndGreyAsRgb) {
  TempDir tmp;
  ImageF hdr(2, 1, 3);
  hdr.pixels = {0.5f, 1000.0f, 0.0f, 3.0f, 2.0f, 1.0f};
  WriteExrRgb(tmp.File("a.exr"), hdr, ExrPixelType::kFloat);
  const LinearImage image = ReadLinearImage(tmp.File("a.exr"), Linearisation{});
  EXPECT_FALSE(image.display_referred);
  EXPECT_TRUE(image.clipped.empty());
  EXPECT_EQ(image.rgb.pixels, hdr.pixels);
  cv::Mat grey(1, 2, CV_8UC1, cv::Scalar(128));
  ASSERT_TRUE(cv::imwrite(tmp.File("g.png"), grey));
  const LinearImage g = ReadLinearImage(tmp.File("g.png"), Linearisation{});
  ASSERT_EQ(g.rgb.channels, 3);
  EXPECT_EQ(g.rgb.at(1, 0, 0), g.rgb.at(1, 0, 2));
}

TEST(LinearImage, BadFilesAreNamed) {
  TempDir tmp;
  WriteText(tmp.File("a.jpg"), "not an image");
  std::string m;
  try {
    ReadLinearImage(tmp.File("a.jpg"), Linearisation{});
  } catch (const InputError& e) {
    m = e.what();
  }
  EXPECT_NE(m.find(tmp.File("a.jpg") + ": not a PNG or JPEG file"), std::string::npos) << m;
  // A JPEG's signature and a 16x16 frame header over a broken body reach the
  // decoder, which refuses it.
  WriteText(tmp.File("b.jpg"), std::string("\xff\xd8\xff\xc0\x00\x11\x08\x00\x10\x00\x10\x03", 12) + "truncated");
  m.clear();
  try {
    ReadLinearImage(tmp.File("b.jpg"), Linearisation{});
  } catch (const InputError& e) {
    m = e.what();
  }
  EXPECT_NE(m.find(tmp.File("b.jpg") + ": cannot decode image"), std::string::npos) << m;
  // A PNG header stating 100000x100000 pixels is refused before decoding.
  WriteText(tmp.File("c.png"),
            std::string("\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR\0\x01\x86\xa0\0\x01\x86\xa0\x08\x02\0\0\0", 29));
  m.clear();
  try {
    ReadLinearImage(tmp.File("c.png"), Linearisation{});
  } catch (const InputError& e) {
    m = e.what();
  }
  EXPECT_NE(m.find(tmp.File("c.png") + ": header states 100000x100000 pixels"), std::string::npos) << m;
  cv::Mat mask(3, 5, CV_8UC1, cv::Scalar(0));
  ASSERT_TRUE(cv::imwrite(tmp.File("m.png"), mask));
  EXPECT_EQ(ReadMask(tmp.File("m.png"), 5, 3).width, 5);
  m.clear();
  try {
    ReadMask(tmp.File("m.png"), 4, 3);
  } catch (const InputError& e) {
    m = e.what();
  }
  EXPECT_NE(m.find("mask is 5x3 (expected 4x3"), std::string::npos) << m;
}

TEST(LinearImage, DatasetCameraJsonChoosesTheResponse) {
  TempDir tmp;
  EXPECT_FALSE(DatasetLinearisation(tmp.path()).response.has_value());
  EXPECT_NE(DatasetLinearisation(tmp.path()).Describe().find("sRGB"), std::string::npos);
  CameraFile file;
  file.camera.width = 4;
  file.camera.height = 2;
  file.camera.fx = file.camera.fy = 4;
  file.camera.cx = 2;
  file.camera.cy = 1;
  file.response = CameraResponse::Display8(3);
  WriteCameraFile(tmp.File("camera.json"), file);
  const Linearisation l = DatasetLinearisation(tmp.path());
  ASSERT_TRUE(l.response.has_value());
  EXPECT_NE(l.Describe().find(tmp.File("camera.json")), std::string::npos);
}

// ------------------------------------------------------------- scene box

Pose LookingAt(const Vec3& eye, const Vec3& target) { return LookAt(eye, target); }

TEST(SceneBox, LookAtPointOfCamerasAimedAtOnePoint) {
  const Vec3 target{0.1, -0.2, 0.05};
  std::vector<Pose> poses;
  for (int k = 0; k < 12; ++k) {
    const double a = 2 * kPi * k / 12, e = 0.3 + 0.1 * (k % 4);
    poses.push_back(LookingAt(
        target + Vec3{std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e)} * (0.8 + 0.05 * k), target));
  }
  Vec3 found;
  ASSERT_TRUE(LookAtPoint(poses, found));
  EXPECT_NEAR(Length(found - target), 0.0, 1e-9);
  // Parallel axes meet nowhere.
  std::vector<Pose> parallel = {LookingAt({0, 0, 1}, {0, 0, 0}), LookingAt({1, 0, 1}, {1, 0, 0})};
  EXPECT_FALSE(LookAtPoint(parallel, found));
}

TEST(SceneBox, FromCamerasIsWhatTheMedianViewFramesAroundTheirTarget) {
  // Three 400x300 cameras with a 90 degree horizontal view (tan 1, vertical
  // tan 0.75) at distances 1, 2 and 3 from the origin: the median half-side
  // is 2 · hypot(1, 0.75) = 2.5.
  Dataset d;
  d.path = "t.json";
  d.camera.width = 400;
  d.camera.height = 300;
  d.camera.fx = d.camera.fy = 200;
  d.camera.cx = 200;
  d.camera.cy = 150;
  for (const Vec3& eye : {Vec3{1, 0, 0}, Vec3{0, 2, 0}, Vec3{0, 0, 3}}) {
    DatasetFrame f;
    f.T_world_camera = LookingAt(eye, {0, 0, 0});
    d.frames.push_back(f);
  }
  const SceneBox box = DeriveSceneBox(d, nullptr);
  EXPECT_NEAR(box.box.min.x, -2.5, 1e-9);
  EXPECT_NEAR(box.box.max.z, 2.5, 1e-9);
  EXPECT_NE(box.how.find("from the cameras"), std::string::npos) << box.how;
  // instant-ngp's box, where the file gives one, bounds it.
  d.ngp_box = Aabb{{-1, -5, -5}, {5, 0.5, 5}};
  const SceneBox cut = DeriveSceneBox(d, nullptr);
  EXPECT_NEAR(cut.box.min.x, -1.0, 1e-9);
  EXPECT_NEAR(cut.box.max.y, 0.5, 1e-9);
  EXPECT_NEAR(cut.box.max.x, 2.5, 1e-9);
  EXPECT_NE(cut.how.find("instant-ngp"), std::string::npos) << cut.how;
}

TEST(SceneBox, AroundTheBoardsTags) {
  Board board;
  board.tag_size_m = 0.06;
  for (const Vec3& c : {Vec3{-0.5, -0.3, 0}, Vec3{0.5, 0.3, 0}}) {
    BoardTag tag;
    tag.center = c;
    for (int k = 0; k < 4; ++k) tag.corners[k] = c + Vec3{k == 1 || k == 2 ? 0.03 : -0.03, k < 2 ? 0.03 : -0.03, 0};
    board.tags.push_back(tag);
  }
  Dataset d;
  const SceneBox box = DeriveSceneBox(d, &board);
  EXPECT_NEAR(box.box.min.x, -0.53 - kBoardBoxMarginM, 1e-12);
  EXPECT_NEAR(box.box.max.y, 0.33 + kBoardBoxMarginM, 1e-12);
  EXPECT_EQ(box.box.min.z, -kBoardBoxBelowM);
  EXPECT_EQ(box.box.max.z, kBoardBoxHeightM);
  EXPECT_NE(box.how.find("board's 2 tags"), std::string::npos) << box.how;
}

TEST(SceneBox, SharedScenesCamerasFrameTheTable) {
  // The shared scenes' cameras look at the table centre from 0.8-1.3 m with a
  // 60 degree view: the box derived without their aabb holds the table top
  // (1.2 x 0.8 m at z = 0) and is not much larger than the scene's own box.
  NERFAR_REQUIRE_SHARED_SCENES(scenes);
  Dataset d = ReadDataset(DatasetSplitPath(scenes + "/lamps", "train"), false);
  d.aabb.reset();
  const SceneBox box = DeriveSceneBox(d, nullptr);
  std::printf("lamps without its aabb: %s\n", box.how.c_str());
  EXPECT_LT(box.box.min.x, -0.6);
  EXPECT_GT(box.box.max.x, 0.6);
  EXPECT_LT(box.box.min.y, -0.4);
  EXPECT_GT(box.box.max.y, 0.4);
  EXPECT_LT(box.box.min.z, 0.0);
  EXPECT_LT(box.box.max.x - box.box.min.x, 2 * 1.24);  // within twice the scene's own 1.24 m
}

}  // namespace
}  // namespace nerfar
