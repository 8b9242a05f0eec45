// The HDR radiance field: a sparse explicit voxel grid over the dataset's aabb.
// Each grid vertex holds a raw log-density s (σ = exp(s), 1/m) and a log-linear
// colour per channel, log L_c(d) = a_c + b_c·d (d the unit ray direction, world
// frame), so radiance is positive and spans 1e-6..1e5 without saturating. Both
// are interpolated trilinearly and then exponentiated. Vertices come in bricks
// of 4x4x4; unallocated bricks are empty space. A per-cell occupancy bitfield
// (cell occupied when any corner's σ exceeds the threshold) lets rays skip
// empty bricks and cells; the trained grid is the query form (no baking).
// Distances in metres, world frame (z up); radiance linear HDR RGB.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "calib/camera.h"
#include "calib/core/image.h"
#include "calib/core/math.h"
#include "calib/dataset.h"

namespace nerfar {

inline constexpr int kNerfBrickSide = 4;                                                  // vertices per brick side
inline constexpr int kNerfBrickSlots = kNerfBrickSide * kNerfBrickSide * kNerfBrickSide;  // 64
inline constexpr int kNerfColorCoeffs = 12;  // per vertex: 3 channels x (a, bx, by, bz)
// Largest brick table a reader allocates from a file's stated grid (512 MB; a 2.5 mm grid over a
// 5 m cube needs 2^27): a corrupt resolution fails instead of allocating tens of gigabytes.
inline constexpr size_t kNerfMaxBrickTable = size_t{1} << 27;
// Raw log-density of vertices in unallocated bricks (σ ≈ 1e-13 / m).
inline constexpr float kNerfEmptyDensityRaw = -30.0f;
// Raw values are clamped to these ranges by the trainer and the file reader.
inline constexpr float kNerfDensityRawMin = -30.0f, kNerfDensityRawMax = 14.0f;  // σ up to 1.2e6 / m
// Raw log-density given to vertices that pruning empties (σ ≈ 1e-3 / m): below
// any occupancy threshold, yet close enough that a vertex beside a surface can
// grow back within a few dozen Adam steps.
inline constexpr float kNerfPrunedDensityRaw = -7.0f;
inline constexpr float kNerfLogColorMin = -20.0f, kNerfLogColorMax = 14.0f;  // radiance 2e-9 .. 1.2e6

// A ray x(t) = origin + t·dir (dir unit) integrated over [t_near, t_far].
struct NerfRay {
  Vec3f origin;
  Vec3f dir;
  float t_near = 0, t_far = 0;
};

// Volume rendering of one ray (paper §3): colour C = Σ T_k α_k c_k, opacity
// O = Σ T_k α_k, depth = Σ T_k α_k t_k / O (the expected termination distance
// along the ray, 0 when O = 0; the paper's unnormalised D is O·depth).
// surface_depth is where the transmittance falls to 0.5 (the median of the
// termination distribution: a fog or a thick surface in front moves it far
// less than the mean; NerfRenderOptions::surface_transmittance picks another
// level); where the ray's transmittance stays above that level it is the
// expected depth (0 when O = 0).
struct NerfRayResult {
  Vec3f color;
  float opacity = 0;
  float depth = 0;
  float surface_depth = 0;
  // Cost: density samples taken along the ray, and how many of them also evaluated colour.
  uint32_t samples = 0, color_samples = 0;
};

struct NerfRenderOptions {
  // Sample spacing along rays in voxels; smaller is more accurate and slower.
  float step_voxels = 0.5f;
  // A ray stops once its transmittance falls below this (the rest counts as opaque).
  float min_transmittance = 1e-3f;
  // Samples with α below this skip the colour evaluation (their colour weight is negligible).
  float min_alpha = 1e-5f;
  // The transmittance at which NerfRayResult::surface_depth is taken (0.5: the termination's median).
  float surface_transmittance = 0.5f;
  // Prefetch the next sample's cell while evaluating this one (same result; speed only).
  bool prefetch = true;
  // Read the field's compact render copy where one is current (NerfField::UpdateRenderCopy): values
  // quantised per brick (log colour to 8 bits, log-density to 16; see NerfRenderCopy), fewer bytes
  // and instructions per sample. false: always the exact float arrays. Without a current copy this does nothing.
  bool use_render_copy = true;

  // Named settings. "full": the defaults above. "live" (interactive previews and per-frame
  // insertion): 2-voxel steps, rays stop at transmittance 3e-2 - about 4.5x fewer samples per
  // ray, with psnr_tm within 0.05 dB and surface depth within 0.1 mm of "full" on the shared
  // scenes' balanced models (docs/BENCHMARKS.md); a ray's opacity is then at most 0.97.
  // "preview" (small interactive views): 3-voxel steps, stop at 3e-2 - a third fewer samples than
  // live, at a cost: psnr_tm 0.1-0.3 dB below full, surface depth +0.1 mm.
  // Throws InputError for any other name.
  static NerfRenderOptions Preset(const std::string& name);
  // Every problem as "field: what is wrong (expected ...)"; empty when valid.
  std::vector<std::string> Validate() const;
};

// Coarse occupancy for empty-space skipping, derived from NerfField::occupancy
// by NerfField::UpdateSkipGrid(): one bit per block of 2^shift cells per side,
// set when any cell of the block is occupied, at shifts 2 (a brick), 3 and 4
// (16 cells), and the bounding box of the occupied cells. The renderer tests
// the coarsest level first and jumps a whole empty block at once; rays are
// clipped to the bounding box. The samples taken are exactly those of the
// brick-and-cell skipping alone (only empty blocks are jumped).
struct NerfSkipGrid {
  struct Level {
    int shift = 0;                              // block side 2^shift cells
    int dims[3] = {0, 0, 0};                    // blocks per axis
    std::vector<uint64_t> bits;                 // bit (z*dims[1]+y)*dims[0]+x, x fastest
    bool Occupied(int i, int j, int k) const {  // cell (i,j,k) inside the grid
      const size_t n =
          (size_t(k >> shift) * size_t(dims[1]) + size_t(j >> shift)) * size_t(dims[0]) + size_t(i >> shift);
      return (bits[n >> 6] >> (n & 63)) & 1u;
    }
  };
  std::vector<Level> levels;  // coarsest first; empty: not built (the renderer skips bricks and cells only)
  int lo[3] = {0, 0, 0}, hi[3] = {-1, -1, -1};  // occupied cells' bounding box, inclusive (lo > hi: none)
  // The occupancy array it was built from (data pointer and size): a copied or
  // reallocated field does not match and renders without the coarse levels.
  const uint64_t* source = nullptr;
  size_t source_size = 0;
};

// A compact copy of the field for the renderer, built by NerfField::UpdateRenderCopy(): every brick
// that holds an occupied cell (the only ones a ray samples) as a block of 5x5x5 vertices - its own
// 4 per side and the first of the next brick - so that the 8 corners of any of its cells lie in the
// block. A vertex is 16 bytes: the colour coefficients as 8-bit codes over the block's range of
// each (a_r a_g a_b, bx_r bx_g bx_b, by_r ..., bz_r ...) and the raw log-density as a 16-bit code
// over the block's range, lane order [a_r a_g a_b d_lo | bx_r bx_g bx_b d_hi | by_r by_g by_b 0 |
// bz_r bz_g bz_b 0]. Value = code·scale + offset (scale and offset per block and lane, in the
// block's 128-byte header; the density's high byte has scale 256·scale), so |error| <= scale/2:
// colour range/510 (the file stores bases at 8 bits per brick too), density range/131070.
// Each block is 2176 bytes (34 cache lines, aligned): 0.6x the float arrays' bytes per vertex.
// For empty-space skipping the copy keeps, per position of the field's brick table, either the
// brick's block or the Chebyshev distance (in bricks) to the nearest brick that has one: a ray in
// an empty brick jumps the whole cube of bricks around it that the distance proves empty (one
// look-up, where the skip grid's aligned levels need one per level and jump less).
struct NerfRenderCopy {
  static constexpr int kSide = 5;           // vertices per block side
  static constexpr int kLanes = 16;         // bytes (8-bit lanes) per vertex
  static constexpr int kHeaderBytes = 128;  // float scale[16], offset[16]
  static constexpr int kBlockBytes = 2176;  // header + 125 vertices, padded to 64 bytes
  static constexpr int kMaxDistance = 64;   // distances are capped here (a cap only shortens jumps)
  // Per brick-table position (x fastest, as NerfField::brick_table): the block index (>= 0) of a
  // brick with an occupied cell, else -D with 1 <= D <= kMaxDistance: every brick (bx', by', bz')
  // with max(|bx' - bx|, |by' - by|, |bz' - bz|) < D has no block (positions outside the table have none).
  std::vector<int32_t> entry;
  std::vector<uint64_t> occupancy;  // per block: its brick's occupancy bits (NerfField::occupancy)
  std::vector<uint8_t> bytes;       // the blocks, block b at first + b * kBlockBytes
  size_t first = 0;                 // 64-byte aligned offset of block 0 in `bytes`
  // The arrays it was built from (data pointers and sizes): a field whose arrays were replaced or
  // resized renders from its float arrays instead.
  const float* density_source = nullptr;
  const float* color_source = nullptr;
  const uint64_t* occupancy_source = nullptr;
  const int32_t* table_source = nullptr;
  size_t density_size = 0, color_size = 0, occupancy_size = 0, table_size = 0;
  // Block b's scale[16] followed by offset[16].
  const float* Header(int32_t b) const {
    return reinterpret_cast<const float*>(bytes.data() + first + size_t(b) * kBlockBytes);
  }
  // Lanes of block b's vertex (i, j, k), 0 <= i, j, k < 5.
  const uint8_t* Vertex(int32_t b, int i, int j, int k) const {
    return bytes.data() + first + size_t(b) * kBlockBytes + kHeaderBytes + size_t((k * kSide + j) * kSide + i) * kLanes;
  }
};

// The grid and its storage layout (public: the trainer and the file reader fill it).
class NerfField {
 public:
  NerfField() = default;
  // A grid over `aabb` with cubic voxels of side voxel_m and every brick
  // allocated, each vertex set to the given raw density and log colour.
  static NerfField Dense(const Aabb& aabb, double voxel_m, float density_raw, const Vec3f& log_color);

  // --- layout
  Aabb aabb;                          // the box rays are clipped to (metres, world)
  Vec3f origin;                       // world position of vertex (0,0,0) (= aabb.min)
  float voxel_m = 0;                  // vertex spacing
  int res[3] = {0, 0, 0};             // vertices per axis (covers the aabb)
  int bricks[3] = {0, 0, 0};          // brick table size: ceil(res / 4)
  float occupancy_sigma = 0;          // σ threshold (1/m) of the occupancy bitfield
  std::vector<int32_t> brick_table;   // bricks[0]*bricks[1]*bricks[2] (x fastest): -1 or brick index
  std::vector<int32_t> brick_coords;  // 3 per allocated brick
  std::vector<float> density;         // raw log-density, 64 per brick (slot = brick*64 + (k*4+j)*4+i)
  std::vector<float> color;           // 12 per slot
  std::vector<uint64_t> occupancy;    // per brick: bit (k*4+j)*4+i for the cell at local vertex (i,j,k)
  // Derived from `occupancy` by UpdateSkipGrid() (UpdateOccupancy, Dense and the file reader call it);
  // code that edits `occupancy` in place calls UpdateSkipGrid() afterwards.
  NerfSkipGrid skip;
  // Derived from density, colour and occupancy by UpdateRenderCopy() (no one builds it by default:
  // call it on a field that will not change, e.g. after loading). UpdateSkipGrid() (so also
  // UpdateOccupancy) drops it; code that edits density or colour in place calls UpdateRenderCopy()
  // again or ClearRenderCopy(), or the renderer reads the old values.
  NerfRenderCopy render_copy;

  // --- the capture
  // Where the cameras the field was learnt from stood (world, in the capture's
  // order; NerfTrainer::FinalField fills it). The NeRF's radiance is right
  // towards these, so the light's seen radiance looks from them
  // (render/lighting/seen_radiance.h). Empty when unknown (a synthetic field,
  // a model saved before they were stored).
  std::vector<Vec3f> capture_centres;

  size_t BrickCount() const { return brick_coords.size() / 3; }
  size_t SlotCount() const { return density.size(); }
  bool empty() const { return density.empty(); }
  // Slot of vertex (i,j,k), or -1 when outside the grid or unallocated.
  int32_t Slot(int i, int j, int k) const;
  // Allocates a brick (zero-filled is not done: density kNerfEmptyDensityRaw, colour 0) and returns its index.
  int32_t AllocateBrick(int bx, int by, int bz);
  // Recomputes the occupancy bitfield: a cell is occupied when σ at any of its corners > sigma_threshold.
  void UpdateOccupancy(float sigma_threshold);
  // Rebuilds `skip` from `occupancy`.
  void UpdateSkipGrid();
  // Whether `skip` was built from the current `occupancy` array (same data pointer and size).
  bool SkipGridCurrent() const {
    return !skip.levels.empty() && skip.source == occupancy.data() && skip.source_size == occupancy.size();
  }
  // Builds `render_copy` from the current density, colour and occupancy (parallel; ~0.1 s per 10^5 bricks).
  void UpdateRenderCopy();
  void ClearRenderCopy() { render_copy = NerfRenderCopy{}; }
  // Whether `render_copy` was built from the current arrays (same data pointers and sizes).
  bool RenderCopyCurrent() const {
    const NerfRenderCopy& c = render_copy;
    return !c.bytes.empty() && c.density_source == density.data() && c.density_size == density.size() &&
           c.color_source == color.data() && c.color_size == color.size() && c.occupancy_source == occupancy.data() &&
           c.occupancy_size == occupancy.size() && c.table_source == brick_table.data() &&
           c.table_size == brick_table.size() && c.entry.size() == brick_table.size();
  }
  // Fraction of the grid's cells that are occupied.
  double OccupiedFraction() const;
  // Every problem with the layout (sizes, indices, finiteness); empty when consistent.
  std::vector<std::string> Validate() const;

  // --- point queries (single point; the batched forms below run them in parallel)
  float Density(const Vec3f& p) const;                     // σ(p), 1/m; 0 outside the grid
  Vec3f Radiance(const Vec3f& p, const Vec3f& dir) const;  // c(p, d), dir unit; 0 outside the grid
  Vec3f DensityGradient(const Vec3f& p) const;             // ∇σ (normals: -∇σ/|∇σ|); 0 outside

  // --- batched, multi-threaded queries (results do not depend on the thread count)
  void QueryDensity(const Vec3f* points, size_t count, float* sigma) const;
  void QueryRadiance(const Vec3f* points, const Vec3f* dirs, size_t count, Vec3f* radiance) const;
  void QueryDensityGradient(const Vec3f* points, size_t count, Vec3f* gradient) const;

  // --- volume rendering
  NerfRayResult RenderRay(const NerfRay& ray, const NerfRenderOptions& options = {}) const;
  void RenderRays(const NerfRay* rays, size_t count, NerfRayResult* results,
                  const NerfRenderOptions& options = {}) const;

  // Grid coordinates (units of voxels from the origin) of a world point.
  Vec3f ToGrid(const Vec3f& p) const { return (p - origin) * (1.0f / voxel_m); }
};

// [t_near, t_far] of a ray against a box; false (range untouched) if it misses
// or the box lies behind the origin. t_near >= 0.
bool IntersectAabb(const Aabb& box, const Vec3f& origin, const Vec3f& dir, float& t_near, float& t_far);

// The compositing rule (paper §4.4): a ray whose pixel shows a virtual object
// at distance d integrates over [min(d, t_n), min(d, t_f)].
inline void ClipRayToDepth(NerfRay& ray, float d) {
  ray.t_near = ray.t_near < d ? ray.t_near : d;
  ray.t_far = ray.t_far < d ? ray.t_far : d;
}

// Camera rays through pixel centres (row-major, width*height), clipped to the
// aabb (rays that miss get an empty range t_near = t_far = 0).
std::vector<NerfRay> CameraRays(const CameraIntrinsics& camera, const Pose& T_world_camera, const Aabb& aabb);
// Rays leaving `origin` in the given unit directions, clipped to the aabb.
std::vector<NerfRay> PointRays(const Vec3f& origin, const std::vector<Vec3f>& dirs, const Aabb& aabb);

// A rendered view: colour (RGB), opacity (1 channel) and depth along the
// camera's viewing axis (1 channel, metres; 0 where opacity is 0), the
// convention of the scenes' depth maps.
// surface_depth (1 channel) is NerfRayResult::surface_depth along the viewing axis.
struct NerfImages {
  ImageF color, opacity, depth, surface_depth;
};
NerfImages RenderView(const NerfField& field, const CameraIntrinsics& camera, const Pose& T_world_camera,
                      const NerfRenderOptions& options = {});

}  // namespace nerfar
