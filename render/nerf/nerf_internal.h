// Internal to render/nerf (the renderer and the trainer share it): trilinear
// corner lookup and the empty-space-skipping ray marcher. Not an API.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

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

// CellSlots for a cell whose own brick (the one holding corner 0) has index b0 >= 0: the other
// bricks are looked up only where the cell's corners cross into them.
inline void CellSlotsInBrick(const NerfField& f, int i, int j, int k, int32_t b0, int32_t slot[8]) {
  const int li = i & 3, lj = j & 3, lk = k & 3;
  const int32_t s0 = b0 * kNerfBrickSlots + (lk * 4 + lj) * 4 + li;
  if (li < 3 && lj < 3 && lk < 3) {
    for (int n = 0; n < 8; ++n) slot[n] = s0 + (n & 1) + ((n >> 1) & 1) * 4 + (n >> 2) * 16;
    return;
  }
  // i + 1 <= res - 1, so every neighbouring brick index lies inside the table.
  const size_t row = size_t(f.bricks[0]), plane = row * size_t(f.bricks[1]);
  const size_t base = (size_t(k >> 2) * size_t(f.bricks[1]) + size_t(j >> 2)) * row + size_t(i >> 2);
  for (int n = 0; n < 8; ++n) {
    const int ci = li + (n & 1), cj = lj + ((n >> 1) & 1), ck = lk + (n >> 2);
    const int cross = (ci >> 2) | (cj >> 2) << 1 | (ck >> 2) << 2;
    const int32_t b =
        cross == 0 ? b0 : f.brick_table[base + size_t(ci >> 2) + size_t(cj >> 2) * row + size_t(ck >> 2) * plane];
    slot[n] = b < 0 ? -1 : b * kNerfBrickSlots + ((ck & 3) * 4 + (cj & 3)) * 4 + (ci & 3);
  }
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

// The render copy (NerfRenderCopy) seen from one ray: per lane, the factor of the lane's value in
// the sample's log radiance a + b·d (1 for the bases and the density, d.x, d.y, d.z for the slopes).
struct CopyRay {
  alignas(16) float dm[NerfRenderCopy::kLanes];
  explicit CopyRay(const Vec3f& dir) {
    const float d[4][4] = {{1, 1, 1, 1}, {dir.x, dir.x, dir.x, 1}, {dir.y, dir.y, dir.y, 0}, {dir.z, dir.z, dir.z, 0}};
    for (int m = 0; m < NerfRenderCopy::kLanes; ++m) dm[m] = d[m / 4][m % 4];
  }
};

// One block of the copy seen from one ray: factors that turn interpolated codes into the log
// radiance (r, g, b) in the ray's direction and the raw log-density. Interpolating codes first is
// exact algebra: value = code·scale + offset is affine and the trilinear weights sum to 1.
struct CopyBlock {
  alignas(16) float w[NerfRenderCopy::kLanes];
  alignas(16) float k[4];  // log colour r, g, b and raw density at all codes 0
  void Set(const float* header, const CopyRay& r) {
    for (int m = 0; m < NerfRenderCopy::kLanes; ++m) w[m] = header[m] * r.dm[m];
    for (int c = 0; c < 4; ++c) {
      float sum = 0.0f;
      for (int g = 0; g < 4; ++g) sum += header[NerfRenderCopy::kLanes + 4 * g + c] * r.dm[4 * g + c];
      k[c] = sum;
    }
  }
};

// v = log radiance r, g, b in the ray's direction and the raw log-density (not clamped), at cell-local
// coordinates (fx, fy, fz) of the cell whose corner 0 has the lanes at v0 (a vertex of block b).
inline void CopyCellValues(const CopyBlock& b, const uint8_t* v0, float fx, float fy, float fz, float v[4]) {
  constexpr int L = NerfRenderCopy::kLanes, S = NerfRenderCopy::kSide;
  const float wxy[4] = {(1.0f - fx) * (1.0f - fy), fx * (1.0f - fy), (1.0f - fx) * fy, fx * fy};
  const float wz[2] = {1.0f - fz, fz};
#if defined(__SSE2__)
  // Four lanes at a time: 8-bit codes widened to 32 bits (unpack with zero), converted, accumulated.
  const __m128i zero = _mm_setzero_si128();
  __m128 acc[4] = {_mm_setzero_ps(), _mm_setzero_ps(), _mm_setzero_ps(), _mm_setzero_ps()};
  for (int n = 0; n < 8; ++n) {
    const uint8_t* q = v0 + (((n >> 2) * S + ((n >> 1) & 1)) * S + (n & 1)) * L;
    const __m128 w = _mm_set1_ps(wxy[n & 3] * wz[n >> 2]);
    const __m128i x = _mm_load_si128(reinterpret_cast<const __m128i*>(q));
    const __m128i lo = _mm_unpacklo_epi8(x, zero), hi = _mm_unpackhi_epi8(x, zero);
    acc[0] = _mm_add_ps(acc[0], _mm_mul_ps(w, _mm_cvtepi32_ps(_mm_unpacklo_epi16(lo, zero))));
    acc[1] = _mm_add_ps(acc[1], _mm_mul_ps(w, _mm_cvtepi32_ps(_mm_unpackhi_epi16(lo, zero))));
    acc[2] = _mm_add_ps(acc[2], _mm_mul_ps(w, _mm_cvtepi32_ps(_mm_unpacklo_epi16(hi, zero))));
    acc[3] = _mm_add_ps(acc[3], _mm_mul_ps(w, _mm_cvtepi32_ps(_mm_unpackhi_epi16(hi, zero))));
  }
  __m128 sum = _mm_load_ps(b.k);
  for (int c = 0; c < 4; ++c) sum = _mm_add_ps(sum, _mm_mul_ps(acc[c], _mm_load_ps(b.w + 4 * c)));
  _mm_storeu_ps(v, sum);
#else
  float acc[L] = {};
  for (int n = 0; n < 8; ++n) {
    const uint8_t* q = v0 + (((n >> 2) * S + ((n >> 1) & 1)) * S + (n & 1)) * L;
    const float w = wxy[n & 3] * wz[n >> 2];
    for (int m = 0; m < L; ++m) acc[m] += w * float(q[m]);
  }
  for (int c = 0; c < 4; ++c)
    v[c] = b.k[c] + acc[c] * b.w[c] + acc[4 + c] * b.w[4 + c] + acc[8 + c] * b.w[8 + c] + acc[12 + c] * b.w[12 + c];
#endif
}

#if defined(__SSE2__)
// exp of four floats with |x| <= 80, relative error below 3e-7 (float's own rounding is 6e-8): 2^n by
// the exponent bits times a degree-6 polynomial on [-ln2/2, ln2/2].
inline __m128 ExpPs(__m128 x) {
  const __m128i n = _mm_cvtps_epi32(_mm_mul_ps(x, _mm_set1_ps(1.44269504f)));  // round to nearest
  const __m128 nf = _mm_cvtepi32_ps(n);
  const __m128 r = _mm_sub_ps(_mm_sub_ps(x, _mm_mul_ps(nf, _mm_set1_ps(0.693359375f))),
                              _mm_mul_ps(nf, _mm_set1_ps(-2.12194440e-4f)));
  __m128 p = _mm_set1_ps(1.9875691500e-4f);
  for (const float c : {1.3981999507e-3f, 8.3334519073e-3f, 4.1665795894e-2f, 1.6666665459e-1f, 5.0000001201e-1f})
    p = _mm_add_ps(_mm_mul_ps(p, r), _mm_set1_ps(c));
  p = _mm_add_ps(_mm_add_ps(_mm_mul_ps(_mm_mul_ps(p, r), r), r), _mm_set1_ps(1.0f));
  const __m128 two_n = _mm_castsi128_ps(_mm_slli_epi32(_mm_add_epi32(n, _mm_set1_epi32(127)), 23));
  return _mm_mul_ps(p, two_n);
}
#endif

// v[m] = exp(v[m]) for |v[m]| <= 80 (ExpPs; std::exp without SSE2).
inline void Exp4(float v[4]) {
#if defined(__SSE2__)
  _mm_storeu_ps(v, ExpPs(_mm_loadu_ps(v)));
#else
  for (int m = 0; m < 4; ++m) v[m] = std::exp(v[m]);
#endif
}

// α = 1 - exp(-x) for x = σ·dt >= 0, relative error below 1.2e-6 (std::expm1 in float: 1.2e-7): below
// x = 0.25 the series x (1 - x/2 + x²/6 - ... - x⁵/720) (truncation < x⁶/5040 <= 5e-8 relative), above
// it 1 - ExpPs(-x), where α > 0.22 (so exp's 3e-7 is < 1.1e-6 of α); x above 80 gives α = 1 in float.
inline float OneMinusExpNeg(float x) {
  if (x < 0.25f)
    return x * (1.0f -
                x * (1.0f / 2.0f - x * (1.0f / 6.0f - x * (1.0f / 24.0f - x * (1.0f / 120.0f - x * (1.0f / 720.0f))))));
#if defined(__SSE2__)
  return 1.0f - _mm_cvtss_f32(ExpPs(_mm_set_ss(-std::min(x, 80.0f))));
#else
  return -std::expm1(-x);
#endif
}

// The render copy's raw log-density and log colour at grid point g in direction dir; false when g lies
// outside the grid or its cell's brick has no block (no occupied cell).
inline bool CopyPointValues(const NerfField& f, const Vec3f& g, const Vec3f& dir, float& raw_density,
                            float log_color[3]) {
  if (!(g.x >= 0.0f && g.y >= 0.0f && g.z >= 0.0f)) return false;
  if (!(g.x <= float(f.res[0] - 1) && g.y <= float(f.res[1] - 1) && g.z <= float(f.res[2] - 1))) return false;
  const int i = std::min(int(g.x), f.res[0] - 2), j = std::min(int(g.y), f.res[1] - 2),
            k = std::min(int(g.z), f.res[2] - 2);
  const int32_t block =
      f.render_copy.entry[(size_t(k >> 2) * f.bricks[1] + size_t(j >> 2)) * f.bricks[0] + size_t(i >> 2)];
  if (block < 0) return false;
  CopyBlock cb;
  cb.Set(f.render_copy.Header(block), CopyRay(dir));
  float v[4];
  CopyCellValues(cb, f.render_copy.Vertex(block, i & 3, j & 3, k & 3), g.x - float(i), g.y - float(j), g.z - float(k),
                 v);
  log_color[0] = v[0], log_color[1] = v[1], log_color[2] = v[2];
  raw_density = v[3];
  return true;
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

// The samples of a ray marched over [t_near, t_far] in intervals of `step`
// metres: the sample of interval n lies at t_near + (n + offset)·step (offset in
// [0,1); the last, shorter interval places it at the same fraction of its
// length). The trainer's MarchRay and the renderer take their samples from here,
// so both see exactly the same ones.
struct RaySteps {
  // One sample: its ray parameter, interval length, grid point (clamped into the grid) and cell.
  struct Sample {
    float t, dt;
    Vec3f g;
    int i, j, k;
  };

  RaySteps(const NerfField& f, const NerfRay& ray, float step, float offset)
      : t0(ray.t_near),
        t1(ray.t_far),
        step(step),
        offset(offset),
        o((ray.origin - f.origin) * (1.0f / f.voxel_m)),
        d(ray.dir * (1.0f / f.voxel_m)),
        count(int64_t(std::ceil((t1 - t0) / step))) {
    for (int axis = 0; axis < 3; ++axis) {
      inv_d[axis] = d[axis] != 0.0f ? 1.0f / d[axis] : 1e30f;
      last_cell[axis] = f.res[axis] - 2;
      max_g[axis] = float(f.res[axis] - 1);
      // An axis the ray does not move along never limits a block's exit: its plane distance is
      // plane + 1e30 (factor 1), beyond every other axis' exit.
      exit_far[axis] = d[axis] > 0.0f ? 1 : 0;
      exit_o[axis] = d[axis] != 0.0f ? o[axis] : -1e30f;
      exit_inv[axis] = d[axis] != 0.0f ? inv_d[axis] : 1.0f;
    }
  }

  // Grid coordinates of the ray at t (not clamped).
  Vec3f Grid(float t) const { return o + d * t; }

  // Sample of interval n; false when rounding leaves the interval empty (the ray's end).
  bool At(int64_t n, Sample& s) const {
    const float a = t0 + float(n) * step;
    s.dt = std::min(step, t1 - a);
    if (!(s.dt > 0.0f)) return false;
    s.t = a + offset * s.dt;
    const Vec3f g = Grid(s.t);
    s.g = {std::clamp(g.x, 0.0f, max_g[0]), std::clamp(g.y, 0.0f, max_g[1]), std::clamp(g.z, 0.0f, max_g[2])};
    s.i = std::min(int(s.g.x), last_cell[0]);
    s.j = std::min(int(s.g.y), last_cell[1]);
    s.k = std::min(int(s.g.z), last_cell[2]);
    return true;
  }

  // The next interval to visit after interval n, whose sample s lies in an empty brick (state 0 of
  // CellState) or an empty cell (state 1): the first one beyond it, and never n itself.
  int64_t SkipEmpty(int64_t n, int state, const Sample& s) const { return SkipBlock(n, state == 0 ? 2 : 0, s); }

  // The next interval to visit after interval n, whose sample s lies in an empty block of 2^shift
  // cells per side (aligned to multiples of 2^shift): the first one beyond the block, never n itself.
  int64_t SkipBlock(int64_t n, int shift, const Sample& s) const {
    return SkipPast(n, float(((s.i >> shift) + exit_far[0]) << shift), float(((s.j >> shift) + exit_far[1]) << shift),
                    float(((s.k >> shift) + exit_far[2]) << shift));
  }

  // SkipBlock for the empty cube of bricks (4 cells per side) within Chebyshev distance < D of the
  // brick holding s (NerfRenderCopy::entry): from brick b - (D - 1) to b + (D - 1) on each axis.
  int64_t SkipBricks(int64_t n, int D, const Sample& s) const {
    return SkipPast(n, float(((s.i >> 2) + (exit_far[0] ? D : 1 - D)) * 4),
                    float(((s.j >> 2) + (exit_far[1] ? D : 1 - D)) * 4),
                    float(((s.k >> 2) + (exit_far[2] ? D : 1 - D)) * 4));
  }

  // The next interval to visit after interval n, whose sample lies in an empty box of cells that the
  // ray leaves through the planes x = px, y = py, z = pz (grid coordinates; on each axis the face the
  // ray moves towards): the first interval beyond the box, never n itself.
  int64_t SkipPast(int64_t n, float px, float py, float pz) const {
    const float tx = (px - exit_o[0]) * exit_inv[0];
    const float ty = (py - exit_o[1]) * exit_inv[1];
    const float tz = (pz - exit_o[2]) * exit_inv[2];
    const float t_exit = std::min(std::min(tx, ty), std::min(tz, 1e30f));
    // 1e-3 of a step of slack: a sample that rounding puts on the exit plane is visited, never skipped.
    // The first interval whose sample lies beyond is ceil(x); ceil(x) > n + 1 exactly when x > n + 1
    // and ceil(x) < count when x <= count - 1 (integers), so ceil is taken only on that range.
    const float x = (t_exit - t0) / step - offset - 1e-3f;
    if (!(x > float(n + 1))) return n + 1;
    if (!(x <= float(count - 1))) return count;
    const int64_t k = int64_t(x);
    return k + (float(k) < x ? 1 : 0);
  }

  float t0, t1, step, offset;
  Vec3f o, d;  // grid coordinates, grid units per metre
  int64_t count;
  float inv_d[3], max_g[3];
  int last_cell[3];
  int exit_far[3];               // 1 where the ray moves up the axis (exits a block at its far face)
  float exit_o[3], exit_inv[3];  // SkipBlock's o and inv_d, made neutral on axes with d = 0
};

// Calls visit(t, dt, corners) for every sample of RaySteps in an occupied cell,
// in order, until it returns false. Empty bricks and empty cells are jumped over.
template <typename Visit>
inline void MarchRay(const NerfField& f, const NerfRay& ray, float step, float offset, Visit&& visit) {
  if (!(ray.t_far > ray.t_near) || f.empty()) return;
  const RaySteps steps(f, ray, step, offset);
  RaySteps::Sample s;
  Corners c;
  for (int64_t n = 0; n < steps.count;) {
    if (!steps.At(n, s)) break;
    const int state = CellState(f, s.i, s.j, s.k);
    if (state != 2) {
      n = steps.SkipEmpty(n, state, s);
      continue;
    }
    if (!LocateGrid(f, s.g, c)) break;
    if (!visit(s.t, s.dt, c)) return;
    ++n;
  }
}

}  // namespace nerfar::nerf_detail
