#include "render/lighting/seen_radiance.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>

#include "calib/core/error.h"
#include "calib/core/parallel.h"
#include "render/sg/sg.h"

namespace nerfar {
namespace {
constexpr float kFar = 4.0f;  // metres from the point to the start of a view's ray (outside any tabletop volume)
// Face views are picked from a spiral of this many directions per view over
// the band (a face that sees a tenth of the band still gets ~1.6 per view).
constexpr int kFaceCandidatesPerView = 16;

// The i-th of `count` picks spread evenly over `size` items: the middle of its share.
size_t SpreadIndex(size_t i, size_t count, size_t size) { return (2 * i + 1) * size / (2 * count); }

// `count` directions (from a point towards a camera) on a spiral over the
// band's elevations [lo, hi] (radians): evenly in elevation, golden-angle
// steps in azimuth.
std::vector<Vec3f> BandSpiral(double lo, double hi, int count) {
  std::vector<Vec3f> dirs;
  const double golden = kPi * (3.0 - std::sqrt(5.0));
  for (int k = 0; k < count; ++k) {
    const double el = lo + (hi - lo) * (k + 0.5) / count, az = golden * k;
    dirs.push_back(Vec3f(Vec3{std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)}));
  }
  return dirs;
}

// How many of the capture's cameras the views take: at most as many as the
// band has face candidates, so that a long capture (a video's thousands of
// frames) costs each point no more candidates than the band does.
size_t CaptureCamerasUsed(const NerfField& field, const SeenRadianceOptions& options) {
  return std::min(field.capture_centres.size(), static_cast<size_t>(kFaceCandidatesPerView * options.views));
}

}  // namespace

std::string SeenViewsNote(const NerfField& field, const SeenRadianceOptions& options) {
  const size_t all = field.capture_centres.size(), used = CaptureCamerasUsed(field, options);
  if (all == 0) return "views from the capture band: the model does not store its cameras (retrain it to store them)";
  return "views from " + (used < all ? std::to_string(used) + " of " : std::string()) + "the capture's " +
         std::to_string(all) + " cameras";
}

bool AgreeingRadiance(const std::vector<Vec3f>& radiances, double agree_fraction, Vec3f& out) {
  if (radiances.empty()) return false;
  double brightest = -1;
  for (const Vec3f& c : radiances) brightest = std::max(brightest, LuminanceOf(Vec3(c)));
  Vec3 sum{};
  int count = 0;
  for (const Vec3f& c : radiances)
    if (LuminanceOf(Vec3(c)) >= agree_fraction * std::max(brightest, 0.0)) {
      sum += Vec3(c);
      ++count;
    }
  if (count == 0)  // all darker than black (a field's negative colour): their plain mean
    for (const Vec3f& c : radiances) {
      sum += Vec3(c);
      ++count;
    }
  out = Vec3f(sum * (1.0 / count));
  return true;
}

Vec3f AveragedGradientNormal(const NerfField& field, const Vec3f& p) {
  // Normalising each gradient first keeps σ's range (1e-13 to 1e6 per
  // metre) from letting one sample decide alone; the seven smooth the
  // trilinear field's piecewise gradient.
  const float h = field.voxel_m;
  const Vec3f offsets[7] = {{0, 0, 0}, {h, 0, 0}, {-h, 0, 0}, {0, h, 0}, {0, -h, 0}, {0, 0, h}, {0, 0, -h}};
  Vec3f g{};
  for (const Vec3f& o : offsets) {
    const Vec3f d = field.DensityGradient(p + o);
    const float len = Length(d);
    if (len > 0.0f && std::isfinite(len)) g += d * (1.0f / len);
  }
  const float len = Length(g);
  return len > 0.0f && std::isfinite(len) ? g * (-1.0f / len) : Vec3f{};
}

namespace {

// What a cache's answers depend on (SeenRadianceCache::Key).
SeenRadianceCache::Key SeenRadianceKey(const NerfField& field, const SeenRadianceOptions& options,
                                       const NerfRenderOptions& render) {
  return {.field = &field,
          .density = field.density.data(),
          .density_size = field.density.size(),
          .color = field.color.data(),
          .color_size = field.color.size(),
          .occupancy = field.occupancy.data(),
          .occupancy_size = field.occupancy.size(),
          .render_copy_current = field.RenderCopyCurrent(),
          .render_copy = field.render_copy.bytes.data(),
          .voxel_m = field.voxel_m,
          .origin = field.origin,
          .aabb_min = field.aabb.min,
          .aabb_max = field.aabb.max,
          .options = options,
          .step_voxels = render.step_voxels,
          .min_transmittance = render.min_transmittance,
          .min_alpha = render.min_alpha,
          .use_render_copy = render.use_render_copy};
}

// The rays to treat, grouped by the cell (group_m, or one voxel) of their
// surface point and by kind: rays opaque enough for the seen radiance never
// share a point with fainter (see-through) ones, whose point may lie off any
// surface.
struct PointCells {
  std::vector<Vec3f> points;           // one per cell: the first ray's surface point
  std::vector<Vec3f> dirs;             // the first ray's direction (turns the face normal towards it)
  std::vector<unsigned char> surface;  // some ray there is opaque enough for the seen radiance
  std::vector<int64_t> keys;           // the cell and kind of each point (the cache's key)
  std::vector<size_t> ray_slot;        // each ray's point (SIZE_MAX: not treated)
};

PointCells GroupRaysByCell(const NerfField& field, const std::vector<NerfRay>& rays,
                           const std::vector<NerfRayResult>& results, const SeenRadianceOptions& options) {
  struct Key {
    int64_t v;
    bool operator==(const Key& o) const { return v == o.v; }
  };
  struct KeyHash {
    size_t operator()(const Key& k) const { return std::hash<int64_t>()(k.v); }
  };
  std::unordered_map<Key, size_t, KeyHash> slot_of;
  PointCells cells;
  cells.ray_slot.assign(rays.size(), SIZE_MAX);
  const double z_min = std::sin(options.min_elevation_deg * kPi / 180);
  const float voxel = options.group_m > 0.0 ? static_cast<float>(options.group_m) : field.voxel_m;
  for (size_t r = 0; r < rays.size(); ++r) {
    const NerfRayResult& res = results[r];
    const double min_opacity =
        options.see_through ? std::min(options.min_opacity, options.see_through_min_opacity) : options.min_opacity;
    if (!(res.opacity > min_opacity) || !(res.surface_depth > 0)) continue;
    if (-rays[r].dir.z >= z_min) continue;  // seen from the capture side: the NeRF's own colour
    const Vec3f x = rays[r].origin + rays[r].dir * res.surface_depth;
    const Vec3f g = (x - Vec3f(field.aabb.min)) * (1.0f / voxel);
    const int64_t i = static_cast<int64_t>(std::floor(g.x)), j = static_cast<int64_t>(std::floor(g.y)),
                  k = static_cast<int64_t>(std::floor(g.z));
    const Key key{((i * 4096 + j) * 4096 + k) * 2 + (res.opacity > options.min_opacity ? 1 : 0)};
    const auto it = slot_of.emplace(key, cells.points.size()).first;
    if (it->second == cells.points.size()) {
      cells.points.push_back(x);
      cells.keys.push_back(key.v);
      cells.dirs.push_back(rays[r].dir);
      cells.surface.push_back(0);
    }
    cells.ray_slot[r] = it->second;
    if (res.opacity > options.min_opacity) cells.surface[it->second] = 1;
  }
  return cells;
}

// Each point's answer (its seen radiance and see-through votes), the density
// samples its views took, and whether an earlier call's cache gave it.
struct PointAnswers {
  std::vector<Vec3f> seen;
  std::vector<unsigned char> reached;  // bytes: written from several threads
  std::vector<uint64_t> samples;
  std::vector<int> meet, pass;  // views that meet a surface at the point, and views that pass it (see-through)
  std::vector<unsigned char> cached;
  explicit PointAnswers(size_t n) : seen(n), reached(n, 0), samples(n, 0), meet(n, 0), pass(n, 0), cached(n, 0) {}
};

// The points of cells an earlier call answered take that answer.
void AnswerFromCache(const PointCells& cells, SeenRadianceCache& cache, PointAnswers& answers) {
  size_t fresh = 0;
  for (size_t p = 0; p < cells.points.size(); ++p) {
    const auto it = cache.cells.find(cells.keys[p]);
    if (it == cache.cells.end()) {
      ++fresh;
      continue;
    }
    answers.cached[p] = 1;
    answers.seen[p] = it->second.seen;
    answers.reached[p] = it->second.reached ? 1 : 0;
    answers.meet[p] = it->second.meet;
    answers.pass[p] = it->second.pass;
  }
  cache.hits += cells.points.size() - fresh;
  cache.misses += fresh;
  if (fresh > 0 && cache.cells.size() + fresh > cache.max_cells) cache.cells.clear();  // answers copied above
}

// The views that answer one point: the face views (the band's directions, or
// the capture's cameras, in front of the point's face) first, then the whole
// band (or cameras spread over the capture) for the see-through votes and the
// seen radiance of a point no face view saw.
class PointViews {
 public:
  PointViews(const NerfField& field, const SeenRadianceOptions& options, const NerfRenderOptions& render,
             const PointCells& cells, PointAnswers& answers)
      : field_(field), options_(options), render_(render), cells_(cells), answers_(answers) {
    // The capture's cameras (CaptureCamerasUsed), spread over its order.
    const std::vector<Vec3f>& all = field.capture_centres;
    const size_t count = CaptureCamerasUsed(field, options);
    for (size_t i = 0; i < count; ++i) cameras_.push_back(all[SpreadIndex(i, count, all.size())]);
    if (!cameras_.empty()) return;
    // Without them, the view directions (from the point towards the camera):
    // a spiral over the capture band, the same for every point.
    const double lo = options.min_elevation_deg * kPi / 180, hi = options.max_elevation_deg * kPi / 180;
    view_dirs_ = BandSpiral(lo, hi, options.views);
    // Candidates of the face views: a denser spiral, the same for every point.
    if (options.face_views) face_candidates_ = BandSpiral(lo, hi, kFaceCandidatesPerView * options.views);
  }

  void Answer(size_t p) const {
    if (answers_.cached[p]) return;
    std::vector<Vec3f> found;
    const std::vector<Vec3f> cameras = TowardsCameras(p);
    if (options_.face_views && cells_.surface[p]) {
      FaceViews(p, cameras, found);
      Settle(p, found);
    }
    const bool face_seen = answers_.reached[p] != 0;
    if (face_seen && !options_.see_through) return;
    BandViews(p, cameras, face_seen, found);
    if (!face_seen) Settle(p, found);
  }

 private:
  // One view from outside the volume towards the point, along -u (false
  // where it misses the volume).
  bool Look(size_t p, const Vec3f& u, NerfRayResult& res) const {
    NerfRay ray{cells_.points[p] + u * kFar, -u, 0, 0};
    if (!IntersectAabb(field_.aabb, ray.origin, ray.dir, ray.t_near, ray.t_far)) return false;
    res = field_.RenderRay(ray, render_);
    answers_.samples[p] += res.samples;
    return true;
  }
  // The radiance (per unit opacity) of a view that sees the point.
  static void Keep(const NerfRayResult& res, std::vector<Vec3f>& found) {
    found.push_back(res.color * (1.0f / res.opacity));
  }
  // The seen radiance the views found agree on (AgreeingRadiance).
  void Settle(size_t p, std::vector<Vec3f>& found) const {
    if (AgreeingRadiance(found, options_.agree_fraction, answers_.seen[p])) answers_.reached[p] = 1;
    found.clear();
  }

  // Unit directions from point p towards the capture's cameras.
  std::vector<Vec3f> TowardsCameras(size_t p) const {
    std::vector<Vec3f> towards;
    towards.reserve(cameras_.size());
    for (const Vec3f& c : cameras_) {
      const Vec3f d = c - cells_.points[p];
      if (Dot(d, d) > 0.0f) towards.push_back(Normalized(d));
    }
    return towards;
  }

  // `cameras`: TowardsCameras(p).
  void FaceViews(size_t p, const std::vector<Vec3f>& cameras, std::vector<Vec3f>& found) const {
    Vec3f n = AveragedGradientNormal(field_, cells_.points[p]);
    if (Dot(n, cells_.dirs[p]) > 0.0f) n = -n;  // the face the ray meets
    std::vector<const Vec3f*> facing;
    if (Dot(n, n) > 0.5f)
      for (const Vec3f& u : cameras.empty() ? face_candidates_ : cameras)
        if (Dot(u, n) >= options_.face_min_cosine) facing.push_back(&u);
    const size_t count = std::min(facing.size(), static_cast<size_t>(options_.views));
    for (size_t i = 0; i < count; ++i) {
      // Evenly over the facing candidates (up the band's elevations, or over the capture's order).
      NerfRayResult res;
      if (!Look(p, *facing[SpreadIndex(i, count, facing.size())], res)) continue;
      if (res.opacity > options_.min_opacity && std::fabs(res.surface_depth - kFar) <= options_.face_reach_m)
        Keep(res, found);
    }
  }

  // `cameras`: TowardsCameras(p).
  void BandViews(size_t p, const std::vector<Vec3f>& cameras, bool face_seen, std::vector<Vec3f>& found) const {
    // With the cameras: `views` of them spread over the list (a capture's order walks round the table).
    std::vector<Vec3f> picked;
    const size_t count = std::min(cameras.size(), static_cast<size_t>(options_.views));
    for (size_t i = 0; i < count; ++i) picked.push_back(cameras[SpreadIndex(i, count, cameras.size())]);
    for (const Vec3f& u : cameras.empty() ? view_dirs_ : picked) {
      NerfRayResult res;
      if (!Look(p, u, res)) continue;
      // The point lies kFar along the view. The vote (see-through): a view
      // still more than half transparent past the point sees through it,
      // one whose surface lies at it (within see_through_reach_m) meets
      // matter, one stopped before it is hidden and says nothing.
      const bool opaque = res.opacity > options_.min_opacity;
      const float offset = opaque ? res.surface_depth - kFar : std::numeric_limits<float>::infinity();
      if (offset > options_.see_through_reach_m)
        ++answers_.pass[p];
      else if (offset >= -options_.see_through_reach_m)
        ++answers_.meet[p];
      // The seen radiance: a surface within reach_m of the point.
      if (!face_seen && opaque && !(std::fabs(offset) > options_.reach_m)) Keep(res, found);
    }
  }

  const NerfField& field_;
  const SeenRadianceOptions& options_;
  const NerfRenderOptions& render_;
  const PointCells& cells_;
  PointAnswers& answers_;
  std::vector<Vec3f> view_dirs_, face_candidates_, cameras_;
};

// The answers applied to the rays: the seen radiance where brighter than
// the ray's own colour, the see-through share on the opacity. How many rays
// changed.
size_t ApplyAnswers(const PointCells& cells, const PointAnswers& answers, const SeenRadianceOptions& options,
                    std::vector<NerfRayResult>& results) {
  size_t changed = 0;
  for (size_t r = 0; r < results.size(); ++r) {
    const size_t p = cells.ray_slot[r];
    if (p == SIZE_MAX) continue;
    bool change = false;
    if (answers.reached[p] && results[r].opacity > options.min_opacity) {
      const Vec3f color = answers.seen[p] * results[r].opacity;
      if (LuminanceOf(Vec3(color)) > LuminanceOf(Vec3(results[r].color))) {
        results[r].color = color;
        change = true;
      }
    }
    if (options.see_through && answers.pass[p] > 0) {
      // The share of the informative views that find matter at the point.
      const float share = static_cast<float>(answers.meet[p]) / static_cast<float>(answers.meet[p] + answers.pass[p]);
      results[r].opacity *= share;
      change = true;
    }
    changed += change ? 1 : 0;
  }
  return changed;
}

}  // namespace

size_t ApplySeenRadiance(const NerfField& field, const std::vector<NerfRay>& rays, std::vector<NerfRayResult>& results,
                         const SeenRadianceOptions& options, const NerfRenderOptions& render, uint64_t* samples,
                         SeenRadianceCache* cache) {
  NERFAR_CHECK_EQ(rays.size(), results.size());
  if (cache) {
    SeenRadianceCache::Key key = SeenRadianceKey(field, options, render);
    if (cache->key != key) {
      cache->Clear();
      cache->key = std::move(key);
    }
  }
  const PointCells cells = GroupRaysByCell(field, rays, results, options);
  PointAnswers answers(cells.points.size());
  if (cache) AnswerFromCache(cells, *cache, answers);
  const PointViews views(field, options, render, cells, answers);
  ParallelFor(
      cells.points.size(), [&](size_t p) { views.Answer(p); }, 8);
  if (samples)
    for (uint64_t s : answers.samples) *samples += s;
  if (cache)
    for (size_t p = 0; p < cells.points.size(); ++p)
      if (!answers.cached[p])
        cache->cells[cells.keys[p]] = {answers.seen[p], answers.reached[p] != 0, answers.meet[p], answers.pass[p]};
  return ApplyAnswers(cells, answers, options, results);
}

}  // namespace nerfar
