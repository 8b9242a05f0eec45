// Analytic scenes for the NeRF trainer's tests: boxes of constant radiance
// seen against black, photographed by cameras on a ring around the z axis,
// each pixel supersampled (the images a trained field must reproduce).
#pragma once

#include <cmath>
#include <vector>

#include "render/nerf/nerf_field.h"
#include "render/nerf/nerf_train.h"

namespace nerfar::testing {

struct RadiantBox {
  Vec3 lo, hi;
  Vec3f radiance;  // the same in every direction from every face
};

// Radiance of the first box the ray o + t·d meets; black where it meets none.
inline Vec3f TraceBoxes(const std::vector<RadiantBox>& boxes, const Vec3& o, const Vec3& d) {
  float best = 1e30f;
  Vec3f value;
  for (const RadiantBox& b : boxes) {
    float t0, t1;
    if (IntersectAabb(Aabb{b.lo, b.hi}, Vec3f(o), Vec3f(d), t0, t1) && t0 < best) {
      best = t0;
      value = b.radiance;
    }
  }
  return value;
}

// A w×h view (focal 0.9·w, principal point at the centre) from `radius` metres
// at `azimuth` and `elevation` (radians), looking at (0, 0, target_z); each
// pixel is the mean of supersample² rays spread over its square.
inline NerfView RingView(const std::vector<RadiantBox>& boxes, double azimuth, double elevation, double radius,
                         double target_z, int w, int h, int supersample) {
  NerfView v;
  v.camera.width = w, v.camera.height = h;
  v.camera.fx = v.camera.fy = 0.9 * w;
  v.camera.cx = w / 2.0, v.camera.cy = h / 2.0;
  const Vec3 centre(radius * std::cos(elevation) * std::cos(azimuth), radius * std::cos(elevation) * std::sin(azimuth),
                    radius * std::sin(elevation));
  const Vec3 z = Normalized(Vec3(0, 0, target_z) - centre);
  const Vec3 x = Normalized(Cross(z, Vec3(0, 0, 1)));
  v.T_world_camera.rotation = Mat3::FromColumns(x, Cross(z, x), z);
  v.T_world_camera.translation = centre;
  v.rgb = ImageF(w, h, 3);
  const int ss = supersample;
  for (int py = 0; py < h; ++py)
    for (int px = 0; px < w; ++px) {
      Vec3f sum;
      for (int sy = 0; sy < ss; ++sy)
        for (int sx = 0; sx < ss; ++sx) {
          const Vec3 dc = Normalized(Vec3((px + (sx + 0.5) / ss - v.camera.cx) / v.camera.fx,
                                          (py + (sy + 0.5) / ss - v.camera.cy) / v.camera.fy, 1.0));
          sum += TraceBoxes(boxes, centre, v.T_world_camera.Rotate(dc));
        }
      for (int ch = 0; ch < 3; ++ch) v.rgb.at(px, py, ch) = sum[ch] / float(ss * ss);
    }
  return v;
}

}  // namespace nerfar::testing
