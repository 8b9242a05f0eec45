// Pinhole camera with OpenCV distortion (k1, k2, p1, p2, k3).
// Frames: camera coordinates follow OpenCV (x right, y down, z forward).
// Pixels: continuous coordinates with the origin at the top-left corner of the
// image, so pixel (i, j) covers [i, i+1] x [j, j+1] and its centre is
// (i+0.5, j+0.5); cx, cy are in these coordinates, exactly as transforms.json
// stores them. OpenCV's calibration puts pixel centres at integers: convert
// with ToOpenCvPrincipalPoint / FromOpenCvPrincipalPoint at that boundary only.
#pragma once

#include <string>
#include <vector>

#include "calib/core/math.h"

namespace nerfar {

struct Vec2 {
  double x = 0, y = 0;
};

struct CameraIntrinsics {
  int width = 0, height = 0;  // pixels
  double fx = 0, fy = 0;      // focal lengths, pixels
  double cx = 0, cy = 0;      // principal point, continuous pixel coordinates
  double k1 = 0, k2 = 0, p1 = 0, p2 = 0, k3 = 0;

  bool HasDistortion() const { return k1 != 0 || k2 != 0 || p1 != 0 || p2 != 0 || k3 != 0; }
  // Every problem with the values (non-positive size or focal, non-finite terms).
  std::vector<std::string> Validate() const;
  // The same camera at another resolution (focal and principal point scaled).
  CameraIntrinsics Scaled(int new_width, int new_height) const;
};

// OpenCV's principal point (pixel centres at integers) and back.
Vec2 ToOpenCvPrincipalPoint(const CameraIntrinsics& camera);
void FromOpenCvPrincipalPoint(CameraIntrinsics& camera, double cx_opencv, double cy_opencv);

// Normalised image coordinates (x/z, y/z) -> distorted normalised coordinates.
Vec2 Distort(const CameraIntrinsics& camera, const Vec2& undistorted);
// Inverse of Distort by fixed-point iteration refined with Newton steps;
// accurate to 1e-10 inside the image for realistic lens distortion.
Vec2 Undistort(const CameraIntrinsics& camera, const Vec2& distorted);

// Camera-frame point -> pixel. False (pixel unchanged) if z <= 0.
bool Project(const CameraIntrinsics& camera, const Vec3& p_camera, Vec2& pixel);
// Pixel -> unit ray direction in the camera frame (z > 0).
Vec3 Unproject(const CameraIntrinsics& camera, const Vec2& pixel);

// Undistortion maps: for each pixel centre of the ideal (undistorted) image,
// the continuous pixel position to sample in the distorted image. map_x and
// map_y are width*height, row-major.
void UndistortMaps(const CameraIntrinsics& camera, std::vector<float>& map_x, std::vector<float>& map_y);

}  // namespace nerfar
