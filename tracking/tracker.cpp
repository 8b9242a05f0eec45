#include "tracking/tracker.h"

#include <chrono>
#include <cmath>
#include <cstdlib>

#include "calib/core/error.h"

namespace nerfar {
namespace {

double Milliseconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - since).count();
}

void AddAll(std::vector<std::string>& into, const std::string& prefix, const std::vector<std::string>& items) {
  for (const std::string& item : items) into.push_back(prefix + item);
}

// Every problem with the options, the camera and the board, thrown at once.
const TrackerOptions& Checked(const TrackerOptions& options, const CameraIntrinsics& camera, const Board& board) {
  Problems problems("tracker");
  for (const std::string& p : options.Validate()) problems.Add("options", p);
  for (const std::string& p : camera.Validate()) problems.Add("camera", p);
  if (board.tags.empty()) problems.Add("board", "has no tags (expected at least one)");
  problems.ThrowIfAny();
  return options;
}

}  // namespace

const char* TrackingStateName(TrackingState state) {
  switch (state) {
    case TrackingState::kTracking:
      return "tracking";
    case TrackingState::kLost:
      return "lost";
    case TrackingState::kRecovering:
      return "recovering";
  }
  return "unknown";
}

std::vector<std::string> TrackerOptions::Validate() const {
  std::vector<std::string> problems;
  AddAll(problems, "detector.", detector.Validate());
  AddAll(problems, "pose.", pose.Validate());
  AddAll(problems, "filter.", filter.Validate());
  if (confirm_frames < 0 || confirm_frames > 1000)
    problems.push_back("confirm_frames: " + std::to_string(confirm_frames) + " (expected 0 to 1000)");
  if (history_frames < 0 || history_frames > 100000)
    problems.push_back("history_frames: " + std::to_string(history_frames) + " (expected >= 0)");
  if (!(max_rms_px > 0 && max_rms_px <= 100))
    problems.push_back("max_rms_px: " + std::to_string(max_rms_px) + " (expected 0 < value <= 100 pixels)");
  return problems;
}

TrackerOptions TrackerOptions::Preset(const std::string& name) {
  TrackerOptions options;
  options.detector = TagDetectorOptions::Preset(name);
  return options;
}

Tracker::Tracker(Board board, CameraIntrinsics camera, const TrackerOptions& options)
    : board_(std::move(board)),
      camera_(camera),
      options_(Checked(options, camera, board_)),
      detector_(options_.detector),
      filter_(options_.filter) {}

void Tracker::Reset() {
  state_ = TrackingState::kLost;
  has_good_ = false;
  filter_.Reset();
  frames_since_good_ = 1 << 20;
  consistent_run_ = 0;
  last_t_ns_ = 0;
}

TrackResult Tracker::Lost(TrackResult result, const std::string& why) {
  state_ = TrackingState::kLost;
  consistent_run_ = 0;
  if (frames_since_good_ < (1 << 20)) ++frames_since_good_;
  // A short gap keeps the filter (its prediction bridges it); a long one
  // starts the next track afresh.
  if (frames_since_good_ > options_.history_frames) filter_.Reset();
  result.state = state_;
  result.measured = false;
  result.has_pose = has_good_;
  result.T_world_camera = last_good_;
  result.note = why;
  return result;
}

TrackResult Tracker::MarkLost(const std::string& why) { return Lost(TrackResult{}, why); }

TrackResult Tracker::Process(const Frame& frame) {
  TrackResult result;
  const Image8& image = frame.image;
  if (image.empty() || image.width <= 0 || image.height <= 0) return Lost(std::move(result), "empty frame");

  CameraIntrinsics camera = camera_;
  if (image.width != camera_.width || image.height != camera_.height) {
    // Same aspect ratio within half a pixel: the same sensor at another resolution.
    const double mismatch = std::abs(static_cast<double>(image.width) * camera_.height -
                                     static_cast<double>(image.height) * camera_.width) /
                            std::max(camera_.width, camera_.height);
    if (mismatch > 0.5)
      return Lost(std::move(result), "frame of " + std::to_string(image.width) + "x" + std::to_string(image.height) +
                                         " does not match the camera's " + std::to_string(camera_.width) + "x" +
                                         std::to_string(camera_.height));
    camera = camera_.Scaled(image.width, image.height);
  }

  const auto t0 = std::chrono::steady_clock::now();
  result.detect_status = detector_.Detect(image, result.detections);
  result.detect_ms = Milliseconds(t0);
  result.tags_detected = static_cast<int>(result.detections.size());
  if (result.detect_status != DetectStatus::kOk) return Lost(std::move(result), detector_.last_error());

  const auto t1 = std::chrono::steady_clock::now();
  const BoardPose board_pose = EstimateBoardPose(result.detections, board_, camera, options_.pose);
  result.pose_ms = Milliseconds(t1);
  result.tags_used = static_cast<int>(board_pose.inlier_ids.size());
  result.tags_rejected = static_cast<int>(board_pose.outlier_ids.size());
  if (!board_pose.ok) return Lost(std::move(result), board_pose.why);
  result.rms_px = board_pose.rms_px;
  if (board_pose.rms_px > options_.max_rms_px)
    return Lost(std::move(result), "reprojection RMS " + std::to_string(board_pose.rms_px) + " px above " +
                                       std::to_string(options_.max_rms_px));

  double dt_s = 0;
  if (frame.t_ns > 0 && last_t_ns_ > 0 && frame.t_ns > last_t_ns_) dt_s = (frame.t_ns - last_t_ns_) * 1e-9;
  const bool recent = has_good_ && frames_since_good_ <= options_.history_frames;

  Pose chosen = board_pose.T_world_camera;
  if (board_pose.alternative) {
    result.ambiguous = true;
    if (recent) {
      // Keep the solution that continues the track.
      const Pose reference = filter_.initialized() ? filter_.Predict(dt_s) : last_raw_;
      const double d_best = RotationAngleBetween(reference.rotation, board_pose.T_world_camera.rotation);
      const double d_alt = RotationAngleBetween(reference.rotation, board_pose.alternative->rotation);
      if (d_alt < d_best) {
        chosen = *board_pose.alternative;
        result.rms_px = board_pose.alternative_rms_px;
      }
      result.note = "ambiguous pose resolved by the track";
    } else {
      result.note = "ambiguous pose, no track yet: lower reprojection error kept";
    }
  }

  // Consistency with the previous frame's pose decides recovery.
  const bool previous_good = has_good_ && frames_since_good_ == 0;
  const bool consistent =
      previous_good &&
      RotationAngleBetween(chosen.rotation, last_raw_.rotation) <= options_.filter.reset_rotation_rad &&
      Length(chosen.translation - last_raw_.translation) <= options_.filter.reset_translation_m;
  if (state_ == TrackingState::kTracking && previous_good) {
    consistent_run_ = consistent_run_ + 1;
  } else {
    consistent_run_ = consistent ? consistent_run_ + 1 : 1;
    state_ =
        consistent_run_ >= std::max(1, options_.confirm_frames) ? TrackingState::kTracking : TrackingState::kRecovering;
  }
  if (!recent) filter_.Reset();
  const Pose filtered = filter_.Update(chosen, dt_s);

  has_good_ = true;
  frames_since_good_ = 0;
  last_raw_ = chosen;
  last_good_ = filtered;
  if (frame.t_ns > 0) last_t_ns_ = frame.t_ns;

  result.state = state_;
  result.has_pose = true;
  result.measured = true;
  result.T_world_camera = filtered;
  result.T_world_camera_raw = chosen;
  return result;
}

}  // namespace nerfar
