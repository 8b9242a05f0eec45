// Tests of the NeRF renderer's compact render copy (NerfRenderCopy, NerfField::UpdateRenderCopy):
// its values against the exact float field within the quantisation bound, rendering from it against
// the plain float march and against an analytic slab, that a changed field never renders stale
// copy data, the 4-wide exp against std::exp, and the renderer's march (empty-space skipping, from the
// float arrays and from the copy's brick distances) against a brute-force march that visits every interval.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "calib/core/error.h"
#include "render/nerf/nerf_field.h"
#include "render/nerf/nerf_internal.h"

namespace nerfar {
namespace {

// Where vertex slot v of brick b lies, in metres from the field's origin.
Vec3f SlotOffset(const NerfField& f, size_t b, int v) {
  return Vec3f(float(f.brick_coords[3 * b] * 4 + (v & 3)), float(f.brick_coords[3 * b + 1] * 4 + (v >> 2 & 3)),
               float(f.brick_coords[3 * b + 2] * 4 + (v >> 4))) *
         f.voxel_m;
}

// Ranges of the random test field: raw log-density in [-3, 5], colour bases in [-2, 2], slopes in
// [-0.5, 0.5]. A block at the grid's far faces also holds vertices outside the grid (density -30),
// so a block's density range is at most 35 and its colour ranges at most 4 (bases) and 1 (slopes).
constexpr float kDensityLo = -3.0f, kDensityHi = 5.0f, kBaseRange = 2.0f, kSlopeRange = 0.5f;
constexpr float kBlockDensityRange = kDensityHi - kNerfEmptyDensityRaw;

// A 1 m box at voxel 0.1 m (11 vertices and 3 bricks per axis: bricks cut cells and the last brick is
// partial), every vertex random, every cell occupied.
NerfField RandomField(uint32_t seed) {
  NerfField f = NerfField::Dense({Vec3(0, 0, 0), Vec3(1, 1, 1)}, 0.1, 0.0f, Vec3f(0, 0, 0));
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> density(kDensityLo, kDensityHi), base(-kBaseRange, kBaseRange),
      slope(-kSlopeRange, kSlopeRange);
  for (float& d : f.density) d = density(rng);
  for (size_t n = 0; n < f.color.size(); ++n) f.color[n] = n % 4 == 0 ? base(rng) : slope(rng);
  f.UpdateOccupancy(1e-6f);
  return f;
}

Vec3f RandomDirection(std::mt19937& rng) {
  std::normal_distribution<float> g;
  for (;;) {
    const Vec3f d(g(rng), g(rng), g(rng));
    if (Length(d) > 1e-3f) return Normalized(d);
  }
}

// Rays from outside the box through random points of it, clipped to the box.
std::vector<NerfRay> RandomRays(const NerfField& f, size_t count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.05f, 0.95f);
  std::vector<NerfRay> rays;
  while (rays.size() < count) {
    const Vec3f target(u(rng), u(rng), u(rng)), dir = RandomDirection(rng);
    NerfRay r;
    r.origin = target - dir * 2.0f;
    r.dir = dir;
    if (IntersectAabb(f.aabb, r.origin, r.dir, r.t_near, r.t_far)) rays.push_back(r);
  }
  return rays;
}

NerfRenderOptions FloatArrays(NerfRenderOptions o = {}) {
  o.use_render_copy = false;
  return o;
}

TEST(NerfRenderCopy, ValuesLieWithinTheQuantisationBoundOfTheExactField) {
  NerfField f = RandomField(1);
  f.UpdateRenderCopy();
  ASSERT_TRUE(f.RenderCopyCurrent());
  std::mt19937 rng(2);
  std::uniform_real_distribution<float> u(0.0f, 10.0f);  // grid coordinates over the whole grid
  double max_density_error = 0, max_color_error = 0;
  for (int n = 0; n < 20000; ++n) {
    const Vec3f g(u(rng), u(rng), u(rng)), dir = RandomDirection(rng);
    nerf_detail::Corners c;
    ASSERT_TRUE(nerf_detail::LocateGrid(f, g, c));
    float q[kNerfColorCoeffs];
    nerf_detail::ColorCoeffs(f, c, q);
    float raw = 0, log_color[3];
    ASSERT_TRUE(nerf_detail::CopyPointValues(f, g, dir, raw, log_color));
    // Each vertex value is off by at most half a step: range/131070 for the density (16 bits),
    // range/510 for each colour coefficient (8 bits); trilinear weights sum to 1, so the
    // interpolated log colour a + b·d is off by at most (base range + slope range·(|dx|+|dy|+|dz|))/510.
    // 1e-5: float rounding of the sums (values of magnitude <= 35).
    const double density_bound = kBlockDensityRange / 131070.0 + 1e-5;
    const double color_bound =
        (2 * kBaseRange + 2 * kSlopeRange * (std::abs(dir.x) + std::abs(dir.y) + std::abs(dir.z))) / 510.0 + 1e-5;
    const double density_error = std::abs(raw - nerf_detail::RawDensity(f, c));
    EXPECT_LE(density_error, density_bound) << "at " << g.x << " " << g.y << " " << g.z;
    max_density_error = std::max(max_density_error, density_error);
    for (int ch = 0; ch < 3; ++ch) {
      const float* a = q + 4 * ch;
      const double exact = a[0] + a[1] * dir.x + a[2] * dir.y + a[3] * dir.z;
      const double error = std::abs(log_color[ch] - exact);
      EXPECT_LE(error, color_bound) << "channel " << ch;
      max_color_error = std::max(max_color_error, error);
    }
  }
  // The copy is a quantisation, not a copy of the floats: errors exist but stay below the bounds.
  EXPECT_GT(max_color_error, 1e-4);
  EXPECT_GT(max_density_error, 1e-7);
}

TEST(NerfRenderCopy, RendersLikeThePlainFloatMarch) {
  NerfField f = RandomField(3);
  // Faint random fog (σ = e^-9 .. e^-1 / m) around a dense random ball (e^-1 .. e^7 within 0.3 m of the
  // centre), so that rays end in all states: clear, half and opaque.
  for (size_t b = 0; b < f.BrickCount(); ++b)
    for (int v = 0; v < kNerfBrickSlots; ++v) {
      const Vec3f p = SlotOffset(f, b, v);
      f.density[b * kNerfBrickSlots + size_t(v)] += Length(p - Vec3f(0.5f, 0.5f, 0.5f)) < 0.3f ? 2.0f : -6.0f;
    }
  f.UpdateOccupancy(1e-6f);
  f.UpdateRenderCopy();
  const std::vector<NerfRay> rays = RandomRays(f, 3000, 4);
  for (const char* quality : {"full", "live"}) {
    const NerfRenderOptions o = NerfRenderOptions::Preset(quality);
    int opaque = 0, clear = 0;
    for (const NerfRay& ray : rays) {
      const NerfRayResult a = f.RenderRay(ray, o), b = f.RenderRay(ray, FloatArrays(o));
      // The same samples are taken (the copy changes values, not the march).
      ASSERT_EQ(a.samples, b.samples);
      // Log colour off by <= 1.5e-2 (bound of the test above at |d|_1 <= sqrt 3) -> radiance by <= 1.6 %;
      // log-density off by <= 3.5e-4 (range now <= 43) -> each α by <= 0.04 %, so weights (and opacity) move by < 0.1 %
      // of their sum. 2 % relative (+1e-6 absolute for dark rays) holds both.
      for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(a.color[ch], b.color[ch], 0.02f * b.color[ch] + 1e-6f) << quality;
      EXPECT_NEAR(a.opacity, b.opacity, 1e-3f) << quality;
      // Depths: the termination distribution moves by < 0.1 % of its weight; over a ray of at most
      // sqrt(3) m that is < 2 mm, and far less in practice.
      EXPECT_NEAR(a.depth, b.depth, 2e-3f) << quality;
      EXPECT_NEAR(a.surface_depth, b.surface_depth, 2e-3f) << quality;
      opaque += b.opacity > 0.9f;
      clear += b.opacity < 0.1f;
    }
    EXPECT_GT(opaque, 50) << "the test rays include opaque ones";
    EXPECT_GT(clear, 50) << "and nearly transparent ones";
    std::printf("%s: %d opaque, %d clear of %zu rays\n", quality, opaque, clear, rays.size());
  }
}

TEST(NerfRenderCopy, ConstantSlabIsAnalytic) {
  // A constant field is exact in the copy (each lane's range is empty: scale 0, offset = the value),
  // except the far faces' blocks, whose out-of-grid vertices are never a corner of a grid cell.
  const float sigma = 3.0f;
  NerfField f = NerfField::Dense({Vec3(0, 0, 0), Vec3(1, 1, 1)}, 0.05, std::log(sigma), Vec3f(0.5f, -1.0f, 2.0f));
  f.UpdateOccupancy(1e-3f);
  f.UpdateRenderCopy();
  ASSERT_TRUE(f.RenderCopyCurrent());
  for (float length : {0.1f, 0.37f, 0.8f}) {
    NerfRay r;
    r.origin = Vec3f(-1.0f, 0.3f, 0.6f);
    r.dir = Vec3f(1.0f, 0.0f, 0.0f);
    r.t_near = 1.1f;
    r.t_far = 1.1f + length;
    const NerfRayResult res = f.RenderRay(r, {});
    // Opacity 1 - exp(-σL); colour exp(log_c)·opacity. 1e-4: the density's 16-bit step in the far
    // blocks (range 30 + ln 3 over 65535 levels -> 2.5e-4 in log σ) and float sums over <= 32 samples.
    const float opacity = 1.0f - std::exp(-sigma * length);
    EXPECT_NEAR(res.opacity, opacity, 1e-4f) << length;
    EXPECT_NEAR(res.color.x, std::exp(0.5f) * opacity, 2e-4f) << length;
    EXPECT_NEAR(res.color.y, std::exp(-1.0f) * opacity, 1e-4f) << length;
    EXPECT_NEAR(res.color.z, std::exp(2.0f) * opacity, 1e-3f) << length;
  }
}

// Renders every ray both ways and returns whether all results are bit-identical.
bool SameAsFloatArrays(const NerfField& f, const std::vector<NerfRay>& rays) {
  for (const NerfRay& ray : rays) {
    const NerfRayResult a = f.RenderRay(ray, {}), b = f.RenderRay(ray, FloatArrays());
    if (a.color.x != b.color.x || a.color.y != b.color.y || a.color.z != b.color.z || a.opacity != b.opacity ||
        a.depth != b.depth || a.surface_depth != b.surface_depth)
      return false;
  }
  return true;
}

TEST(NerfRenderCopy, AChangedFieldNeverRendersStaleCopyData) {
  NerfField f = RandomField(5);
  const std::vector<NerfRay> rays = RandomRays(f, 300, 6);
  EXPECT_TRUE(SameAsFloatArrays(f, rays)) << "no copy until UpdateRenderCopy";
  f.UpdateRenderCopy();
  ASSERT_TRUE(f.RenderCopyCurrent());
  ASSERT_FALSE(SameAsFloatArrays(f, rays)) << "the copy is read (it quantises)";

  // A copied field owns new arrays: it renders from its floats, also after edits.
  NerfField g = f;
  EXPECT_FALSE(g.RenderCopyCurrent());
  for (float& c : g.color) c += 0.25f;
  EXPECT_TRUE(SameAsFloatArrays(g, rays));

  // Re-thresholding the occupancy (in place, same array) drops the copy.
  NerfField h = f;
  h.UpdateRenderCopy();
  ASSERT_TRUE(h.RenderCopyCurrent());
  h.UpdateOccupancy(0.5f);
  EXPECT_FALSE(h.RenderCopyCurrent());
  EXPECT_TRUE(SameAsFloatArrays(h, rays));

  // A new brick resizes the arrays: the copy no longer matches.
  NerfField grown = NerfField::Dense({Vec3(0, 0, 0), Vec3(1, 1, 1)}, 0.1, 0.0f, Vec3f(0, 0, 0));
  std::fill(grown.brick_table.begin(), grown.brick_table.end(), -1);  // no bricks: start again sparse
  grown.brick_coords.clear(), grown.density.clear(), grown.color.clear(), grown.occupancy.clear();
  grown.AllocateBrick(1, 1, 1);
  grown.occupancy[0] = ~uint64_t{0};
  grown.UpdateSkipGrid();
  grown.UpdateRenderCopy();
  ASSERT_TRUE(grown.RenderCopyCurrent());
  const size_t before = grown.density.size();
  grown.AllocateBrick(0, 0, 0);
  ASSERT_NE(grown.density.size(), before);
  EXPECT_FALSE(grown.RenderCopyCurrent());

  // An in-place edit followed by UpdateRenderCopy (the documented rule) renders the new values: the
  // colour bases +1 multiply radiance by e, within the copy's 2 % of the float march.
  for (size_t n = 0; n < f.color.size(); n += 4) f.color[n] += 1.0f;
  f.UpdateRenderCopy();
  for (const NerfRay& ray : rays) {
    const NerfRayResult a = f.RenderRay(ray, {}), b = f.RenderRay(ray, FloatArrays());
    for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(a.color[ch], b.color[ch], 0.02f * b.color[ch] + 1e-6f);
  }
  // And ClearRenderCopy returns to the floats.
  f.ClearRenderCopy();
  EXPECT_TRUE(SameAsFloatArrays(f, rays));
}

TEST(NerfRenderCopy, RenderViewUsesTheCopyAndMatchesTheFloatArrays) {
  NerfField f = RandomField(7);
  for (float& d : f.density) d -= 1.0f;
  f.UpdateOccupancy(1e-6f);
  f.UpdateRenderCopy();
  CameraIntrinsics camera;
  camera.width = 40, camera.height = 30, camera.fx = camera.fy = 40, camera.cx = 20, camera.cy = 15;
  const Pose pose = LookAt({2.0, -1.5, 1.2}, {0.5, 0.5, 0.5});
  const NerfImages a = RenderView(f, camera, pose, {}), b = RenderView(f, camera, pose, FloatArrays());
  size_t differ = 0;
  for (size_t n = 0; n < a.color.pixels.size(); ++n) {
    EXPECT_NEAR(a.color.pixels[n], b.color.pixels[n], 0.02f * b.color.pixels[n] + 1e-6f);  // as per ray above
    differ += a.color.pixels[n] != b.color.pixels[n];
  }
  EXPECT_GT(differ, 0u) << "RenderView reads the copy";
  for (size_t n = 0; n < a.opacity.pixels.size(); ++n) EXPECT_NEAR(a.opacity.pixels[n], b.opacity.pixels[n], 1e-3f);
}

// A 3 m box at voxel 0.1 m (30 cells, 8 bricks per axis) of sparse occupancy: blobs of random density
// (cells occupied one by one inside them), empty cells inside occupied bricks, empty bricks and empty
// blocks of 8 and 16 cells between them.
constexpr float kBlobs[3][3] = {{0.7f, 0.8f, 0.6f}, {2.2f, 1.9f, 2.3f}, {1.6f, 0.5f, 2.4f}};
NerfField SparseField(uint32_t seed) {
  NerfField f = NerfField::Dense({Vec3(0, 0, 0), Vec3(3, 3, 3)}, 0.1, 0.0f, Vec3f(0, 0, 0));
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f), raw(0.0f, 4.0f);
  for (size_t b = 0; b < f.BrickCount(); ++b)
    for (int v = 0; v < kNerfBrickSlots; ++v) {
      const Vec3f p = SlotOffset(f, b, v);
      bool in_blob = false;
      for (const auto& c : kBlobs) in_blob |= Length(p - Vec3f(c[0], c[1], c[2])) < 0.45f;
      // Outside blobs σ = e^-9 (below the threshold); inside, one vertex in 4 dense (σ 1 .. 55 / m).
      f.density[b * kNerfBrickSlots + size_t(v)] = in_blob && u(rng) < 0.25f ? raw(rng) : -9.0f;
    }
  f.UpdateOccupancy(1e-2f);
  return f;
}

// Opacity, mean depth and sample count of a ray by brute force: every interval of RaySteps visited
// (no empty-space skipping), the sample kept when its cell is occupied, no early stop - what RenderRay
// takes with min_alpha = 0 and min_transmittance = 0, and what MarchRay visits.
struct PlainMarch {
  double opacity = 0.0, depth = 0.0;
  int64_t samples = 0;
};
PlainMarch MarchPlain(const NerfField& f, const NerfRay& ray, float step_voxels) {
  PlainMarch m;
  double transmittance = 1.0, depth_sum = 0.0;
  const nerf_detail::RaySteps steps(f, ray, step_voxels * f.voxel_m, 0.5f);
  nerf_detail::RaySteps::Sample s;
  nerf_detail::Corners c;
  for (int64_t n = 0; n < steps.count && steps.At(n, s); ++n) {
    if (nerf_detail::CellState(f, s.i, s.j, s.k) != 2) continue;
    EXPECT_TRUE(nerf_detail::LocateGrid(f, s.g, c));
    const double alpha = -std::expm1(-double(std::exp(nerf_detail::RawDensity(f, c))) * s.dt);
    depth_sum += transmittance * alpha * s.t;
    transmittance *= 1.0 - alpha;
    ++m.samples;
  }
  m.opacity = 1.0 - transmittance;
  m.depth = m.opacity > 0.0 ? depth_sum / m.opacity : 0.0;
  return m;
}

TEST(NerfRenderMarch, TakesThePlainMarchsSamples) {
  NerfField f = SparseField(11);
  // The field has all kinds of space: occupied cells, empty cells in occupied bricks, empty bricks.
  size_t occupied_bricks = 0, empty_cells_in_occupied = 0;
  for (const uint64_t bits : f.occupancy)
    if (bits != 0) ++occupied_bricks, empty_cells_in_occupied += 64 - size_t(__builtin_popcountll(bits));
  ASSERT_GT(occupied_bricks, 20u);
  ASSERT_LT(occupied_bricks, f.BrickCount() / 3);
  ASSERT_GT(empty_cells_in_occupied, 500u);
  std::mt19937 rng(12);
  std::uniform_real_distribution<float> u(0.0f, 3.0f);
  std::vector<NerfRay> rays;
  // Rays from random points towards random points near a blob's centre, starting and stopping at
  // random points (inside blocks; a quarter stop before the aim), and diagonal rays through brick
  // corners (0.4 m apart), which cross brick and cell faces at their edges and corners.
  std::uniform_real_distribution<float> jitter(-0.3f, 0.3f);
  for (int n = 0; n < 1500; ++n) {
    NerfRay r;
    r.origin = Vec3f(u(rng), u(rng), u(rng));
    const float* c = kBlobs[n % 3];
    const Vec3f aim = Vec3f(c[0] + jitter(rng), c[1] + jitter(rng), c[2] + jitter(rng));
    const float dist = Length(aim - r.origin);
    if (dist < 0.1f) continue;
    r.dir = (aim - r.origin) * (1.0f / dist);
    float t_near = 0.0f, t_far = 0.0f;
    if (!IntersectAabb(f.aabb, r.origin, r.dir, t_near, t_far)) continue;
    r.t_near = std::uniform_real_distribution<float>(0.0f, 0.5f * dist)(rng);
    r.t_far = n % 4 == 0 ? std::uniform_real_distribution<float>(r.t_near, dist)(rng)
                         : std::uniform_real_distribution<float>(dist, std::max(dist, t_far))(rng);
    rays.push_back(r);
  }
  for (int a = 0; a <= 7; ++a)
    for (int sx : {-1, 1})
      for (int sy : {-1, 1}) {
        NerfRay r;
        r.origin = Vec3f(0.4f * float(a), sx > 0 ? 0.0f : 2.8f, 0.4f * float(7 - a)) + Vec3f(0, 0, 0.1f * float(sy));
        r.dir = Normalized(Vec3f(1.0f, float(sx), float(sy)));
        if (IntersectAabb(f.aabb, r.origin, r.dir, r.t_near, r.t_far)) rays.push_back(r);
      }
  ASSERT_GT(rays.size(), 1000u);
  NerfField no_skip_grid = f;  // a copy: its skip grid is not current, so no coarse levels
  ASSERT_FALSE(no_skip_grid.SkipGridCurrent());
  ASSERT_TRUE(f.SkipGridCurrent());
  // Steps below and above a cell's diagonal (sqrt 3 voxels), and the live and preview spacings.
  for (const float step : {0.5f, 1.0f, 1.7f, 1.8f, 2.0f, 3.0f}) {
    NerfRenderOptions o = NerfRenderOptions::Preset("live");
    o.step_voxels = step, o.min_alpha = 0.0f, o.min_transmittance = 0.0f;
    int64_t total = 0;
    int dense = 0;
    for (const NerfRay& ray : rays) {
      const PlainMarch want = MarchPlain(f, ray, step);
      for (const NerfField* field : {&f, &no_skip_grid}) {
        const NerfRayResult got = field->RenderRay(ray, FloatArrays(o));
        ASSERT_EQ(got.samples, want.samples) << "step " << step;
        int64_t marched = 0;  // the trainer's march (MarchRay) visits the same samples
        nerf_detail::MarchRay(*field, ray, step * f.voxel_m, 0.5f,
                              [&](float, float, const nerf_detail::Corners&) { return ++marched, true; });
        ASSERT_EQ(marched, want.samples) << "step " << step;
        // Float sums and products over <= ~500 samples against double ones (relative error up to
        // ~500 x 6e-8 = 3e-5), and trilinear forms that differ by rounding (~1e-6 relative in log σ):
        // 1e-5 in opacity, 1e-4 of the depth (+1e-5 m) where the opacity is > 0.1 (the renderer's
        // opacity 1 - T in float loses 6e-8 / opacity relative, which the mean depth divides by).
        EXPECT_NEAR(got.opacity, want.opacity, 1e-5) << "step " << step;
        if (want.opacity > 0.1) {
          EXPECT_NEAR(got.depth, want.depth, 1e-4 * want.depth + 1e-5) << "step " << step;
        }
      }
      total += want.samples;
      dense += want.opacity > 0.5;
    }
    EXPECT_GT(total, int64_t(rays.size())) << "the rays sample occupied cells";
    EXPECT_GT(dense, 10) << "and some are mostly opaque";
  }
}

// A 28.8 m box at voxel 0.1 m (288 cells, 73 bricks per axis: more than NerfRenderCopy::kMaxDistance)
// holding only a few allocated bricks near one corner, so that most of the brick table is empty space
// whose distance to the nearest block runs from 1 to beyond the cap.
NerfField LargeSparseField(uint32_t seed) {
  NerfField f;
  f.aabb = {Vec3(0, 0, 0), Vec3(28.8, 28.8, 28.8)};
  f.origin = Vec3f(0, 0, 0);
  f.voxel_m = 0.1f;
  for (int a = 0; a < 3; ++a) f.res[a] = 289, f.bricks[a] = (f.res[a] + 3) / 4;
  f.brick_table.assign(size_t(f.bricks[0]) * f.bricks[1] * f.bricks[2], -1);
  for (int z = 1; z <= 3; ++z)
    for (int y = 2; y <= 3; ++y)
      for (int x = 1; x <= 4; ++x) f.AllocateBrick(x, y, z);
  f.AllocateBrick(8, 6, 9);
  f.AllocateBrick(9, 6, 9);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f), raw(-1.0f, 3.0f);
  // One vertex in 3 dense (σ e^-1 .. e^3 / m), the rest below the threshold: empty cells in occupied bricks.
  for (float& d : f.density) d = u(rng) < 0.33f ? raw(rng) : -9.0f;
  f.UpdateOccupancy(1e-2f);
  return f;
}

// Chebyshev distance in bricks from brick (x, y, z) to the nearest brick with an occupied cell,
// against every such brick (1 << 20 when there is none).
int BruteForceBrickDistance(const NerfField& f, int x, int y, int z) {
  int best = 1 << 20;
  for (size_t b = 0; b < f.BrickCount(); ++b)
    if (f.occupancy[b] != 0)
      best = std::min(best, std::max({std::abs(f.brick_coords[3 * b] - x), std::abs(f.brick_coords[3 * b + 1] - y),
                                      std::abs(f.brick_coords[3 * b + 2] - z)}));
  return best;
}

// The copy's per-brick entries against brute force: every brick with an occupied cell has its own
// block (with the brick's occupancy bits), every other position the capped distance to the nearest one.
void ExpectEntriesMatchBruteForce(const NerfField& f) {
  ASSERT_TRUE(f.RenderCopyCurrent());
  const NerfRenderCopy& c = f.render_copy;
  std::vector<int> seen(c.occupancy.size(), 0);
  int capped = 0, far = 0;
  for (int z = 0; z < f.bricks[2]; ++z)
    for (int y = 0; y < f.bricks[1]; ++y)
      for (int x = 0; x < f.bricks[0]; ++x) {
        const size_t n = (size_t(z) * f.bricks[1] + size_t(y)) * f.bricks[0] + size_t(x);
        const int32_t b = f.brick_table[n], e = c.entry[n];
        if (b >= 0 && f.occupancy[size_t(b)] != 0) {
          ASSERT_GE(e, 0);
          ASSERT_LT(size_t(e), c.occupancy.size());
          EXPECT_EQ(c.occupancy[size_t(e)], f.occupancy[size_t(b)]);
          ++seen[size_t(e)];
        } else {
          const int want = std::min(BruteForceBrickDistance(f, x, y, z), NerfRenderCopy::kMaxDistance);
          ASSERT_EQ(-e, want) << "brick " << x << " " << y << " " << z;
          capped += want == NerfRenderCopy::kMaxDistance;
          far += want >= 3;
        }
      }
  for (const int count : seen) EXPECT_EQ(count, 1) << "each block belongs to one brick";
  std::printf("entries: %zu blocks, %d positions at distance >= 3, %d capped\n", c.occupancy.size(), far, capped);
}

TEST(NerfRenderMarch, CopyEntriesAreTheBrickDistances) {
  const NerfField small = [] {
    NerfField f = SparseField(11);
    f.UpdateRenderCopy();
    return f;
  }();
  ExpectEntriesMatchBruteForce(small);
  NerfField large = LargeSparseField(21);
  large.UpdateRenderCopy();
  ExpectEntriesMatchBruteForce(large);
  // The large field reaches the cap (73 bricks per axis, blocks only near one corner).
  EXPECT_EQ(*std::min_element(large.render_copy.entry.begin(), large.render_copy.entry.end()),
            -NerfRenderCopy::kMaxDistance);
}

// Rays that stress a march over bricks (0.4 m here): diagonal rays through brick corners, rays
// along brick faces and edges (a direction component 0 with the origin exactly on a brick plane, or
// off it by 1e-4 rad), rays starting and stopping inside bricks, and random rays towards `aims`.
std::vector<NerfRay> BrickTraversalRays(const NerfField& f, const std::vector<Vec3f>& aims, uint32_t seed) {
  std::mt19937 rng(seed);
  const Vec3f size = Vec3f(f.aabb.max - f.aabb.min);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<NerfRay> rays;
  auto add = [&](const Vec3f& origin, const Vec3f& dir, bool clip_inside) {
    NerfRay r;
    r.origin = origin;
    r.dir = Normalized(dir);
    if (!IntersectAabb(f.aabb, r.origin, r.dir, r.t_near, r.t_far)) return;
    if (clip_inside) {  // [t_near, t_far] cut at random points, both ends inside the box (often inside a brick)
      const float a = r.t_near + u(rng) * (r.t_far - r.t_near), b = r.t_near + u(rng) * (r.t_far - r.t_near);
      r.t_near = std::min(a, b), r.t_far = std::max(a, b);
      if (!(r.t_far > r.t_near)) return;
    }
    rays.push_back(r);
  };
  const int bricks = f.bricks[0];
  std::uniform_int_distribution<int> brick(0, bricks - 1);
  const float side = 4.0f * f.voxel_m;  // a brick's side
  for (int n = 0; n < 300; ++n) {
    // Through a brick corner along a cube diagonal (crossing brick and cell corners on the way).
    const Vec3f corner = Vec3f(float(brick(rng)), float(brick(rng)), float(brick(rng))) * side;
    const Vec3f diagonal(n & 1 ? 1.0f : -1.0f, n & 2 ? 1.0f : -1.0f, n & 4 ? 1.0f : -1.0f);
    add(corner - diagonal * (2.0f * size.x), diagonal, n % 3 == 0);
    // Along a face (one coordinate on a brick plane, direction component 0) or an edge (two), or just
    // off them.
    const int axis = n % 3;
    Vec3f origin(u(rng) * size.x, u(rng) * size.y, u(rng) * size.z), dir = RandomDirection(rng);
    origin[axis] = float(brick(rng)) * side;
    dir[axis] = n % 4 == 3 ? 1e-4f : 0.0f;
    if (n % 2 == 0) {
      const int second = (axis + 1) % 3;
      origin[second] = float(brick(rng)) * side;
      dir[second] = 0.0f;
    }
    add(origin - Normalized(dir) * (2.0f * size.x), dir, n % 5 == 0);
    // Towards an aim from a random point, starting inside the box, half of them clipped inside.
    const Vec3f from(u(rng) * size.x, u(rng) * size.y, u(rng) * size.z);
    const Vec3f aim = aims[size_t(n) % aims.size()] + Vec3f(u(rng) - 0.5f, u(rng) - 0.5f, u(rng) - 0.5f) * side;
    if (Length(aim - from) > 1e-3f) add(from, aim - from, n % 2 == 0);
  }
  return rays;
}

TEST(NerfRenderMarch, CopyDistanceJumpsTakeThePlainMarchsSamples) {
  NerfField small = SparseField(11), large = LargeSparseField(21);
  std::vector<Vec3f> small_aims, large_aims = {Vec3f(1.0f, 1.0f, 0.9f), Vec3f(3.6f, 2.6f, 3.8f)};
  for (const auto& c : kBlobs) small_aims.push_back(Vec3f(c[0], c[1], c[2]));
  for (NerfField* f : {&small, &large}) {
    f->UpdateRenderCopy();
    ASSERT_TRUE(f->RenderCopyCurrent());
    const std::vector<NerfRay> rays = BrickTraversalRays(*f, f == &small ? small_aims : large_aims, 31);
    ASSERT_GT(rays.size(), 600u);
    for (const float step : {0.5f, 2.0f, 3.0f}) {
      NerfRenderOptions o = NerfRenderOptions::Preset("live");
      o.step_voxels = step, o.min_alpha = 0.0f, o.min_transmittance = 0.0f;
      int64_t total = 0;
      int sampled = 0;
      for (const NerfRay& ray : rays) {
        const PlainMarch want = MarchPlain(*f, ray, step);
        const NerfRayResult got = f->RenderRay(ray, o);
        ASSERT_EQ(got.samples, want.samples) << "step " << step;
        // The copy's values: log-density within range/131070 of the floats (range <= 39 here: -30 at
        // vertices outside the grid or unallocated, up to 3 or 4), so each σ within 3e-4 relative and
        // the opacity within 3e-4 · max(τ e^-τ) < 1.2e-4; plus float rounding (1e-5, as above).
        EXPECT_NEAR(got.opacity, want.opacity, 1.3e-4) << "step " << step;
        total += want.samples;
        sampled += want.samples > 0;
      }
      EXPECT_GT(sampled, int(rays.size()) / 10) << "a tenth of the rays or more meet occupied cells";
      std::printf("%s field, step %.1f: %zu rays, %d sample occupied cells, %lld samples\n",
                  f == &small ? "small" : "large", step, rays.size(), sampled, static_cast<long long>(total));
    }
  }
}

TEST(NerfRenderOptions, NamedSettingsAreValidAndOrderedBySpacing) {
  const NerfRenderOptions full = NerfRenderOptions::Preset("full"), live = NerfRenderOptions::Preset("live"),
                          preview = NerfRenderOptions::Preset("preview");
  for (const NerfRenderOptions& o : {full, live, preview}) EXPECT_TRUE(o.Validate().empty());
  EXPECT_LT(full.step_voxels, live.step_voxels);
  EXPECT_LT(live.step_voxels, preview.step_voxels);
  EXPECT_THROW(NerfRenderOptions::Preset("fastest"), InputError);
  // A preview march takes fewer samples than a live one along the same rays.
  NerfField f = RandomField(9);
  f.UpdateRenderCopy();
  size_t live_samples = 0, preview_samples = 0;
  for (const NerfRay& ray : RandomRays(f, 200, 10))
    live_samples += f.RenderRay(ray, live).samples, preview_samples += f.RenderRay(ray, preview).samples;
  EXPECT_LT(preview_samples, live_samples);
}

TEST(NerfRenderCopy, Exp4MatchesStdExp) {
  std::mt19937 rng(8);
  std::uniform_real_distribution<float> u(-80.0f, 80.0f);
  double worst = 0;
  for (int n = 0; n < 100000; ++n) {
    float v[4];
    for (float& x : v) x = u(rng);
    const float in[4] = {v[0], v[1], v[2], v[3]};
    nerf_detail::Exp4(v);
    for (int m = 0; m < 4; ++m) worst = std::max(worst, std::abs(double(v[m]) / std::exp(double(in[m])) - 1.0));
  }
  // The polynomial's error (2e-7) plus float rounding of its steps: below 4 float ulps (4.8e-7).
  EXPECT_LT(worst, 4.8e-7);
}

TEST(NerfRenderMarch, OneMinusExpNegMatchesExpm1) {
  // Both branches (the series below 0.25, 1 - exp above), their boundary, tiny, large and huge x.
  std::vector<float> xs = {0.0f, 1e-30f, 1e-12f, 1e-6f, 0.2499999f, 0.25f, 0.2500001f, 79.9f, 80.0f, 1e4f, 1e30f};
  std::mt19937 rng(13);
  std::uniform_real_distribution<float> exponent(-20.0f, 2.5f);
  for (int n = 0; n < 200000; ++n) xs.push_back(std::pow(10.0f, exponent(rng)));
  double worst = 0;
  for (const float x : xs) {
    const double want = -std::expm1(-double(x)), got = nerf_detail::OneMinusExpNeg(x);
    if (want == 0.0) {
      EXPECT_EQ(got, 0.0);
      continue;
    }
    worst = std::max(worst, std::abs(got / want - 1.0));
  }
  // The stated bound: 1.1e-6 from exp's polynomial above 0.25 plus float rounding of 1 - e (6e-8).
  EXPECT_LT(worst, 1.2e-6);
  std::printf("worst relative error %.3g\n", worst);
}

}  // namespace
}  // namespace nerfar
