// Camera paths for videos of an insertion: an orbit around a point, or a
// nerfstudio camera_path.json. World frame: metres, z up (DESIGN.md);
// poses T_world_camera with OpenCV camera axes; pinhole cameras without
// distortion (the NeRF renders the background).
#pragma once

#include <string>
#include <vector>

#include "calib/camera.h"
#include "calib/core/math.h"

namespace nerfar {

struct PathView {
  CameraIntrinsics camera;
  Pose T_world_camera;
};

struct CameraPath {
  std::vector<PathView> views;
  double fps = 24;
};

// A circle at `elevation_rad` above the horizontal plane through `centre`,
// `radius_m` from it, every camera looking at it; `frames` views a full turn
// apart evenly (counter-clockwise seen from above), starting at azimuth
// `start_azimuth_rad` (0: along +x).
struct Orbit {
  Vec3 centre;
  double radius_m = 0.5;
  double elevation_rad = 0.5;
  double start_azimuth_rad = 0;
  int frames = 72;
};

std::vector<Pose> OrbitPoses(const Orbit& orbit);

// The orbit a capture suggests around `centre`: the median distance and
// elevation of its cameras seen from the centre, starting at its first
// camera's azimuth (the first frame looks as the capture began).
Orbit OrbitOfCapture(const std::vector<Pose>& capture, const Vec3& centre, int frames);

// The same camera at `width` pixels across (the aspect kept), its sizes made
// even (H.264 in 4:2:0 needs them) and its distortion dropped.
CameraIntrinsics VideoCamera(const CameraIntrinsics& camera, int width);

// Reads nerfstudio's camera_path.json ("camera_type" perspective,
// "render_width", "render_height", "fps", "camera_path": [{"camera_to_world":
// 16 numbers row-major, OpenGL axes, "fov": vertical degrees}]), its
// camera_to_world in the world of the scene's transforms.json. Keys nerfar
// does not use are logged once as ignored; InputError naming the file and
// every problem (missing or mistyped keys, no views, a fov outside (0, 180),
// a matrix that is not a rigid transform, another camera type).
CameraPath ReadCameraPath(const std::string& path);

}  // namespace nerfar
