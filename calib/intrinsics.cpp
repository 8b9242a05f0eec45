#include "calib/intrinsics.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/calib3d.hpp>

#include "calib/core/error.h"
#include "calib/core/image.h"

namespace nerfar {
namespace {

std::string Format(const char* format, double v) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, format, v);
  return buffer;
}

// The view's object points in a frame where they lie in z = 0 when they are
// coplanar (OpenCV's closed-form start needs that); T_plane_board maps board
// points into it. Non-planar views keep the board frame.
struct PreparedView {
  std::vector<cv::Point3f> object;
  std::vector<cv::Point2f> image;  // OpenCV convention: pixel centres at integers
  Pose T_plane_board;
  bool planar = false;
};

PreparedView Prepare(const CalibrationView& view, Problems& problems, const std::string& where) {
  PreparedView out;
  const size_t n = view.object_points.size();
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Vec3& p : view.object_points) mean += Eigen::Vector3d(p.x, p.y, p.z);
  mean /= static_cast<double>(n);
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const Vec3& p : view.object_points) {
    const Eigen::Vector3d d = Eigen::Vector3d(p.x, p.y, p.z) - mean;
    cov += d * d.transpose();
  }
  cov /= static_cast<double>(n);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  const Eigen::Vector3d values = eig.eigenvalues();  // ascending
  const double extent = std::sqrt(std::max(values(2), 0.0));
  if (!(extent > 0) || std::sqrt(std::max(values(1), 0.0)) < 1e-6 * extent) {
    problems.Add(where, "object points are collinear or coincide (expected a board spanning two directions)");
    return out;
  }
  // Coplanar within a micrometre per metre of extent: a flat board.
  out.planar = std::sqrt(std::max(values(0), 0.0)) <= 1e-6 * extent;
  if (out.planar) {
    Eigen::Matrix3d axes = eig.eigenvectors();  // columns: normal (smallest), then in-plane
    Eigen::Vector3d ex = axes.col(2), ey = axes.col(1);
    Eigen::Vector3d ez = ex.cross(ey);
    Mat3 r_board_plane =
        Mat3::FromColumns({ex.x(), ex.y(), ex.z()}, {ey.x(), ey.y(), ey.z()}, {ez.x(), ez.y(), ez.z()});
    const Pose T_board_plane{r_board_plane, {mean.x(), mean.y(), mean.z()}};
    out.T_plane_board = T_board_plane.Inverse();
  }
  for (size_t i = 0; i < n; ++i) {
    Vec3 p = out.T_plane_board * view.object_points[i];
    if (out.planar) p.z = 0;
    out.object.emplace_back(static_cast<float>(p.x), static_cast<float>(p.y), static_cast<float>(p.z));
    out.image.emplace_back(static_cast<float>(view.image_points[i].x - 0.5),
                           static_cast<float>(view.image_points[i].y - 0.5));
  }
  return out;
}

double ViewRms(const CameraIntrinsics& camera, const CalibrationView& view, const Pose& T_camera_board) {
  double sum = 0;
  for (size_t i = 0; i < view.object_points.size(); ++i) {
    Vec2 px;
    if (!Project(camera, T_camera_board * view.object_points[i], px)) return INFINITY;
    const double dx = px.x - view.image_points[i].x, dy = px.y - view.image_points[i].y;
    sum += dx * dx + dy * dy;
  }
  return std::sqrt(sum / static_cast<double>(view.object_points.size()));
}

struct Fit {
  CameraIntrinsics camera;
  IntrinsicsSigma sigma;
  std::vector<Pose> T_camera_board;  // per active view
};

Fit RunCalibration(const std::vector<PreparedView>& prepared, const std::vector<int>& active, int width, int height,
                   const IntrinsicsOptions& options) {
  std::vector<std::vector<cv::Point3f>> object;
  std::vector<std::vector<cv::Point2f>> image;
  bool all_planar = true;
  for (int i : active) {
    object.push_back(prepared[i].object);
    image.push_back(prepared[i].image);
    all_planar = all_planar && prepared[i].planar;
  }
  int flags = 0;
  if (!options.fit_k3) flags |= cv::CALIB_FIX_K3;
  if (!options.fit_tangential) flags |= cv::CALIB_ZERO_TANGENT_DIST;
  if (options.fix_aspect_ratio) flags |= cv::CALIB_FIX_ASPECT_RATIO;
  // Start (used only for non-planar sets, and for the fx/fy ratio): a
  // 60-degree pinhole at the image centre.
  const double f0 = 0.5 * width / std::tan(kPi / 6);
  cv::Mat K = (cv::Mat_<double>(3, 3) << f0, 0, 0.5 * width - 0.5, 0, f0, 0.5 * height - 0.5, 0, 0, 1);
  if (!all_planar) flags |= cv::CALIB_USE_INTRINSIC_GUESS;
  cv::Mat dist = cv::Mat::zeros(1, 5, CV_64F);
  std::vector<cv::Mat> rvecs, tvecs;
  cv::Mat std_intrinsics, std_extrinsics, per_view;
  try {
    cv::calibrateCamera(object, image, cv::Size(width, height), K, dist, rvecs, tvecs, std_intrinsics, std_extrinsics,
                        per_view, flags, cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 30, 1e-12));
  } catch (const cv::Exception& e) {
    ThrowInputError("calibration", std::string("the views do not determine a camera (") + e.err + ")");
  }
  Fit fit;
  CameraIntrinsics& c = fit.camera;
  c.width = width;
  c.height = height;
  c.fx = K.at<double>(0, 0);
  c.fy = K.at<double>(1, 1);
  FromOpenCvPrincipalPoint(c, K.at<double>(0, 2), K.at<double>(1, 2));
  const double* d = dist.ptr<double>();
  c.k1 = d[0];
  c.k2 = d[1];
  c.p1 = d[2];
  c.p2 = d[3];
  c.k3 = dist.total() > 4 ? d[4] : 0.0;
  if (std_intrinsics.total() >= 9) {
    const double* s = std_intrinsics.ptr<double>();
    fit.sigma = {s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7], s[8]};
  }
  for (size_t k = 0; k < active.size(); ++k) {
    cv::Mat r;
    cv::Rodrigues(rvecs[k], r);
    Pose T_camera_plane;
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) T_camera_plane.rotation(i, j) = r.at<double>(i, j);
      T_camera_plane.translation[i] = tvecs[k].at<double>(i);
    }
    fit.T_camera_board.push_back(T_camera_plane * prepared[active[k]].T_plane_board);
  }
  const std::vector<std::string> problems = c.Validate();
  if (!problems.empty()) ThrowInputError("calibration", "the fit gave an invalid camera (" + problems[0] + ")");
  return fit;
}

}  // namespace

std::vector<std::string> IntrinsicsOptions::Validate() const {
  std::vector<std::string> problems;
  const auto positive = [&](const char* name, double v) {
    if (!(v > 0) || !std::isfinite(v))
      problems.push_back(std::string(name) + ": is " + Format("%g", v) + " (expected > 0)");
  };
  positive("max_rms_px", max_rms_px);
  positive("min_reject_rms_px", min_reject_rms_px);
  if (!(reject_factor > 1) || !std::isfinite(reject_factor))
    problems.push_back("reject_factor: is " + Format("%g", reject_factor) + " (expected > 1)");
  if (max_rejection_rounds < 0 || max_rejection_rounds > 100)
    problems.push_back("max_rejection_rounds: is " + std::to_string(max_rejection_rounds) + " (expected 0 to 100)");
  if (min_views < 3) problems.push_back("min_views: is " + std::to_string(min_views) + " (expected at least 3)");
  if (min_points_per_view < 4)
    problems.push_back("min_points_per_view: is " + std::to_string(min_points_per_view) + " (expected at least 4)");
  if (coverage_cols < 1 || coverage_cols > 64 || coverage_rows < 1 || coverage_rows > 64)
    problems.push_back("coverage_cols/rows: are " + std::to_string(coverage_cols) + "x" +
                       std::to_string(coverage_rows) + " (expected 1 to 64 each)");
  if (!(min_coverage >= 0 && min_coverage <= 1))
    problems.push_back("min_coverage: is " + Format("%g", min_coverage) + " (expected 0 to 1)");
  return problems;
}

double CoverageGrid::FractionCovered() const {
  if (counts.empty()) return 0;
  const auto covered = std::count_if(counts.begin(), counts.end(), [](int c) { return c > 0; });
  return static_cast<double>(covered) / static_cast<double>(counts.size());
}

std::string CoverageGrid::Render() const {
  std::string out;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) out += counts[static_cast<size_t>(r) * cols + c] > 0 ? '#' : '.';
    out += '\n';
  }
  return out;
}

std::string CoverageGrid::DescribeGaps() const {
  if (counts.empty()) return "the whole image";
  const auto fraction = [&](int r0, int r1, int c0, int c1) {
    int covered = 0, total = 0;
    for (int r = r0; r < r1; ++r)
      for (int c = c0; c < c1; ++c) {
        ++total;
        covered += counts[static_cast<size_t>(r) * cols + c] > 0;
      }
    return total > 0 ? static_cast<double>(covered) / total : 1.0;
  };
  std::vector<std::string> gaps;
  // An edge counts as seen when at least half of its cells hold corners.
  if (fraction(0, rows, 0, 1) < 0.5) gaps.push_back("left edge");
  if (fraction(0, rows, cols - 1, cols) < 0.5) gaps.push_back("right edge");
  if (fraction(0, 1, 0, cols) < 0.5) gaps.push_back("top edge");
  if (fraction(rows - 1, rows, 0, cols) < 0.5) gaps.push_back("bottom edge");
  if (fraction(rows / 4, rows - rows / 4, cols / 4, cols - cols / 4) < 0.5) gaps.push_back("centre");
  std::string out;
  for (const std::string& g : gaps) out += (out.empty() ? "" : ", ") + g;
  return out;
}

CoverageGrid ComputeCoverage(const std::vector<std::vector<Vec2>>& image_points, int width, int height, int cols,
                             int rows) {
  NERFAR_CHECK(width > 0 && height > 0 && cols > 0 && rows > 0);
  CoverageGrid grid;
  grid.cols = cols;
  grid.rows = rows;
  grid.counts.assign(static_cast<size_t>(cols) * rows, 0);
  for (const auto& view : image_points) {
    for (const Vec2& p : view) {
      if (!(p.x >= 0 && p.x < width && p.y >= 0 && p.y < height)) continue;
      const int c = std::min(cols - 1, static_cast<int>(p.x * cols / width));
      const int r = std::min(rows - 1, static_cast<int>(p.y * rows / height));
      ++grid.counts[static_cast<size_t>(r) * cols + c];
    }
  }
  return grid;
}

IntrinsicsResult CalibrateIntrinsics(const std::vector<CalibrationView>& views, int width, int height,
                                     const IntrinsicsOptions& options) {
  Problems problems("calibration");
  for (const std::string& p : options.Validate()) problems.Add("options", p);
  if (width < 1 || width > kMaxImageSide || height < 1 || height > kMaxImageSide)
    problems.Add("image size", std::to_string(width) + "x" + std::to_string(height) + " (expected 1 to " +
                                   std::to_string(kMaxImageSide) + " each)");
  if (static_cast<int>(views.size()) < options.min_views)
    problems.Add("views",
                 std::to_string(views.size()) + " given (expected at least " + std::to_string(options.min_views) + ")");
  for (size_t v = 0; v < views.size(); ++v) {
    const CalibrationView& view = views[v];
    const std::string where = "view " + (view.name.empty() ? std::to_string(v) : view.name);
    if (view.object_points.size() != view.image_points.size()) {
      problems.Add(where, std::to_string(view.object_points.size()) + " object points and " +
                              std::to_string(view.image_points.size()) + " image points (expected equal counts)");
      continue;
    }
    if (static_cast<int>(view.object_points.size()) < options.min_points_per_view)
      problems.Add(where, std::to_string(view.object_points.size()) + " points (expected at least " +
                              std::to_string(options.min_points_per_view) + ")");
    for (size_t i = 0; i < view.object_points.size(); ++i) {
      const Vec3& o = view.object_points[i];
      const Vec2& p = view.image_points[i];
      if (!std::isfinite(o.x) || !std::isfinite(o.y) || !std::isfinite(o.z) || !std::isfinite(p.x) ||
          !std::isfinite(p.y)) {
        problems.Add(where, "point " + std::to_string(i) + " is not finite");
        break;
      }
      if (p.x < 0 || p.x > width || p.y < 0 || p.y > height) {
        problems.Add(where, "image point " + std::to_string(i) + " (" + Format("%.1f", p.x) + ", " +
                                Format("%.1f", p.y) + ") is outside the " + std::to_string(width) + "x" +
                                std::to_string(height) + " image");
        break;
      }
    }
  }
  problems.ThrowIfAny();

  std::vector<PreparedView> prepared;
  for (size_t v = 0; v < views.size(); ++v)
    prepared.push_back(
        Prepare(views[v], problems, "view " + (views[v].name.empty() ? std::to_string(v) : views[v].name)));
  problems.ThrowIfAny();

  IntrinsicsResult result;
  result.views.resize(views.size());
  std::vector<int> active;
  for (size_t v = 0; v < views.size(); ++v) {
    active.push_back(static_cast<int>(v));
    result.views[v].name = views[v].name;
    result.views[v].points = static_cast<int>(views[v].object_points.size());
  }

  Fit fit;
  for (int round = 0;; ++round) {
    fit = RunCalibration(prepared, active, width, height, options);
    std::vector<double> rms(active.size());
    for (size_t k = 0; k < active.size(); ++k) {
      rms[k] = ViewRms(fit.camera, views[active[k]], fit.T_camera_board[k]);
      result.views[active[k]].rms_px = rms[k];
      result.views[active[k]].T_camera_board = fit.T_camera_board[k];
    }
    if (round >= options.max_rejection_rounds) break;
    std::vector<double> sorted = rms;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double median = sorted[sorted.size() / 2];
    const double threshold = std::max(options.reject_factor * median, options.min_reject_rms_px);
    std::vector<int> keep;
    for (size_t k = 0; k < active.size(); ++k)
      if (!(rms[k] > threshold)) keep.push_back(active[k]);
    if (keep.size() == active.size() || static_cast<int>(keep.size()) < options.min_views) break;
    for (size_t k = 0; k < active.size(); ++k)
      if (rms[k] > threshold) result.views[active[k]].rejected = true;
    active = keep;
  }

  result.camera = fit.camera;
  result.sigma = fit.sigma;
  result.views_used = static_cast<int>(active.size());
  double sum = 0;
  size_t count = 0;
  std::vector<std::vector<Vec2>> kept_points;
  for (int v : active) {
    sum += result.views[v].rms_px * result.views[v].rms_px * views[v].object_points.size();
    count += views[v].object_points.size();
    kept_points.push_back(views[v].image_points);
  }
  result.rms_px = std::sqrt(sum / static_cast<double>(count));
  result.coverage = ComputeCoverage(kept_points, width, height, options.coverage_cols, options.coverage_rows);

  const double covered = result.coverage.FractionCovered();
  const int rejected = static_cast<int>(views.size()) - result.views_used;
  const std::string summary = "RMS " + Format("%.3f", result.rms_px) + " px over " + std::to_string(result.views_used) +
                              " of " + std::to_string(views.size()) + " views" +
                              (rejected > 0 ? " (" + std::to_string(rejected) + " rejected)" : "") + ", corners in " +
                              Format("%.0f", 100 * covered) + "% of the image";
  const bool rms_ok = result.rms_px < options.max_rms_px;
  const bool coverage_ok = covered >= options.min_coverage;
  result.passed = rms_ok && coverage_ok;
  if (result.passed) {
    result.verdict = "calibration good: " + summary;
  } else if (!rms_ok) {
    result.verdict = "recalibrate: " + summary + "; the RMS is above the " + Format("%.2f", options.max_rms_px) +
                     " px gate (hold the board flat and still, avoid motion blur, check the board's tag size)";
  } else {
    const std::string gaps = result.coverage.DescribeGaps();
    result.verdict = "take more views: " + summary + ", need " + Format("%.0f", 100 * options.min_coverage) + "%" +
                     (gaps.empty() ? "" : "; no corners yet near the " + gaps);
  }
  return result;
}

}  // namespace nerfar
