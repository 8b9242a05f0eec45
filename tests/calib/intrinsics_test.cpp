// calib/intrinsics: calibration from synthetic views of a known camera. The
// views are made with cv::projectPoints (independent of our projection), with
// Gaussian corner noise of known sigma and fixed seeds.
#include "calib/intrinsics.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <opencv2/calib3d.hpp>
#include <random>

#include "calib/core/error.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

CameraIntrinsics TrueCamera() {
  CameraIntrinsics c;
  c.width = 640;
  c.height = 480;
  c.fx = 600.0;
  c.fy = 603.0;
  c.cx = 322.4;
  c.cy = 241.1;
  c.k1 = -0.21;
  c.k2 = 0.06;
  c.p1 = 4e-4;
  c.p2 = -3e-4;
  return c;
}

// A flat board of 10 x 7 corners, 4 cm apart, printed 0.5 mm above z = 0 of
// its frame (like the shared scenes' tags), so the plane is not z = 0.
std::vector<Vec3> BoardCorners() {
  std::vector<Vec3> points;
  for (int j = 0; j < 7; ++j)
    for (int i = 0; i < 10; ++i) points.push_back({0.04 * i - 0.18, 0.04 * j - 0.12, 0.0005});
  return points;
}

struct SyntheticSet {
  std::vector<CalibrationView> views;
  std::vector<Pose> T_camera_board;
};

// Views with the board centre at `targets` (fractions of the image), tilted up
// to 35 degrees, 0.45 to 0.8 m away; noise_px Gaussian on every corner.
SyntheticSet MakeViews(const std::vector<Vec2>& targets, double noise_px, unsigned seed) {
  const CameraIntrinsics c = TrueCamera();
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> tilt(-0.6, 0.6), spin(-0.35, 0.35), dist(0.45, 0.8);
  std::normal_distribution<double> noise(0.0, noise_px);
  const cv::Mat K = (cv::Mat_<double>(3, 3) << c.fx, 0, c.cx - 0.5, 0, c.fy, c.cy - 0.5, 0, 0, 1);
  const cv::Mat D = (cv::Mat_<double>(1, 5) << c.k1, c.k2, c.p1, c.p2, c.k3);
  const std::vector<Vec3> board = BoardCorners();
  SyntheticSet set;
  for (size_t v = 0; v < targets.size(); ++v) {
    const Mat3 r = RotationFromAxisAngle({1, 0, 0}, tilt(rng)) * RotationFromAxisAngle({0, 1, 0}, tilt(rng)) *
                   RotationFromAxisAngle({0, 0, 1}, spin(rng));
    const Vec3 ray =
        Normalized(Vec3{(targets[v].x * c.width - c.cx) / c.fx, (targets[v].y * c.height - c.cy) / c.fy, 1});
    const Pose T_camera_board{r, ray * dist(rng)};
    std::vector<cv::Point3d> points;
    for (const Vec3& p : board) {
      const Vec3 q = T_camera_board * p;
      points.push_back({q.x, q.y, q.z});
    }
    std::vector<cv::Point2d> pixels;
    cv::projectPoints(points, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K, D, pixels);
    CalibrationView view;
    view.name = "v" + std::to_string(v);
    for (size_t i = 0; i < pixels.size(); ++i) {
      const Vec2 px{pixels[i].x + 0.5 + noise(rng), pixels[i].y + 0.5 + noise(rng)};
      if (px.x < 0 || px.x > c.width || px.y < 0 || px.y > c.height) continue;  // the camera sees only these
      view.object_points.push_back(board[i]);
      view.image_points.push_back(px);
    }
    set.views.push_back(view);
    set.T_camera_board.push_back(T_camera_board);
  }
  return set;
}

// Board centres over a 4 x 3 grid of the image plus the centre: full coverage.
std::vector<Vec2> SpreadTargets() {
  std::vector<Vec2> t;
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 4; ++i) t.push_back({0.2 + 0.2 * i, 0.25 + 0.25 * j});
  t.push_back({0.5, 0.5});
  return t;
}

TEST(Intrinsics, RecoversKnownCameraAndRejectsABadView) {
  SyntheticSet set = MakeViews(SpreadTargets(), 0.2, 5);
  // View 4 is corrupted: 4 px noise, as from a blurred frame or a misdetection.
  std::mt19937 rng(9);
  std::normal_distribution<double> noise(0.0, 4.0);
  for (Vec2& p : set.views[4].image_points) {
    p.x = std::clamp(p.x + noise(rng), 0.0, 640.0);
    p.y = std::clamp(p.y + noise(rng), 0.0, 480.0);
  }
  const IntrinsicsResult r = CalibrateIntrinsics(set.views, 640, 480);
  const CameraIntrinsics t = TrueCamera();
  std::printf(
      "calibration, 13 views (1 corrupted), 0.2 px noise: fx err %.3f%%, fy err %.3f%%, cx err %.3f px, "
      "cy err %.3f px, RMS %.3f px, sigma fx %.3f px\n",
      100 * (r.camera.fx - t.fx) / t.fx, 100 * (r.camera.fy - t.fy) / t.fy, r.camera.cx - t.cx, r.camera.cy - t.cy,
      r.rms_px, r.sigma.fx);
  // Issue 8's acceptance: focal error <= 0.5 %, principal point <= 1 px.
  EXPECT_LE(std::abs(r.camera.fx - t.fx) / t.fx, 0.005);
  EXPECT_LE(std::abs(r.camera.fy - t.fy) / t.fy, 0.005);
  EXPECT_LE(std::abs(r.camera.cx - t.cx), 1.0);
  EXPECT_LE(std::abs(r.camera.cy - t.cy), 1.0);
  // k1 of -0.21: with 0.2 px noise and 13 views it is pinned to a few 1e-3.
  EXPECT_NEAR(r.camera.k1, t.k1, 0.02);
  ASSERT_EQ(r.views.size(), 13u);
  for (size_t v = 0; v < r.views.size(); ++v) EXPECT_EQ(r.views[v].rejected, v == 4) << v;
  EXPECT_GT(r.views[4].rms_px, 3.0);
  EXPECT_EQ(r.views_used, 12);
  // RMS of 2-D residuals with per-axis sigma 0.2: sqrt(2) * 0.2 = 0.28, a bit
  // less after the fit absorbs some (about 1 - params / observations).
  EXPECT_GT(r.rms_px, 0.22);
  EXPECT_LT(r.rms_px, 0.32);
  EXPECT_TRUE(r.passed) << r.verdict;
  EXPECT_NE(r.verdict.find("calibration good"), std::string::npos) << r.verdict;
  EXPECT_NE(r.verdict.find("1 rejected"), std::string::npos) << r.verdict;
  // Board poses: 0.2 px noise gives well under a degree and a centimetre.
  for (int v : {0, 7, 12}) {
    EXPECT_LT(RotationAngleBetween(r.views[v].T_camera_board.rotation, set.T_camera_board[v].rotation), 0.01);
    EXPECT_LT(Length(r.views[v].T_camera_board.translation - set.T_camera_board[v].translation), 0.005);
  }
  EXPECT_GT(r.coverage.FractionCovered(), 0.9);
  EXPECT_EQ(r.coverage.DescribeGaps(), "");
}

TEST(Intrinsics, UncertaintyMatchesScatterOverSeeds) {
  // The reported 1-sigma of fx against the actual scatter of fx over 10
  // independent noise draws. The sample deviation of 10 draws lies within
  // [0.47, 1.45] x sigma with 95 % probability; [0.4, 2.0] leaves margin.
  std::vector<double> errors;
  double sigma_sum = 0;
  for (unsigned seed = 100; seed < 110; ++seed) {
    const IntrinsicsResult r = CalibrateIntrinsics(MakeViews(SpreadTargets(), 0.3, seed).views, 640, 480);
    errors.push_back(r.camera.fx - TrueCamera().fx);
    sigma_sum += r.sigma.fx;
    EXPECT_GT(r.sigma.cx, 0.0);
    EXPECT_GT(r.sigma.k1, 0.0);
  }
  double mean = 0, var = 0;
  for (double e : errors) mean += e / errors.size();
  for (double e : errors) var += (e - mean) * (e - mean) / (errors.size() - 1);
  const double ratio = std::sqrt(var) / (sigma_sum / errors.size());
  EXPECT_GT(ratio, 0.4);
  EXPECT_LT(ratio, 2.0);
}

TEST(Intrinsics, GateFailsOnLargeError) {
  const IntrinsicsResult r = CalibrateIntrinsics(MakeViews(SpreadTargets(), 0.7, 6).views, 640, 480);
  // Uniformly noisy views: none stands out, none is rejected.
  EXPECT_EQ(r.views_used, 13);
  EXPECT_GT(r.rms_px, 0.5);
  EXPECT_FALSE(r.passed);
  EXPECT_EQ(r.verdict.rfind("recalibrate:", 0), 0u) << r.verdict;
}

TEST(Intrinsics, GateFailsOnPoorCoverage) {
  // Every view in the left third of the image, boards held far away.
  std::vector<Vec2> targets;
  for (int k = 0; k < 8; ++k) targets.push_back({0.18 + 0.02 * (k % 2), 0.3 + 0.06 * k});
  SyntheticSet set = MakeViews(targets, 0.1, 8);
  IntrinsicsOptions options;
  options.min_coverage = 0.6;
  const IntrinsicsResult r = CalibrateIntrinsics(set.views, 640, 480, options);
  EXPECT_LT(r.coverage.FractionCovered(), 0.6);
  EXPECT_FALSE(r.passed);
  EXPECT_EQ(r.verdict.rfind("take more views:", 0), 0u) << r.verdict;
  EXPECT_NE(r.verdict.find("right edge"), std::string::npos) << r.verdict;
}

TEST(Intrinsics, CoverageGridCountsCells) {
  const CoverageGrid g = ComputeCoverage({{{1, 1}, {639, 479}, {700, 10}}, {{1.5, 2}}}, 640, 480, 4, 2);
  ASSERT_EQ(g.counts.size(), 8u);
  EXPECT_EQ(g.counts[0], 2);                       // two corners in the top-left cell
  EXPECT_EQ(g.counts[7], 1);                       // bottom-right
  EXPECT_DOUBLE_EQ(g.FractionCovered(), 2.0 / 8);  // the point outside the image is not counted
  EXPECT_EQ(g.Render(), "#...\n...#\n");
}

TEST(Intrinsics, BadInputListsProblems) {
  SyntheticSet set = MakeViews(SpreadTargets(), 0.2, 5);
  std::vector<CalibrationView> views = set.views;
  views[1].image_points.pop_back();
  views[2].image_points[3].x = std::nan("");
  views[3].image_points[0].x = 5000;
  for (Vec3& p : views[5].object_points) p = {p.x, 0, 0};  // collinear
  for (Vec2& p : views[5].image_points) p.y = 10;
  std::string message;
  try {
    CalibrateIntrinsics(views, 640, 480);
  } catch (const InputError& e) {
    message = e.what();
  }
  EXPECT_NE(message.find("(expected equal counts)"), std::string::npos) << message;
  EXPECT_NE(message.find("view v2: point 3 is not finite"), std::string::npos) << message;
  EXPECT_NE(message.find("view v3: image point 0"), std::string::npos) << message;
  views = {set.views[0], set.views[1]};
  EXPECT_THROW(CalibrateIntrinsics(views, 640, 480), InputError);
  views = set.views;
  for (Vec3& p : views[5].object_points) p = {p.x, 0, 0};
  try {
    CalibrateIntrinsics(views, 640, 480);
    ADD_FAILURE() << "collinear view accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("view v5: object points are collinear"), std::string::npos) << e.what();
  }
  IntrinsicsOptions bad;
  bad.max_rms_px = -1;
  bad.min_views = 1;
  EXPECT_EQ(bad.Validate().size(), 2u);
}

}  // namespace
}  // namespace nerfar
