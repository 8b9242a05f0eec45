// Camera pose from every visible tag of a board at once. Frames: world = the
// board's frame (metres); the result is T_world_camera with OpenCV camera
// axes (x right, y down, z forward). Pixels: continuous coordinates as in
// calib/camera.h; lens distortion is removed through calib's Undistort.
// Method: every tag's two IPPE solutions are hypotheses scored on all tags;
// the best is refined by Levenberg-Marquardt over the corners of its inlier
// tags, tags beyond the outlier threshold are rejected, and where a second
// solution explains the corners nearly as well (one tag seen face-on) both
// are returned so a tracker can choose by consistency over time.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "calib/board.h"
#include "calib/camera.h"
#include "calib/core/math.h"
#include "tracking/tag_detector.h"

namespace nerfar {

struct BoardPoseOptions {
  // A tag whose corners reproject with an RMS above this (pixels) is an
  // outlier (a misdetection, a tag moved on the board). Raise it for
  // blurry frames or poor intrinsics.
  double outlier_rms_px = 3.0;
  // A second solution whose RMS is below ambiguity_ratio times the best one
  // (and whose rotation differs by more than 1 degree) is kept as the
  // alternative. 1 turns the ambiguity handling off.
  double ambiguity_ratio = 3.0;
  // Corner noise of the detector (pixels): RMS values below it are not told
  // apart, so a second solution within ambiguity_ratio times this level is
  // ambiguous however small the best one's RMS.
  double corner_noise_px = 0.25;
  // Levenberg-Marquardt iterations of the refinement (0: none, IPPE only).
  int refine_iterations = 30;
  // Fewest inlier tags for a pose.
  int min_tags = 1;

  std::vector<std::string> Validate() const;
};

struct BoardPose {
  bool ok = false;
  std::string why;                                        // reason when !ok ("no board tag seen", ...)
  Pose T_world_camera;                                    // refined pose
  double rms_px = 0;                                      // reprojection RMS over the inlier corners
  std::vector<int> inlier_ids, outlier_ids, unknown_ids;  // unknown: not on the board
  // The other solution when the pose is ambiguous (a single tag face-on).
  std::optional<Pose> alternative;
  double alternative_rms_px = 0;
};

BoardPose EstimateBoardPose(const std::vector<TagDetection>& detections, const Board& board,
                            const CameraIntrinsics& camera, const BoardPoseOptions& options = {});

// Reprojection RMS (pixels) of the given tags' corners under a pose; used for
// quality figures and tests. Tags not on the board are skipped.
double BoardReprojectionRms(const std::vector<TagDetection>& detections, const Board& board,
                            const CameraIntrinsics& camera, const Pose& T_world_camera);

}  // namespace nerfar
