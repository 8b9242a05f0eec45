// camera.json: a calibrated camera as `nerfar calibrate` writes it and
// `nerfar capture` reads it. The intrinsics use the keys of transforms.json
// (fl_x, fl_y, cx, cy, w, h, k1, k2, p1, p2, k3, camera_model,
// camera_angle_x/y; pixel conventions of calib/camera.h), optionally with the
// camera response of calib/hdr.h and a calibration report. A transforms.json
// is accepted as a camera source too (its frames are ignored).
#pragma once

#include <optional>
#include <string>

#include "calib/camera.h"
#include "calib/hdr.h"

namespace nerfar {

// What the calibration said about itself (kept for the record and the gate).
struct CalibrationRecord {
  double rms_px = 0;
  int views_used = 0;
  int views_rejected = 0;
  double coverage = 0;                                            // fraction of the coverage grid's cells with corners
  double sigma_fx = 0, sigma_fy = 0, sigma_cx = 0, sigma_cy = 0;  // 1-sigma, pixels
};

struct CameraFile {
  CameraIntrinsics camera;
  std::string camera_model = "OPENCV";
  std::optional<CameraResponse> response;  // Debevec g(z) per channel
  std::optional<CalibrationRecord> calibration;
};

// Reads camera.json, or the camera of a transforms.json (recognised by its
// "frames" key). InputError listing every problem.
CameraFile ReadCameraFile(const std::string& path);
// Writes camera.json (atomic).
void WriteCameraFile(const std::string& path, const CameraFile& file);

}  // namespace nerfar
