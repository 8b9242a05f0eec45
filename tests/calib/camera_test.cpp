// calib/camera: distortion model against OpenCV (an independent
// implementation), Distort/Undistort and Project/Unproject round trips over
// stratified pixels, undistortion maps against cv::initUndistortRectifyMap
// (minding the half-pixel convention), scaling and validation.
#include "calib/camera.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/calib3d.hpp>
#include <random>

#include "tests/support/support.h"

namespace nerfar {
namespace {

// A realistic webcam-like lens: barrel distortion of a few pixels at the
// corners, small decentering terms.
CameraIntrinsics DistortedCamera() {
  CameraIntrinsics c;
  c.width = 640;
  c.height = 480;
  c.fx = 520.5;
  c.fy = 518.25;
  c.cx = 321.3;
  c.cy = 238.9;
  c.k1 = -0.28;
  c.k2 = 0.09;
  c.p1 = 1.2e-3;
  c.p2 = -8e-4;
  c.k3 = -0.012;
  return c;
}

CameraIntrinsics PinholeCamera() {
  CameraIntrinsics c;
  c.width = 400;
  c.height = 300;
  c.fx = c.fy = 346.4101615137755;
  c.cx = 200;
  c.cy = 150;
  return c;
}

// Stratified pixel positions: one jittered sample per cell of a grid over the
// whole image (fixed seed), so corners and edges are covered.
std::vector<Vec2> StratifiedPixels(const CameraIntrinsics& c, int nx, int ny) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Vec2> out;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) out.push_back({(i + u(rng)) * c.width / nx, (j + u(rng)) * c.height / ny});
  return out;
}

cv::Mat OpenCvK(const CameraIntrinsics& c) {
  const Vec2 pp = ToOpenCvPrincipalPoint(c);
  return (cv::Mat_<double>(3, 3) << c.fx, 0, pp.x, 0, c.fy, pp.y, 0, 0, 1);
}
cv::Mat OpenCvDistortion(const CameraIntrinsics& c) { return (cv::Mat_<double>(1, 5) << c.k1, c.k2, c.p1, c.p2, c.k3); }

TEST(Camera, PrincipalPointConvention) {
  CameraIntrinsics c = PinholeCamera();
  const Vec2 pp = ToOpenCvPrincipalPoint(c);
  // README: cx 200 (continuous) is 199.5 with pixel centres at integers.
  EXPECT_EQ(pp.x, 199.5);
  EXPECT_EQ(pp.y, 149.5);
  FromOpenCvPrincipalPoint(c, 10.0, 20.0);
  EXPECT_EQ(c.cx, 10.5);
  EXPECT_EQ(c.cy, 20.5);
}

TEST(Camera, PinholeAnalytic) {
  const CameraIntrinsics c = PinholeCamera();
  Vec2 px;
  ASSERT_TRUE(Project(c, {0, 0, 2}, px));
  EXPECT_EQ(px.x, 200.0);  // the optical axis meets the image centre exactly
  EXPECT_EQ(px.y, 150.0);
  ASSERT_TRUE(Project(c, {1, -0.5, 1}, px));
  EXPECT_NEAR(px.x, 200 + c.fx, 1e-12);
  EXPECT_NEAR(px.y, 150 - 0.5 * c.fy, 1e-12);
  EXPECT_FALSE(Project(c, {0, 0, 0}, px));
  EXPECT_FALSE(Project(c, {0, 0, -1}, px));
  const Vec3 d = Unproject(c, {200 + c.fx, 150});
  EXPECT_NEAR(d.x, std::sqrt(0.5), 1e-15);
  EXPECT_NEAR(d.y, 0.0, 1e-15);
  EXPECT_NEAR(d.z, std::sqrt(0.5), 1e-15);
  // The right edge of the 60-degree image is 30 degrees off axis.
  const Vec3 edge = Unproject(c, {400, 150});
  EXPECT_NEAR(std::atan2(edge.x, edge.z), kPi / 6, 1e-12);
}

TEST(Camera, DistortMatchesOpenCvProjectPoints) {
  // cv::projectPoints is an independent implementation of the same model:
  // our continuous pixel = OpenCV pixel + 0.5.
  const CameraIntrinsics c = DistortedCamera();
  std::vector<cv::Point3d> points;
  for (const Vec2& p : StratifiedPixels(c, 16, 12)) {
    const double x = (p.x - c.cx) / c.fx * 0.9, y = (p.y - c.cy) / c.fy * 0.9;  // within the image
    points.push_back({x * 2.0, y * 2.0, 2.0});
  }
  std::vector<cv::Point2d> cv_pixels;
  cv::projectPoints(points, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), OpenCvK(c), OpenCvDistortion(c), cv_pixels);
  for (size_t i = 0; i < points.size(); ++i) {
    Vec2 px;
    ASSERT_TRUE(Project(c, {points[i].x, points[i].y, points[i].z}, px));
    // Both evaluate the same polynomial in double: 1e-9 px is rounding only.
    EXPECT_NEAR(px.x, cv_pixels[i].x + 0.5, 1e-9);
    EXPECT_NEAR(px.y, cv_pixels[i].y + 0.5, 1e-9);
  }
}

TEST(Camera, DistortUndistortInverse) {
  const CameraIntrinsics c = DistortedCamera();
  double worst = 0;
  for (const Vec2& p : StratifiedPixels(c, 40, 30)) {
    const Vec2 distorted{(p.x - c.cx) / c.fx, (p.y - c.cy) / c.fy};
    const Vec2 u = Undistort(c, distorted);
    const Vec2 back = Distort(c, u);
    worst = std::max({worst, std::abs(back.x - distorted.x), std::abs(back.y - distorted.y)});
    // And the other way: undistorting a distorted point gives it back.
    const Vec2 again = Undistort(c, Distort(c, u));
    EXPECT_NEAR(again.x, u.x, 1e-10);
    EXPECT_NEAR(again.y, u.y, 1e-10);
  }
  // Header promise: 1e-10 in normalised units inside the image (~5e-8 px).
  EXPECT_LT(worst, 1e-10);
}

TEST(Camera, UndistortMatchesOpenCvUndistortPoints) {
  // cv::undistortPoints iterates the same inverse independently; with enough
  // iterations it converges to the same point.
  const CameraIntrinsics c = DistortedCamera();
  std::vector<cv::Point2d> in;
  for (const Vec2& p : StratifiedPixels(c, 10, 8)) in.push_back({p.x - 0.5, p.y - 0.5});
  std::vector<cv::Point2d> out;
  cv::undistortPoints(in, out, OpenCvK(c), OpenCvDistortion(c), cv::noArray(), cv::noArray(),
                      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 200, 1e-15));
  for (size_t i = 0; i < in.size(); ++i) {
    const Vec2 u = Undistort(c, {(in[i].x + 0.5 - c.cx) / c.fx, (in[i].y + 0.5 - c.cy) / c.fy});
    // OpenCV stops on a step size criterion; 1e-7 normalised is ~5e-5 px.
    EXPECT_NEAR(u.x, out[i].x, 1e-7);
    EXPECT_NEAR(u.y, out[i].y, 1e-7);
  }
}

TEST(Camera, ProjectUnprojectRoundTrip) {
  for (const CameraIntrinsics& c : {PinholeCamera(), DistortedCamera()}) {
    double worst_px = 0;
    for (const Vec2& p : StratifiedPixels(c, 32, 24)) {
      const Vec3 ray = Unproject(c, p);
      EXPECT_NEAR(Length(ray), 1.0, 1e-14);
      EXPECT_GT(ray.z, 0.0);
      for (double depth : {0.1, 1.0, 37.0}) {
        Vec2 back;
        ASSERT_TRUE(Project(c, ray * depth, back));
        worst_px = std::max({worst_px, std::abs(back.x - p.x), std::abs(back.y - p.y)});
      }
    }
    // Undistort is exact to ~1e-10 normalised = ~1e-7 px; 1e-6 px leaves margin.
    EXPECT_LT(worst_px, 1e-6);
  }
}

TEST(Camera, UndistortMapsMatchOpenCv) {
  const CameraIntrinsics c = DistortedCamera();
  std::vector<float> map_x, map_y;
  UndistortMaps(c, map_x, map_y);
  ASSERT_EQ(map_x.size(), size_t(c.width) * c.height);
  cv::Mat cv_x, cv_y;
  cv::initUndistortRectifyMap(OpenCvK(c), OpenCvDistortion(c), cv::Mat(), OpenCvK(c), cv::Size(c.width, c.height),
                              CV_32FC1, cv_x, cv_y);
  double worst = 0;
  for (int j = 0; j < c.height; ++j) {
    for (int i = 0; i < c.width; ++i) {
      const size_t k = size_t(j) * c.width + i;
      // OpenCV samples at integer centres; ours are continuous (+0.5).
      worst = std::max(worst, double(std::abs(map_x[k] - (cv_x.at<float>(j, i) + 0.5f))));
      worst = std::max(worst, double(std::abs(map_y[k] - (cv_y.at<float>(j, i) + 0.5f))));
    }
  }
  // Both are float maps of the same double polynomial: the float rounding of
  // values up to ~700 px is 3e-5 px; 1e-3 px is far below any visible shift.
  EXPECT_LT(worst, 1e-3);
  // The map's own definition: the ideal pixel centre's ray projects there.
  const int i = 17, j = 401;
  Vec2 px;
  ASSERT_TRUE(Project(c, {(i + 0.5 - c.cx) / c.fx, (j + 0.5 - c.cy) / c.fy, 1.0}, px));
  EXPECT_NEAR(map_x[size_t(j) * c.width + i], px.x, 1e-4);
  EXPECT_NEAR(map_y[size_t(j) * c.width + i], px.y, 1e-4);
}

TEST(Camera, ScaledKeepsRaysOfTheSameImagePoint) {
  const CameraIntrinsics c = DistortedCamera();
  const CameraIntrinsics half = c.Scaled(320, 240);
  // The same relative point of the image (a corner, the centre) sees the same ray.
  for (const Vec2& rel : {Vec2{0, 0}, Vec2{1, 1}, Vec2{0.5, 0.5}, Vec2{0.25, 0.8}}) {
    const Vec3 a = Unproject(c, {rel.x * c.width, rel.y * c.height});
    const Vec3 b = Unproject(half, {rel.x * half.width, rel.y * half.height});
    EXPECT_NEAR(Length(a - b), 0.0, 1e-12);
  }
}

TEST(Camera, ValidateListsEveryProblem) {
  CameraIntrinsics c;
  c.width = 0;
  c.height = 100000;
  c.fx = -1;
  c.fy = std::nan("");
  c.k2 = INFINITY;
  const auto problems = c.Validate();
  EXPECT_EQ(problems.size(), 5u);
  EXPECT_TRUE(PinholeCamera().Validate().empty());
}

}  // namespace
}  // namespace nerfar
