#include "calib/scene_box.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "calib/camera_keys.h"
#include "calib/core/error.h"
#include "calib/scene_frame.h"

namespace nerfar {
namespace {

std::string Format(const char* format, double a, double b = 0, double c = 0) {
  char buffer[128];
  std::snprintf(buffer, sizeof buffer, format, a, b, c);
  return buffer;
}

std::string BoxText(const Aabb& b) {
  return "[" + Format("%.3f, %.3f, %.3f", b.min.x, b.min.y, b.min.z) + "] to [" +
         Format("%.3f, %.3f, %.3f", b.max.x, b.max.y, b.max.z) + "]";
}

Vec3 OpticalAxis(const Pose& T_world_camera) { return T_world_camera.rotation.Column(2); }

double Median(std::vector<double> values) {
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  return values[mid];
}

}  // namespace

Aabb BoxAroundBoard(const Board& board, double margin_m, double height_m) {
  Aabb box{{1e9, 1e9, -kBoardBoxBelowM}, {-1e9, -1e9, height_m}};
  for (const BoardTag& tag : board.tags)
    for (const Vec3& c : tag.corners) {
      box.min.x = std::min(box.min.x, c.x - margin_m);
      box.min.y = std::min(box.min.y, c.y - margin_m);
      box.max.x = std::max(box.max.x, c.x + margin_m);
      box.max.y = std::max(box.max.y, c.y + margin_m);
    }
  return box;
}

bool LookAtPoint(const std::vector<Pose>& T_world_cameras, Vec3& point) {
  std::vector<Vec3> origins, directions;
  for (const Pose& pose : T_world_cameras) {
    origins.push_back(pose.translation);
    directions.push_back(OpticalAxis(pose));
  }
  return ClosestPointToLines(origins, directions, point);
}

Aabb BoxFromCameras(const Dataset& dataset, std::string* how) {
  std::vector<Pose> poses;
  for (const DatasetFrame& frame : dataset.frames) poses.push_back(frame.T_world_camera);
  Vec3 target;
  if (!LookAtPoint(poses, target))
    ThrowInputError(dataset.path,
                    "no aabb, and the cameras do not look at a common point (fewer than 2 frames or parallel optical "
                    "axes): give the NeRF box as \"aabb\": [[min x, y, z], [max x, y, z]]");
  std::vector<double> distances, half_extents;
  for (const DatasetFrame& frame : dataset.frames) {
    const CameraIntrinsics& camera = dataset.CameraOf(frame);
    // Half the diagonal of the view's frame at the target: cameras circling
    // the target turn that frame about it, sweeping a disc of this radius.
    const double tan_x = std::tan(0.5 * FieldOfView(camera.width, camera.fx));
    const double tan_y = std::tan(0.5 * FieldOfView(camera.height, camera.fy));
    const double distance = Length(target - frame.T_world_camera.translation);
    distances.push_back(distance);
    half_extents.push_back(distance * std::hypot(tan_x, tan_y));
  }
  const double half = Median(half_extents);
  const Vec3 extent{half, half, half};
  if (how != nullptr)
    *how = "from the cameras: they look at " + Format("(%.3f, %.3f, %.3f)", target.x, target.y, target.z) +
           Format(
               " from a median distance of %.3f; a cube of half-side %.3f (half the diagonal the median view frames "
               "there)",
               Median(distances), half);
  return {target - extent, target + extent};
}

SceneBox DeriveSceneBox(const Dataset& dataset, const Board* board) {
  SceneBox out;
  if (board != nullptr) {
    out.box = BoxAroundBoard(*board);
    out.how = "from the board's " + std::to_string(board->tags.size()) + " tags" +
              Format(" (their extent and %.2f m around it, %.2f m below the table to %.2f m above)", kBoardBoxMarginM,
                     kBoardBoxBelowM, kBoardBoxHeightM);
  } else {
    out.box = BoxFromCameras(dataset, &out.how);
  }
  if (dataset.ngp_box.has_value()) {
    const Aabb& ngp = *dataset.ngp_box;
    Aabb cut = out.box;
    for (int k = 0; k < 3; ++k) {
      cut.min[k] = std::max(cut.min[k], ngp.min[k]);
      cut.max[k] = std::min(cut.max[k], ngp.max[k]);
    }
    if (cut.min.x < cut.max.x && cut.min.y < cut.max.y && cut.min.z < cut.max.z) {
      out.how += "; within instant-ngp's box " + BoxText(ngp) + " (aabb_scale, scale, offset)";
      out.box = cut;
    } else {
      out.how += "; instant-ngp's box " + BoxText(ngp) + " (aabb_scale, scale, offset) does not meet it: not used";
    }
  }
  out.how = "box " + BoxText(out.box) + " " + out.how;
  return out;
}

}  // namespace nerfar
