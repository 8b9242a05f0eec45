#include "tracking/board_pose.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "calib/core/error.h"

namespace nerfar {
namespace {

// A tag of the board matched to its detection: world corners and the
// undistorted image corners in OpenCV pixels (centres at integers).
struct MatchedTag {
  int id = 0;
  const BoardTag* tag = nullptr;
  std::array<cv::Point2d, 4> image;
};

struct PinholeCv {
  double fx, fy, cx, cy;  // OpenCV principal point
};

cv::Matx33d ToCv(const Mat3& m) {
  return {m(0, 0), m(0, 1), m(0, 2), m(1, 0), m(1, 1), m(1, 2), m(2, 0), m(2, 1), m(2, 2)};
}

Pose PoseFromRvecTvec(const cv::Vec3d& rvec, const cv::Vec3d& tvec) {
  cv::Matx33d r;
  cv::Rodrigues(rvec, r);
  Pose pose;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) pose.rotation(i, j) = r(i, j);
  pose.translation = {tvec[0], tvec[1], tvec[2]};
  return pose;
}

void RvecTvecFromPose(const Pose& pose, cv::Vec3d& rvec, cv::Vec3d& tvec) {
  cv::Rodrigues(ToCv(pose.rotation), rvec);
  tvec = {pose.translation.x, pose.translation.y, pose.translation.z};
}

// Sum of squared reprojection errors of one tag under T_camera_world; +inf if
// a corner is behind the camera.
double TagSquaredError(const MatchedTag& m, const PinholeCv& k, const Pose& T_camera_world) {
  double sum = 0;
  for (int c = 0; c < 4; ++c) {
    const Vec3 p = T_camera_world * m.tag->corners[c];
    if (!(p.z > 1e-9)) return std::numeric_limits<double>::infinity();
    const double du = k.fx * p.x / p.z + k.cx - m.image[c].x;
    const double dv = k.fy * p.y / p.z + k.cy - m.image[c].y;
    sum += du * du + dv * dv;
  }
  return sum;
}

double TagRms(const MatchedTag& m, const PinholeCv& k, const Pose& T_camera_world) {
  return std::sqrt(TagSquaredError(m, k, T_camera_world) / 4.0);
}

// The tag's own frame: origin at its centre, x along its top edge, y along
// its left edge (downwards in the printed image), z = x cross y.
Pose TagFrame(const BoardTag& tag) {
  const Vec3 center = (tag.corners[0] + tag.corners[1] + tag.corners[2] + tag.corners[3]) * 0.25;
  const Vec3 x = Normalized(tag.corners[1] - tag.corners[0]);
  Vec3 y = tag.corners[3] - tag.corners[0];
  y = Normalized(y - x * Dot(x, y));
  const Vec3 z = Cross(x, y);
  return {Mat3::FromColumns(x, y, z), center};  // T_world_tag
}

struct Refined {
  Pose T_camera_world;
  std::vector<int> inliers;  // indices into the matched tags
  double rms_px = std::numeric_limits<double>::infinity();
};

// LM over the corners of `subset`; returns false if OpenCV fails.
bool RefineLm(const std::vector<MatchedTag>& tags, const std::vector<int>& subset, const cv::Matx33d& K, int iterations,
              Pose& T_camera_world) {
  if (iterations <= 0 || subset.empty()) return true;
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> image;
  for (int i : subset)
    for (int c = 0; c < 4; ++c) {
      const Vec3& w = tags[i].tag->corners[c];
      object.emplace_back(w.x, w.y, w.z);
      image.push_back(tags[i].image[c]);
    }
  cv::Vec3d rvec, tvec;
  RvecTvecFromPose(T_camera_world, rvec, tvec);
  try {
    cv::solvePnPRefineLM(object, image, K, cv::noArray(), rvec, tvec,
                         cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, iterations, 1e-12));
  } catch (const cv::Exception&) {
    return false;
  }
  if (!std::isfinite(rvec[0] + rvec[1] + rvec[2] + tvec[0] + tvec[1] + tvec[2])) return false;
  T_camera_world = PoseFromRvecTvec(rvec, tvec);
  return true;
}

std::vector<int> Inliers(const std::vector<MatchedTag>& tags, const PinholeCv& k, const Pose& T_camera_world,
                         double threshold_px) {
  std::vector<int> inliers;
  for (size_t i = 0; i < tags.size(); ++i)
    if (TagRms(tags[i], k, T_camera_world) <= threshold_px) inliers.push_back(static_cast<int>(i));
  return inliers;
}

double SubsetRms(const std::vector<MatchedTag>& tags, const std::vector<int>& subset, const PinholeCv& k,
                 const Pose& T_camera_world) {
  if (subset.empty()) return std::numeric_limits<double>::infinity();
  double sum = 0;
  for (int i : subset) sum += TagSquaredError(tags[i], k, T_camera_world);
  return std::sqrt(sum / (4.0 * subset.size()));
}

// The detections of tags on the board, their corners undistorted into OpenCV pixels; the ids of
// tags not on the board go to unknown_ids. A tag with a non-finite corner is dropped.
std::vector<MatchedTag> MatchTags(const std::vector<TagDetection>& detections, const Board& board,
                                  const CameraIntrinsics& camera, const PinholeCv& k, std::vector<int>& unknown_ids) {
  const bool distorted = camera.HasDistortion();
  std::vector<MatchedTag> tags;
  for (const TagDetection& d : detections) {
    const BoardTag* tag = board.FindTag(d.id);
    if (tag == nullptr) {
      unknown_ids.push_back(d.id);
      continue;
    }
    MatchedTag m{d.id, tag, {}};
    bool finite = true;
    for (int c = 0; c < 4; ++c) {
      Vec2 n{(d.corners[c].x - camera.cx) / camera.fx, (d.corners[c].y - camera.cy) / camera.fy};
      if (distorted) n = Undistort(camera, n);
      m.image[c] = {k.fx * n.x + k.cx, k.fy * n.y + k.cy};
      finite = finite && std::isfinite(m.image[c].x) && std::isfinite(m.image[c].y);
    }
    if (finite) tags.push_back(m);
  }
  return tags;
}

// An unrefined pose and how well it explains every tag at the loose gate.
struct Hypothesis {
  Pose T_camera_world;
  int loose_count = 0;  // tags within the gate
  double cost = 0;      // sum over tags of the RMS, capped at the gate
};

// Both IPPE solutions of every tag (a degenerate quad gives none), best first: most tags within
// loose_px, then the lowest cost.
std::vector<Hypothesis> IppeHypotheses(const std::vector<MatchedTag>& tags, const cv::Matx33d& K, const PinholeCv& k,
                                       double loose_px) {
  std::vector<Hypothesis> hypotheses;
  for (const MatchedTag& m : tags) {
    const Pose T_world_tag = TagFrame(*m.tag);
    const Pose T_tag_world = T_world_tag.Inverse();
    std::vector<cv::Point3d> object;
    for (int c = 0; c < 4; ++c) {
      const Vec3 p = T_tag_world * m.tag->corners[c];
      object.emplace_back(p.x, p.y, 0.0);  // planar by construction
    }
    std::vector<cv::Point2d> image(m.image.begin(), m.image.end());
    std::vector<cv::Mat> rvecs, tvecs;
    try {
      cv::solvePnPGeneric(object, image, K, cv::noArray(), rvecs, tvecs, false, cv::SOLVEPNP_IPPE);
    } catch (const cv::Exception&) {
      continue;  // degenerate quad (collapsed corners): this tag gives no hypothesis
    }
    for (size_t s = 0; s < rvecs.size(); ++s) {
      const cv::Vec3d rvec(rvecs[s].ptr<double>()), tvec(tvecs[s].ptr<double>());
      if (!std::isfinite(rvec[0] + rvec[1] + rvec[2] + tvec[0] + tvec[1] + tvec[2])) continue;
      Hypothesis h;
      h.T_camera_world = PoseFromRvecTvec(rvec, tvec) * T_tag_world;
      for (const MatchedTag& other : tags) {
        const double rms = TagRms(other, k, h.T_camera_world);
        if (rms <= loose_px) ++h.loose_count;
        h.cost += std::min(rms, loose_px);
      }
      hypotheses.push_back(h);
    }
  }
  std::stable_sort(hypotheses.begin(), hypotheses.end(), [](const Hypothesis& a, const Hypothesis& b) {
    return a.loose_count != b.loose_count ? a.loose_count > b.loose_count : a.cost < b.cost;
  });
  return hypotheses;
}

// One hypothesis refined: inliers at the loose gate, LM, inliers at the outlier threshold, LM
// again until the set settles (at most 4 rounds). Nothing where OpenCV fails.
std::optional<Refined> Refine(const std::vector<MatchedTag>& tags, const Hypothesis& h, const cv::Matx33d& K,
                              const PinholeCv& k, double loose_px, const BoardPoseOptions& options) {
  Refined r;
  r.T_camera_world = h.T_camera_world;
  std::vector<int> subset = Inliers(tags, k, r.T_camera_world, loose_px);
  for (int round = 0; round < 4 && !subset.empty(); ++round) {
    if (!RefineLm(tags, subset, K, options.refine_iterations, r.T_camera_world)) return std::nullopt;
    std::vector<int> next = Inliers(tags, k, r.T_camera_world, options.outlier_rms_px);
    if (next == subset) break;
    subset = std::move(next);
  }
  r.inliers = subset;
  r.rms_px = SubsetRms(tags, subset, k, r.T_camera_world);
  return r;
}

constexpr double kDistinctRad = 1.0 * kPi / 180.0;  // solutions closer in rotation are one

bool RotationNear(const std::vector<Refined>& kept, const Pose& T_camera_world) {
  for (const Refined& r : kept)
    if (RotationAngleBetween(r.T_camera_world.rotation, T_camera_world.rotation) < kDistinctRad) return true;
  return false;
}

// The distinct solutions of the best few distinct hypotheses, best first: most inliers, then
// the lowest RMS. `collapsed`: the first hypothesis whose refinement slid into a kept solution.
struct Solutions {
  std::vector<Refined> refined;
  std::optional<Refined> collapsed;
};

Solutions RefineHypotheses(const std::vector<MatchedTag>& tags, const std::vector<Hypothesis>& hypotheses,
                           const cv::Matx33d& K, const PinholeCv& k, double loose_px, const BoardPoseOptions& options) {
  constexpr size_t kMaxRefined = 4;
  Solutions out;
  for (const Hypothesis& h : hypotheses) {
    if (out.refined.size() >= kMaxRefined) break;
    if (RotationNear(out.refined, h.T_camera_world)) continue;
    std::optional<Refined> r = Refine(tags, h, K, k, loose_px, options);
    if (!r) continue;
    // A refinement that lands on an already kept solution adds nothing.
    if (!RotationNear(out.refined, r->T_camera_world)) {
      out.refined.push_back(std::move(*r));
    } else if (!out.collapsed) {
      // LM slid from this hypothesis into a kept solution (a shallow valley:
      // one tag nearly face-on); the unrefined IPPE pose stays a candidate.
      out.collapsed = Refined{h.T_camera_world, {}, 0};
    }
  }
  std::stable_sort(out.refined.begin(), out.refined.end(), [](const Refined& a, const Refined& b) {
    return a.inliers.size() != b.inliers.size() ? a.inliers.size() > b.inliers.size() : a.rms_px < b.rms_px;
  });
  return out;
}

// The best solution's rival on the same inlier tags, if its RMS is within ambiguity_ratio of the
// best one's (or of the corner noise, below which RMS values are not told apart).
void SetAlternative(const std::vector<MatchedTag>& tags, Solutions& solutions, const PinholeCv& k,
                    const BoardPoseOptions& options, BoardPose& result) {
  std::vector<Refined>& refined = solutions.refined;
  const Refined best = refined.front();
  std::optional<Refined>& collapsed = solutions.collapsed;
  if (collapsed &&
      RotationAngleBetween(collapsed->T_camera_world.rotation, best.T_camera_world.rotation) >= kDistinctRad) {
    collapsed->inliers = best.inliers;
    collapsed->rms_px = SubsetRms(tags, best.inliers, k, collapsed->T_camera_world);
    refined.push_back(*collapsed);
  }
  for (size_t j = 1; j < refined.size(); ++j) {
    const Refined& other = refined[j];
    if (other.inliers != best.inliers) continue;
    if (other.rms_px <= options.ambiguity_ratio * std::max(best.rms_px, options.corner_noise_px)) {
      result.alternative = other.T_camera_world.Inverse();
      result.alternative_rms_px = other.rms_px;
    }
    break;
  }
}

}  // namespace

std::vector<std::string> BoardPoseOptions::Validate() const {
  std::vector<std::string> problems;
  if (!(outlier_rms_px > 0 && outlier_rms_px <= 100))
    problems.push_back("outlier_rms_px: " + std::to_string(outlier_rms_px) + " (expected 0 < value <= 100 pixels)");
  if (!(ambiguity_ratio >= 1 && ambiguity_ratio <= 100))
    problems.push_back("ambiguity_ratio: " + std::to_string(ambiguity_ratio) + " (expected 1 to 100)");
  if (refine_iterations < 0 || refine_iterations > 1000)
    problems.push_back("refine_iterations: " + std::to_string(refine_iterations) + " (expected 0 to 1000)");
  if (!(corner_noise_px >= 0 && corner_noise_px <= 10))
    problems.push_back("corner_noise_px: " + std::to_string(corner_noise_px) + " (expected 0 to 10 pixels)");
  if (min_tags < 1 || min_tags > 1000) problems.push_back("min_tags: " + std::to_string(min_tags) + " (expected >= 1)");
  return problems;
}

BoardPose EstimateBoardPose(const std::vector<TagDetection>& detections, const Board& board,
                            const CameraIntrinsics& camera, const BoardPoseOptions& options) {
  BoardPose result;
  const Vec2 pp = ToOpenCvPrincipalPoint(camera);
  const PinholeCv k{camera.fx, camera.fy, pp.x, pp.y};
  const cv::Matx33d K(k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
  const std::vector<MatchedTag> tags = MatchTags(detections, board, camera, k, result.unknown_ids);
  if (tags.empty()) {
    result.why = detections.empty() ? "no tag seen" : "no tag of the board seen";
    return result;
  }
  // Loose gate for unrefined hypotheses: a pose from one small tag is off by
  // degrees, which moves far tags by tens of pixels.
  const double loose_px = std::max(25.0, 10.0 * options.outlier_rms_px);
  const std::vector<Hypothesis> hypotheses = IppeHypotheses(tags, K, k, loose_px);
  if (hypotheses.empty()) {
    result.why = "every seen tag is degenerate";
    return result;
  }
  Solutions solutions = RefineHypotheses(tags, hypotheses, K, k, loose_px, options);
  if (solutions.refined.empty() || static_cast<int>(solutions.refined.front().inliers.size()) < options.min_tags) {
    result.why = "no pose explains " + std::to_string(options.min_tags) + " tag(s) within " +
                 std::to_string(options.outlier_rms_px) + " px";
    for (const MatchedTag& m : tags) result.outlier_ids.push_back(m.id);
    return result;
  }
  const Refined& best = solutions.refined.front();
  result.ok = true;
  result.T_world_camera = best.T_camera_world.Inverse();
  result.rms_px = best.rms_px;
  for (size_t i = 0; i < tags.size(); ++i) {
    const bool in = std::find(best.inliers.begin(), best.inliers.end(), static_cast<int>(i)) != best.inliers.end();
    (in ? result.inlier_ids : result.outlier_ids).push_back(tags[i].id);
  }
  SetAlternative(tags, solutions, k, options, result);
  return result;
}

double BoardReprojectionRms(const std::vector<TagDetection>& detections, const Board& board,
                            const CameraIntrinsics& camera, const Pose& T_world_camera) {
  const Pose T_camera_world = T_world_camera.Inverse();
  double sum = 0;
  int count = 0;
  for (const TagDetection& d : detections) {
    const BoardTag* tag = board.FindTag(d.id);
    if (tag == nullptr) continue;
    for (int c = 0; c < 4; ++c) {
      Vec2 pixel;
      if (!Project(camera, T_camera_world * tag->corners[c], pixel)) return std::numeric_limits<double>::infinity();
      sum += (pixel.x - d.corners[c].x) * (pixel.x - d.corners[c].x) +
             (pixel.y - d.corners[c].y) * (pixel.y - d.corners[c].y);
      ++count;
    }
  }
  return count ? std::sqrt(sum / count) : 0.0;
}

}  // namespace nerfar
