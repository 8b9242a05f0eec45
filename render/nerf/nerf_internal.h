// Internal to render/nerf (the renderer and the trainer share it): trilinear
// corner lookup and the empty-space-skipping ray marcher. Not an API.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "render/nerf/nerf_field.h"

namespace nerfar::nerf_detail {

// The 8 corners of the cell holding a point: slots (-1 = empty) and trilinear weights.
struct Corners {
  int32_t slot[8];
  float weight[8];
};

// Slots (-1 = empty) of the 8 corners of cell (i,j,k), corner n at (i + (n&1), j + (n>>1 & 1), k + (n>>2));
// i, j, k < res - 1. One brick look-up when the cell lies inside one brick (27 of a brick's 64 cells).
inline void CellSlots(const NerfField& f, int i, int j, int k, int32_t slot[8]) {
  if ((i & 3) < 3 && (j & 3) < 3 && (k & 3) < 3) {
    const int32_t s0 = f.Slot(i, j, k);
    for (int n = 0; n < 8; ++n) slot[n] = s0 < 0 ? -1 : s0 + (n & 1) + ((n >> 1) & 1) * 4 + (n >> 2) * 16;
    return;
  }
  for (int n = 0; n < 8; ++n) slot[n] = f.Slot(i + (n & 1), j + ((n >> 1) & 1), k + (n >> 2));
}

// Trilinear corners at grid coordinates g (voxels). False when g lies outside the grid.
inline bool LocateGrid(const NerfField& f, const Vec3f& g, Corners& c) {
  if (!(g.x >= 0.0f && g.y >= 0.0f && g.z >= 0.0f)) return false;
  if (!(g.x <= float(f.res[0] - 1) && g.y <= float(f.res[1] - 1) && g.z <= float(f.res[2] - 1))) return false;
  const int i = std::min(int(g.x), f.res[0] - 2), j = std::min(int(g.y), f.res[1] - 2),
            k = std::min(int(g.z), f.res[2] - 2);
  const float fx = g.x - float(i), fy = g.y - float(j), fz = g.z - float(k);
  const float wx[2] = {1.0f - fx, fx}, wy[2] = {1.0f - fy, fy}, wz[2] = {1.0f - fz, fz};
  CellSlots(f, i, j, k, c.slot);
  for (int n = 0; n < 8; ++n) c.weight[n] = wx[n & 1] * wy[(n >> 1) & 1] * wz[n >> 2];
  return true;
}

inline float RawDensity(const NerfField& f, const Corners& c) {
  float s = 0.0f;
  for (int n = 0; n < 8; ++n) s += c.weight[n] * (c.slot[n] >= 0 ? f.density[c.slot[n]] : kNerfEmptyDensityRaw);
  return s;
}

// Interpolated 12 colour coefficients (empty corners contribute 0).
inline void ColorCoeffs(const NerfField& f, const Corners& c, float out[kNerfColorCoeffs]) {
  for (int m = 0; m < kNerfColorCoeffs; ++m) out[m] = 0.0f;
  for (int n = 0; n < 8; ++n) {
    if (c.slot[n] < 0) continue;
    const float* q = &f.color[size_t(c.slot[n]) * kNerfColorCoeffs];
    const float w = c.weight[n];
    for (int m = 0; m < kNerfColorCoeffs; ++m) out[m] += w * q[m];
  }
}

// Radiance from interpolated coefficients: exp(a + b·d) per channel.
inline Vec3f ColorFromCoeffs(const float q[kNerfColorCoeffs], const Vec3f& d) {
  float l[3];
  for (int ch = 0; ch < 3; ++ch) {
    const float* a = q + 4 * ch;
    l[ch] = std::exp(std::clamp(a[0] + a[1] * d.x + a[2] * d.y + a[3] * d.z, kNerfLogColorMin, kNerfLogColorMax));
  }
  return {l[0], l[1], l[2]};
}

// Whether the brick / cell at integer cell coordinates (i,j,k) may hold density.
// Returns 0: empty brick, 1: occupied brick but empty cell, 2: occupied cell.
inline int CellState(const NerfField& f, int i, int j, int k) {
  const int bx = i >> 2, by = j >> 2, bz = k >> 2;
  const int32_t b = f.brick_table[(size_t(bz) * f.bricks[1] + by) * f.bricks[0] + bx];
  if (b < 0) return 0;
  const uint64_t bits = f.occupancy[b];
  if (bits == 0) return 0;
  return (bits >> (((k & 3) * 4 + (j & 3)) * 4 + (i & 3))) & 1u ? 2 : 1;
}

// Marches a ray over [t_near, t_far] in intervals of `step` metres; the sample
// of interval n lies at t_near + (n + offset)·step (offset in [0,1); the last,
// shorter interval places it at the same fraction of its length). Calls
// visit(t, dt, corners) for every sample in an occupied cell, in order, until
// it returns false. Empty bricks and empty cells are jumped over.
template <typename Visit>
inline void MarchRay(const NerfField& f, const NerfRay& ray, float step, float offset, Visit&& visit) {
  const float t0 = ray.t_near, t1 = ray.t_far;
  if (!(t1 > t0) || f.empty()) return;
  const float inv_h = 1.0f / f.voxel_m;
  const Vec3f o = (ray.origin - f.origin) * inv_h;  // grid coordinates
  const Vec3f d = ray.dir * inv_h;                  // grid units per metre
  const float inv_d[3] = {d.x != 0.0f ? 1.0f / d.x : 1e30f, d.y != 0.0f ? 1.0f / d.y : 1e30f,
                          d.z != 0.0f ? 1.0f / d.z : 1e30f};
  const float span = t1 - t0;
  const int64_t count = int64_t(std::ceil(span / step));
  const float max_g[3] = {float(f.res[0] - 1), float(f.res[1] - 1), float(f.res[2] - 1)};
  Corners c;
  for (int64_t n = 0; n < count;) {
    const float a = t0 + float(n) * step;
    const float dt = std::min(step, t1 - a);
    if (!(dt > 0.0f)) break;
    const float t = a + offset * dt;
    Vec3f g = o + d * t;
    g.x = std::clamp(g.x, 0.0f, max_g[0]);
    g.y = std::clamp(g.y, 0.0f, max_g[1]);
    g.z = std::clamp(g.z, 0.0f, max_g[2]);
    const int i = std::min(int(g.x), f.res[0] - 2), j = std::min(int(g.y), f.res[1] - 2),
              k = std::min(int(g.z), f.res[2] - 2);
    const int state = CellState(f, i, j, k);
    if (state == 2) {
      if (!LocateGrid(f, g, c)) break;
      if (!visit(t, dt, c)) return;
      ++n;
    } else {
      // Jump to the first sample beyond this empty brick (state 0) or empty cell (state 1).
      const int shift = state == 0 ? 2 : 0;
      const int b[3] = {i >> shift, j >> shift, k >> shift};
      float t_exit = 1e30f;
      for (int axis = 0; axis < 3; ++axis) {
        const float dir = axis == 0 ? d.x : (axis == 1 ? d.y : d.z);
        const float org = axis == 0 ? o.x : (axis == 1 ? o.y : o.z);
        if (dir == 0.0f) continue;
        const float plane = float((dir > 0.0f ? b[axis] + 1 : b[axis]) << shift);
        t_exit = std::min(t_exit, (plane - org) * inv_d[axis]);
      }
      // 1e-3 of a step of slack: a sample that rounding puts on the exit plane is visited, never skipped.
      const float next = std::ceil((t_exit - t0) / step - offset - 1e-3f);
      n = next > float(n + 1) ? (next < float(count) ? int64_t(next) : count) : n + 1;
    }
  }
}

}  // namespace nerfar::nerf_detail
