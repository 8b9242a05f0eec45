// The pinhole camera the insertion tests render with: focal 0.9 x width,
// principal point at the image centre, no distortion.
#pragma once

#include "calib/camera.h"

namespace nerfar::testing {

inline CameraIntrinsics TestCamera(int width, int height) {
  CameraIntrinsics camera;
  camera.width = width;
  camera.height = height;
  camera.fx = camera.fy = 0.9 * width;
  camera.cx = width / 2.0;
  camera.cy = height / 2.0;
  return camera;
}

}  // namespace nerfar::testing
