// The per-frame tracker: tag detection -> board pose -> choice between
// ambiguous solutions by consistency with the recent track -> temporal filter
// -> tracking state. Poses are T_world_camera (board world frame, metres,
// OpenCV camera axes). Process() never throws on frame content: a frame
// without a usable pose makes the state kLost and the last good pose is kept.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "calib/board.h"
#include "calib/camera.h"
#include "calib/core/frame_source.h"
#include "tracking/board_pose.h"
#include "tracking/pose_filter.h"
#include "tracking/tag_detector.h"

namespace nerfar {

// kTracking: this frame gave a pose consistent with the track.
// kLost: this frame gave no usable pose; the last good pose is reported.
// kRecovering: poses again after a loss (or at the start), not yet confirmed
//   by `confirm_frames` consistent frames in a row.
enum class TrackingState { kTracking, kLost, kRecovering };
const char* TrackingStateName(TrackingState state);

struct TrackerOptions {
  TagDetectorOptions detector;
  BoardPoseOptions pose;
  PoseFilterOptions filter;
  // Consistent frames in a row needed to go from recovering to tracking
  // (0: a single good frame is tracking; use 0 for unordered image sets).
  int confirm_frames = 2;
  // Frames after which the track is too old to arbitrate an ambiguous pose.
  int history_frames = 15;
  // A pose whose reprojection RMS exceeds this (pixels) is not used.
  double max_rms_px = 2.0;
  // A single tag seen face-on has two poses that fit (ambiguous): the tracker
  // follows the one that continues the track, and switches once to the other
  // when it explains the corners better by this log-likelihood (summed over
  // the ambiguous frames; 4.6 = 100:1).
  double branch_switch_evidence = 4.6;
  // While tracking, search only around the tags the motion-extrapolated pose
  // predicts (much less area than the frame); a frame whose region search
  // gives no pose is searched whole at once. Off: every frame whole.
  bool region_search = true;
  // Whole-frame search at least every this many frames while tracking, so
  // tags entering the view join the pose (1: every frame).
  int full_search_every = 10;
  // Margin around each predicted tag: this many pixels plus this fraction of
  // the tag's predicted size (room for acceleration and the white border).
  double region_margin_px = 16;
  double region_margin_tag = 0.5;

  std::vector<std::string> Validate() const;
  // "fast", "balanced", "accurate": detector presets with the balanced filter.
  static TrackerOptions Preset(const std::string& name);
};

struct TrackResult {
  TrackingState state = TrackingState::kLost;
  bool has_pose = false;    // a pose (current or last good) is available
  bool measured = false;    // this frame produced a pose
  Pose T_world_camera;      // filtered pose, or the last good one when lost
  Pose T_world_camera_raw;  // this frame's unfiltered pose (when measured)
  double rms_px = 0;        // reprojection RMS of this frame's pose
  int tags_detected = 0;    // detections of any id
  int tags_used = 0;        // inlier board tags
  int tags_rejected = 0;    // outlier board tags
  bool ambiguous = false;   // two solutions were possible this frame
  std::vector<TagDetection> detections;
  DetectStatus detect_status = DetectStatus::kOk;
  std::string note;  // why a frame was lost, or what happened
  double detect_ms = 0, pose_ms = 0;
  bool region_searched = false;  // only predicted regions were searched
  double searched_fraction = 1;  // searched area / frame area
};

class Tracker {
 public:
  // InputError if the options or the camera are invalid or the board is empty.
  Tracker(Board board, CameraIntrinsics camera, const TrackerOptions& options = {});

  const TrackerOptions& options() const { return options_; }
  // One frame. The camera is rescaled if the frame size differs from the
  // intrinsics' size with the same aspect ratio; otherwise the frame is lost.
  TrackResult Process(const Frame& frame);
  // The same from detections made elsewhere (another detector, a replay)
  // in a frame of width x height taken at t_ns (0: unknown).
  TrackResult ProcessDetections(const std::vector<TagDetection>& detections, int width, int height,
                                std::int64_t t_ns = 0);
  // A frame that never arrived (corrupt, device lost): the state becomes lost.
  TrackResult MarkLost(const std::string& why);
  void Reset();
  TrackingState state() const { return state_; }

 private:
  TrackResult Lost(TrackResult result, const std::string& why);
  // The camera for a frame size (rescaled for the same aspect ratio).
  bool CameraFor(int width, int height, CameraIntrinsics& camera, std::string& why) const;
  // Ambiguity, state and filter from a frame's board pose.
  TrackResult Conclude(TrackResult result, const BoardPose& board_pose, std::int64_t t_ns);
  // Regions around the tags predicted for this frame; empty if none.
  std::vector<SearchRect> PredictRegions(const CameraIntrinsics& camera, int width, int height) const;

  Board board_;
  CameraIntrinsics camera_;
  TrackerOptions options_;
  TagDetector detector_;
  PoseFilter filter_;
  TrackingState state_ = TrackingState::kLost;
  bool has_good_ = false;
  Pose last_good_;                  // last reported (filtered) pose
  Pose last_raw_;                   // last measured pose
  Pose prior_raw_;                  // the measured pose of the frame before last_raw_'s
  bool prior_consecutive_ = false;  // prior_raw_ is from the frame just before
  int frames_since_full_ = 1 << 20;
  int last_tags_used_ = 0;
  double branch_evidence_ = 0;  // log-likelihood of the followed branch over the other
  std::int64_t last_t_ns_ = 0;
  int frames_since_good_ = 1 << 20;
  int consistent_run_ = 0;
};

}  // namespace nerfar
