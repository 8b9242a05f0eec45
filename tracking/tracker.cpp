#include "tracking/tracker.h"

#include <algorithm>
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
  if (!(branch_switch_evidence > 0 && branch_switch_evidence <= 1e6))
    problems.push_back("branch_switch_evidence: " + std::to_string(branch_switch_evidence) + " (expected > 0)");
  if (full_search_every < 1 || full_search_every > 100000)
    problems.push_back("full_search_every: " + std::to_string(full_search_every) + " (expected >= 1)");
  if (!(region_margin_px >= 0 && region_margin_px <= 1000))
    problems.push_back("region_margin_px: " + std::to_string(region_margin_px) + " (expected 0 to 1000 pixels)");
  if (!(region_margin_tag >= 0 && region_margin_tag <= 10))
    problems.push_back("region_margin_tag: " + std::to_string(region_margin_tag) + " (expected 0 to 10)");
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
  branch_evidence_ = 0;
  prior_consecutive_ = false;
  frames_since_full_ = 1 << 20;
}

std::vector<SearchRect> Tracker::PredictRegions(const CameraIntrinsics& camera, int width, int height) const {
  // Constant motion: this frame's pose continues the last step.
  const Pose step = last_raw_ * prior_raw_.Inverse();
  const Pose predicted = step * last_raw_;
  const Pose poses[2] = {last_raw_.Inverse(), predicted.Inverse()};  // T_camera_world
  std::vector<SearchRect> rects;
  for (const BoardTag& tag : board_.tags) {
    double x0 = 1e30, y0 = 1e30, x1 = -1e30, y1 = -1e30;
    bool behind = false;
    for (const Pose& T : poses)
      for (const Vec3& corner : tag.corners) {
        const Vec3 p = T * corner;
        Vec2 pixel;
        if (!(p.z > 1e-6) || !Project(camera, p, pixel)) {
          behind = true;
          continue;
        }
        x0 = std::min(x0, pixel.x), y0 = std::min(y0, pixel.y);
        x1 = std::max(x1, pixel.x), y1 = std::max(y1, pixel.y);
      }
    if (behind || x1 < 0 || y1 < 0 || x0 > width || y0 > height) continue;
    const double margin = options_.region_margin_px + options_.region_margin_tag * std::max(x1 - x0, y1 - y0);
    SearchRect r{static_cast<int>(std::floor(std::max(0.0, x0 - margin))),
                 static_cast<int>(std::floor(std::max(0.0, y0 - margin))),
                 static_cast<int>(std::ceil(std::min<double>(width, x1 + margin))),
                 static_cast<int>(std::ceil(std::min<double>(height, y1 + margin)))};
    if (r.Width() > 0 && r.Height() > 0) rects.push_back(r);
  }
  // Overlapping regions become their bounding box (a tag is never cut in two).
  for (bool merged = true; merged;) {
    merged = false;
    for (size_t i = 0; i < rects.size() && !merged; ++i)
      for (size_t j = i + 1; j < rects.size() && !merged; ++j) {
        SearchRect& a = rects[i];
        const SearchRect& b = rects[j];
        if (a.x0 < b.x1 && b.x0 < a.x1 && a.y0 < b.y1 && b.y0 < a.y1) {
          a = {std::min(a.x0, b.x0), std::min(a.y0, b.y0), std::max(a.x1, b.x1), std::max(a.y1, b.y1)};
          rects.erase(rects.begin() + static_cast<std::ptrdiff_t>(j));
          merged = true;
        }
      }
  }
  return rects;
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

bool Tracker::CameraFor(int width, int height, CameraIntrinsics& camera, std::string& why) const {
  camera = camera_;
  if (width == camera_.width && height == camera_.height) return true;
  // Same aspect ratio within half a pixel: the same sensor at another resolution.
  const double mismatch =
      std::abs(static_cast<double>(width) * camera_.height - static_cast<double>(height) * camera_.width) /
      std::max(camera_.width, camera_.height);
  if (mismatch > 0.5 || width <= 0 || height <= 0) {
    why = "frame of " + std::to_string(width) + "x" + std::to_string(height) + " does not match the camera's " +
          std::to_string(camera_.width) + "x" + std::to_string(camera_.height);
    return false;
  }
  camera = camera_.Scaled(width, height);
  return true;
}

TrackResult Tracker::ProcessDetections(const std::vector<TagDetection>& detections, int width, int height,
                                       std::int64_t t_ns) {
  TrackResult result;
  CameraIntrinsics camera;
  std::string why;
  if (!CameraFor(width, height, camera, why)) return Lost(std::move(result), why);
  result.detections = detections;
  result.tags_detected = static_cast<int>(detections.size());
  const auto t0 = std::chrono::steady_clock::now();
  const BoardPose board_pose = EstimateBoardPose(detections, board_, camera, options_.pose);
  result.pose_ms = Milliseconds(t0);
  return Conclude(std::move(result), board_pose, t_ns);
}

TrackResult Tracker::Process(const Frame& frame) {
  TrackResult result;
  const Image8& image = frame.image;
  if (image.empty() || image.width <= 0 || image.height <= 0) return Lost(std::move(result), "empty frame");

  CameraIntrinsics camera;
  std::string why;
  if (!CameraFor(image.width, image.height, camera, why)) return Lost(std::move(result), why);

  // Region search while tracking frame to frame, whole frames otherwise.
  std::vector<SearchRect> regions;
  if (options_.region_search && state_ == TrackingState::kTracking && frames_since_good_ == 0 && prior_consecutive_ &&
      frames_since_full_ + 1 < options_.full_search_every)
    regions = PredictRegions(camera, image.width, image.height);
  double area = 0;
  for (const SearchRect& r : regions) area += static_cast<double>(r.Width()) * r.Height();
  const double frame_area = static_cast<double>(image.width) * image.height;
  // Regions covering most of the frame save nothing.
  if (area > 0.7 * frame_area) regions.clear();

  BoardPose board_pose;
  auto t0 = std::chrono::steady_clock::now();
  if (!regions.empty()) {
    result.detect_status = detector_.DetectInRegions(image, regions, result.detections);
    result.detect_ms = Milliseconds(t0);
    if (result.detect_status == DetectStatus::kOk) {
      t0 = std::chrono::steady_clock::now();
      board_pose = EstimateBoardPose(result.detections, board_, camera, options_.pose);
      result.pose_ms = Milliseconds(t0);
    }
    // Half the tags of the last pose lost (occlusion, a bad prediction): the
    // whole frame may still hold them.
    result.region_searched = board_pose.ok && 2 * static_cast<int>(board_pose.inlier_ids.size()) >= last_tags_used_;
    result.searched_fraction = area / frame_area;
    ++frames_since_full_;
  }
  if (!result.region_searched) {
    t0 = std::chrono::steady_clock::now();
    result.detect_status = detector_.Detect(image, result.detections);
    result.detect_ms += Milliseconds(t0);
    result.searched_fraction = 1;
    frames_since_full_ = 0;
    if (result.detect_status == DetectStatus::kOk) {
      t0 = std::chrono::steady_clock::now();
      board_pose = EstimateBoardPose(result.detections, board_, camera, options_.pose);
      result.pose_ms += Milliseconds(t0);
    }
  }
  result.tags_detected = static_cast<int>(result.detections.size());
  if (result.detect_status != DetectStatus::kOk) return Lost(std::move(result), detector_.last_error());
  return Conclude(std::move(result), board_pose, frame.t_ns);
}

TrackResult Tracker::Conclude(TrackResult result, const BoardPose& board_pose, std::int64_t t_ns) {
  result.tags_used = static_cast<int>(board_pose.inlier_ids.size());
  result.tags_rejected = static_cast<int>(board_pose.outlier_ids.size());
  if (!board_pose.ok) return Lost(std::move(result), board_pose.why);
  result.rms_px = board_pose.rms_px;
  if (board_pose.rms_px > options_.max_rms_px)
    return Lost(std::move(result), "reprojection RMS " + std::to_string(board_pose.rms_px) + " px above " +
                                       std::to_string(options_.max_rms_px));

  double dt_s = 0;
  if (t_ns > 0 && last_t_ns_ > 0 && t_ns > last_t_ns_) dt_s = (t_ns - last_t_ns_) * 1e-9;
  const bool recent = has_good_ && frames_since_good_ <= options_.history_frames;

  Pose chosen = board_pose.T_world_camera;
  bool switched = false;
  if (board_pose.alternative) {
    result.ambiguous = true;
    if (recent) {
      // Keep the solution that continues the track...
      const Pose reference = filter_.initialized() ? filter_.Predict(dt_s) : last_raw_;
      const double d_best = RotationAngleBetween(reference.rotation, board_pose.T_world_camera.rotation);
      const double d_alt = RotationAngleBetween(reference.rotation, board_pose.alternative->rotation);
      Pose other = *board_pose.alternative;
      double rms_chosen = board_pose.rms_px, rms_other = board_pose.alternative_rms_px;
      if (d_alt < d_best) {
        std::swap(chosen, other);
        std::swap(rms_chosen, rms_other);
      }
      // ...unless the other explains the corners better over many frames:
      // the log-likelihood ratio of the two branches, 4 corners per tag of
      // Gaussian noise at the detector's level, summed while ambiguous.
      const double sigma2 = std::pow(std::max(options_.pose.corner_noise_px, 0.01), 2);
      const double corners = 4.0 * std::max<size_t>(1, board_pose.inlier_ids.size());
      branch_evidence_ += 0.5 * corners * (rms_other * rms_other - rms_chosen * rms_chosen) / sigma2;
      if (branch_evidence_ < -options_.branch_switch_evidence) {
        std::swap(chosen, other);
        std::swap(rms_chosen, rms_other);
        branch_evidence_ = 0;
        switched = true;
        result.note = "ambiguous pose: switched to the solution that fits better over recent frames";
      } else {
        result.note = "ambiguous pose resolved by the track";
      }
      result.rms_px = rms_chosen;
    } else {
      branch_evidence_ = 0;
      result.note = "ambiguous pose, no track yet: lower reprojection error kept";
    }
  } else {
    branch_evidence_ = 0;
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
  if (!recent || switched) filter_.Reset();
  const Pose filtered = filter_.Update(chosen, dt_s);

  prior_consecutive_ = has_good_ && frames_since_good_ == 0;
  last_tags_used_ = result.tags_used;
  prior_raw_ = last_raw_;
  has_good_ = true;
  frames_since_good_ = 0;
  last_raw_ = chosen;
  last_good_ = filtered;
  if (t_ns > 0) last_t_ns_ = t_ns;

  result.state = state_;
  result.has_pose = true;
  result.measured = true;
  result.T_world_camera = filtered;
  result.T_world_camera_raw = chosen;
  return result;
}

}  // namespace nerfar
