// Camera intrinsics and distortion from 2-D/3-D correspondences of several
// views of a known board (the pure half of `nerfar calibrate`; tag detection
// lives in tracking/, app/ joins them). Object points in metres in the board
// frame; image points in the continuous pixel coordinates of calib/camera.h
// (pixel centres at i + 0.5). Reports per-view RMS reprojection error, views
// rejected as outliers, 1-sigma parameter uncertainties, which cells of the
// image saw corners, and a pass/fail gate with a plain message.
#pragma once

#include <string>
#include <vector>

#include "calib/camera.h"
#include "calib/core/math.h"

namespace nerfar {

// One image of the board: corresponding points, in the same order.
struct CalibrationView {
  std::string name;                 // for messages ("frame 12", a file name)
  std::vector<Vec3> object_points;  // board frame, metres
  std::vector<Vec2> image_points;   // continuous pixel coordinates
};

struct IntrinsicsOptions {
  // Fit k3 too. Off by default: webcams rarely need it and it trades off
  // against k1/k2 with few views; turn on for wide-angle lenses.
  bool fit_k3 = false;
  // Fit tangential terms p1, p2. Turn off for a well-centred lens and few views.
  bool fit_tangential = true;
  // Force fx == fy (square pixels). Turn on if fx/fy wander with few views.
  bool fix_aspect_ratio = false;
  // Gate: the calibration passes when the RMS over kept views is below this.
  double max_rms_px = 0.5;
  // A view is rejected when its RMS exceeds reject_factor x the median view
  // RMS and also min_reject_rms_px (so that a uniformly excellent set keeps
  // every view). Views are dropped and the fit repeated until none is.
  double reject_factor = 3.0;
  double min_reject_rms_px = 0.5;
  int max_rejection_rounds = 5;
  // At least this many views must remain (each with min_points_per_view).
  int min_views = 3;
  int min_points_per_view = 6;
  // Coverage grid over the image, and the fraction of its cells that must
  // hold at least one corner for the gate to pass (corners near the edges
  // are what pin down distortion).
  int coverage_cols = 8;
  int coverage_rows = 6;
  double min_coverage = 0.6;
  // Every problem with the values, each "field: what (expected)".
  std::vector<std::string> Validate() const;
};

struct ViewReport {
  std::string name;
  int points = 0;
  double rms_px = 0;  // RMS of the 2-D reprojection error; at rejection time if rejected
  bool rejected = false;
  Pose T_camera_board;  // pose of the board in this view (meaningful when kept)
};

// Corners per cell of a cols x rows grid over the image.
struct CoverageGrid {
  int cols = 0, rows = 0;
  std::vector<int> counts;  // row-major, rows x cols
  double FractionCovered() const;
  // One line per row, '#' for a covered cell and '.' for an empty one.
  std::string Render() const;
  // Plain words for the empty regions ("left edge", "top-right corner", ...);
  // empty when all four edges and the centre have corners.
  std::string DescribeGaps() const;
};

// 1-sigma uncertainties of the fitted parameters (pixels / unitless).
struct IntrinsicsSigma {
  double fx = 0, fy = 0, cx = 0, cy = 0, k1 = 0, k2 = 0, p1 = 0, p2 = 0, k3 = 0;
};

struct IntrinsicsResult {
  CameraIntrinsics camera;
  IntrinsicsSigma sigma;
  double rms_px = 0;  // over all points of the kept views
  int views_used = 0;
  std::vector<ViewReport> views;  // one per input view, in input order
  CoverageGrid coverage;          // from the kept views
  bool passed = false;            // the gate
  std::string verdict;            // plain message: what was found and, if failed, what to do
};

// Fits intrinsics and distortion for an image of width x height pixels.
// InputError (every problem listed) for bad input: too few views or points,
// mismatched counts, non-finite numbers, points outside the image. Planar
// boards need no initial guess; non-planar point sets start from a
// 60-degree pinhole at the image centre.
IntrinsicsResult CalibrateIntrinsics(const std::vector<CalibrationView>& views, int width, int height,
                                     const IntrinsicsOptions& options = {});

// Coverage of the given image points over a grid (used by the live guide too).
CoverageGrid ComputeCoverage(const std::vector<std::vector<Vec2>>& image_points, int width, int height, int cols,
                             int rows);

}  // namespace nerfar
