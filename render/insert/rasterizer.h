// CPU rasteriser for the virtual objects: a depth-buffered G-buffer (object
// id, ray distance, world position, normal, UV) over the objects' screen
// bounding box only, with triangles clipped at the near plane and attributes
// interpolated perspective-correctly. Headless, no display needed.
// Cameras: pinhole (CameraIntrinsics without distortion: frames are expected
// undistorted), OpenCV axes, pixel (i, j) sampled at its centre (i+0.5, j+0.5).
// Distances in metres along unit rays from the camera centre.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "calib/camera.h"
#include "calib/core/math.h"
#include "render/mesh/mesh.h"

namespace nerfar {

// Half-open pixel rectangle [x0, x1) × [y0, y1).
struct PixelRect {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  int width() const { return x1 > x0 ? x1 - x0 : 0; }
  int height() const { return y1 > y0 ? y1 - y0 : 0; }
  bool empty() const { return width() == 0 || height() == 0; }
  size_t area() const { return static_cast<size_t>(width()) * height(); }
  bool Contains(int x, int y) const { return x >= x0 && x < x1 && y >= y0 && y < y1; }
};

// The rectangle covering both (an empty one is ignored).
PixelRect Union(const PixelRect& a, const PixelRect& b);
// The part of r inside the image.
PixelRect ClipToImage(const PixelRect& r, int width, int height);

// Unit world direction of the ray through the centre of pixel (x, y).
Vec3f CameraRayDirection(const CameraIntrinsics& camera, const Pose& T_world_camera, int x, int y);

// One object to draw: its mesh in its local frame and p_world = T_world_object·(scale·p).
struct RasterObject {
  const TriangleMesh* mesh = nullptr;  // loan for the call
  Pose T_world_object;
  double scale = 1.0;
};

// Per-pixel surface data over `rect`; index with At(x, y) (full-image coordinates).
struct ObjectGBuffer {
  PixelRect rect;                          // where the objects can be; empty when none is visible
  std::vector<int32_t> object;             // index into the object list, −1 where no object is seen
  std::vector<float> t;                    // distance from the camera centre along the unit pixel ray
  std::vector<Vec3f> position;             // world, metres
  std::vector<Vec3f> normal;               // world, unit (the shading normal, facing the camera)
  std::vector<std::array<float, 2>> uv;    // (0, 0) where the mesh has no UVs
  std::vector<uint32_t> triangle;          // index of the visible triangle in its object's mesh
  std::vector<std::array<float, 2>> bary;  // its perspective-correct barycentrics (b1, b2); b0 = 1 − b1 − b2
  // Fraction of the pixel's square covered by any object (coverage_grid² sub-samples; empty when off).
  // Pixels whose centre misses every object can still be partly covered.
  std::vector<float> coverage;
  size_t covered = 0;  // number of pixels with an object

  size_t Index(int x, int y) const {
    return static_cast<size_t>(y - rect.y0) * static_cast<size_t>(rect.width()) + static_cast<size_t>(x - rect.x0);
  }
};

struct RasterOptions {
  double z_near_m = 1e-3;  // triangles are clipped at this camera depth (parts behind are not drawn)
  int coverage_grid = 0;   // > 1: coverage of each pixel from coverage_grid² sub-samples (at most 4); else none
};

// Rasterises every object into one depth buffer (the nearest surface wins).
// Degenerate and non-finite triangles are skipped; never throws on geometry.
ObjectGBuffer Rasterize(const CameraIntrinsics& camera, const Pose& T_world_camera,
                        const std::vector<RasterObject>& objects, const RasterOptions& options = {});

// Screen rectangle of a world-space ball (conservative; the whole image when
// the camera is inside or close to it; empty when it is behind the camera).
PixelRect ProjectBall(const CameraIntrinsics& camera, const Pose& T_world_camera, const Vec3& center, double radius);

}  // namespace nerfar
