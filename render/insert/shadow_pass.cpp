#include "render/insert/shadow_pass.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <utility>

#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "calib/core/parallel.h"
#include "render/insert/cache_keys.h"
#include "render/insert/drag_hold.h"
#include "render/insert/shadow_terms.h"

namespace nerfar {

namespace {

// A coarse κ cell whose receivers lie on one plane.
struct CellPlane {
  bool valid = false;
  Vec3f point, normal;         // a point of the plane and its unit normal (facing the camera)
  float t_min = 0, t_max = 0;  // range of the corners' ray distances
};

// One thread's memos of one lattice level: its nodes, and the corners of
// its cells read last (receivers a few pixels apart mostly share a cell,
// and then need no node key or memo probe).
struct LevelMemo {
  LatticeMemo nodes;
  LatticeCellMemo cells;
};

// Per-thread scratch of the κ pass.
struct ThreadScratch {
  KappaScratch kappa;
  std::array<LevelMemo, 1 + kKappaFineLevels> levels;  // the top level, then the fine ones
};

// This thread's scratch for pass `pass` (a number new for every κ pass of
// any inserter) over the lattice of generation `lattice`
// (KappaCache::generation): its memos are kept across passes and frames
// while the lattice stays (its nodes, once computed, keep their values, so
// that a frame much like the last finds most of its nodes in them) and
// emptied for another lattice; the light's scratch is new for each pass
// (the lights may have changed).
ThreadScratch& ScratchFor(uint64_t pass, uint64_t lattice) {
  thread_local ThreadScratch scratch;
  thread_local uint64_t scratch_pass = 0, scratch_lattice = 0;
  if (scratch_lattice != lattice) {
    for (LevelMemo& level : scratch.levels) {
      level.nodes.Clear();
      level.cells.Clear();
    }
    scratch_lattice = lattice;
  }
  if (scratch_pass != pass) {
    scratch.kappa.cw_light = nullptr;
    scratch_pass = pass;
  }
  return scratch;
}
std::atomic<uint64_t> g_kappa_passes{0};
std::atomic<uint64_t> g_kappa_generations{0};

// rgb[3i + c] *= k[i] for i < n (the same products as one pixel at a time).
void MultiplyRgb(float* rgb, const float* k, int n) {
  int i = 0;
#ifdef __SSE2__
  for (; i + 4 <= n; i += 4) {
    const __m128 kv = _mm_loadu_ps(k + i);
    float* p = rgb + 3 * i;
    _mm_storeu_ps(p, _mm_mul_ps(_mm_loadu_ps(p), _mm_shuffle_ps(kv, kv, _MM_SHUFFLE(1, 0, 0, 0))));
    _mm_storeu_ps(p + 4, _mm_mul_ps(_mm_loadu_ps(p + 4), _mm_shuffle_ps(kv, kv, _MM_SHUFFLE(2, 2, 1, 1))));
    _mm_storeu_ps(p + 8, _mm_mul_ps(_mm_loadu_ps(p + 8), _mm_shuffle_ps(kv, kv, _MM_SHUFFLE(3, 3, 3, 2))));
  }
#endif
  for (; i < n; ++i) {
    rgb[3 * i] *= k[i];
    rgb[3 * i + 1] *= k[i];
    rgb[3 * i + 2] *= k[i];
  }
}

// out[i] = min(1, a + slope·i) for i < n (the same values as one at a time).
void FillRamp(float* out, float a, float slope, int n) {
  int i = 0;
#ifdef __SSE2__
  const __m128 va = _mm_set1_ps(a), vs = _mm_set1_ps(slope), one = _mm_set1_ps(1.0f), four = _mm_set1_ps(4.0f);
  __m128 vi = _mm_setr_ps(0.0f, 1.0f, 2.0f, 3.0f);
  for (; i + 4 <= n; i += 4) {
    _mm_storeu_ps(out + i, _mm_min_ps(_mm_add_ps(va, _mm_mul_ps(vs, vi)), one));  // v < 1 ? v : 1
    vi = _mm_add_ps(vi, four);
  }
#endif
  for (; i < n; ++i) out[i] = std::min(1.0f, a + slope * float(i));
}

// κ over `rect` from the grid (nodes at columns xs, rows ys; values in
// `grid`, row-major) into `layer` (over rect, every pixel written: 1 where
// the grid's cell holds 1 at all four nodes), and `frame` multiplied by it where no object of `g`
// covers the pixel. passed[r]: pixels of row r in cells not skipped.
void MultiplyKappa(const std::vector<int>& xs, const std::vector<int>& ys, const std::vector<float>& grid,
                   const PixelRect& rect, const ObjectGBuffer& g, ImageF& layer, ImageF& frame,
                   std::vector<size_t>& passed) {
  const size_t nx = xs.size(), ny = ys.size();
  const size_t cells = nx >= 2 ? nx - 1 : 1;
  // Per pair of grid rows, the cells not all κ = 1 (the rows of pixels
  // between them pass only these).
  std::vector<std::vector<uint32_t>> open(ny >= 2 ? ny - 1 : 1);
  ParallelFor(
      open.size(),
      [&](size_t iy) {
        const float* g0 = &grid[iy * nx];
        const float* g1 = &grid[(ny >= 2 ? iy + 1 : iy) * nx];
        for (size_t ix = 0; ix < cells; ++ix) {
          const size_t ix1 = nx >= 2 ? ix + 1 : ix;
          if (!(g0[ix] >= 1.0f && g0[ix1] >= 1.0f && g1[ix] >= 1.0f && g1[ix1] >= 1.0f))
            open[iy].push_back(static_cast<uint32_t>(ix));
        }
      },
      16);
  ParallelFor(
      static_cast<size_t>(rect.height()),
      [&](size_t r) {
        const int y = rect.y0 + static_cast<int>(r);
        const size_t iy =
            std::min<size_t>(std::upper_bound(ys.begin(), ys.end(), y) - ys.begin() - 1, ny >= 2 ? ny - 2 : 0);
        const size_t iy1 = ny >= 2 ? iy + 1 : iy;
        const float wy = ny >= 2 ? float(y - ys[iy]) / float(ys[iy1] - ys[iy]) : 0.0f;
        const float* g0 = &grid[iy * nx];
        const float* g1 = &grid[iy1 * nx];
        float* out_row = &layer.at(0, y - rect.y0);
        float* f = &frame.pixels[static_cast<size_t>(y) * frame.width * 3];
        // The objects' pixels on this row (left alone): [ox0, ox1) and their ids.
        int ox0 = rect.x1, ox1 = rect.x1;
        const int32_t* ids = nullptr;
        std::vector<std::pair<int, int>> runs;
        if (y >= g.rect.y0 && y < g.rect.y1 && g.rect.x0 < g.rect.x1) {
          ox0 = std::max(g.rect.x0, rect.x0);
          ox1 = std::min(g.rect.x1, rect.x1);
          ids = &g.object[g.Index(g.rect.x0, y)];
        }
        // The layer first, cell by cell (every pixel of the row written once:
        // 1 between the passed cells); the passed cells merged into runs.
        runs.clear();
        int x_done = rect.x0;
        for (const uint32_t ix : open[iy]) {
          const size_t ix1 = nx >= 2 ? ix + 1 : ix;
          const float a = g0[ix] + wy * (g1[ix] - g0[ix]), b = g0[ix1] + wy * (g1[ix1] - g0[ix1]);
          const int x_begin = nx >= 2 ? xs[ix] : rect.x0;
          const int x_end = nx >= 2 && ix + 2 < nx ? xs[ix1] : rect.x1;
          const float slope = nx >= 2 ? (b - a) / float(xs[ix1] - xs[ix]) : 0.0f;
          std::fill(out_row + (x_done - rect.x0), out_row + (x_begin - rect.x0), 1.0f);
          x_done = x_end;
          FillRamp(out_row + (x_begin - rect.x0), a, slope, x_end - x_begin);
          passed[r] += static_cast<size_t>(x_end - x_begin);
          if (!runs.empty() && runs.back().second == x_begin)
            runs.back().second = x_end;
          else
            runs.emplace_back(x_begin, x_end);
        }
        std::fill(out_row + (x_done - rect.x0), out_row + (rect.x1 - rect.x0), 1.0f);
        // Then the background, run by run (κ = 1 multiplies by exactly 1:
        // skipped cells need nothing), around the objects' pixels.
        for (const auto& [x_begin, x_end] : runs) {
          const int left = std::min(x_end, ox0), right = std::max(x_begin, ox1);
          if (left > x_begin) MultiplyRgb(f + 3 * x_begin, out_row + (x_begin - rect.x0), left - x_begin);
          for (int x = std::max(x_begin, ox0); x < std::min(x_end, ox1); ++x)
            if (ids[x - g.rect.x0] < 0) {
              const float k = out_row[x - rect.x0];
              f[3 * x] *= k;
              f[3 * x + 1] *= k;
              f[3 * x + 2] *= k;
            }
          if (x_end > right) MultiplyRgb(f + 3 * right, out_row + (right - rect.x0), x_end - right);
        }
      },
      4);
}

// Grid nodes (columns xs, rows ys) whose κ no background pixel takes: every
// pixel of the grid cells around the node (closed pixel ranges, as the
// bilinear multiply reads them) is an object's.
std::vector<uint8_t> HiddenNodes(const std::vector<int>& xs, const std::vector<int>& ys, const ObjectGBuffer& g) {
  const size_t nx = xs.size(), ny = ys.size();
  std::vector<uint8_t> hidden(nx * ny, 0);
  if (g.covered == 0 || nx < 2 || ny < 2) return hidden;
  const size_t cx = nx - 1;
  std::vector<uint8_t> covered(cx * (ny - 1), 0);
  ParallelFor(
      ny - 1,
      [&](size_t iy) {
        const int y0 = ys[iy], y1 = ys[iy + 1];
        if (y0 < g.rect.y0 || y1 >= g.rect.y1) return;
        for (size_t ix = 0; ix < cx; ++ix) {
          const int x0 = xs[ix], x1 = xs[ix + 1];
          if (x0 < g.rect.x0 || x1 >= g.rect.x1) continue;
          bool all = true;
          for (int y = y0; all && y <= y1; ++y) {
            const int32_t* ids = &g.object[g.Index(x0, y)];
            for (int x = 0; all && x <= x1 - x0; ++x) all = ids[x] >= 0;
          }
          covered[iy * cx + ix] = all ? 1 : 0;
        }
      },
      8);
  for (size_t r = 0; r < ny; ++r)
    for (size_t q = 0; q < nx; ++q) {
      bool all = true;
      for (size_t iy = r > 0 ? r - 1 : 0; all && iy <= std::min(r, ny - 2); ++iy)
        for (size_t ix = q > 0 ? q - 1 : 0; all && ix <= std::min(q, nx - 2); ++ix) all = covered[iy * cx + ix] != 0;
      hidden[r * nx + q] = all ? 1 : 0;
    }
  return hidden;
}

// Object pixels within any pixel rectangle in constant time (a summed-area
// table over the objects' box), to tell the κ cells on the objects'
// outline: a shadow begins where its caster meets the receivers, so a
// caster's visible shadow touches its outline, and one smaller than a cell
// can pass between the cell's corners unseen.
class ObjectPixels {
 public:
  explicit ObjectPixels(const ObjectGBuffer& g) : rect_(g.rect) {
    if (g.covered == 0 || rect_.empty()) return;
    const size_t w = static_cast<size_t>(rect_.width()) + 1;
    sum_.assign(w * (static_cast<size_t>(rect_.height()) + 1), 0);
    for (int y = rect_.y0; y < rect_.y1; ++y) {
      uint32_t row = 0;
      for (int x = rect_.x0; x < rect_.x1; ++x) {
        row += g.object[g.Index(x, y)] >= 0 ? 1u : 0u;
        const size_t at = static_cast<size_t>(y - rect_.y0 + 1) * w + static_cast<size_t>(x - rect_.x0 + 1);
        sum_[at] = sum_[at - w] + row;
      }
    }
  }
  // Whether the closed pixel rectangle [x0, x1] × [y0, y1] holds both
  // object and background pixels.
  bool Outline(int x0, int y0, int x1, int y1) const {
    if (sum_.empty()) return false;
    const int a0 = std::max(x0, rect_.x0), a1 = std::min(x1 + 1, rect_.x1);
    const int b0 = std::max(y0, rect_.y0), b1 = std::min(y1 + 1, rect_.y1);
    if (a0 >= a1 || b0 >= b1) return false;
    const size_t w = static_cast<size_t>(rect_.width()) + 1;
    const auto at = [&](int x, int y) { return sum_[static_cast<size_t>(y - rect_.y0) * w + size_t(x - rect_.x0)]; };
    const uint32_t objects = at(a1, b1) - at(a0, b1) - at(a1, b0) + at(a0, b0);
    return objects > 0 && objects < uint32_t(x1 - x0 + 1) * uint32_t(y1 - y0 + 1);
  }

 private:
  PixelRect rect_;
  std::vector<uint32_t> sum_;  // (width + 1) × (height + 1), object pixels above and left
};

// What decides where a marched receiver lies (ReceiverFrame::rule).
std::vector<float> ReceiverRule(const ShadowPassInputs& in) {
  std::vector<float> rule = {static_cast<float>(in.options.receiver_min_opacity)};
  if (in.support != nullptr)
    for (const Vec3f& v : {in.support->point, in.support->normal}) rule.insert(rule.end(), {v.x, v.y, v.z});
  return rule;
}

}  // namespace

uint64_t NewKappaGeneration() { return ++g_kappa_generations; }

KappaSpacing KappaSpacingFor(const InsertOptions& options, int width) {
  const int factor = std::max(1, options.kappa_coarse_factor);
  if (options.kappa_grid_width <= 0) return {options.kappa_step, size_t(factor)};
  const double scale = double(width) / double(options.kappa_grid_width);
  KappaSpacing s;
  s.step = std::max(1, static_cast<int>(std::lround(options.kappa_step * scale)));
  const int coarse = std::max(s.step, static_cast<int>(std::lround(options.kappa_step * factor * scale)));
  s.factor = static_cast<size_t>(std::max(1, static_cast<int>(std::lround(double(coarse) / s.step))));
  return s;
}

namespace {

ViewKey ViewOf(const CameraIntrinsics& camera, const Pose& T_world_camera) {
  ViewKey v;
  v.fx = camera.fx, v.fy = camera.fy, v.cx = camera.cx, v.cy = camera.cy;
  v.width = camera.width, v.height = camera.height;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) v.rotation[size_t(3 * r + c)] = T_world_camera.rotation(r, c);
  for (int c = 0; c < 3; ++c) v.translation[size_t(c)] = T_world_camera.translation[c];
  return v;
}

// Whether view `b` sees what `a` saw to within the lattice: the same
// intrinsics, rotations within 0.1 mrad per entry, the eye within half a
// lattice spacing (its receivers then fall in the same lattice cells).
bool SameViewWithin(const ViewKey& a, const ViewKey& b, double spacing) {
  bool same =
      a.fx == b.fx && a.fy == b.fy && a.cx == b.cx && a.cy == b.cy && a.width == b.width && a.height == b.height;
  for (size_t i = 0; same && i < 9; ++i) same = std::abs(a.rotation[i] - b.rotation[i]) <= 1e-4;
  for (size_t i = 0; same && i < 3; ++i) same = std::abs(a.translation[i] - b.translation[i]) <= 0.5 * spacing;
  return same;
}

// One frame's κ pass (RenderShadows), as stages over shared state: the
// casters' reach rectangle; the world lattice that caches κ while casters
// and lights stay (narrowed to the known shadow for a view already passed,
// or the last layer reused whole for the same view); κ at a coarse grid of
// receivers, refined where its corners disagree or an object's outline
// crosses (κ varies slowly away from shadow edges); the layer multiplied
// into the background.
class KappaPass {
 public:
  KappaPass(const ShadowPassInputs& in, std::vector<LightPrep>& preps, std::unique_ptr<KappaCache>& cache_owner,
            ImageF& frame, InsertLayers& layers, InsertTimings& times)
      : in_(in),
        options_(in.options),
        camera_(in.camera),
        T_world_camera_(in.T_world_camera),
        g_(in.gbuffer),
        receivers_(in.receivers),
        preps_(preps),
        cache_owner_(cache_owner),
        frame_(frame),
        layers_(layers),
        times_(times),
        eye_(in.T_world_camera.translation),
        box_(in.scene.Box()) {}

  void Run() {
    for (size_t j = 0; j < in_.objects.size(); ++j)
      if (in_.objects[j].visibility && in_.spheres[j].radius > 0) casters_.push_back(j);
    if (!options_.shadows || casters_.empty()) return;
    ReachRect();
    if (options_.kappa_cache_spacing_radii > 0) UseLattice();
    view_ = ViewOf(camera_, T_world_camera_);
    if (cache_ != nullptr && receivers_.distance == nullptr && !rect_.empty()) NarrowToKnownShadow();
    AllocateLayer();
    // The same camera exactly, the same rectangle, nothing moved: the last
    // frame's κ layer holds (NeRF receivers only).
    const bool reuse = cache_ != nullptr && receivers_.distance == nullptr && !rect_.empty() &&
                       view_ == cache_->last_view && rect_.x0 == cache_->last_rect.x0 &&
                       rect_.y0 == cache_->last_rect.y0 && rect_.x1 == cache_->last_rect.x1 &&
                       rect_.y1 == cache_->last_rect.y1;
    if (reuse) {
      Multiply(cache_->last_xs, cache_->last_ys, cache_->last_grid);
    } else if (!rect_.empty()) {
      ComputeGrid();
    }
  }

 private:
  // Cells of the grid by node index ranges [x0, x1] × [y0, y1].
  struct Cell {
    uint32_t x0, y0, x1, y1;
  };
  // A node inside a planar coarse cell, its receiver on the plane.
  struct PlaneNode {
    size_t q;
    Vec3f point;
    const CellPlane* plane;
  };

  // The union of the casters' reach balls on screen.
  void ReachRect() {
    for (size_t j : casters_)
      rect_ = Union(rect_, ProjectBall(camera_, T_world_camera_, Vec3(in_.spheres[j].center),
                                       options_.shadow_reach_radii * in_.spheres[j].radius));
    rect_ = ClipToImage(rect_, camera_.width, camera_.height);
    spacing_px_ = KappaSpacingFor(options_, camera_.width);
    for (size_t j : casters_) smallest_ = std::min(smallest_, in_.spheres[j].radius);
  }

  // The world lattice of κ, dropped when a caster or a light changed.
  void UseLattice() {
    spacing_ = options_.kappa_cache_spacing_radii * smallest_;
    // Through a drag, the objects as κ's held light was taken: κ relative
    // to them does not change with their common translation.
    const bool dragged = in_.drag != nullptr && in_.drag->dragged();
    // Near lobes re-aimed at each receiver change κ as much as the light does.
    std::vector<ReaimedLobesKey> reaimed;
    for (const LightPrep& prep : preps_) reaimed.push_back(ReaimedLobesKeyOf(prep.parallax));
    // Also what shapes the κ layer kept for an unchanged camera.
    KappaKey key{.spacing_m = spacing_,
                 .reach_radii = options_.shadow_reach_radii,
                 .epsilon = options_.shadow_epsilon,
                 .step_px = spacing_px_.step,
                 .coarse_factor = spacing_px_.factor,
                 .refine_delta = options_.kappa_refine_delta,
                 .plane_upsampling = options_.kappa_plane_upsampling,
                 .epsilon_snap = options_.shadow_epsilon_snap,
                 .skip_covered = options_.kappa_skip_covered,
                 .receiver_rule = ReceiverRule(in_),
                 .casters = ObjectsKeyOf(in_.objects, dragged ? in_.drag->kappa_key : nullptr, &casters_),
                 .lights = in_.lights,
                 .reaimed = std::move(reaimed)};
    if (!cache_owner_) cache_owner_ = std::make_unique<KappaCache>();
    if (key != cache_owner_->key || cache_owner_->Size() > kKappaCacheMaxNodes) {
      cache_owner_->Clear();
      cache_owner_->key = std::move(key);
    }
    // While the lattice moves with a dragged object, the top level alone:
    // the fine levels' nodes lie closer than the receivers' travel between
    // frames, so each frame would compute them anew; a frame where nothing
    // moved (and the one after the release) refines as a still one does.
    const bool moved = ShiftLattice(dragged ? in_.drag->kappa_shift : Vec3{});
    levels_ = dragged && moved ? 0 : kKappaFineLevels;
    cache_owner_->Publish();  // the last frame's nodes: read without locks this frame
    cache_ = cache_owner_.get();
  }

  // The lattice's nodes moved with the objects: the views passed whole and
  // the last layer no longer hold (the receivers sit elsewhere relative to
  // the objects); the nodes themselves do. Whether they moved since the
  // last frame.
  bool ShiftLattice(const Vec3& shift) {
    shift_ = shift;
    if (cache_owner_->shift == shift) return false;
    cache_owner_->shift = shift;
    cache_owner_->explored.clear();
    cache_owner_->last_view.reset();
    return true;
  }

  // A view already passed whole under this cache (receivers marched by the
  // NeRF, the same camera within a lattice spacing and 0.1 mrad): its
  // receivers' κ < 1 − ε lie within one spacing of the shadowed nodes' box,
  // so only that box's projection needs a pass (aligned to the coarse grid
  // of the whole rectangle, so its values are unchanged).
  void NarrowToKnownShadow() {
    bool seen = false;
    for (const ViewKey& e : cache_->explored) seen = seen || SameViewWithin(e, view_, spacing_);
    if (!seen) {
      if (cache_->explored.size() >= 16) cache_->explored.erase(cache_->explored.begin());  // a moving camera
      cache_->explored.push_back(view_);
      return;
    }
    PixelRect shadow;
    const Vec3f lo = cache_->lattice.shadow_min(), hi = cache_->lattice.shadow_max();
    if (lo.x <= hi.x) {
      const Vec3 centre = Vec3((lo + hi) * 0.5f) + shift_;
      const double radius = 0.5 * Length(Vec3(hi - lo)) + 1.75 * spacing_;  // + the nodes' trilinear support
      shadow = ClipToImage(ProjectBall(camera_, T_world_camera_, centre, radius), camera_.width, camera_.height);
    }
    if (shadow.empty()) {
      rect_ = {};
      return;
    }
    const int unit = spacing_px_.step * static_cast<int>(spacing_px_.factor);
    const auto down = [&](int v, int origin) { return origin + (std::max(v, origin) - origin) / unit * unit; };
    PixelRect r{down(shadow.x0 - unit, rect_.x0), down(shadow.y0 - unit, rect_.y0),
                down(shadow.x1 + 2 * unit, rect_.x0) + 1, down(shadow.y1 + 2 * unit, rect_.y0) + 1};
    r = {std::max(r.x0, rect_.x0), std::max(r.y0, rect_.y0), std::min(r.x1, rect_.x1), std::min(r.y1, rect_.y1)};
    rect_ = r.empty() ? PixelRect{} : r;
  }

  void AllocateLayer() {
    layers_.kappa_rect = rect_;
    // Every pixel is written by MultiplyKappa (in parallel, once): no fill.
    layers_.kappa = ImageF();
    layers_.kappa.width = rect_.width();
    layers_.kappa.height = rect_.height();
    layers_.kappa.channels = 1;
    layers_.kappa.pixels.resize(static_cast<size_t>(rect_.area()));
  }

  // Bilinear from the sample grid to every pixel; multiply the background
  // where no object covers it (MultiplyKappa).
  void Multiply(const std::vector<int>& xs, const std::vector<int>& ys, const std::vector<float>& grid) {
    const auto t_multiply = InsertClock::now();
    std::vector<size_t> multiplied_per_row(static_cast<size_t>(rect_.height()), 0);
    MultiplyKappa(xs, ys, grid, rect_, g_, layers_.kappa, frame_, multiplied_per_row);
    for (size_t q : multiplied_per_row) times_.kappa_multiplied += q;
    times_.kappa_multiply_ms = MsSince(t_multiply);
  }

  // κ over the rectangle's grid: coarse nodes, refined, the hidden ones 1;
  // the receivers and the layer kept for the next frame.
  void ComputeGrid() {
    SetUpGrid();
    CoarsePass();
    if (factor_ > 1) {
      FitCellPlanes();
      Refine();
      InterpolateSmooth();
    }
    // Nodes no background pixel reads hold 1 (κ is not applied there).
    for (size_t i = 0; i < nx_ * ny_; ++i)
      if (hidden_[i]) kappa_grid_[i] = 1.0f;
    Count();
    if (cache_ != nullptr && receivers_.distance == nullptr && options_.kappa_receiver_reuse) KeepReceivers();
    // Cell by cell of the grid: a cell whose four nodes hold κ = 1 is skipped
    // whole (the layer is 1 already). Per row, the grid's two rows are first
    // blended in y at the cell's two columns, then each pixel is one step
    // along x; the multiply runs over the row's passed pixels, around the
    // objects' pixels.
    Multiply(xs_, ys_, kappa_grid_);
    if (cache_ != nullptr && receivers_.distance == nullptr) {
      cache_->last_view = view_;
      cache_->last_rect = rect_;
      cache_->last_xs = xs_;
      cache_->last_ys = ys_;
      cache_->last_grid = std::move(kappa_grid_);
    }
  }

  void SetUpGrid() {
    // Light owners: each receiver takes the light of its nearest object
    // (relative to size); queries of every caster at each owner's lobe axes.
    for (size_t o = 0; o < in_.objects.size(); ++o) PrepareLight(in_.lights[o], in_.objects, preps_[o]);
    const int step = spacing_px_.step;
    const auto grid_axis = [step](int lo, int hi) {
      std::vector<int> s;
      for (int v = lo; v < hi; v += step) s.push_back(v);
      if (s.back() != hi - 1) s.push_back(hi - 1);
      return s;
    };
    xs_ = grid_axis(rect_.x0, rect_.x1), ys_ = grid_axis(rect_.y0, rect_.y1);
    nx_ = xs_.size(), ny_ = ys_.size();
    kappa_grid_.assign(nx_ * ny_, 1.0f);
    for (std::vector<size_t>* counts : {&queries_per_row_, &evaluated_per_row_, &marched_per_row_, &reused_per_row_,
                                        &looked_up_per_row_, &receivers_per_row_})
      counts->assign(ny_, 0);
    min_opacity_ = static_cast<float>(options_.receiver_min_opacity);
    one_minus_eps_ = 1.0 - options_.shadow_epsilon;
    // The last frame's receivers, when they can stand for marching.
    reuse_receivers_ = cache_ != nullptr && receivers_.distance == nullptr && options_.kappa_receiver_reuse &&
                       cache_->receivers.valid && cache_->receivers.rule == ReceiverRule(in_);
    cell_normals_ = cache_ != nullptr && receivers_.distance == nullptr && options_.receiver_normal_per_cell;
    reuse_tolerance_ = static_cast<float>(options_.kappa_reuse_tolerance_radii * smallest_);
    context_ = KappaContext{
        &casters_,      &in_.spheres, &preps_, &in_.lights, static_cast<float>(options_.shadow_reach_radii),
        one_minus_eps_, in_.sources};
    SharpestPenumbra();
    pass_ = ++g_kappa_passes;
    generation_ = cache_ != nullptr ? cache_->generation : 0;
    node_point_.assign(nx_ * ny_, Vec3f{});
    node_normal_.assign(nx_ * ny_, Vec3f{});
    node_valid_.assign(nx_ * ny_, 0);
    node_state_.assign(nx_ * ny_, 0);
    found_.assign(ny_, {});
    // Coarse to fine: κ at every coarse_factor-th node; cells whose corners
    // differ by more than kappa_refine_delta get all their nodes, the others
    // are interpolated.
    factor_ = spacing_px_.factor;
    if (nx_ < 2 * factor_ || ny_ < 2 * factor_) factor_ = 1;  // too small a grid to coarsen
    const auto coarse_axis = [this](size_t n) {
      std::vector<size_t> c;
      for (size_t i = 0; i < n; i += factor_) c.push_back(i);
      if (c.back() != n - 1) c.push_back(n - 1);
      return c;
    };
    cx_ = coarse_axis(nx_), cy_ = coarse_axis(ny_);
  }

  // The lattice's cells are trusted where their corners agree within
  // kappa_refine_delta (the screen grid's rule) or where the sharpest light's
  // penumbra is wider than a cell; elsewhere κ is exact at the receiver.
  void SharpestPenumbra() {
    double sharpest = 0;
    for (const SgMixture& light : in_.lights)
      for (const Sg& lobe : light) sharpest = std::max(sharpest, lobe.sharpness);
    penumbra_per_metre_ = sharpest > 0 ? 2.0 * std::sqrt(2.0 * std::log(2.0) / sharpest) : 1.0;
    delta_lattice_ = static_cast<float>(options_.kappa_refine_delta);
    sample_angle_ = double(spacing_px_.step) / camera_.fx;
  }

  // κ at receiver x (normal n): exact, or trilinear in the world lattice,
  // in a finer level of it where the level's cell cannot hold a sharp
  // penumbra (its corners disagree and the penumbra is narrower than the
  // cell) and the cell is wider than what one κ sample covers on screen
  // (finer nodes than samples would be computed anew as the camera moves).
  // Every level's nodes are kept across frames; a dragged object's κ keeps to
  // the top level (UseLattice).
  float ExactOrLatticeKappa(const Vec3f& x, const Vec3f& n, ThreadScratch& sc, size_t row) {
    if (cache_ == nullptr) return ExactKappa(x, n, sc, row);
    ++receivers_per_row_[row];
    const uint32_t cell = NormalCell(n);
    double spacing = spacing_;
    for (size_t level = 0;; ++level, spacing *= 0.5) {
      Spread spread;
      KappaLattice& lattice = level == 0 ? cache_->lattice : cache_->fine[level - 1];
      const float k = LevelKappa(lattice, sc.levels[level], spacing, x, cell, sc, row, &spread);
      if (level == levels_ || spread.highest - spread.lowest <= delta_lattice_ || !PenumbraNarrowerThan(x, spacing) ||
          !WiderThanAPixel(x, spacing))
        return k;
    }
  }

  // The lowest and highest corner value of a trilinear look-up.
  struct Spread {
    float lowest = 1.0f, highest = 0.0f;
    void Add(float v) { lowest = std::min(lowest, v), highest = std::max(highest, v); }
  };

  // One lattice node's κ (computed and kept on a miss); `node` in the
  // lattice's frame (world point node + shift_).
  float NodeKappa(KappaLattice& lattice, uint64_t key, const Vec3f& node, uint32_t cell, ThreadScratch& sc,
                  size_t row) {
    float value;
    if (++looked_up_per_row_[row], lattice.Find(key, &value)) return value;
    bool queried = false;
    value = KappaAt(context_, Vec3f(Vec3(node) + shift_), CellNormal(cell), sc.kappa, &queried);
    lattice.Insert(key, value);
    if (value < one_minus_eps_) cache_->lattice.GrowShadow(node);
    ++evaluated_per_row_[row];
    if (queried) ++queries_per_row_[row];
    return value;
  }

  // x's cell in a lattice of `spacing` (the lattice's frame: x − shift_):
  // its lowest node and x's fractions along the axes.
  struct LatticeCell {
    int64_t i, j, k;
    double wx, wy, wz;
    // A corner (bits x, y, z): its node and trilinear weight.
    int64_t I(int corner) const { return i + (corner & 1); }
    int64_t J(int corner) const { return j + ((corner >> 1) & 1); }
    int64_t K(int corner) const { return k + (corner >> 2); }
    double Weight(int corner) const {
      return (corner & 1 ? wx : 1 - wx) * ((corner >> 1) & 1 ? wy : 1 - wy) * (corner >> 2 ? wz : 1 - wz);
    }
  };
  LatticeCell CellAt(const Vec3f& x, double spacing) const {
    const double fx = (x.x - shift_.x) / spacing, fy = (x.y - shift_.y) / spacing, fz = (x.z - shift_.z) / spacing;
    const double bx = std::floor(fx), by = std::floor(fy), bz = std::floor(fz);
    return {int64_t(bx), int64_t(by), int64_t(bz), fx - bx, fy - by, fz - bz};
  }
  // Nodes that hardly count are not computed (a receiver plane on a lattice
  // plane would otherwise pull in the layer beyond it).
  static constexpr double kMinCornerWeight = 1e-3;

  // Trilinear κ over the nodes of `lattice` (a level of spacing `spacing`)
  // around x for x's normal cell, through this thread's memos of the level.
  float LevelKappa(KappaLattice& lattice, LevelMemo& memo, double spacing, const Vec3f& x, uint32_t cell,
                   ThreadScratch& sc, size_t row, Spread* spread) {
    const LatticeCell c = CellAt(x, spacing);
    std::array<float, 8>& corners = memo.cells.Corners(LatticeKey(c.i, c.j, c.k, cell));
    std::array<double, 8> weight;
    for (int corner = 0; corner < 8; ++corner) weight[size_t(corner)] = c.Weight(corner);
    FetchCorners(c, spacing, cell, weight, memo.nodes, lattice, corners, sc, row);
    double sum = 0.0, total = 0.0;
    for (size_t corner = 0; corner < 8; ++corner) {
      if (weight[corner] < kMinCornerWeight) continue;
      total += weight[corner];
      sum += weight[corner] * corners[corner];
      spread->Add(corners[corner]);
    }
    return total > 0.0 ? static_cast<float>(std::clamp(sum / total, 0.0, 1.0)) : 1.0f;
  }

  // The corners of c (a cell of `spacing`, normal cell `cell`) that count
  // (`weight` not negligible) and are not in `corners` yet, through the node
  // memo: first the snapshot slots of those the memo lacks prefetched, so
  // that their cache misses overlap, then each looked up in corner order.
  void FetchCorners(const LatticeCell& c, double spacing, uint32_t cell, const std::array<double, 8>& weight,
                    LatticeMemo& memo, KappaLattice& lattice, std::array<float, 8>& corners, ThreadScratch& sc,
                    size_t row) {
    std::array<uint64_t, 8> key;
    bool missing = false;
    for (int corner = 0; corner < 8; ++corner) {
      if (weight[size_t(corner)] < kMinCornerWeight || corners[size_t(corner)] >= 0.0f) continue;
      key[size_t(corner)] = LatticeKey(c.I(corner), c.J(corner), c.K(corner), cell);
      if (!memo.Holds(key[size_t(corner)])) lattice.Prefetch(key[size_t(corner)]);
      missing = true;
    }
    if (!missing) return;
    for (int corner = 0; corner < 8; ++corner)
      if (weight[size_t(corner)] >= kMinCornerWeight && corners[size_t(corner)] < 0.0f)
        corners[size_t(corner)] = MemoKappa(memo, lattice, key[size_t(corner)], c, corner, spacing, cell, sc, row);
  }

  // Corner `corner` of c (a lattice of `spacing`) through `memo`: looked up
  // in `lattice` (computed there on a miss) when the memo lacks it.
  float MemoKappa(LatticeMemo& memo, KappaLattice& lattice, uint64_t key, const LatticeCell& c, int corner,
                  double spacing, uint32_t cell, ThreadScratch& sc, size_t row) {
    LatticeMemo::Entry& e = memo.At(key);
    if (e.key != key || e.value < 0.0f) {
      e.key = key;
      const Vec3 node = Vec3(double(c.I(corner)), double(c.J(corner)), double(c.K(corner))) * spacing;
      e.value = NodeKappa(lattice, key, Vec3f(node), cell, sc, row);
    }
    return e.value;
  }

  float ExactKappa(const Vec3f& x, const Vec3f& n, ThreadScratch& sc, size_t row) {
    bool queried = false;
    const float k = KappaAt(context_, x, n, sc.kappa, &queried);
    ++evaluated_per_row_[row];
    if (queried) ++queries_per_row_[row];
    return k;
  }

  // Whether a lattice cell of `spacing` at x is wider than the table's width
  // one κ sample (kappa_step pixels) covers there.
  bool WiderThanAPixel(const Vec3f& x, double spacing) const {
    return spacing > double(Length(x - eye_)) * sample_angle_;
  }

  // Whether the sharpest light's penumbra at x is narrower than a lattice
  // cell of `spacing`, so that trilinear κ would widen it: the penumbra
  // spans the light's angular width (the lobe's full width at half maximum,
  // 2·sqrt(2 ln 2 / λ)) times the distance to the caster, at least x's
  // distance to the nearest caster's bounding sphere.
  bool PenumbraNarrowerThan(const Vec3f& x, double spacing) const {
    float nearest = std::numeric_limits<float>::infinity();
    for (size_t j : casters_) nearest = std::min(nearest, Length(x - in_.spheres[j].center) - in_.spheres[j].radius);
    return double(std::max(nearest, 0.0f)) * penumbra_per_metre_ < spacing;
  }

  // κ at a receiver; with shadow_epsilon_snap, κ ≥ 1 − ε is 1 (the bound's rule).
  float ReceiverKappa(const Vec3f& x, const Vec3f& n, ThreadScratch& sc, size_t row) {
    const float k = ExactOrLatticeKappa(x, n, sc, row);
    return options_.shadow_epsilon_snap && double(k) >= one_minus_eps_ ? 1.0f : k;
  }

  // Marched receivers with a surface (opacity ≥ receiver_min_opacity and
  // 1/2: `out.depth` is where the transmittance crossed 1/2) taken onto the
  // support plane, with its normal, where they end on it (ReceiversOnPlane).
  void PlaceOnSupport(const std::vector<size_t>& march, const SceneSamples& out, const SceneRays& rays,
                      const std::vector<Vec3f>& dirs, const std::vector<float>& opacity, std::vector<Vec3f>& normals,
                      std::vector<Vec3f>& points) const {
    std::vector<size_t> surface;
    std::vector<Vec3f> surface_dirs;
    std::vector<float> t, t_near;
    for (size_t m = 0; m < march.size(); ++m) {
      const size_t ix = march[m];
      if (opacity[ix] < std::max(min_opacity_, 0.5f) || !std::isfinite(out.depth[m])) continue;
      surface.push_back(ix);
      surface_dirs.push_back(dirs[ix]);
      t.push_back(out.depth[m]);
      t_near.push_back(rays.t_near[m]);
    }
    std::vector<uint8_t> on_plane;
    ReceiversOnPlane(in_.scene, *in_.support, eye_, surface_dirs, t_near, t, on_plane);
    for (size_t k = 0; k < surface.size(); ++k)
      if (on_plane[k]) {
        points[surface[k]] = eye_ + dirs[surface[k]] * t[k];
        normals[surface[k]] = in_.support->normal;
      }
  }

  // Receivers of the row's nodes `given` by the last frame (state 1 or 2),
  // the rest marched through the NeRF into points, normals and opacity.
  void MarchRow(size_t row, const std::vector<size_t>& cols, const std::vector<Vec3f>& dirs, std::vector<Vec3f>& points,
                std::vector<Vec3f>& normals, std::vector<float>& opacity) {
    const int y = ys_[row];
    const size_t nc = cols.size();
    SceneRays rays;
    SceneSamples out;
    std::vector<uint8_t> given(nc, 0);
    normals.resize(nc);
    std::vector<size_t> march;
    march.reserve(nc);
    for (size_t ix = 0; ix < nc; ++ix) {
      if (reuse_receivers_)
        given[ix] = static_cast<uint8_t>(ReuseReceiver(cache_->receivers, eye_, dirs[ix], xs_[cols[ix]], y,
                                                       reuse_tolerance_, points[ix], normals[ix]));
      if (given[ix] == 1) opacity[ix] = 1.0f;
      if (given[ix] == 0) march.push_back(ix);
    }
    reused_per_row_[row] += nc - march.size();
    if (march.empty()) return;
    rays.Reserve(march.size());
    for (size_t ix : march) {
      const auto range = IntersectBox(box_, Vec3(eye_), Vec3(dirs[ix]));
      rays.Add(eye_, dirs[ix], range ? static_cast<float>(range->first) : 0.0f,
               range ? static_cast<float>(range->second) : 0.0f);
    }
    in_.scene.RenderRays(rays, out);
    marched_per_row_[row] += march.size();
    std::vector<Vec3f> marched_points(march.size()), marched_normals;
    for (size_t m = 0; m < march.size(); ++m) {
      const size_t ix = march[m];
      opacity[ix] = std::isfinite(out.opacity[m]) ? out.opacity[m] : 0.0f;
      const float t = std::isfinite(out.depth[m]) ? out.depth[m] : 0.0f;
      points[ix] = marched_points[m] = eye_ + dirs[ix] * t;
    }
    in_.scene.Normals(marched_points, marched_normals);
    for (size_t m = 0; m < march.size(); ++m) normals[march[m]] = marched_normals[m];
    if (in_.support != nullptr) PlaceOnSupport(march, out, rays, dirs, opacity, normals, points);
  }

  // The receivers at the grid nodes (row, cols[j]) of one row: node_state 2
  // (no surface) or 1 with node_point and the receiver's own normal in
  // node_normal (not yet unit; replaced by its cell's normal with
  // receiver_normal_per_cell), the surface nodes listed in found[row].
  void FindRow(size_t row, const std::vector<size_t>& cols) {
    found_[row].clear();
    if (cols.empty()) return;
    const int y = ys_[row];
    const size_t nc = cols.size();
    std::vector<Vec3f> points(nc), normals;
    std::vector<float> opacity(nc, 0.0f);
    std::vector<Vec3f> dirs(nc);
    for (size_t ix = 0; ix < nc; ++ix) dirs[ix] = CameraRayDirection(camera_, T_world_camera_, xs_[cols[ix]], y);
    if (receivers_.distance) {
      for (size_t ix = 0; ix < nc; ++ix) {
        const float t = receivers_.distance->at(xs_[cols[ix]], y);
        opacity[ix] = t > 0.0f && std::isfinite(t) ? 1.0f : 0.0f;
        points[ix] = eye_ + dirs[ix] * (opacity[ix] > 0 ? t : 0.0f);
      }
    } else {
      MarchRow(row, cols, dirs, points, normals, opacity);
    }
    if (receivers_.normal) {
      normals.resize(nc);
      for (size_t ix = 0; ix < nc; ++ix)
        normals[ix] = {receivers_.normal->at(xs_[cols[ix]], y, 0), receivers_.normal->at(xs_[cols[ix]], y, 1),
                       receivers_.normal->at(xs_[cols[ix]], y, 2)};
    } else if (receivers_.distance) {
      in_.scene.Normals(points, normals);
    }
    for (size_t ix = 0; ix < nc; ++ix) {
      const size_t node = row * nx_ + cols[ix];
      node_state_[node] = 2;
      if (opacity[ix] < min_opacity_ || !Finite(points[ix])) continue;
      node_state_[node] = 1;
      node_point_[node] = points[ix];
      node_normal_[node] = normals[ix];
      found_[row].push_back({node, points[ix], normals[ix]});
    }
  }

  // With receiver_normal_per_cell, between finding one pass's receivers and
  // their κ: every receiver in a world cell takes that cell's normal
  // (CellNormals: kept from earlier passes, else the deterministic pick among
  // this pass's receivers in it), whatever the threads' order.
  void ResolveCellNormals() {
    if (!cell_normals_) return;
    std::vector<CellCandidate> all;
    for (const std::vector<CellCandidate>& row : found_) all.insert(all.end(), row.begin(), row.end());
    cache_->cell_normals.Resolve(spacing_, all);
    for (const CellCandidate& c : all) node_normal_[c.node] = c.normal;
  }

  // κ at the receivers FindRow found in this row (cols as there).
  void KappaRow(size_t row, const std::vector<size_t>& cols) {
    ThreadScratch& scratch = ScratchFor(pass_, generation_);
    for (size_t q : cols) {
      const size_t node = row * nx_ + q;
      if (node_state_[node] != 1) continue;
      Vec3f n = node_normal_[node];
      if (!Finite(n) || Dot(n, n) < 0.25f) {
        node_state_[node] = 2;
        continue;
      }
      n = Normalized(n);
      node_normal_[node] = n;
      node_valid_[node] = 1;
      kappa_grid_[node] = ReceiverKappa(node_point_[node], n, scratch, row);
    }
  }

  // κ at the coarse nodes. Nodes no background pixel needs
  // (kappa_skip_covered): neither found nor evaluated, except coarse nodes
  // of a coarse grid (their cells' refinement compares them).
  void CoarsePass() {
    auto t_stage = InsertClock::now();
    hidden_ = options_.kappa_skip_covered ? HiddenNodes(xs_, ys_, g_) : std::vector<uint8_t>(nx_ * ny_, 0);
    std::vector<std::vector<size_t>> coarse_cols(cy_.size());
    for (size_t i = 0; i < cy_.size(); ++i)
      for (size_t q : cx_)
        if (factor_ > 1 || !hidden_[cy_[i] * nx_ + q]) coarse_cols[i].push_back(q);
    for (size_t r = 0; r < ny_; ++r)
      for (size_t q = 0; q < nx_; ++q) times_.kappa_hidden += hidden_[r * nx_ + q];
    find_ms_ += MsSince(t_stage);
    t_stage = InsertClock::now();
    ParallelFor(
        cy_.size(), [&](size_t i) { FindRow(cy_[i], coarse_cols[i]); }, 1);
    ResolveCellNormals();
    find_ms_ += MsSince(t_stage);
    t_stage = InsertClock::now();
    ParallelFor(
        cy_.size(), [&](size_t i) { KappaRow(cy_[i], coarse_cols[i]); }, 1);
    kappa_ms_ += MsSince(t_stage);
  }

  // Coarse cells whose four receivers lie on one plane (normals within 10°
  // of their mean, points within 5% of the cell's size of the plane through
  // their mean); only where the receivers were marched.
  void FitCellPlanes() {
    planes_.assign((cy_.size() - 1) * (cx_.size() - 1), CellPlane{});
    if (!options_.kappa_plane_upsampling || receivers_.distance != nullptr) return;
    for (size_t j = 0; j + 1 < cy_.size(); ++j)
      for (size_t i = 0; i + 1 < cx_.size(); ++i) {
        const size_t corner[4] = {cy_[j] * nx_ + cx_[i], cy_[j] * nx_ + cx_[i + 1], cy_[j + 1] * nx_ + cx_[i],
                                  cy_[j + 1] * nx_ + cx_[i + 1]};
        CellPlane& plane = planes_[j * (cx_.size() - 1) + i];
        Vec3f mean_p{}, mean_n{};
        bool ok = true;
        for (size_t c : corner) {
          ok = ok && node_valid_[c];
          mean_p = mean_p + node_point_[c] * 0.25f;
          mean_n = mean_n + node_normal_[c];
        }
        if (!ok || !(Dot(mean_n, mean_n) > 1e-6f)) continue;
        mean_n = Normalized(mean_n);
        float size = 0.0f, off = 0.0f;
        plane.t_min = std::numeric_limits<float>::infinity();
        plane.t_max = 0.0f;
        for (size_t c : corner) {
          ok = ok && Dot(node_normal_[c], mean_n) > 0.985f;
          size = std::max(size, Length(node_point_[c] - mean_p));
          off = std::max(off, std::abs(Dot(node_point_[c] - mean_p, mean_n)));
          const float t = Length(node_point_[c] - eye_);
          plane.t_min = std::min(plane.t_min, t);
          plane.t_max = std::max(plane.t_max, t);
        }
        if (!ok || off > 0.05f * size) continue;
        plane.valid = true;
        plane.point = mean_p;
        plane.normal = mean_n;
      }
  }

  // Whether the cell's corners differ by more than kappa_refine_delta.
  bool Differ(const Cell& c) const {
    const float a = kappa_grid_[c.y0 * nx_ + c.x0], b = kappa_grid_[c.y0 * nx_ + c.x1];
    const float d0 = kappa_grid_[c.y1 * nx_ + c.x0], d1 = kappa_grid_[c.y1 * nx_ + c.x1];
    return std::max({a, b, d0, d1}) - std::min({a, b, d0, d1}) > delta_;
  }
  // Cells on the objects' outline are refined whatever their corners, at
  // every level (ObjectPixels).
  bool Refined(const Cell& c) const {
    return Differ(c) || object_pixels_->Outline(xs_[c.x0], ys_[c.y0], xs_[c.x1], ys_[c.y1]);
  }
  // A coarse cell left smooth whose border holds nodes its refined
  // neighbours found differing from its corners by more than the delta (an
  // edge that entered it between its corners) is refined in turn.
  bool BorderDiffers(const Cell& c) const {
    float lo = kappa_grid_[c.y0 * nx_ + c.x0], hi = lo;
    const auto take = [&](size_t node) {
      if (!known_[node]) return;
      lo = std::min(lo, kappa_grid_[node]);
      hi = std::max(hi, kappa_grid_[node]);
    };
    for (uint32_t q = c.x0; q <= c.x1; ++q) take(c.y0 * nx_ + q), take(c.y1 * nx_ + q);
    for (uint32_t r = c.y0; r <= c.y1; ++r) take(r * nx_ + c.x0), take(r * nx_ + c.x1);
    return hi - lo > delta_;
  }

  // The coarse cells refined level by level: a cell whose corners differ by
  // more than kappa_refine_delta gets the nodes that halve it (edge midpoints
  // and centre), each half then tested the same way with its own corners down
  // to cells one node apart (a soft gradient stops at the first half whose
  // corners agree; an edge is followed to every node). Cells that pass are
  // interpolated from their corners (`smooth_`, per level: a finer level's
  // values win on the edges they share).
  void Refine() {
    delta_ = static_cast<float>(options_.kappa_refine_delta);
    const ObjectPixels object_pixels(g_);
    object_pixels_ = &object_pixels;
    smooth_.assign(1, {});
    std::vector<Cell> refine;
    for (size_t j = 0; j + 1 < cy_.size(); ++j)
      for (size_t i = 0; i + 1 < cx_.size(); ++i) {
        const Cell c{uint32_t(cx_[i]), uint32_t(cy_[j]), uint32_t(cx_[i + 1]), uint32_t(cy_[j + 1])};
        (Refined(c) ? refine : smooth_[0]).push_back(c);
      }
    known_.assign(nx_ * ny_, 0);  // κ set (or scheduled) at the node
    for (size_t r : cy_)
      for (size_t q : cx_) known_[r * nx_ + q] = 1;
    new_cols_.assign(ny_, {});
    refine_cols_.assign(ny_, {});
    plane_nodes_.assign(ny_, {});
    for (;;) {
      while (!refine.empty()) refine = RefineLevel(refine);
      std::vector<Cell> still;
      for (const Cell& c : smooth_[0]) (BorderDiffers(c) ? refine : still).push_back(c);
      if (refine.empty()) break;
      smooth_[0] = std::move(still);
    }
    object_pixels_ = nullptr;
  }

  // One level: κ at the nodes that halve the cells in `refine`; returns their
  // halves still to refine (the others into a new level of smooth_).
  std::vector<Cell> RefineLevel(const std::vector<Cell>& refine) {
    // This level's nodes per row: each cell's halving nodes; hidden ones only
    // where no finer cell compares them (the cell's halves hold no node
    // inside).
    std::vector<size_t> rows;
    const auto schedule = [&](uint32_t q, uint32_t r, bool skip_hidden) {
      const size_t node = size_t(r) * nx_ + q;
      if (known_[node] || (skip_hidden && hidden_[node])) return;
      known_[node] = 1;
      if (new_cols_[r].empty()) rows.push_back(r);
      new_cols_[r].push_back(q);
    };
    for (const Cell& c : refine) {
      const bool last = c.x1 - c.x0 <= 2 && c.y1 - c.y0 <= 2;
      const uint32_t px[3] = {c.x0, (c.x0 + c.x1) / 2, c.x1}, py[3] = {c.y0, (c.y0 + c.y1) / 2, c.y1};
      for (uint32_t r : py)
        for (uint32_t q : px) schedule(q, r, last);
    }
    std::sort(rows.begin(), rows.end());
    for (std::vector<CellCandidate>& f : found_) f.clear();
    // Per row: plane nodes placed, the others found, ...
    auto t_stage = InsertClock::now();
    ParallelFor(
        rows.size(), [&](size_t k) { FindRefinedRow(rows[k]); }, 1);
    ResolveCellNormals();
    // Plane-placed nodes take their world cell's normal too (a new cell's
    // from their planes' normals), so that their lattice nodes, like every
    // receiver's, do not change with the view: the mean normal of a coarse
    // cell's corners changes as the grid slides over the scene, and each new
    // normal cell costs eight new lattice nodes.
    if (cell_normals_) {
      std::vector<CellCandidate> placed;
      for (size_t r : rows)
        for (const PlaneNode& p : plane_nodes_[r]) placed.push_back({r * nx_ + p.q, p.point, p.plane->normal});
      cache_->cell_normals.Resolve(spacing_, placed);
      for (const CellCandidate& c : placed) node_normal_[c.node] = c.normal;
    }
    find_ms_ += MsSince(t_stage);
    // ... then their κ.
    t_stage = InsertClock::now();
    ParallelFor(
        rows.size(),
        [&](size_t k) {
          const size_t r = rows[k];
          ThreadScratch& scratch = ScratchFor(pass_, generation_);
          for (const PlaneNode& p : plane_nodes_[r])
            kappa_grid_[r * nx_ + p.q] =
                ReceiverKappa(p.point, cell_normals_ ? node_normal_[r * nx_ + p.q] : p.plane->normal, scratch, r);
          KappaRow(r, refine_cols_[r]);
        },
        1);
    kappa_ms_ += MsSince(t_stage);
    // The halves of this level's cells (those with nodes inside).
    std::vector<Cell> next;
    smooth_.emplace_back();
    for (const Cell& c : refine) {
      const uint32_t xm = (c.x0 + c.x1) / 2, ym = (c.y0 + c.y1) / 2;
      const bool split_x = c.x1 - c.x0 >= 2, split_y = c.y1 - c.y0 >= 2;
      for (int b = 0; b < (split_y ? 2 : 1); ++b)
        for (int a = 0; a < (split_x ? 2 : 1); ++a) {
          const Cell h{split_x ? (a ? xm : c.x0) : c.x0, split_y ? (b ? ym : c.y0) : c.y0,
                       split_x ? (a ? c.x1 : xm) : c.x1, split_y ? (b ? c.y1 : ym) : c.y1};
          if (h.x1 - h.x0 <= 1 && h.y1 - h.y0 <= 1) continue;  // every node a corner
          (Refined(h) ? next : smooth_.back()).push_back(h);
        }
    }
    return next;
  }

  // The receivers of row r's new nodes: inside a planar coarse cell where the
  // node's ray meets the plane (depth-aware upsampling), else found.
  void FindRefinedRow(size_t r) {
    std::vector<size_t>& cols = refine_cols_[r];
    cols.clear();
    plane_nodes_[r].clear();
    std::sort(new_cols_[r].begin(), new_cols_[r].end());
    const size_t j = std::min<size_t>(r / factor_, cy_.size() - 2);
    for (size_t q : new_cols_[r]) {
      const CellPlane& plane = planes_[j * (cx_.size() - 1) + std::min<size_t>(q / factor_, cx_.size() - 2)];
      if (plane.valid) {
        const Vec3f d = CameraRayDirection(camera_, T_world_camera_, xs_[q], ys_[r]);
        const float cosine = Dot(d, plane.normal);
        const float t = cosine < -0.05f ? Dot(plane.point - eye_, plane.normal) / cosine : -1.0f;
        if (t >= 0.9f * plane.t_min && t <= 1.1f * plane.t_max) {
          plane_nodes_[r].push_back({q, eye_ + d * t, &plane});
          continue;
        }
      }
      cols.push_back(q);
    }
    new_cols_[r].clear();
    FindRow(r, cols);
  }

  // The nodes no level set, bilinear in their smooth cell, level by level
  // (each row by one thread).
  void InterpolateSmooth() {
    const auto t_stage = InsertClock::now();
    for (const std::vector<Cell>& level : smooth_) {
      std::vector<std::vector<uint32_t>> by_row(ny_);
      for (size_t k = 0; k < level.size(); ++k)
        for (uint32_t r = level[k].y0; r <= level[k].y1; ++r) by_row[r].push_back(uint32_t(k));
      ParallelFor(
          ny_,
          [&](size_t r) {
            for (uint32_t k : by_row[r]) {
              const Cell& c = level[k];
              const float wy = float(r - c.y0) / float(c.y1 - c.y0);
              const float a = kappa_grid_[c.y0 * nx_ + c.x0], b = kappa_grid_[c.y0 * nx_ + c.x1];
              const float d0 = kappa_grid_[c.y1 * nx_ + c.x0], d1 = kappa_grid_[c.y1 * nx_ + c.x1];
              for (size_t q = c.x0; q <= c.x1; ++q) {
                if (known_[r * nx_ + q]) continue;
                const float wx = float(q - c.x0) / float(c.x1 - c.x0);
                kappa_grid_[r * nx_ + q] =
                    (1 - wx) * (1 - wy) * a + wx * (1 - wy) * b + (1 - wx) * wy * d0 + wx * wy * d1;
              }
            }
          },
          8);
    }
    kappa_ms_ += MsSince(t_stage);
  }

  // The per-row counters into the frame's timings (summed in row order).
  void Count() {
    times_.kappa_receivers_ms = find_ms_;
    times_.kappa_lookup_ms = kappa_ms_;
    for (size_t q : looked_up_per_row_) times_.kappa_lookups += q;
    for (size_t q : receivers_per_row_) times_.kappa_receivers += q;
    for (size_t q : queries_per_row_) layers_.kappa_queries += q;
    for (size_t q : evaluated_per_row_) times_.kappa_evaluated += q;
    for (size_t q : marched_per_row_) times_.kappa_marched += q;
    for (size_t q : reused_per_row_) times_.kappa_reused += q;
  }

  // The receivers kept for the next frame (nodes only interpolated or
  // plane-placed stay unknown).
  void KeepReceivers() {
    ReceiverFrame& kept = cache_->receivers;
    kept.valid = true;
    kept.rule = ReceiverRule(in_);
    kept.camera = camera_;
    kept.T_world_camera = T_world_camera_;
    kept.T_camera_world = T_world_camera_.Inverse();
    kept.xs = xs_;
    kept.ys = ys_;
    kept.cx = cx_;
    kept.cy = cy_;
    kept.factor = factor_;
    kept.step = spacing_px_.step;
    kept.nearest = std::numeric_limits<float>::infinity();
    for (size_t i = 0; i < node_state_.size(); ++i)
      if (node_state_[i] == 1) kept.nearest = std::min(kept.nearest, Length(node_point_[i] - eye_));
    kept.state = std::move(node_state_);
    kept.point = std::move(node_point_);
    kept.normal = std::move(node_normal_);
  }

  // The frame's inputs and outputs (loans for the pass).
  const ShadowPassInputs& in_;
  const InsertOptions& options_;
  const CameraIntrinsics& camera_;
  const Pose& T_world_camera_;
  const ObjectGBuffer& g_;
  const ReceiverOverride& receivers_;
  std::vector<LightPrep>& preps_;
  std::unique_ptr<KappaCache>& cache_owner_;
  ImageF& frame_;
  InsertLayers& layers_;
  InsertTimings& times_;
  const Vec3f eye_;
  const Aabb box_;

  // The reach rectangle and the lattice.
  std::vector<size_t> casters_;  // objects that cast: a visibility field and a radius
  PixelRect rect_;               // κ's pixels this frame
  KappaSpacing spacing_px_;
  float smallest_ = std::numeric_limits<float>::infinity();  // the smallest caster's radius
  KappaCache* cache_ = nullptr;       // the lattice and last layer; nullptr: κ exact per receiver
  double spacing_ = 0.0;              // the lattice's spacing, metres
  Vec3 shift_;                        // the lattice's nodes lie at world point node + shift_ (KappaCache::shift)
  double penumbra_per_metre_ = 1;     // the sharpest light's penumbra width per metre from the caster
  float delta_lattice_ = 0;           // corners further apart than this are not interpolated (when sharp)
  double sample_angle_ = 0;           // radians between κ samples on screen (kappa_step pixels)
  size_t levels_ = kKappaFineLevels;  // fine lattice levels used this frame
  ViewKey view_;

  // The grid: nodes at pixel columns xs_, rows ys_; coarse nodes cx_, cy_
  // (indices into them) every factor_ nodes.
  std::vector<int> xs_, ys_;
  size_t nx_ = 0, ny_ = 0;
  std::vector<size_t> cx_, cy_;
  size_t factor_ = 1;
  std::vector<float> kappa_grid_;  // κ per node, row-major
  std::vector<uint8_t> hidden_;    // nodes only the objects' pixels cover (HiddenNodes)
  // Counters per grid row (summed in order by Count, whatever the threads).
  std::vector<size_t> queries_per_row_, evaluated_per_row_, marched_per_row_, reused_per_row_, looked_up_per_row_,
      receivers_per_row_;
  double find_ms_ = 0, kappa_ms_ = 0;
  float min_opacity_ = 0;         // InsertOptions::receiver_min_opacity
  double one_minus_eps_ = 1;      // 1 − InsertOptions::shadow_epsilon
  bool reuse_receivers_ = false;  // the last frame's receivers may stand for marching
  bool cell_normals_ = false;     // one normal per world cell (InsertOptions::receiver_normal_per_cell)
  float reuse_tolerance_ = 0;     // metres
  KappaContext context_;
  uint64_t pass_ = 0;        // this pass's number (ScratchFor)
  uint64_t generation_ = 0;  // the lattice's generation (KappaCache::generation; 0: no lattice)

  // What the receiver search found at each node (for the upsampling):
  // state 0 not found, 1 surface, 2 no surface (as ReceiverFrame).
  std::vector<Vec3f> node_point_, node_normal_;
  std::vector<uint8_t> node_valid_, node_state_;
  // Receivers of one search's nodes found, per row: the surface nodes
  // (opacity above the threshold, finite point) and their own normals.
  std::vector<std::vector<CellCandidate>> found_;

  // The refinement (factor_ > 1).
  float delta_ = 0;                                          // InsertOptions::kappa_refine_delta
  std::vector<CellPlane> planes_;                            // per coarse cell (FitCellPlanes)
  const ObjectPixels* object_pixels_ = nullptr;              // during Refine
  std::vector<uint8_t> known_;                               // κ set (or scheduled) at the node
  std::vector<std::vector<Cell>> smooth_;                    // per level, cells interpolated from their corners
  std::vector<std::vector<size_t>> new_cols_, refine_cols_;  // per row: a level's new nodes; those found
  std::vector<std::vector<PlaneNode>> plane_nodes_;          // per row: a level's nodes placed on a plane
};

}  // namespace

void RenderShadows(const ShadowPassInputs& in, std::vector<LightPrep>& preps, std::unique_ptr<KappaCache>& cache,
                   ImageF& frame, InsertLayers& layers, InsertTimings& times) {
  KappaPass(in, preps, cache, frame, layers, times).Run();
}

}  // namespace nerfar
