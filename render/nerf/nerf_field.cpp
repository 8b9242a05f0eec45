#include "render/nerf/nerf_field.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>

#include "calib/core/error.h"
#include "calib/core/parallel.h"
#include "render/nerf/nerf_internal.h"

namespace nerfar {

using nerf_detail::Corners;

NerfField NerfField::Dense(const Aabb& box, double voxel, float density_raw, const Vec3f& log_color) {
  NERFAR_CHECK(voxel > 0);
  NerfField f;
  f.aabb = box;
  f.origin = Vec3f(box.min);
  f.voxel_m = float(voxel);
  const Vec3 extent = box.max - box.min;
  for (int a = 0; a < 3; ++a) {
    NERFAR_CHECK(extent[a] > 0);
    f.res[a] = std::max(2, int(std::ceil(extent[a] / voxel - 1e-6)) + 1);
    f.bricks[a] = (f.res[a] + kNerfBrickSide - 1) / kNerfBrickSide;
  }
  f.brick_table.assign(size_t(f.bricks[0]) * f.bricks[1] * f.bricks[2], -1);
  for (int bz = 0; bz < f.bricks[2]; ++bz)
    for (int by = 0; by < f.bricks[1]; ++by)
      for (int bx = 0; bx < f.bricks[0]; ++bx) f.AllocateBrick(bx, by, bz);
  std::fill(f.density.begin(), f.density.end(), density_raw);
  for (size_t s = 0; s < f.SlotCount(); ++s) {
    float* q = &f.color[s * kNerfColorCoeffs];
    q[0] = log_color.x, q[4] = log_color.y, q[8] = log_color.z;
  }
  f.occupancy.assign(f.BrickCount(), ~uint64_t{0});
  f.UpdateSkipGrid();
  return f;
}

NerfRenderOptions NerfRenderOptions::Preset(const std::string& name) {
  NerfRenderOptions o;
  if (name == "full") return o;
  if (name == "live") {
    o.step_voxels = 2.0f;
    o.min_transmittance = 3e-2f;
    return o;
  }
  if (name == "preview") {
    o.step_voxels = 3.0f;
    o.min_transmittance = 3e-2f;
    return o;
  }
  throw InputError("render quality '" + name + "' (expected full, live or preview)");
}

std::vector<std::string> NerfRenderOptions::Validate() const {
  std::vector<std::string> problems;
  if (!(step_voxels >= 0.01f && step_voxels <= 16.0f)) problems.push_back("step_voxels: (expected 0.01..16)");
  if (!(min_transmittance >= 0.0f && min_transmittance < 1.0f))
    problems.push_back("min_transmittance: (expected 0 <= T < 1)");
  if (!(min_alpha >= 0.0f && min_alpha < 1.0f)) problems.push_back("min_alpha: (expected 0 <= a < 1)");
  if (!(surface_transmittance > 0.0f && surface_transmittance < 1.0f))
    problems.push_back("surface_transmittance: (expected 0 < T < 1)");
  return problems;
}

int32_t NerfField::Slot(int i, int j, int k) const {
  if (i < 0 || j < 0 || k < 0 || i >= res[0] || j >= res[1] || k >= res[2]) return -1;
  const int32_t b = brick_table[(size_t(k >> 2) * bricks[1] + (j >> 2)) * bricks[0] + (i >> 2)];
  if (b < 0) return -1;
  return b * kNerfBrickSlots + ((k & 3) * 4 + (j & 3)) * 4 + (i & 3);
}

int32_t NerfField::AllocateBrick(int bx, int by, int bz) {
  int32_t& entry = brick_table[(size_t(bz) * bricks[1] + by) * bricks[0] + bx];
  if (entry >= 0) return entry;
  entry = int32_t(BrickCount());
  brick_coords.insert(brick_coords.end(), {bx, by, bz});
  density.resize(density.size() + kNerfBrickSlots, kNerfEmptyDensityRaw);
  color.resize(color.size() + size_t(kNerfBrickSlots) * kNerfColorCoeffs, 0.0f);
  occupancy.push_back(0);
  return entry;
}

void NerfField::UpdateOccupancy(float sigma_threshold) {
  occupancy_sigma = sigma_threshold;
  const float raw_threshold = std::log(std::max(sigma_threshold, 1e-30f));
  occupancy.assign(BrickCount(), 0);
  ParallelFor(
      BrickCount(),
      [&](size_t b) {
        const int bx = brick_coords[3 * b], by = brick_coords[3 * b + 1], bz = brick_coords[3 * b + 2];
        uint64_t bits = 0;
        for (int k = 0; k < 4; ++k)
          for (int j = 0; j < 4; ++j)
            for (int i = 0; i < 4; ++i) {
              const int vi = bx * 4 + i, vj = by * 4 + j, vk = bz * 4 + k;
              if (vi >= res[0] - 1 || vj >= res[1] - 1 || vk >= res[2] - 1) continue;  // not a cell
              float max_raw = kNerfEmptyDensityRaw;
              for (int n = 0; n < 8; ++n) {
                const int32_t s = Slot(vi + (n & 1), vj + ((n >> 1) & 1), vk + (n >> 2));
                if (s >= 0) max_raw = std::max(max_raw, density[s]);
              }
              if (max_raw > raw_threshold) bits |= uint64_t{1} << ((k * 4 + j) * 4 + i);
            }
        occupancy[b] = bits;
      },
      16);
  UpdateSkipGrid();
}

void NerfField::UpdateSkipGrid() {
  skip = NerfSkipGrid{};
  ClearRenderCopy();  // it holds only the bricks occupied when it was built
  if (empty() || occupancy.size() != BrickCount() || brick_coords.size() != 3 * BrickCount()) return;
  const int cells[3] = {res[0] - 1, res[1] - 1, res[2] - 1};
  for (int shift : {4, 3, 2}) {
    NerfSkipGrid::Level level;
    level.shift = shift;
    size_t blocks = 1;
    for (int a = 0; a < 3; ++a) {
      level.dims[a] = (cells[a] + (1 << shift) - 1) >> shift;
      blocks *= size_t(level.dims[a]);
    }
    level.bits.assign((blocks + 63) / 64, 0);
    skip.levels.push_back(std::move(level));
  }
  for (int a = 0; a < 3; ++a) skip.lo[a] = cells[a], skip.hi[a] = -1;
  for (size_t b = 0; b < BrickCount(); ++b) {
    const uint64_t bits = occupancy[b];
    if (bits == 0) continue;
    const int bx = brick_coords[3 * b], by = brick_coords[3 * b + 1], bz = brick_coords[3 * b + 2];
    for (uint64_t rest = bits; rest != 0; rest &= rest - 1) {
      const int cell = __builtin_ctzll(rest);
      // Bits of cells outside the grid (possible in hand-made fields) mark the last cell instead.
      const int c[3] = {std::min(bx * 4 + (cell & 3), cells[0] - 1), std::min(by * 4 + ((cell >> 2) & 3), cells[1] - 1),
                        std::min(bz * 4 + (cell >> 4), cells[2] - 1)};
      for (int a = 0; a < 3; ++a) skip.lo[a] = std::min(skip.lo[a], c[a]), skip.hi[a] = std::max(skip.hi[a], c[a]);
      for (NerfSkipGrid::Level& level : skip.levels) {
        const size_t n = (size_t(c[2] >> level.shift) * size_t(level.dims[1]) + size_t(c[1] >> level.shift)) *
                             size_t(level.dims[0]) +
                         size_t(c[0] >> level.shift);
        level.bits[n >> 6] |= uint64_t{1} << (n & 63);
      }
    }
  }
  skip.source = occupancy.data();
  skip.source_size = occupancy.size();
}

namespace {

// The values of vertex (i,j,k) in render-copy lane order with the density in lane 3 (lane 7, its
// high byte, 0); an unallocated vertex or one outside the grid has the empty density and colour 0,
// as the float path reads it.
void VertexLanes(const NerfField& f, int i, int j, int k, float lanes[NerfRenderCopy::kLanes]) {
  const int32_t s = f.Slot(i, j, k);
  for (int m = 0; m < NerfRenderCopy::kLanes; ++m) lanes[m] = 0.0f;
  if (s < 0) {
    lanes[3] = kNerfEmptyDensityRaw;
    return;
  }
  lanes[3] = f.density[size_t(s)];
  const float* q = &f.color[size_t(s) * kNerfColorCoeffs];
  for (int ch = 0; ch < 3; ++ch)
    for (int c = 0; c < 4; ++c) lanes[4 * c + ch] = q[4 * ch + c];  // a, bx, by, bz of channel ch
}

// NerfRenderCopy::entry: block indices in the order of the allocated bricks with an occupied cell,
// and for every other brick-table position -D, D the Chebyshev distance in bricks to the nearest
// brick with a block, capped at kMaxDistance. The distance is separable: one pass per axis,
// d'(x) = min over x' on x's line of max(|x - x'|, d(x')), starting from 0 at bricks with a block and
// the cap elsewhere, gives min(D, cap) exactly (ties of max and min keep the cap a cap).
std::vector<int32_t> CopyEntries(const NerfField& f) {
  constexpr int32_t kCap = NerfRenderCopy::kMaxDistance;
  const size_t dims[3] = {size_t(f.bricks[0]), size_t(f.bricks[1]), size_t(f.bricks[2])};
  const size_t count = dims[0] * dims[1] * dims[2];
  std::vector<int32_t> dist(count, kCap), next(count);
  for (size_t n = 0; n < count; ++n) {
    const int32_t b = f.brick_table[n];
    if (b >= 0 && f.occupancy[size_t(b)] != 0) dist[n] = 0;
  }
  const size_t strides[3] = {1, dims[0], dims[0] * dims[1]};
  for (int axis = 0; axis < 3; ++axis) {
    const size_t len = dims[axis], stride = strides[axis];
    // Lines along `axis`: start positions are those with coordinate 0 on it.
    ParallelFor(
        count / len,
        [&](size_t line) {
          const size_t start = axis == 0   ? line * len
                               : axis == 1 ? (line / dims[0]) * dims[0] * dims[1] + line % dims[0]
                                           : line;
          for (size_t x = 0; x < len; ++x) {
            int32_t best = dist[start + x * stride];
            for (size_t r = 1; int32_t(r) < best; ++r) {
              if (x >= r) best = std::min(best, std::max(int32_t(r), dist[start + (x - r) * stride]));
              if (x + r < len) best = std::min(best, std::max(int32_t(r), dist[start + (x + r) * stride]));
            }
            next[start + x * stride] = best;
          }
        },
        64);
    dist.swap(next);
  }
  for (int32_t& d : dist) d = -d;  // the zeros (bricks with a block) are all set below
  int32_t blocks = 0;
  // Block indices follow the allocated bricks' order (the order the blocks are filled in).
  for (size_t b = 0; b < f.BrickCount(); ++b)
    if (f.occupancy[b] != 0) {
      const size_t n = (size_t(f.brick_coords[3 * b + 2]) * dims[1] + size_t(f.brick_coords[3 * b + 1])) * dims[0] +
                       size_t(f.brick_coords[3 * b]);
      dist[n] = blocks++;
    }
  return dist;
}

}  // namespace

void NerfField::UpdateRenderCopy() {
  using C = NerfRenderCopy;
  constexpr int kVertices = C::kSide * C::kSide * C::kSide;
  ClearRenderCopy();
  if (empty() || occupancy.size() != BrickCount() || brick_coords.size() != 3 * BrickCount() ||
      density.size() != BrickCount() * kNerfBrickSlots || color.size() != density.size() * kNerfColorCoeffs ||
      brick_table.size() != size_t(bricks[0]) * size_t(bricks[1]) * size_t(bricks[2]))
    return;
  C c;
  std::vector<int32_t> bricks_of_block;
  for (size_t b = 0; b < BrickCount(); ++b)
    if (occupancy[b] != 0) {
      bricks_of_block.push_back(int32_t(b));
      c.occupancy.push_back(occupancy[b]);
    }
  const size_t blocks = bricks_of_block.size();
  c.entry = CopyEntries(*this);
  c.bytes.assign(std::max<size_t>(blocks, 1) * C::kBlockBytes + 64, 0);
  c.first = (64 - reinterpret_cast<uintptr_t>(c.bytes.data()) % 64) % 64;
  ParallelFor(
      blocks,
      [&](size_t block) {
        const int32_t b = bricks_of_block[block];
        const int bx = brick_coords[3 * size_t(b)] * 4, by = brick_coords[3 * size_t(b) + 1] * 4,
                  bz = brick_coords[3 * size_t(b) + 2] * 4;
        float values[kVertices][C::kLanes];
        for (int k = 0; k < C::kSide; ++k)
          for (int j = 0; j < C::kSide; ++j)
            for (int i = 0; i < C::kSide; ++i)
              VertexLanes(*this, bx + i, by + j, bz + k, values[(k * C::kSide + j) * C::kSide + i]);
        uint8_t* out = c.bytes.data() + c.first + block * C::kBlockBytes;
        float scale[C::kLanes] = {}, offset[C::kLanes] = {}, inv[C::kLanes] = {};
        for (int m = 0; m < C::kLanes; ++m) {
          if (m == 7 || m == 11 || m == 15) continue;  // the density's high byte; unused
          float lo = values[0][m], hi = lo;
          for (int v = 1; v < kVertices; ++v) lo = std::min(lo, values[v][m]), hi = std::max(hi, values[v][m]);
          const float levels = m == 3 ? 65535.0f : 255.0f;
          offset[m] = lo;
          scale[m] = (hi - lo) / levels;
          inv[m] = scale[m] > 0.0f ? 1.0f / scale[m] : 0.0f;
        }
        for (int v = 0; v < kVertices; ++v) {
          uint8_t* q = out + C::kHeaderBytes + size_t(v) * C::kLanes;
          for (int m = 0; m < C::kLanes; ++m) {
            if (m == 7 || m == 11 || m == 15) continue;
            const long code = std::lrint((values[v][m] - offset[m]) * inv[m]);
            if (m == 3) {
              const long d = std::clamp(code, 0L, 65535L);
              q[3] = uint8_t(d & 255), q[7] = uint8_t(d >> 8);
            } else {
              q[m] = uint8_t(std::clamp(code, 0L, 255L));
            }
          }
        }
        scale[7] = 256.0f * scale[3];  // d = d_lo + 256·d_hi
        std::memcpy(out, scale, sizeof(scale));
        std::memcpy(out + sizeof(scale), offset, sizeof(offset));
      },
      64);
  c.density_source = density.data(), c.density_size = density.size();
  c.color_source = color.data(), c.color_size = color.size();
  c.occupancy_source = occupancy.data(), c.occupancy_size = occupancy.size();
  c.table_source = brick_table.data(), c.table_size = brick_table.size();
  render_copy = std::move(c);
}

double NerfField::OccupiedFraction() const {
  size_t bits = 0;
  for (uint64_t o : occupancy) bits += size_t(__builtin_popcountll(o));
  const double cells = double(res[0] - 1) * (res[1] - 1) * (res[2] - 1);
  return cells > 0 ? double(bits) / cells : 0.0;
}

std::vector<std::string> NerfField::Validate() const {
  std::vector<std::string> problems;
  auto add = [&](const std::string& s) { problems.push_back(s); };
  if (!(voxel_m > 0) || !std::isfinite(voxel_m)) add("voxel size " + std::to_string(voxel_m) + " (expected > 0)");
  for (int a = 0; a < 3; ++a) {
    if (res[a] < 2 || res[a] > 8192) add("resolution " + std::to_string(res[a]) + " (expected 2..8192)");
    if (bricks[a] != (res[a] + 3) / 4) add("brick table size does not match the resolution");
    if (!std::isfinite(aabb.min[a]) || !std::isfinite(aabb.max[a]) || !(aabb.max[a] > aabb.min[a]))
      add("aabb is empty or not finite");
  }
  if (!std::all_of(capture_centres.begin(), capture_centres.end(), Finite<float>))
    add("a capture camera's centre is not finite");
  if (!problems.empty()) return problems;
  const size_t table = size_t(bricks[0]) * bricks[1] * bricks[2];
  const size_t n = BrickCount();
  if (brick_table.size() != table)
    add("brick table has " + std::to_string(brick_table.size()) + " entries (expected " + std::to_string(table) + ")");
  if (brick_coords.size() % 3 != 0) add("brick coordinates are not triples");
  if (density.size() != n * kNerfBrickSlots) add("density array size does not match the brick count");
  if (color.size() != n * kNerfBrickSlots * kNerfColorCoeffs) add("colour array size does not match the brick count");
  if (occupancy.size() != n) add("occupancy size does not match the brick count");
  if (!problems.empty()) return problems;
  for (size_t b = 0; b < n; ++b) {
    const int bx = brick_coords[3 * b], by = brick_coords[3 * b + 1], bz = brick_coords[3 * b + 2];
    if (bx < 0 || by < 0 || bz < 0 || bx >= bricks[0] || by >= bricks[1] || bz >= bricks[2] ||
        brick_table[(size_t(bz) * bricks[1] + by) * bricks[0] + bx] != int32_t(b)) {
      add("brick " + std::to_string(b) + " has coordinates that disagree with the brick table");
      break;
    }
  }
  size_t referenced = 0;
  for (int32_t e : brick_table) {
    if (e >= int64_t(n) || e < -1) {
      add("brick table entry " + std::to_string(e) + " out of range");
      break;
    }
    referenced += e >= 0;
  }
  if (referenced != n)
    add("brick table references " + std::to_string(referenced) + " bricks (expected " + std::to_string(n) + ")");
  for (float v : density)
    if (!std::isfinite(v)) {
      add("density holds a non-finite value");
      break;
    }
  for (float v : color)
    if (!std::isfinite(v)) {
      add("colour holds a non-finite value");
      break;
    }
  return problems;
}

float NerfField::Density(const Vec3f& p) const {
  Corners c;
  if (empty() || !nerf_detail::LocateGrid(*this, ToGrid(p), c)) return 0.0f;
  return std::exp(nerf_detail::RawDensity(*this, c));
}

Vec3f NerfField::Radiance(const Vec3f& p, const Vec3f& dir) const {
  Corners c;
  if (empty() || !nerf_detail::LocateGrid(*this, ToGrid(p), c)) return {};
  float q[kNerfColorCoeffs];
  nerf_detail::ColorCoeffs(*this, c, q);
  return nerf_detail::ColorFromCoeffs(q, dir);
}

Vec3f NerfField::DensityGradient(const Vec3f& p) const {
  Corners c;
  const Vec3f g = ToGrid(p);
  if (empty() || !nerf_detail::LocateGrid(*this, g, c)) return {};
  const float sigma = std::exp(nerf_detail::RawDensity(*this, c));
  // ∂s/∂g from the trilinear form: differences of the corner values along each axis.
  const int i = std::min(int(g.x), res[0] - 2), j = std::min(int(g.y), res[1] - 2), k = std::min(int(g.z), res[2] - 2);
  const float fr[3] = {g.x - float(i), g.y - float(j), g.z - float(k)};
  float v[8];
  for (int n = 0; n < 8; ++n) v[n] = c.slot[n] >= 0 ? density[c.slot[n]] : kNerfEmptyDensityRaw;
  float grad[3] = {0, 0, 0};
  for (int n = 0; n < 8; ++n) {
    const int bit[3] = {n & 1, (n >> 1) & 1, n >> 2};
    for (int a = 0; a < 3; ++a) {
      float w = bit[a] ? 1.0f : -1.0f;
      for (int o = 0; o < 3; ++o)
        if (o != a) w *= bit[o] ? fr[o] : 1.0f - fr[o];
      grad[a] += w * v[n];
    }
  }
  const float scale = sigma / voxel_m;  // ∇σ = σ ∇s, and ∂g/∂p = 1/h
  return {grad[0] * scale, grad[1] * scale, grad[2] * scale};
}

void NerfField::QueryDensity(const Vec3f* points, size_t count, float* sigma) const {
  ParallelFor(
      count, [&](size_t n) { sigma[n] = Density(points[n]); }, 4096);
}

void NerfField::QueryRadiance(const Vec3f* points, const Vec3f* dirs, size_t count, Vec3f* radiance) const {
  ParallelFor(
      count, [&](size_t n) { radiance[n] = Radiance(points[n], dirs[n]); }, 2048);
}

void NerfField::QueryDensityGradient(const Vec3f* points, size_t count, Vec3f* gradient) const {
  ParallelFor(
      count, [&](size_t n) { gradient[n] = DensityGradient(points[n]); }, 2048);
}

namespace {

// The render marcher's view of the cell it is in: corner raw log-densities and,
// once a sample there needs colour, the corners' log radiance in the ray's
// direction (a + b·d per channel; linear in the coefficients, so interpolating
// it equals interpolating the coefficients first).
struct RenderCell {
  int i = -1, j = -1, k = -1;
  int32_t slot[8];
  float s[8] = {};
  bool has_color = false;
  float log_color[3][8];

  // Cell (ci,cj,ck), whose own brick has index brick >= 0.
  void Load(const NerfField& f, int ci, int cj, int ck, int32_t brick) {
    i = ci, j = cj, k = ck;
    nerf_detail::CellSlotsInBrick(f, ci, cj, ck, brick, slot);
    for (int n = 0; n < 8; ++n) s[n] = slot[n] >= 0 ? f.density[slot[n]] : kNerfEmptyDensityRaw;
    has_color = false;
  }
  void LoadColor(const NerfField& f, const Vec3f& d) {
    for (int n = 0; n < 8; ++n) {
      if (slot[n] < 0) {
        log_color[0][n] = log_color[1][n] = log_color[2][n] = 0.0f;
        continue;
      }
      const float* q = &f.color[size_t(slot[n]) * kNerfColorCoeffs];
      for (int ch = 0; ch < 3; ++ch)
        log_color[ch][n] = q[4 * ch] + q[4 * ch + 1] * d.x + q[4 * ch + 2] * d.y + q[4 * ch + 3] * d.z;
    }
    has_color = true;
  }
};

// Asks for the cache line holding p. On x86 an instruction the compiler keeps: GCC 12 at -O3 removed
// __builtin_prefetch from the render loop (its dead-code pass; measured: none of the copy's
// prefetches were in the built renderer, those of the float arrays only with -fPIC).
inline void Prefetch(const void* p) {
#if defined(__x86_64__) || defined(__i386__)
  asm volatile("prefetcht0 %0" : : "m"(*static_cast<const char*>(p)));
#else
  __builtin_prefetch(p);
#endif
}

// Asks the memory system for the data of the cell holding grid point g (the
// ray's next sample), so that its loads overlap the current sample's arithmetic:
// the render is bound by the latency of these loads (measured: 150-350 ns per
// cell on the shared VM, a few cache misses each).
inline void PrefetchCell(const NerfField& f, const Vec3f& g) {
  if (!(g.x >= 0.0f && g.y >= 0.0f && g.z >= 0.0f)) return;
  const int i = std::min(int(g.x), f.res[0] - 2), j = std::min(int(g.y), f.res[1] - 2),
            k = std::min(int(g.z), f.res[2] - 2);
  const int32_t s = f.Slot(i, j, k);
  if (s < 0) return;
  Prefetch(&f.density[size_t(s)]);
  for (int n : {0, 4, 16, 20}) {  // corner rows (y, z); x and x+1 are adjacent (96 bytes of colour)
    if (size_t(s) + size_t(n) + 1 >= f.SlotCount()) break;
    const float* c = &f.color[(size_t(s) + size_t(n)) * kNerfColorCoeffs];
    Prefetch(c);
    Prefetch(c + 2 * kNerfColorCoeffs - 1);
  }
}

// PrefetchCell for the render copy: the 4 corner rows (2 vertices, 32 bytes each) of the cell holding g.
inline void PrefetchCopyCell(const NerfField& f, const Vec3f& g) {
  if (!(g.x >= 0.0f && g.y >= 0.0f && g.z >= 0.0f)) return;
  const int i = std::min(int(g.x), f.res[0] - 2), j = std::min(int(g.y), f.res[1] - 2),
            k = std::min(int(g.z), f.res[2] - 2);
  const int32_t block =
      f.render_copy.entry[(size_t(k >> 2) * f.bricks[1] + size_t(j >> 2)) * f.bricks[0] + size_t(i >> 2)];
  if (block < 0) return;
  const uint8_t* v = f.render_copy.Vertex(block, i & 3, j & 3, k & 3);
  constexpr int L = NerfRenderCopy::kLanes, S = NerfRenderCopy::kSide;
  Prefetch(f.render_copy.Header(block));
  for (int row : {0, S, S * S, S * S + S}) {
    Prefetch(v + row * L);
    Prefetch(v + row * L + 2 * L - 1);
  }
}

// Trilinear interpolation of corner values v (corner n at offsets n&1, n>>1&1, n>>2).
inline float Trilinear(const float v[8], float fx, float fy, float fz) {
  const float x00 = v[0] + fx * (v[1] - v[0]), x10 = v[2] + fx * (v[3] - v[2]);
  const float x01 = v[4] + fx * (v[5] - v[4]), x11 = v[6] + fx * (v[7] - v[6]);
  const float y0 = x00 + fy * (x10 - x00), y1 = x01 + fy * (x11 - x01);
  return y0 + fz * (y1 - y0);
}

// With a current skip grid, the sample intervals [n, n_end) of a ray that may reach an occupied
// cell: the ray clipped to the occupied cells' box. False when it misses the box.
inline bool ClipToOccupiedCells(const NerfSkipGrid& skip, const nerf_detail::RaySteps& steps, float step, int64_t& n,
                                int64_t& n_end) {
  // The occupied cells span grid coordinates [lo, hi + 1]; grown by one cell so that samples
  // which rounding puts just outside the grid (and At() clamps into it) are kept.
  const float t0 = steps.t0;
  float ta = t0, tb = steps.t1;
  for (int a = 0; a < 3; ++a) {
    const float lo = float(skip.lo[a] - 1), hi = float(skip.hi[a] + 2);
    if (steps.d[a] == 0.0f) {
      if (!(steps.o[a] >= lo && steps.o[a] <= hi)) return false;
      continue;
    }
    float ea = (lo - steps.o[a]) * steps.inv_d[a], eb = (hi - steps.o[a]) * steps.inv_d[a];
    if (ea > eb) std::swap(ea, eb);
    ta = std::max(ta, ea);
    tb = std::min(tb, eb);
  }
  if (!(tb >= ta)) return false;
  // Sample n lies at t0 + (n + 0.5)·step: keep one interval of margin on each side.
  const float first = std::floor((ta - t0) / step - 0.5f) - 1.0f, last = std::ceil((tb - t0) / step) + 1.0f;
  if (first > 0.0f) n = first < float(n_end) ? int64_t(first) : n_end;
  if (last < float(n_end)) n_end = int64_t(last);
  return true;
}

// The brick the march is in, once it is known to hold occupied cells: its block in the render
// copy, else its index in the float arrays, and its cells' occupancy bits.
struct MarchBrick {
  int bi = -1, bj = -1, bk = -1;
  int32_t index = -1;
  uint64_t cells = 0;

  bool Holds(const nerf_detail::RaySteps::Sample& s) const {
    return (s.i >> 2) == bi && (s.j >> 2) == bj && (s.k >> 2) == bk;
  }
  bool CellOccupied(const nerf_detail::RaySteps::Sample& s) const {
    return (cells >> (((s.k & 3) * 4 + (s.j & 3)) * 4 + (s.i & 3))) & 1u;
  }
  // Enters the brick of sample s (interval n); false where the brick is empty, with n moved to
  // the next interval beyond it. From the copy: one entry, a block or the distance to the nearest
  // one (the empty cube of bricks around this one is jumped). From the float arrays: an occupied
  // brick is entered without the coarse levels' tests, an empty one is jumped with the largest
  // empty block of the skip grid holding the sample (at least the brick).
  bool Enter(const NerfField& f, bool use_copy, bool coarse, const nerf_detail::RaySteps& steps, int64_t& n,
             const nerf_detail::RaySteps::Sample& s) {
    const size_t at = (size_t(s.k >> 2) * f.bricks[1] + size_t(s.j >> 2)) * f.bricks[0] + size_t(s.i >> 2);
    if (use_copy) {
      const int32_t e = f.render_copy.entry[at];
      if (e < 0) {
        n = steps.SkipBricks(n, -e, s);
        return false;
      }
      index = e;
      cells = f.render_copy.occupancy[size_t(e)];
    } else {
      const int32_t b = f.brick_table[at];
      if (b < 0 || f.occupancy[b] == 0) {
        int empty_shift = 2;
        if (coarse)
          for (const NerfSkipGrid::Level& level : f.skip.levels)
            if (level.shift > 2 && !level.Occupied(s.i, s.j, s.k)) {
              empty_shift = level.shift;
              break;
            }
        n = steps.SkipBlock(n, empty_shift, s);
        return false;
      }
      index = b;
      cells = f.occupancy[b];
    }
    bi = s.i >> 2, bj = s.j >> 2, bk = s.k >> 2;
    return true;
  }
};

// Front-to-back compositing of a ray's samples into colour, opacity and depths.
class RayCompositor {
 public:
  // level: the transmittance at which the surface's depth is taken (NerfRenderOptions::surface_transmittance).
  explicit RayCompositor(float level) : level_(level) {}
  // Adds the sample at t (middle of an interval dt) of opacity alpha and radiance rgb; false once
  // the transmittance falls below min_transmittance (the ray is done).
  bool Add(float t, float dt, float sigma, float alpha, const float rgb[3], float min_transmittance,
           NerfRayResult& result) {
    const float w = transmittance_ * alpha;
    for (int ch = 0; ch < 3; ++ch) result.color[ch] += w * rgb[ch];
    depth_sum_ += w * t;
    const float next = transmittance_ * (1.0f - alpha);
    if (transmittance_ > level_ && next <= level_) {
      // T(x) = T exp(-σ x) inside the interval (sample at its middle): T(x) = level at x = ln(T/level)/σ.
      const float x = std::min(std::log(transmittance_ / level_) / sigma, dt);
      result.surface_depth = t - 0.5f * dt + x;
    }
    transmittance_ = next;
    return !(transmittance_ < min_transmittance);
  }
  // Opacity, mean depth and, where the ray never crossed the level, the mean depth as the surface's.
  void Finish(NerfRayResult& result) const {
    result.opacity = 1.0f - transmittance_;
    result.depth = result.opacity > 0.0f ? depth_sum_ / result.opacity : 0.0f;
    if (!(result.opacity >= 1.0f - level_) || result.surface_depth == 0.0f) result.surface_depth = result.depth;
  }

 private:
  float level_;
  float transmittance_ = 1.0f, depth_sum_ = 0.0f;
};

}  // namespace

// The samples are those of nerf_detail::MarchRay (interval n's at t_near + (n + 0.5)·step, empty
// bricks and cells jumped over), evaluated with the cell's corners loaded once per cell. With a
// current skip grid the ray is first clipped to the occupied cells' box and empty blocks of 16 and
// 8 cells are jumped whole; with a current render copy an empty brick is left by jumping the cube of
// bricks its distance entry proves empty instead. The samples are the same (only empty space is jumped).
NerfRayResult NerfField::RenderRay(const NerfRay& ray, const NerfRenderOptions& options) const {
  NerfRayResult result;
  if (!(ray.t_far > ray.t_near) || empty()) return result;
  const float step = options.step_voxels * voxel_m;
  const nerf_detail::RaySteps steps(*this, ray, step, 0.5f);
  const bool coarse = SkipGridCurrent();
  int64_t n = 0, n_end = steps.count;
  if (coarse && !ClipToOccupiedCells(skip, steps, step, n, n_end)) return result;
  // Whether one step is longer than a cell's diagonal (sqrt 3 voxels; 1.8 leaves 4 % for rounding):
  // then consecutive samples never share a cell.
  const bool steps_leave_cells = options.step_voxels >= 1.8f;
  // With a current render copy every cell is read from it (every brick with an occupied cell has a block).
  const bool use_copy = options.use_render_copy && RenderCopyCurrent();
  MarchBrick brick;
  RayCompositor compositor(options.surface_transmittance);
  // The occupied cell of the current sample: its corners from the float arrays, or (copy_v0 set)
  // the lanes of its corner 0 in the render copy's block, seen from this ray through copy_block.
  // Locals, not a class: held in one, GCC no longer vectorised CopyBlock::Set (measured with
  // callgrind: 8 % more instructions at live quality).
  RenderCell cell;
  const nerf_detail::CopyRay copy_ray(ray.dir);
  nerf_detail::CopyBlock copy_block;
  int32_t copy_block_index = -1;  // the block copy_block was set for
  const uint8_t* copy_v0 = nullptr;
  nerf_detail::RaySteps::Sample s;
  while (n < n_end) {
    if (!steps.At(n, s)) break;
    if (s.i != cell.i || s.j != cell.j || s.k != cell.k) {
      if (!brick.Holds(s) && !brick.Enter(*this, use_copy, coarse, steps, n, s)) continue;
      if (!brick.CellOccupied(s)) {
        // An empty cell. With steps longer than a cell's diagonal the next sample lies outside it, so
        // SkipBlock(n, 0, s) returns n + 1 (but where At() clamped a sample outside the grid into the
        // cell): taken directly. The samples are the same either way: n + 1 is never beyond the
        // block's exit, and a sample visited is tested for occupancy like any other.
        n = steps_leave_cells ? n + 1 : steps.SkipBlock(n, 0, s);
        continue;
      }
      if (use_copy) {
        cell.i = s.i, cell.j = s.j, cell.k = s.k;
        if (brick.index != copy_block_index)
          copy_block.Set(render_copy.Header(brick.index), copy_ray), copy_block_index = brick.index;
        copy_v0 = render_copy.Vertex(brick.index, s.i & 3, s.j & 3, s.k & 3);
      } else {
        cell.Load(*this, s.i, s.j, s.k, brick.index);
      }
    }
    ++n;
    ++result.samples;
    if (options.prefetch) {
      if (use_copy)
        PrefetchCopyCell(*this, steps.Grid(s.t + step));
      else
        PrefetchCell(*this, steps.Grid(s.t + step));
    }
    const float fx = s.g.x - float(s.i), fy = s.g.y - float(s.j), fz = s.g.z - float(s.k);
    // Radiance (r, g, b) and σ: from the copy all four at once (one 4-wide exp), else from the floats.
    float value[4];
    if (copy_v0 != nullptr) {
      nerf_detail::CopyCellValues(copy_block, copy_v0, fx, fy, fz, value);
      for (int ch = 0; ch < 3; ++ch) value[ch] = std::clamp(value[ch], kNerfLogColorMin, kNerfLogColorMax);
      value[3] = std::clamp(value[3], kNerfDensityRawMin, kNerfDensityRawMax);
      nerf_detail::Exp4(value);
    } else {
      value[3] = std::exp(Trilinear(cell.s, fx, fy, fz));
    }
    const float alpha = nerf_detail::OneMinusExpNeg(value[3] * s.dt);
    if (alpha < options.min_alpha) continue;
    ++result.color_samples;
    if (copy_v0 == nullptr) {
      if (!cell.has_color) cell.LoadColor(*this, ray.dir);
      for (int ch = 0; ch < 3; ++ch)
        value[ch] = std::exp(std::clamp(Trilinear(cell.log_color[ch], fx, fy, fz), kNerfLogColorMin, kNerfLogColorMax));
    }
    if (!compositor.Add(s.t, s.dt, value[3], alpha, value, options.min_transmittance, result)) break;
  }
  compositor.Finish(result);
  return result;
}

void NerfField::RenderRays(const NerfRay* rays, size_t count, NerfRayResult* results,
                           const NerfRenderOptions& options) const {
  ParallelFor(
      count, [&](size_t n) { results[n] = RenderRay(rays[n], options); }, 256);
}

bool IntersectAabb(const Aabb& box, const Vec3f& origin, const Vec3f& dir, float& t_near, float& t_far) {
  float t0 = 0.0f, t1 = 3.0e38f;
  for (int a = 0; a < 3; ++a) {
    const float lo = float(box.min[a]), hi = float(box.max[a]);
    if (dir[a] == 0.0f) {
      if (origin[a] < lo || origin[a] > hi) return false;
      continue;
    }
    const float inv = 1.0f / dir[a];
    float ta = (lo - origin[a]) * inv, tb = (hi - origin[a]) * inv;
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  if (!(t1 > t0)) return false;
  t_near = t0;
  t_far = t1;
  return true;
}

namespace {

// The ray through pixel (x, y)'s centre, clipped to the aabb (an empty range when it misses).
NerfRay PixelRay(const CameraIntrinsics& camera, const Pose& T_world_camera, const Aabb& aabb, int x, int y) {
  Vec3 dir_c;
  if (camera.HasDistortion()) {
    dir_c = Unproject(camera, {x + 0.5, y + 0.5});
  } else {
    dir_c = Normalized(Vec3((x + 0.5 - camera.cx) / camera.fx, (y + 0.5 - camera.cy) / camera.fy, 1.0));
  }
  NerfRay r;
  r.origin = Vec3f(T_world_camera.translation);
  r.dir = Vec3f(T_world_camera.Rotate(dir_c));
  if (!IntersectAabb(aabb, r.origin, r.dir, r.t_near, r.t_far)) r.t_near = r.t_far = 0.0f;
  return r;
}

}  // namespace

std::vector<NerfRay> CameraRays(const CameraIntrinsics& camera, const Pose& T_world_camera, const Aabb& aabb) {
  const int w = camera.width, h = camera.height;
  std::vector<NerfRay> rays(size_t(w) * h);
  ParallelFor(
      size_t(h),
      [&](size_t y) {
        for (int x = 0; x < w; ++x) rays[y * w + x] = PixelRay(camera, T_world_camera, aabb, x, int(y));
      },
      8);
  return rays;
}

std::vector<NerfRay> PointRays(const Vec3f& origin, const std::vector<Vec3f>& dirs, const Aabb& aabb) {
  std::vector<NerfRay> rays(dirs.size());
  for (size_t n = 0; n < dirs.size(); ++n) {
    NerfRay& r = rays[n];
    r.origin = origin;
    r.dir = dirs[n];
    if (!IntersectAabb(aabb, r.origin, r.dir, r.t_near, r.t_far)) r.t_near = r.t_far = 0.0f;
  }
  return rays;
}

NerfImages RenderView(const NerfField& field, const CameraIntrinsics& camera, const Pose& T_world_camera,
                      const NerfRenderOptions& options) {
  const int w = camera.width, h = camera.height;
  NerfImages out{ImageF(w, h, 3), ImageF(w, h, 1), ImageF(w, h, 1), ImageF(w, h, 1)};
  const Vec3f forward(T_world_camera.rotation.Column(2));
  // Square tiles of pixels, so that the rays a thread marches one after another share bricks in the cache.
  constexpr int kTile = 8;
  const int tiles_x = (w + kTile - 1) / kTile, tiles_y = (h + kTile - 1) / kTile;
  ParallelFor(
      size_t(tiles_x) * size_t(tiles_y),
      [&](size_t tile) {
        const int x0 = int(tile % size_t(tiles_x)) * kTile, y0 = int(tile / size_t(tiles_x)) * kTile;
        for (int y = y0; y < std::min(y0 + kTile, h); ++y)
          for (int x = x0; x < std::min(x0 + kTile, w); ++x) {
            const NerfRay ray = PixelRay(camera, T_world_camera, field.aabb, x, y);
            const NerfRayResult r = field.RenderRay(ray, options);
            const size_t n = size_t(y) * size_t(w) + size_t(x);
            out.color.pixels[3 * n] = r.color.x;
            out.color.pixels[3 * n + 1] = r.color.y;
            out.color.pixels[3 * n + 2] = r.color.z;
            out.opacity.pixels[n] = r.opacity;
            const float axial = Dot(ray.dir, forward);
            out.depth.pixels[n] = r.opacity > 0.0f ? r.depth * axial : 0.0f;
            out.surface_depth.pixels[n] = r.opacity > 0.0f ? r.surface_depth * axial : 0.0f;
          }
      },
      4);
  return out;
}

}  // namespace nerfar
