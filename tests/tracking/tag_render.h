// Test-only renderer of planar tag boards: every pixel is the area average of
// supersample x supersample rays intersected with the board plane (a box
// filter one pixel wide, as the shared scenes are rendered), so the true
// corner positions are exact in continuous pixel coordinates. Independent of
// the tracker: it uses only calib's Unproject and the family bitmaps.
#pragma once

#include <cstdint>
#include <vector>

#include "calib/board.h"
#include "calib/camera.h"
#include "calib/core/image.h"

namespace nerfar::testing {

struct RenderOptions {
  int supersample = 4;                          // rays per pixel side
  double ink = 0.03, paper = 0.8, table = 0.3;  // albedos (the scenes' values)
  double gain = 1.0;                            // exposure: > 1 over-exposes (values clip at 1)
  double noise_sigma = 0.0;                     // Gaussian noise, 8-bit levels
  double blur_sigma = 0.0;                      // Gaussian blur, pixels
  std::uint32_t seed = 1;
  // Optional occluder: pixels in [x0, x1) x [y0, y1) painted dark grey.
  int occlude_x0 = 0, occlude_y0 = 0, occlude_x1 = 0, occlude_y1 = 0;
  double paper_margin_cells = 2.0;  // white margin around each tag
};

// A planar board of rows x cols tags of tag36h11 (ids from 0), printed up
// along +y, on the plane z = 0, centred at the origin, `pitch_m` apart.
Board GridBoard(int rows, int cols, double tag_size_m, double pitch_m);

// Grey 8-bit image of the board seen from T_world_camera (OpenCV axes).
Image8 RenderBoard(const Board& board, const CameraIntrinsics& camera, const Pose& T_world_camera,
                   const RenderOptions& options = {});
// Average of renders along a straight motion from `from` to `to` (motion blur).
Image8 RenderMotionBlur(const Board& board, const CameraIntrinsics& camera, const Pose& from, const Pose& to, int steps,
                        const RenderOptions& options = {});

// A camera at `distance_m` from `target`, looking at it from elevation and
// azimuth (radians, world z up), image up towards world +z (no roll).
Pose LookAt(const Vec3& target, double distance_m, double elevation_rad, double azimuth_rad);

CameraIntrinsics TestCamera(int width, int height, double hfov_deg);

}  // namespace nerfar::testing
