// The intrinsics keys shared by transforms.json and camera.json (fl_x, fl_y,
// cx, cy, w, h, camera_angle_x/y, camera_model, k1 k2 p1 p2 k3): one reader
// and one writer for both files. Pixel conventions as in calib/camera.h.
// instant-ngp's and nerfstudio's spellings are read too: sizes written as
// whole floats (1080.0), is_fisheye false and k4 0 (a fisheye is refused).
#pragma once

#include <string>
#include <vector>

#include "calib/camera.h"
#include "calib/core/json.h"

namespace nerfar {

// Reads the intrinsics keys of the object behind `reader` into `camera` and
// returns the camera model ("OPENCV" or "PINHOLE"). Problems go to the
// reader's list: missing or mistyped keys, absurd sizes, non-finite numbers,
// a principal point outside the image, camera_angle_x/y that disagree with
// fl_x/fl_y. fl_x (fl_y) may be omitted when camera_angle_x (_y) is given;
// fl_y defaults to fl_x; absent distortion terms are 0.
std::string ReadCameraKeys(JsonObjectReader& reader, CameraIntrinsics& camera);

// Every key ReadCameraKeys may read (for readers that tell a typo of one of
// them from another tool's key).
const std::vector<std::string>& CameraKeyNames();

// Writes the same keys (camera_angle_x/y included, computed from the focal
// lengths) into `object`, which must be a JSON object.
void WriteCameraKeys(const CameraIntrinsics& camera, const std::string& camera_model, Json& object);

// Horizontal or vertical field of view in radians of a pinhole of this focal.
double FieldOfView(int size_px, double focal_px);

}  // namespace nerfar
