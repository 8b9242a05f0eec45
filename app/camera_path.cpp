#include "app/camera_path.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <set>

#include "calib/core/error.h"
#include "calib/core/image.h"
#include "calib/core/json.h"
#include "calib/core/log.h"
#include "calib/dataset.h"

namespace nerfar {

namespace {

double Median(std::vector<double> values) {
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

// The object's keys that `known` does not list, marked as read so that
// Finish() passes them; named "<prefix>key".
void TakeUnknownKeys(const Json& object, JsonObjectReader& reader, const std::set<std::string>& known,
                     const std::string& prefix, std::set<std::string>& ignored) {
  if (!object.is_object()) return;
  for (const auto& [key, value] : object.items()) {
    if (known.count(key)) continue;
    ignored.insert(prefix + key);
    reader.Allow({key.c_str()});
  }
}

// One entry of "camera_path": its pose and a pinhole camera of the path's
// size with the vertical field of view it states (principal point centred).
PathView ReadPathView(const Json& item, const std::string& pointer, int width, int height, Problems& problems,
                      std::set<std::string>& ignored) {
  JsonObjectReader view(item, pointer, problems);
  PathView out;
  if (!view.valid()) return out;
  TakeUnknownKeys(item, view, {"camera_to_world", "fov", "aspect"}, "camera_path[].", ignored);
  view.Allow({"aspect"});  // render_width / render_height set the aspect
  const std::vector<double> m = view.Numbers("camera_to_world", 16);
  const double fov_deg = view.Number("fov", 1e-3, 179.9);
  view.Finish();
  if (m.size() == 16) {
    std::array<double, 16> matrix;
    std::copy(m.begin(), m.end(), matrix.begin());
    const size_t before = problems.items().size();
    CheckRigidTransform(matrix, view.PointerTo("camera_to_world"), problems);
    if (problems.items().size() == before) out.T_world_camera = PoseFromTransformMatrix(matrix);
  }
  const double focal = 0.5 * height / std::tan(0.5 * fov_deg * kPi / 180.0);
  out.camera.width = width;
  out.camera.height = height;
  out.camera.fx = out.camera.fy = focal;
  out.camera.cx = 0.5 * width;
  out.camera.cy = 0.5 * height;
  return out;
}

}  // namespace

std::vector<Pose> OrbitPoses(const Orbit& orbit) {
  std::vector<Pose> poses;
  for (int i = 0; i < orbit.frames; ++i) {
    const double azimuth = orbit.start_azimuth_rad + 2.0 * kPi * i / orbit.frames;
    const Vec3 direction(std::cos(orbit.elevation_rad) * std::cos(azimuth),
                         std::cos(orbit.elevation_rad) * std::sin(azimuth), std::sin(orbit.elevation_rad));
    poses.push_back(LookAt(orbit.centre + direction * orbit.radius_m, orbit.centre));
  }
  return poses;
}

Orbit OrbitOfCapture(const std::vector<Pose>& capture, const Vec3& centre, int frames) {
  NERFAR_CHECK(!capture.empty());
  std::vector<double> distances, elevations;
  for (const Pose& pose : capture) {
    const Vec3 offset = pose.translation - centre;
    distances.push_back(Length(offset));
    elevations.push_back(std::atan2(offset.z, std::hypot(offset.x, offset.y)));
  }
  const Vec3 first = capture.front().translation - centre;
  return {centre, Median(distances), Median(elevations), std::atan2(first.y, first.x), frames};
}

CameraIntrinsics VideoCamera(const CameraIntrinsics& camera, int width) {
  const int even_width = std::max(2, width / 2 * 2);
  const int height = std::max(2, static_cast<int>(std::lround(double(camera.height) * even_width / camera.width)));
  CameraIntrinsics video = camera.Scaled(even_width, height / 2 * 2);
  video.k1 = video.k2 = video.p1 = video.p2 = video.k3 = 0;
  return video;
}

CameraPath ReadCameraPath(const std::string& path) {
  const Json root = ReadJsonFile(path);
  Problems problems(path);
  JsonObjectReader top(root, "", problems);
  if (!top.valid()) problems.ThrowIfAny();
  std::set<std::string> ignored;
  TakeUnknownKeys(root, top, {"camera_type", "render_width", "render_height", "fps", "camera_path"}, "", ignored);
  const std::string type = top.OptionalString("camera_type").value_or("perspective");
  if (type != "perspective")
    problems.Add("/camera_type", "is '" + type + "' (expected perspective: nerfar renders pinhole views)");
  const int width = static_cast<int>(top.WholeNumber("render_width", 2, kMaxImageSide));
  const int height = static_cast<int>(top.WholeNumber("render_height", 2, kMaxImageSide));
  CameraPath out;
  out.fps = top.OptionalNumber("fps", 1e-3, 1000).value_or(out.fps);
  const Json* views = top.Array("camera_path");
  top.Finish();
  if (views != nullptr && views->empty()) problems.Add("/camera_path", "is empty (expected at least one view)");
  if (views != nullptr)
    for (size_t i = 0; i < views->size(); ++i)
      out.views.push_back(
          ReadPathView((*views)[i], "/camera_path/" + std::to_string(i), width, height, problems, ignored));
  problems.ThrowIfAny();
  if (!ignored.empty()) {
    std::string list;
    for (const std::string& key : ignored) list += (list.empty() ? "" : ", ") + key;
    LogInfo("camera path: " + path + ": ignored keys nerfar does not use: " + list);
  }
  return out;
}

}  // namespace nerfar
