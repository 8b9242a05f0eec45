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
#include "render/insert/shadow_terms.h"

namespace nerfar {

namespace {

// A coarse κ cell whose receivers lie on one plane.
struct CellPlane {
  bool valid = false;
  Vec3f point, normal;         // a point of the plane and its unit normal (facing the camera)
  float t_min = 0, t_max = 0;  // range of the corners' ray distances
};

// Per-thread scratch of the κ pass.
struct ThreadScratch {
  KappaScratch kappa;
  LatticeMemo memo;
  // The eight nodes around the last receiver (its lattice cell and normal
  // cell `corner_key`; value −1: not fetched yet): receivers a few pixels
  // apart mostly share one lattice cell, and then need no key or memo probe.
  uint64_t corner_key = ~uint64_t(0);
  std::array<float, 8> corner_value{};
};

// This thread's scratch for pass `pass` (a number new for every κ pass of
// any inserter): kept across the pass's rows, so that the memo holds the
// nodes of the rows this thread did before (neighbouring rows share most
// of their lattice cells), and emptied for a new pass (its lattice may
// hold other values).
ThreadScratch& ScratchFor(uint64_t pass) {
  thread_local ThreadScratch scratch;
  thread_local uint64_t scratch_pass = 0;
  if (scratch_pass != pass) {
    scratch.memo = LatticeMemo{};
    scratch.corner_key = ~uint64_t(0);
    scratch.kappa.cw_light = nullptr;  // the lights may have changed
    scratch_pass = pass;
  }
  return scratch;
}
std::atomic<uint64_t> g_kappa_passes{0};

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

void RenderShadows(const ShadowPassInputs& in, std::vector<LightPrep>& preps, std::unique_ptr<KappaCache>& cache_owner,
                   ImageF& frame, InsertLayers& layers, InsertTimings& times) {
  const SceneField& scene = in.scene;
  const InsertOptions& options = in.options;
  const CameraIntrinsics& camera = in.camera;
  const Pose& T_world_camera = in.T_world_camera;
  const std::vector<InsertObject>& objects = in.objects;
  const std::vector<WorldSphere>& spheres = in.spheres;
  const std::vector<SgMixture>& lights = in.lights;
  const ObjectGBuffer& g = in.gbuffer;
  const ReceiverOverride& receivers = in.receivers;
  const size_t n_objects = objects.size();
  const Vec3f eye(T_world_camera.translation);
  const Aabb box = scene.Box();
  std::vector<size_t> casters;
  for (size_t j = 0; j < n_objects; ++j)
    if (objects[j].visibility && spheres[j].radius > 0) casters.push_back(j);
  if (options.shadows && !casters.empty()) {
    PixelRect rect;
    for (size_t j : casters)
      rect = Union(rect, ProjectBall(camera, T_world_camera, Vec3(spheres[j].center),
                                     options.shadow_reach_radii * spheres[j].radius));
    rect = ClipToImage(rect, camera.width, camera.height);
    // The world lattice of κ, dropped when a caster or a light changed.
    const KappaSpacing spacing_px = KappaSpacingFor(options, camera.width);
    KappaCache* cache = nullptr;
    double spacing = 0.0;
    float smallest = std::numeric_limits<float>::infinity();
    for (size_t j : casters) smallest = std::min(smallest, spheres[j].radius);
    if (options.kappa_cache_spacing_radii > 0) {
      spacing = options.kappa_cache_spacing_radii * smallest;
      // Also what shapes the κ layer kept for an unchanged camera.
      std::vector<double> key = {spacing,
                                 options.shadow_reach_radii,
                                 options.shadow_epsilon,
                                 double(spacing_px.step),
                                 double(spacing_px.factor),
                                 options.kappa_refine_delta,
                                 options.kappa_plane_upsampling ? 1.0 : 0.0,
                                 options.shadow_epsilon_snap ? 1.0 : 0.0,
                                 options.kappa_skip_covered ? 1.0 : 0.0};
      const std::vector<float> rule = ReceiverRule(in);
      key.insert(key.end(), rule.begin(), rule.end());
      for (size_t j : casters) AppendObjectKey(objects[j], key);
      for (const SgMixture& light : lights) AppendLightKey(light, key);
      // Near lobes re-aimed at each receiver change κ as much as the light does.
      for (const LightPrep& prep : preps) {
        key.push_back(prep.parallax.min_sharpness);
        key.insert(key.end(), prep.parallax.distance.begin(), prep.parallax.distance.end());
      }
      if (!cache_owner) cache_owner = std::make_unique<KappaCache>();
      if (key != cache_owner->key || cache_owner->lattice.Size() > kKappaCacheMaxNodes) {
        cache_owner->Clear();
        cache_owner->key = std::move(key);
      }
      cache_owner->lattice.Publish();  // the last frame's nodes: read without locks this frame
      cache = cache_owner.get();
    }
    // A view already passed whole under this cache (receivers marched by
    // the NeRF, the same camera within a lattice spacing and 0.1 mrad): its
    // receivers' κ < 1 − ε lie within one spacing of the shadowed nodes'
    // box, so only that box's projection needs a pass (aligned to the
    // coarse grid of the whole rectangle, so its values are unchanged).
    std::vector<double> view = {
        camera.fx, camera.fy, camera.cx, camera.cy, double(camera.width), double(camera.height)};
    AppendPoseKey(T_world_camera, 1.0, view);
    if (cache != nullptr && receivers.distance == nullptr && !rect.empty()) {
      bool seen = false;
      for (const std::vector<double>& e : cache->explored) {
        bool same = e.size() == view.size();
        for (size_t i = 0; same && i < 6; ++i) same = e[i] == view[i];
        for (size_t i = 6; same && i < 15; ++i) same = std::abs(e[i] - view[i]) <= 1e-4;            // rotation entries
        for (size_t i = 15; same && i < 18; ++i) same = std::abs(e[i] - view[i]) <= 0.5 * spacing;  // translation
        seen = seen || same;
      }
      if (!seen) {
        if (cache->explored.size() >= 16) cache->explored.erase(cache->explored.begin());  // a moving camera
        cache->explored.push_back(view);
      } else {
        PixelRect shadow;
        const Vec3f lo = cache->lattice.shadow_min(), hi = cache->lattice.shadow_max();
        if (lo.x <= hi.x) {
          const Vec3 centre = Vec3((lo + hi) * 0.5f);
          const double radius = 0.5 * Length(Vec3(hi - lo)) + 1.75 * spacing;  // + the nodes' trilinear support
          shadow = ClipToImage(ProjectBall(camera, T_world_camera, centre, radius), camera.width, camera.height);
        }
        if (shadow.empty()) {
          rect = {};
        } else {
          const int unit = spacing_px.step * static_cast<int>(spacing_px.factor);
          const auto down = [&](int v, int origin) { return origin + (std::max(v, origin) - origin) / unit * unit; };
          PixelRect r{down(shadow.x0 - unit, rect.x0), down(shadow.y0 - unit, rect.y0),
                      down(shadow.x1 + 2 * unit, rect.x0) + 1, down(shadow.y1 + 2 * unit, rect.y0) + 1};
          r = {std::max(r.x0, rect.x0), std::max(r.y0, rect.y0), std::min(r.x1, rect.x1), std::min(r.y1, rect.y1)};
          rect = r.empty() ? PixelRect{} : r;
        }
      }
    }
    layers.kappa_rect = rect;
    // Every pixel is written by MultiplyKappa (in parallel, once): no fill.
    layers.kappa = ImageF();
    layers.kappa.width = rect.width();
    layers.kappa.height = rect.height();
    layers.kappa.channels = 1;
    layers.kappa.pixels.resize(static_cast<size_t>(rect.area()));
    // The same camera exactly, the same rectangle, nothing moved: the last
    // frame's κ layer holds (NeRF receivers only).
    const bool reuse = cache != nullptr && receivers.distance == nullptr && !rect.empty() && view == cache->last_view &&
                       rect.x0 == cache->last_rect.x0 && rect.y0 == cache->last_rect.y0 &&
                       rect.x1 == cache->last_rect.x1 && rect.y1 == cache->last_rect.y1;
    if (reuse) {
      const auto t_multiply = InsertClock::now();
      std::vector<size_t> multiplied_per_row(static_cast<size_t>(rect.height()), 0);
      MultiplyKappa(cache->last_xs, cache->last_ys, cache->last_grid, rect, g, layers.kappa, frame, multiplied_per_row);
      for (size_t q : multiplied_per_row) times.kappa_multiplied += q;
      times.kappa_multiply_ms = MsSince(t_multiply);
    } else if (!rect.empty()) {
      // Light owners: each receiver takes the light of its nearest object
      // (relative to size); queries of every caster at each owner's lobe axes.
      for (size_t o = 0; o < n_objects; ++o) PrepareLight(lights[o], objects, preps[o]);
      const int step = spacing_px.step;
      const auto grid_axis = [step](int lo, int hi) {
        std::vector<int> s;
        for (int v = lo; v < hi; v += step) s.push_back(v);
        if (s.back() != hi - 1) s.push_back(hi - 1);
        return s;
      };
      const std::vector<int> xs = grid_axis(rect.x0, rect.x1), ys = grid_axis(rect.y0, rect.y1);
      const size_t nx = xs.size(), ny = ys.size();
      std::vector<float> kappa_grid(nx * ny, 1.0f);
      std::vector<size_t> queries_per_row(ny, 0);
      const float reach = static_cast<float>(options.shadow_reach_radii);
      const float min_opacity = static_cast<float>(options.receiver_min_opacity);
      const double one_minus_eps = 1.0 - options.shadow_epsilon;
      std::vector<size_t> evaluated_per_row(ny, 0), marched_per_row(ny, 0), reused_per_row(ny, 0);
      std::vector<size_t> looked_up_per_row(ny, 0), receivers_per_row(ny, 0);
      double find_ms = 0, kappa_ms = 0;
      // The last frame's receivers, when they can stand for marching.
      const bool reuse_receivers = cache != nullptr && receivers.distance == nullptr && options.kappa_receiver_reuse &&
                                   cache->receivers.valid && cache->receivers.rule == ReceiverRule(in);
      const bool cell_normals = cache != nullptr && receivers.distance == nullptr && options.receiver_normal_per_cell;
      const float reuse_tolerance = static_cast<float>(options.kappa_reuse_tolerance_radii * smallest);
      const KappaContext context{&casters, &spheres, &preps, &lights, reach, one_minus_eps, in.sources};
      const uint64_t pass = ++g_kappa_passes;
      // κ at receiver x (normal n): exact, or trilinear in the world lattice.
      const auto exact_or_lattice_kappa = [&](const Vec3f& x, const Vec3f& n, ThreadScratch& sc, size_t row) -> float {
        if (cache == nullptr) {
          bool queried = false;
          const float k = KappaAt(context, x, n, sc.kappa, &queried);
          ++evaluated_per_row[row];
          if (queried) ++queries_per_row[row];
          return k;
        }
        ++receivers_per_row[row];
        // No bound test here: nodes that the bound clears hold κ = 1.
        // Trilinear over the lattice nodes around x, for x's normal cell.
        const uint32_t cell = NormalCell(n);
        const double fx = x.x / spacing, fy = x.y / spacing, fz = x.z / spacing;
        const double bx = std::floor(fx), by = std::floor(fy), bz = std::floor(fz);
        const double wx = fx - bx, wy = fy - by, wz = fz - bz;
        const uint64_t corner_key = LatticeKey(int64_t(bx), int64_t(by), int64_t(bz), cell);
        if (corner_key != sc.corner_key) {
          sc.corner_key = corner_key;
          sc.corner_value.fill(-1.0f);
        }
        double sum = 0.0, total = 0.0;
        for (int corner = 0; corner < 8; ++corner) {
          const int dx = corner & 1, dy = (corner >> 1) & 1, dz = corner >> 2;
          const double weight = (dx ? wx : 1 - wx) * (dy ? wy : 1 - wy) * (dz ? wz : 1 - wz);
          // Nodes that hardly count are not computed (a receiver plane on a
          // lattice plane would otherwise pull in the layer beyond it).
          if (weight < 1e-3) continue;
          total += weight;
          float& cached = sc.corner_value[size_t(corner)];
          if (cached >= 0.0f) {
            sum += weight * cached;
            continue;
          }
          const int64_t i = int64_t(bx) + dx, j = int64_t(by) + dy, k = int64_t(bz) + dz;
          const uint64_t key = LatticeKey(i, j, k, cell);
          const size_t slot = LatticeMemo::Slot(key);
          float value;
          if (sc.memo.key[slot] == key && sc.memo.value[slot] >= 0.0f) {
            value = sc.memo.value[slot];
          } else if (++looked_up_per_row[row], !cache->lattice.Find(key, &value)) {
            bool queried = false;
            const Vec3f node(Vec3(double(i), double(j), double(k)) * spacing);
            value = KappaAt(context, node, CellNormal(cell), sc.kappa, &queried);
            cache->lattice.Insert(key, value);
            if (value < one_minus_eps) cache->lattice.GrowShadow(node);
            ++evaluated_per_row[row];
            if (queried) ++queries_per_row[row];
          }
          sc.memo.key[slot] = key;
          sc.memo.value[slot] = value;
          cached = value;
          sum += weight * value;
        }
        return total > 0.0 ? static_cast<float>(std::clamp(sum / total, 0.0, 1.0)) : 1.0f;
      };
      // With shadow_epsilon_snap, κ ≥ 1 − ε is 1 (the bound's rule).
      const bool snap = options.shadow_epsilon_snap;
      const auto snapped = [&](float k) { return snap && double(k) >= one_minus_eps ? 1.0f : k; };
      const auto receiver_kappa = [&](const Vec3f& x, const Vec3f& n, ThreadScratch& sc, size_t row) -> float {
        return snapped(exact_or_lattice_kappa(x, n, sc, row));
      };
      // What the receiver pass found at each grid node (for the upsampling).
      std::vector<Vec3f> node_point(nx * ny), node_normal(nx * ny);
      std::vector<uint8_t> node_valid(nx * ny, 0);
      std::vector<uint8_t> node_state(nx * ny, 0);  // 0 not found, 1 surface, 2 no surface (as ReceiverFrame)
      // Receivers of one pass's nodes found, per row: the surface nodes
      // (opacity above the threshold, finite point) and their own normals.
      std::vector<std::vector<CellCandidate>> found(ny);
      // Marched receivers with a surface (opacity ≥ receiver_min_opacity and
      // 1/2: `out.depth` is where the transmittance crossed 1/2) taken onto
      // the support plane, with its normal, where they end on it
      // (ReceiversOnPlane).
      const auto place_on_support = [&](const std::vector<size_t>& march, const SceneSamples& out,
                                        const SceneRays& rays, const std::vector<Vec3f>& dirs,
                                        const std::vector<float>& opacity, std::vector<Vec3f>& normals,
                                        std::vector<Vec3f>& points) {
        std::vector<size_t> surface;
        std::vector<Vec3f> surface_dirs;
        std::vector<float> t, t_near;
        for (size_t m = 0; m < march.size(); ++m) {
          const size_t ix = march[m];
          if (opacity[ix] < std::max(min_opacity, 0.5f) || !std::isfinite(out.depth[m])) continue;
          surface.push_back(ix);
          surface_dirs.push_back(dirs[ix]);
          t.push_back(out.depth[m]);
          t_near.push_back(rays.t_near[m]);
        }
        std::vector<uint8_t> on_plane;
        ReceiversOnPlane(scene, *in.support, eye, surface_dirs, t_near, t, on_plane);
        for (size_t k = 0; k < surface.size(); ++k)
          if (on_plane[k]) {
            points[surface[k]] = eye + dirs[surface[k]] * t[k];
            normals[surface[k]] = in.support->normal;
          }
      };
      // The receivers at the grid nodes (row, cols[j]) of one row:
      // node_state 2 (no surface) or 1 with node_point and the receiver's own
      // normal in node_normal (not yet unit; replaced by its cell's normal
      // with receiver_normal_per_cell), the surface nodes listed in found[row].
      const auto find_row = [&](size_t row, const std::vector<size_t>& cols) {
        found[row].clear();
        if (cols.empty()) return;
        const int y = ys[row];
        const size_t nc = cols.size();
        SceneRays rays;
        SceneSamples out;
        std::vector<Vec3f> points(nc), normals;
        std::vector<float> opacity(nc, 0.0f);
        std::vector<Vec3f> dirs(nc);
        for (size_t ix = 0; ix < nc; ++ix) dirs[ix] = CameraRayDirection(camera, T_world_camera, xs[cols[ix]], y);
        if (receivers.distance) {
          for (size_t ix = 0; ix < nc; ++ix) {
            const float t = receivers.distance->at(xs[cols[ix]], y);
            opacity[ix] = t > 0.0f && std::isfinite(t) ? 1.0f : 0.0f;
            points[ix] = eye + dirs[ix] * (opacity[ix] > 0 ? t : 0.0f);
          }
        } else {
          // Receivers the last frame gives (state 1 or 2); the rest marched.
          std::vector<uint8_t> given(nc, 0);
          normals.resize(nc);
          std::vector<size_t> march;
          march.reserve(nc);
          for (size_t ix = 0; ix < nc; ++ix) {
            if (reuse_receivers)
              given[ix] = static_cast<uint8_t>(ReuseReceiver(cache->receivers, eye, dirs[ix], xs[cols[ix]], y,
                                                             reuse_tolerance, points[ix], normals[ix]));
            if (given[ix] == 1) opacity[ix] = 1.0f;
            if (given[ix] == 0) march.push_back(ix);
          }
          reused_per_row[row] += nc - march.size();
          if (!march.empty()) {
            rays.Reserve(march.size());
            for (size_t ix : march) {
              const auto range = IntersectBox(box, Vec3(eye), Vec3(dirs[ix]));
              rays.Add(eye, dirs[ix], range ? static_cast<float>(range->first) : 0.0f,
                       range ? static_cast<float>(range->second) : 0.0f);
            }
            scene.RenderRays(rays, out);
            marched_per_row[row] += march.size();
            std::vector<Vec3f> marched_points(march.size()), marched_normals;
            for (size_t m = 0; m < march.size(); ++m) {
              const size_t ix = march[m];
              opacity[ix] = std::isfinite(out.opacity[m]) ? out.opacity[m] : 0.0f;
              const float t = std::isfinite(out.depth[m]) ? out.depth[m] : 0.0f;
              points[ix] = marched_points[m] = eye + dirs[ix] * t;
            }
            scene.Normals(marched_points, marched_normals);
            for (size_t m = 0; m < march.size(); ++m) normals[march[m]] = marched_normals[m];
            if (in.support != nullptr) place_on_support(march, out, rays, dirs, opacity, normals, points);
          }
        }
        if (receivers.normal) {
          normals.resize(nc);
          for (size_t ix = 0; ix < nc; ++ix)
            normals[ix] = {receivers.normal->at(xs[cols[ix]], y, 0), receivers.normal->at(xs[cols[ix]], y, 1),
                           receivers.normal->at(xs[cols[ix]], y, 2)};
        } else if (receivers.distance) {
          scene.Normals(points, normals);
        }
        for (size_t ix = 0; ix < nc; ++ix) {
          const size_t node = row * nx + cols[ix];
          node_state[node] = 2;
          if (opacity[ix] < min_opacity || !Finite(points[ix])) continue;
          node_state[node] = 1;
          node_point[node] = points[ix];
          node_normal[node] = normals[ix];
          found[row].push_back({node, points[ix], normals[ix]});
        }
      };
      // With receiver_normal_per_cell, between finding one pass's receivers
      // and their κ: every receiver in a world cell takes that cell's normal
      // (CellNormals: kept from earlier passes, else the deterministic pick
      // among this pass's receivers in it), whatever the threads' order.
      const auto resolve_cell_normals = [&]() {
        if (!cell_normals) return;
        std::vector<CellCandidate> all;
        for (const std::vector<CellCandidate>& row : found) all.insert(all.end(), row.begin(), row.end());
        cache->cell_normals.Resolve(spacing, all);
        for (const CellCandidate& c : all) node_normal[c.node] = c.normal;
      };
      // κ at the receivers find_row found in this row (cols as there).
      const auto kappa_row = [&](size_t row, const std::vector<size_t>& cols) {
        ThreadScratch& scratch = ScratchFor(pass);
        for (size_t q : cols) {
          const size_t node = row * nx + q;
          if (node_state[node] != 1) continue;
          Vec3f n = node_normal[node];
          if (!Finite(n) || Dot(n, n) < 0.25f) {
            node_state[node] = 2;
            continue;
          }
          n = Normalized(n);
          node_normal[node] = n;
          node_valid[node] = 1;
          kappa_grid[node] = receiver_kappa(node_point[node], n, scratch, row);
        }
      };
      // Coarse to fine: κ at every coarse_factor-th node; cells whose corners
      // differ by more than kappa_refine_delta get all their nodes, the
      // others are interpolated (κ varies slowly away from edges).
      size_t factor = spacing_px.factor;
      if (nx < 2 * factor || ny < 2 * factor) factor = 1;  // too small a grid to coarsen
      const auto coarse_axis = [factor](size_t n) {
        std::vector<size_t> c;
        for (size_t i = 0; i < n; i += factor) c.push_back(i);
        if (c.back() != n - 1) c.push_back(n - 1);
        return c;
      };
      const std::vector<size_t> cx = coarse_axis(nx), cy = coarse_axis(ny);
      auto t_stage = InsertClock::now();
      // Nodes no background pixel needs (kappa_skip_covered): neither found
      // nor evaluated, except coarse nodes of a coarse grid (their cells'
      // refinement compares them).
      const std::vector<uint8_t> hidden =
          options.kappa_skip_covered ? HiddenNodes(xs, ys, g) : std::vector<uint8_t>(nx * ny, 0);
      std::vector<std::vector<size_t>> coarse_cols(cy.size());
      for (size_t i = 0; i < cy.size(); ++i)
        for (size_t q : cx)
          if (factor > 1 || !hidden[cy[i] * nx + q]) coarse_cols[i].push_back(q);
      for (size_t r = 0; r < ny; ++r)
        for (size_t q = 0; q < nx; ++q) times.kappa_hidden += hidden[r * nx + q];
      find_ms += MsSince(t_stage);
      t_stage = InsertClock::now();
      ParallelFor(
          cy.size(), [&](size_t i) { find_row(cy[i], coarse_cols[i]); }, 1);
      resolve_cell_normals();
      find_ms += MsSince(t_stage);
      t_stage = InsertClock::now();
      ParallelFor(
          cy.size(), [&](size_t i) { kappa_row(cy[i], coarse_cols[i]); }, 1);
      kappa_ms += MsSince(t_stage);
      if (factor > 1) {
        const float delta = static_cast<float>(options.kappa_refine_delta);
        // Coarse cells whose four receivers lie on one plane (normals within
        // 10° of their mean, points within 5% of the cell's size of the
        // plane through their mean); only where the receivers were marched.
        std::vector<CellPlane> planes((cy.size() - 1) * (cx.size() - 1));
        if (options.kappa_plane_upsampling && receivers.distance == nullptr) {
          for (size_t j = 0; j + 1 < cy.size(); ++j)
            for (size_t i = 0; i + 1 < cx.size(); ++i) {
              const size_t corner[4] = {cy[j] * nx + cx[i], cy[j] * nx + cx[i + 1], cy[j + 1] * nx + cx[i],
                                        cy[j + 1] * nx + cx[i + 1]};
              CellPlane& plane = planes[j * (cx.size() - 1) + i];
              Vec3f mean_p{}, mean_n{};
              bool ok = true;
              for (size_t c : corner) {
                ok = ok && node_valid[c];
                mean_p = mean_p + node_point[c] * 0.25f;
                mean_n = mean_n + node_normal[c];
              }
              if (!ok || !(Dot(mean_n, mean_n) > 1e-6f)) continue;
              mean_n = Normalized(mean_n);
              float size = 0.0f, off = 0.0f;
              plane.t_min = std::numeric_limits<float>::infinity();
              plane.t_max = 0.0f;
              for (size_t c : corner) {
                ok = ok && Dot(node_normal[c], mean_n) > 0.985f;
                size = std::max(size, Length(node_point[c] - mean_p));
                off = std::max(off, std::abs(Dot(node_point[c] - mean_p, mean_n)));
                const float t = Length(node_point[c] - eye);
                plane.t_min = std::min(plane.t_min, t);
                plane.t_max = std::max(plane.t_max, t);
              }
              if (!ok || off > 0.05f * size) continue;
              plane.valid = true;
              plane.point = mean_p;
              plane.normal = mean_n;
            }
        }
        // Cells of the grid by node index ranges [x0, x1] × [y0, y1], refined
        // level by level: a cell whose corners differ by more than
        // kappa_refine_delta gets the nodes that halve it (edge midpoints and
        // centre), each half then tested the same way with its own corners
        // down to cells one node apart (a soft gradient stops at the first
        // half whose corners agree; an edge is followed to every node). Cells
        // that pass are interpolated from their corners (`smooth`, per level:
        // a finer level's values win on the edges they share).
        struct Cell {
          uint32_t x0, y0, x1, y1;
        };
        const auto differ = [&](const Cell& c) {
          const float a = kappa_grid[c.y0 * nx + c.x0], b = kappa_grid[c.y0 * nx + c.x1];
          const float d0 = kappa_grid[c.y1 * nx + c.x0], d1 = kappa_grid[c.y1 * nx + c.x1];
          return std::max({a, b, d0, d1}) - std::min({a, b, d0, d1}) > delta;
        };
        std::vector<Cell> refine;
        std::vector<std::vector<Cell>> smooth(1);
        // Cells on the objects' outline are refined whatever their corners,
        // at every level (ObjectPixels).
        const ObjectPixels object_pixels(g);
        const auto refined = [&](const Cell& c) {
          return differ(c) || object_pixels.Outline(xs[c.x0], ys[c.y0], xs[c.x1], ys[c.y1]);
        };
        for (size_t j = 0; j + 1 < cy.size(); ++j)
          for (size_t i = 0; i + 1 < cx.size(); ++i) {
            const Cell c{uint32_t(cx[i]), uint32_t(cy[j]), uint32_t(cx[i + 1]), uint32_t(cy[j + 1])};
            (refined(c) ? refine : smooth[0]).push_back(c);
          }
        std::vector<uint8_t> known(nx * ny, 0);  // κ set (or scheduled) at the node
        for (size_t r : cy)
          for (size_t q : cx) known[r * nx + q] = 1;
        // A coarse cell left smooth whose border holds nodes its refined
        // neighbours found differing from its corners by more than the delta
        // (an edge that entered it between its corners) is refined in turn.
        const auto border_differs = [&](const Cell& c) {
          float lo = kappa_grid[c.y0 * nx + c.x0], hi = lo;
          const auto take = [&](size_t node) {
            if (!known[node]) return;
            lo = std::min(lo, kappa_grid[node]);
            hi = std::max(hi, kappa_grid[node]);
          };
          for (uint32_t q = c.x0; q <= c.x1; ++q) take(c.y0 * nx + q), take(c.y1 * nx + q);
          for (uint32_t r = c.y0; r <= c.y1; ++r) take(r * nx + c.x0), take(r * nx + c.x1);
          return hi - lo > delta;
        };
        std::vector<std::vector<size_t>> new_cols(ny), refine_cols(ny);
        // Nodes inside a planar coarse cell take their receiver on the plane.
        struct PlaneNode {
          size_t q;
          Vec3f point;
          const CellPlane* plane;
        };
        std::vector<std::vector<PlaneNode>> plane_nodes(ny);
        for (;;) {
          while (!refine.empty()) {
            // This level's nodes per row: each cell's halving nodes; hidden ones
            // only where no finer cell compares them (the cell's halves hold no
            // node inside).
            std::vector<size_t> rows;
            const auto schedule = [&](uint32_t q, uint32_t r, bool skip_hidden) {
              const size_t node = size_t(r) * nx + q;
              if (known[node] || (skip_hidden && hidden[node])) return;
              known[node] = 1;
              if (new_cols[r].empty()) rows.push_back(r);
              new_cols[r].push_back(q);
            };
            for (const Cell& c : refine) {
              const bool last = c.x1 - c.x0 <= 2 && c.y1 - c.y0 <= 2;
              const uint32_t px[3] = {c.x0, (c.x0 + c.x1) / 2, c.x1}, py[3] = {c.y0, (c.y0 + c.y1) / 2, c.y1};
              for (uint32_t r : py)
                for (uint32_t q : px) schedule(q, r, last);
            }
            std::sort(rows.begin(), rows.end());
            for (std::vector<CellCandidate>& f : found) f.clear();
            // Per row: plane nodes placed, the others found, ...
            t_stage = InsertClock::now();
            ParallelFor(
                rows.size(),
                [&](size_t k) {
                  const size_t r = rows[k];
                  std::vector<size_t>& cols = refine_cols[r];
                  cols.clear();
                  plane_nodes[r].clear();
                  std::sort(new_cols[r].begin(), new_cols[r].end());
                  const size_t j = std::min<size_t>(r / factor, cy.size() - 2);
                  for (size_t q : new_cols[r]) {
                    // Depth-aware upsampling: inside a planar coarse cell the
                    // receiver is where this node's ray meets the plane.
                    const CellPlane& plane = planes[j * (cx.size() - 1) + std::min<size_t>(q / factor, cx.size() - 2)];
                    if (plane.valid) {
                      const Vec3f d = CameraRayDirection(camera, T_world_camera, xs[q], ys[r]);
                      const float cosine = Dot(d, plane.normal);
                      const float t = cosine < -0.05f ? Dot(plane.point - eye, plane.normal) / cosine : -1.0f;
                      if (t >= 0.9f * plane.t_min && t <= 1.1f * plane.t_max) {
                        plane_nodes[r].push_back({q, eye + d * t, &plane});
                        continue;
                      }
                    }
                    cols.push_back(q);
                  }
                  new_cols[r].clear();
                  find_row(r, cols);
                },
                1);
            resolve_cell_normals();
            // Plane-placed nodes take their world cell's normal too (a new
            // cell's from their planes' normals), so that their lattice nodes,
            // like every receiver's, do not change with the view: the mean
            // normal of a coarse cell's corners changes as the grid slides over
            // the scene, and each new normal cell costs eight new lattice nodes.
            if (cell_normals) {
              std::vector<CellCandidate> placed;
              for (size_t r : rows)
                for (const PlaneNode& p : plane_nodes[r]) placed.push_back({r * nx + p.q, p.point, p.plane->normal});
              cache->cell_normals.Resolve(spacing, placed);
              for (const CellCandidate& c : placed) node_normal[c.node] = c.normal;
            }
            find_ms += MsSince(t_stage);
            // ... then their κ.
            t_stage = InsertClock::now();
            ParallelFor(
                rows.size(),
                [&](size_t k) {
                  const size_t r = rows[k];
                  ThreadScratch& scratch = ScratchFor(pass);
                  for (const PlaneNode& p : plane_nodes[r])
                    kappa_grid[r * nx + p.q] =
                        receiver_kappa(p.point, cell_normals ? node_normal[r * nx + p.q] : p.plane->normal, scratch, r);
                  kappa_row(r, refine_cols[r]);
                },
                1);
            kappa_ms += MsSince(t_stage);
            // The halves of this level's cells (those with nodes inside).
            std::vector<Cell> next;
            smooth.emplace_back();
            for (const Cell& c : refine) {
              const uint32_t xm = (c.x0 + c.x1) / 2, ym = (c.y0 + c.y1) / 2;
              const bool split_x = c.x1 - c.x0 >= 2, split_y = c.y1 - c.y0 >= 2;
              for (int b = 0; b < (split_y ? 2 : 1); ++b)
                for (int a = 0; a < (split_x ? 2 : 1); ++a) {
                  const Cell h{split_x ? (a ? xm : c.x0) : c.x0, split_y ? (b ? ym : c.y0) : c.y0,
                               split_x ? (a ? c.x1 : xm) : c.x1, split_y ? (b ? c.y1 : ym) : c.y1};
                  if (h.x1 - h.x0 <= 1 && h.y1 - h.y0 <= 1) continue;  // every node a corner
                  (refined(h) ? next : smooth.back()).push_back(h);
                }
            }
            refine = std::move(next);
          }
          std::vector<Cell> still;
          for (const Cell& c : smooth[0]) (border_differs(c) ? refine : still).push_back(c);
          if (refine.empty()) break;
          smooth[0] = std::move(still);
        }
        // The rest bilinear in its cell, level by level (each row by one thread).
        t_stage = InsertClock::now();
        for (const std::vector<Cell>& level : smooth) {
          std::vector<std::vector<uint32_t>> by_row(ny);
          for (size_t k = 0; k < level.size(); ++k)
            for (uint32_t r = level[k].y0; r <= level[k].y1; ++r) by_row[r].push_back(uint32_t(k));
          ParallelFor(
              ny,
              [&](size_t r) {
                for (uint32_t k : by_row[r]) {
                  const Cell& c = level[k];
                  const float wy = float(r - c.y0) / float(c.y1 - c.y0);
                  const float a = kappa_grid[c.y0 * nx + c.x0], b = kappa_grid[c.y0 * nx + c.x1];
                  const float d0 = kappa_grid[c.y1 * nx + c.x0], d1 = kappa_grid[c.y1 * nx + c.x1];
                  for (size_t q = c.x0; q <= c.x1; ++q) {
                    if (known[r * nx + q]) continue;
                    const float wx = float(q - c.x0) / float(c.x1 - c.x0);
                    kappa_grid[r * nx + q] =
                        (1 - wx) * (1 - wy) * a + wx * (1 - wy) * b + (1 - wx) * wy * d0 + wx * wy * d1;
                  }
                }
              },
              8);
        }
        kappa_ms += MsSince(t_stage);
      }
      // Nodes no background pixel reads hold 1 (κ is not applied there).
      for (size_t i = 0; i < nx * ny; ++i)
        if (hidden[i]) kappa_grid[i] = 1.0f;
      times.kappa_receivers_ms = find_ms;
      times.kappa_lookup_ms = kappa_ms;
      for (size_t q : looked_up_per_row) times.kappa_lookups += q;
      for (size_t q : receivers_per_row) times.kappa_receivers += q;
      for (size_t q : queries_per_row) layers.kappa_queries += q;
      for (size_t q : evaluated_per_row) times.kappa_evaluated += q;
      for (size_t q : marched_per_row) times.kappa_marched += q;
      for (size_t q : reused_per_row) times.kappa_reused += q;
      if (cache != nullptr && receivers.distance == nullptr && options.kappa_receiver_reuse) {
        // Kept for the next frame (nodes only interpolated or plane-placed
        // stay unknown).
        ReceiverFrame& kept = cache->receivers;
        kept.valid = true;
        kept.rule = ReceiverRule(in);
        kept.camera = camera;
        kept.T_world_camera = T_world_camera;
        kept.T_camera_world = T_world_camera.Inverse();
        kept.xs = xs;
        kept.ys = ys;
        kept.cx = cx;
        kept.cy = cy;
        kept.factor = factor;
        kept.step = step;
        kept.nearest = std::numeric_limits<float>::infinity();
        for (size_t i = 0; i < node_state.size(); ++i)
          if (node_state[i] == 1) kept.nearest = std::min(kept.nearest, Length(node_point[i] - eye));
        kept.state = std::move(node_state);
        kept.point = std::move(node_point);
        kept.normal = std::move(node_normal);
      }
      // Bilinear from the sample grid to every pixel; multiply the background
      // where no object covers it. Cell by cell of the grid: a cell whose
      // four nodes hold κ = 1 is skipped whole (the layer is 1 already).
      // Per row, the grid's two rows are first blended in y at the cell's
      // two columns, then each pixel is one step along x; the multiply runs
      // over the row's passed pixels, around the objects' pixels.
      const auto t_multiply = InsertClock::now();
      std::vector<size_t> multiplied_per_row(static_cast<size_t>(rect.height()), 0);
      MultiplyKappa(xs, ys, kappa_grid, rect, g, layers.kappa, frame, multiplied_per_row);
      for (size_t q : multiplied_per_row) times.kappa_multiplied += q;
      times.kappa_multiply_ms = MsSince(t_multiply);
      if (cache != nullptr && receivers.distance == nullptr) {
        cache->last_view = view;
        cache->last_rect = rect;
        cache->last_xs = xs;
        cache->last_ys = ys;
        cache->last_grid = std::move(kappa_grid);
      }
    }
  }
}

}  // namespace nerfar
