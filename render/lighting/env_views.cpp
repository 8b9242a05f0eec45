// View sampling, BRISQUE rejection and surface samples (env_samples.h).
#include <algorithm>
#include <cmath>
#include <memory>

#include "calib/core/error.h"
#include "calib/core/log.h"
#include "calib/core/parallel.h"
#include "render/lighting/env_internal.h"
#include "render/lighting/env_samples.h"
#include "render/lighting/view_quality.h"

namespace nerfar {

using env_internal::kPixelPick;
using env_internal::kViewDir;
using env_internal::Uniform;

namespace {

// Surface normal −∇σ/|∇σ| averaged (unit gradients, equal weights) over the
// point and 6 points `scale` voxels away along the axes: a trained grid's
// gradient is noisy from vertex to vertex, and the average is the normal of
// the surface smoothed over ~2·scale voxels. False when no gradient is usable.
bool SmoothedNormal(const NerfField& field, const Vec3f& x, float scale, Vec3f* normal) {
  const float h = scale * field.voxel_m;
  const Vec3f offsets[7] = {{0, 0, 0}, {h, 0, 0}, {-h, 0, 0}, {0, h, 0}, {0, -h, 0}, {0, 0, h}, {0, 0, -h}};
  Vec3f sum;
  for (const Vec3f& o : offsets) {
    const Vec3f g = field.DensityGradient(x + o);
    const float len = Length(g);
    if (len > 1e-6f && std::isfinite(len)) sum += g * (-1.0f / len);
  }
  const float len = Length(sum);
  if (!(len > 1e-3f)) return false;
  *normal = sum * (1.0f / len);
  return true;
}

// The top of a surface's own layer of density (EnvSurfaceSamples::layer_m):
// where the camera ray's opacity reaches this fraction of its total.
constexpr float kLayerTop = 0.05f;

// Where a camera ray's opacity builds up: the distances at which the
// accumulated opacity 1 − T(t) reaches 1/4, 1/2 and 3/4 of the ray's total.
// The median t50 is the surface: in fog in front of a surface the expected
// depth Σ w t / O is pulled towards the camera by every bit of fog, the median
// only by fog that holds half the ray's opacity; on an opaque ray it is the
// point where T crosses 1/2, and on a translucent surface (a trained table of
// opacity 0.3) it still lies on the surface. The quartile spread t75 − t25
// says whether the opacity comes from a surface (a few voxels) or from a
// layer of fog (centimetres).
struct RaySurface {
  float opacity = 0;  // 1 − T at the end of the march
  float t_top = 0;    // where the opacity reaches kLayerTop of the total: the top of the surface's layer
  float t25 = 0, t50 = 0, t75 = 0;
  bool valid = false;  // opacity > 0 and the quartiles found
};
RaySurface MarchSurface(const NerfField& field, const NerfRay& ray, float step_voxels) {
  RaySurface out;
  if (!(ray.t_far > ray.t_near)) return out;
  const float dt = std::max(1e-6f, step_voxels * field.voxel_m);
  // Accumulated opacity at the end of each step (midpoint rule), as in rendering.
  std::vector<float> t_end, acc;
  double optical = 0;
  for (float t = ray.t_near; t < ray.t_far; t += dt) {
    const float len = std::min(dt, ray.t_far - t);
    optical += static_cast<double>(field.Density(ray.origin + ray.dir * (t + 0.5f * len))) * len;
    t_end.push_back(t + len);
    acc.push_back(static_cast<float>(-std::expm1(-optical)));
    if (optical > 9.2) break;  // T < 1e-4
  }
  if (acc.empty() || !(acc.back() > 0)) return out;
  out.opacity = acc.back();
  const float quantiles[4] = {kLayerTop, 0.25f, 0.5f, 0.75f};
  float* dest[4] = {&out.t_top, &out.t25, &out.t50, &out.t75};
  for (int q = 0; q < 4; ++q) {
    const float level = quantiles[q] * out.opacity;
    const size_t k = static_cast<size_t>(std::lower_bound(acc.begin(), acc.end(), level) - acc.begin());
    const float a0 = k == 0 ? 0.0f : acc[k - 1], t0 = k == 0 ? ray.t_near : t_end[k - 1];
    const float f = acc[k] > a0 ? (level - a0) / (acc[k] - a0) : 0.5f;
    *dest[q] = t0 + f * (t_end[k] - t0);
  }
  out.valid = true;
  return out;
}

// The normal of the surface seen through pixel (px, py) from the surfaces of
// the four pixels `b` away (central differences of the median-depth map),
// turned to face the camera. False at depth edges (the two one-sided
// estimates disagree by more than ~25 degrees) or when a neighbour has no surface.
bool DepthNormal(const NerfField& field, const CameraIntrinsics& camera, const Pose& pose, double px, double py,
                 const Vec3f& x, const Vec3f& view_dir, const EnvEstimateOptions& o, Vec3f* normal) {
  const double b = o.normal_baseline_px;
  const double offsets[4][2] = {{b, 0}, {-b, 0}, {0, b}, {0, -b}};
  Vec3f p[4];
  for (int k = 0; k < 4; ++k) {
    const double u = (px + offsets[k][0] - camera.cx) / camera.fx, v = (py + offsets[k][1] - camera.cy) / camera.fy;
    const Vec3 dir = Normalized(pose.rotation * Vec3{u, v, 1});
    NerfRay ray{Vec3f(pose.translation), Vec3f(dir), 0, 0};
    if (!IntersectAabb(field.aabb, ray.origin, ray.dir, ray.t_near, ray.t_far)) return false;
    const RaySurface s = MarchSurface(field, ray, o.surface_step_voxels);
    if (!s.valid || s.opacity < o.min_pixel_opacity) return false;
    p[k] = ray.origin + ray.dir * s.t50;
  }
  const Vec3f central = Cross(p[0] - p[1], p[2] - p[3]);
  const Vec3f forward = Cross(p[0] - x, p[2] - x), backward = Cross(x - p[1], x - p[3]);
  const float lc = Length(central), lf = Length(forward), lb = Length(backward);
  if (!(lc > 0 && lf > 0 && lb > 0)) return false;
  if (Dot(forward, backward) < 0.9f * lf * lb) return false;  // cos 25°: a depth edge or a fold
  Vec3f n = central * (1.0f / lc);
  if (Dot(n, view_dir) > 0) n = -n;
  *normal = n;
  return true;
}

struct ViewPick {
  double score = -1;
  int tried = 0, not_surface = 0, no_normal = 0, grazing = 0;
  std::vector<Vec3f> positions, normals, radiance;
  std::vector<float> layer;
};

// The virtual camera every sampled view uses.
CameraIntrinsics ViewCamera(const EnvEstimateOptions& options) {
  CameraIntrinsics camera;
  camera.width = options.view_width;
  camera.height = options.view_height;
  camera.fx = camera.fy = 0.5 * camera.width / std::tan(0.5 * options.view_fov_deg * kPi / 180);
  camera.cx = 0.5 * camera.width;
  camera.cy = 0.5 * camera.height;
  return camera;
}

// One rendered view's surface samples: its pixels in a random order, each
// accepted as a sample where the NeRF shows a surface there with a usable
// normal seen not too grazing.
class ViewSampler {
 public:
  ViewSampler(const NerfField& field, const EnvEstimateOptions& options, const CameraIntrinsics& camera,
              const Pose& pose, int attempt)
      : field_(field), options_(options), camera_(camera), pose_(pose), attempt_(attempt) {
    rays_ = CameraRays(camera, pose, field.aabb);
    results_.resize(rays_.size());
    field.RenderRays(rays_.data(), rays_.size(), results_.data(), options.render);
  }

  // The view as an image, for BRISQUE.
  ImageF Image() const {
    ImageF color(camera_.width, camera_.height, 3);
    for (size_t i = 0; i < results_.size(); ++i)
      for (int c = 0; c < 3; ++c) color.pixels[i * 3 + c] = results_[i].color[c];
    return color;
  }

  // Up to pixels_per_view samples into `pick`.
  void Pick(ViewPick& pick) {
    ShuffleEligible();
    // Candidates are evaluated in parallel, a batch at a time, and taken in
    // order: the result does not depend on the thread count.
    const size_t per_view = static_cast<size_t>(options_.pixels_per_view);
    for (size_t next = 0; next < tries_ && pick.positions.size() < per_view;) {
      const size_t end = std::min(tries_, next + std::max<size_t>(per_view - pick.positions.size(), 16));
      std::vector<Candidate> batch(end - next);
      ParallelFor(
          batch.size(), [&](size_t i) { Evaluate(next + i, batch[i]); }, 1);
      for (const Candidate& c : batch) {
        if (pick.positions.size() >= per_view) break;
        Take(c, pick);
      }
      next = end;
    }
  }

 private:
  enum Outcome { kAccepted, kNotSurface, kNoNormal, kGrazing, kNotFinite };
  struct Candidate {
    Outcome outcome = kNotFinite;
    Vec3f x, n, radiance;
    float layer = 0;
  };

  // The pixels opaque enough, the first `tries_` of them in a random order:
  // a partial Fisher-Yates with counter-based draws, taken in that order
  // until P are accepted.
  void ShuffleEligible() {
    for (size_t i = 0; i < results_.size(); ++i)
      if (results_[i].opacity > options_.min_pixel_opacity && rays_[i].t_far > rays_[i].t_near)
        eligible_.push_back(static_cast<uint32_t>(i));
    const size_t per_view = static_cast<size_t>(options_.pixels_per_view);
    tries_ = std::min(eligible_.size(), static_cast<size_t>(options_.max_pixel_tries_factor) * per_view);
    for (size_t k = 0; k < tries_; ++k) {
      const size_t j =
          k + static_cast<size_t>(Uniform(options_.seed, kPixelPick, attempt_, k) * (eligible_.size() - k));
      std::swap(eligible_[k], eligible_[std::min(j, eligible_.size() - 1)]);
    }
  }

  void Evaluate(size_t k, Candidate& c) const {
    const NerfRay& ray = rays_[eligible_[k]];
    const NerfRayResult& res = results_[eligible_[k]];
    // The surface: the median of the ray's opacity (see MarchSurface),
    // kept only where the opacity builds up within a few voxels.
    const RaySurface surf = MarchSurface(field_, ray, options_.surface_step_voxels);
    if (!surf.valid || surf.t75 - surf.t25 > options_.max_surface_spread_voxels * field_.voxel_m) {
      c.outcome = kNotSurface;
      return;
    }
    c.x = ray.origin + ray.dir * surf.t50;
    if (!Normal(eligible_[k], ray, c)) {
      c.outcome = kNoNormal;
      return;
    }
    // A surface seen at a grazing angle is where a noisy density gradient
    // most often gives a wrong normal (e.g. the table top's normal turned
    // sideways or down); such samples drive light from below the horizon.
    if (-Dot(c.n, ray.dir) < options_.min_view_cosine) {
      c.outcome = kGrazing;
      return;
    }
    // Observed radiance: the pixel as rendered (what the camera saw; the
    // scenes' background is black, so a translucent trained surface's pixel
    // is its radiance), or divided by the opacity (partial coverage).
    c.radiance = options_.radiance_over_opacity ? res.color * (1.0f / res.opacity) : res.color;
    c.layer = (surf.t50 - surf.t_top) * std::fabs(Dot(c.n, ray.dir));
    c.outcome = std::isfinite(c.radiance.x + c.radiance.y + c.radiance.z) ? kAccepted : kNotFinite;
  }

  // The normal at the candidate's point, facing the camera: from the rendered
  // depth around the pixel, or the smoothed density gradient.
  bool Normal(uint32_t pixel, const NerfRay& ray, Candidate& c) const {
    if (options_.normal_from_depth) {
      const double px = pixel % camera_.width + 0.5, py = pixel / camera_.width + 0.5;
      return DepthNormal(field_, camera_, pose_, px, py, c.x, ray.dir, options_, &c.n);
    }
    if (!SmoothedNormal(field_, c.x, static_cast<float>(options_.normal_scale_voxels), &c.n)) return false;
    if (Dot(c.n, ray.dir) > 0) c.n = -c.n;  // the camera sees the surface: face it
    return true;
  }

  static void Take(const Candidate& c, ViewPick& pick) {
    ++pick.tried;
    switch (c.outcome) {
      case kAccepted:
        pick.positions.push_back(c.x);
        pick.normals.push_back(c.n);
        pick.radiance.push_back(c.radiance);
        pick.layer.push_back(c.layer);
        break;
      case kNotSurface:
        ++pick.not_surface;
        break;
      case kNoNormal:
        ++pick.no_normal;
        break;
      case kGrazing:
        ++pick.grazing;
        break;
      case kNotFinite:
        break;
    }
  }

  const NerfField& field_;
  const EnvEstimateOptions& options_;
  const CameraIntrinsics& camera_;
  const Pose pose_;
  const int attempt_;
  std::vector<NerfRay> rays_;
  std::vector<NerfRayResult> results_;
  std::vector<uint32_t> eligible_;
  size_t tries_ = 0;
};

// Too few views passed BRISQUE: the best-scoring of the rest are kept (the
// paper repeats until 100 pass; a bounded budget must end).
void KeepBestScoring(const std::vector<ViewPick>& views, const EnvEstimateOptions& options, EnvViewReport& local) {
  const int passed = local.accepted;
  std::vector<size_t> rest;
  for (size_t v = 0; v < views.size(); ++v)
    if (!local.kept[v]) rest.push_back(v);
  std::stable_sort(rest.begin(), rest.end(), [&](size_t a, size_t b) { return views[a].score < views[b].score; });
  for (size_t i = 0; i < rest.size() && local.accepted < options.views; ++i, ++local.accepted)
    local.kept[rest[i]] = true;
  LogWarning("env: only " + std::to_string(passed) + " of " + std::to_string(local.rendered) + " views scored <= " +
             std::to_string(options.brisque_max) + " by BRISQUE; the best-scoring others were kept");
}

// The kept views' samples, in view order, and their pixel counts.
EnvSurfaceSamples GatherKept(const std::vector<ViewPick>& views, EnvViewReport& local) {
  EnvSurfaceSamples samples;
  for (size_t v = 0; v < views.size(); ++v) {
    if (!local.kept[v]) continue;
    local.pixels_tried += views[v].tried;
    local.pixels_not_surface += views[v].not_surface;
    local.pixels_no_normal += views[v].no_normal;
    local.pixels_grazing += views[v].grazing;
    samples.positions.insert(samples.positions.end(), views[v].positions.begin(), views[v].positions.end());
    samples.normals.insert(samples.normals.end(), views[v].normals.begin(), views[v].normals.end());
    samples.radiance.insert(samples.radiance.end(), views[v].radiance.begin(), views[v].radiance.end());
    samples.layer_m.insert(samples.layer_m.end(), views[v].layer.begin(), views[v].layer.end());
  }
  return samples;
}

}  // namespace

EnvSurfaceSamples SampleSurfaces(const NerfField& field, const EnvEstimateOptions& options, EnvViewReport* report,
                                 const EnvProgress& progress) {
  const std::vector<std::string> problems = options.Validate();
  if (!problems.empty()) ThrowInputError("env options", problems.front());
  NERFAR_CHECK(!field.empty());
  const Vec3 centre = (field.aabb.min + field.aabb.max) * 0.5;
  const double radius = options.view_distance_scale * 0.5 * Length(field.aabb.max - field.aabb.min);
  const CameraIntrinsics camera = ViewCamera(options);
  const bool use_brisque = options.brisque_max < 100;
  std::unique_ptr<BrisqueScorer> scorer;
  if (use_brisque) scorer = std::make_unique<BrisqueScorer>();
  const double z_min = std::sin(options.min_view_elevation_deg * kPi / 180);

  // Views from random directions above min_view_elevation_deg, looking at
  // the volume's centre, until `views` pass BRISQUE or the attempts run out.
  std::vector<ViewPick> views;
  EnvViewReport local;
  for (int a = 0; a < options.max_view_attempts && local.accepted < options.views; ++a) {
    const double z = z_min + (1 - z_min) * Uniform(options.seed, kViewDir, a, 0);
    const double phi = 2 * kPi * Uniform(options.seed, kViewDir, a, 1);
    const double r = std::sqrt(std::max(0.0, 1 - z * z));
    const Pose pose = LookAt(centre + Vec3{r * std::cos(phi), r * std::sin(phi), z} * radius, centre);
    ViewSampler sampler(field, options, camera, pose, a);
    ViewPick pick;
    if (use_brisque) pick.score = scorer->ScoreLinear(sampler.Image());
    sampler.Pick(pick);
    const bool ok = !use_brisque || pick.score <= options.brisque_max;
    local.scores.push_back(pick.score);
    local.kept.push_back(ok);
    local.poses.push_back(pose);
    if (ok) ++local.accepted;
    views.push_back(std::move(pick));
    if (progress) progress("views", static_cast<size_t>(local.accepted), static_cast<size_t>(options.views));
  }
  local.rendered = static_cast<int>(views.size());
  local.camera = camera;
  if (local.accepted < options.views) KeepBestScoring(views, options, local);
  EnvSurfaceSamples samples = GatherKept(views, local);
  if (report) *report = std::move(local);
  return samples;
}

}  // namespace nerfar
