#include "render/lighting/env_estimate.h"

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <numeric>

#include "calib/core/error.h"
#include "calib/core/json.h"
#include "calib/core/log.h"
#include "calib/core/parallel.h"
#include "calib/core/random.h"
#include "render/lighting/seen_radiance.h"
#include "render/lighting/view_quality.h"
#include "render/sg/sphere.h"
#include "render/sg/visibility.h"

namespace nerfar {
namespace {

// ----------------------------------------------------------------- randomness
// Counter-based: a number is fixed by (seed, stream, item, k), so results do
// not depend on the order or the thread that draws them.
double Uniform(uint64_t seed, uint64_t stream, uint64_t item, uint64_t k) {
  return UnitDouble(CounterHash(seed, stream, item, k));
}
enum Stream : uint64_t { kViewDir = 1, kPixelPick = 2, kRayTurn = 3 };

double Y(const Vec3& rgb) { return LuminanceOf(rgb); }
Vec3 ToD(const Vec3f& v) { return Vec3(v); }

void OrthonormalBasis(const Vec3& n, Vec3& t, Vec3& b) {
  const Vec3 helper = std::fabs(n.z) < 0.9 ? Vec3{0, 0, 1} : Vec3{1, 0, 0};
  t = Normalized(Cross(helper, n));
  b = Cross(n, t);
}

// R cosine-distributed directions about +z: a Fibonacci spiral on the unit
// disk lifted to the hemisphere (Malley), each standing for π/R of ∫cos dω.
std::vector<Vec3> CosineHemisphere(int count) {
  std::vector<Vec3> dirs(count);
  const double golden = kPi * (3.0 - std::sqrt(5.0));
  for (int j = 0; j < count; ++j) {
    const double r = std::sqrt((j + 0.5) / count), phi = golden * j;
    dirs[j] = {r * std::cos(phi), r * std::sin(phi), std::sqrt(std::max(0.0, 1.0 - r * r))};
  }
  return dirs;
}

// ------------------------------------------------------------------- options
struct OptionField {
  const char* name;
  enum Kind { kInt, kDouble, kBool, kFloat, kU64 } kind;
  void* ptr;
};
std::vector<OptionField> Fields(EnvEstimateOptions& o) {
  using F = OptionField;
  return {{"views", F::kInt, &o.views},
          {"pixels_per_view", F::kInt, &o.pixels_per_view},
          {"view_width", F::kInt, &o.view_width},
          {"view_height", F::kInt, &o.view_height},
          {"view_fov_deg", F::kDouble, &o.view_fov_deg},
          {"view_distance_scale", F::kDouble, &o.view_distance_scale},
          {"min_view_elevation_deg", F::kDouble, &o.min_view_elevation_deg},
          {"brisque_max", F::kDouble, &o.brisque_max},
          {"max_view_attempts", F::kInt, &o.max_view_attempts},
          {"min_pixel_opacity", F::kDouble, &o.min_pixel_opacity},
          {"min_view_cosine", F::kDouble, &o.min_view_cosine},
          {"max_surface_spread_voxels", F::kDouble, &o.max_surface_spread_voxels},
          {"max_pixel_tries_factor", F::kInt, &o.max_pixel_tries_factor},
          {"surface_step_voxels", F::kFloat, &o.surface_step_voxels},
          {"normal_from_depth", F::kBool, &o.normal_from_depth},
          {"normal_baseline_px", F::kDouble, &o.normal_baseline_px},
          {"normal_scale_voxels", F::kDouble, &o.normal_scale_voxels},
          {"radiance_over_opacity", F::kBool, &o.radiance_over_opacity},
          {"rays_per_point", F::kInt, &o.rays_per_point},
          {"ray_offset_voxels", F::kDouble, &o.ray_offset_voxels},
          {"near_field_pool_m", F::kDouble, &o.near_field_pool_m},
          {"near_field_seen_radiance", F::kBool, &o.near_field_seen_radiance},
          {"seen_radiance_views", F::kInt, &o.seen_radiance_views},
          {"step_voxels", F::kFloat, &o.render.step_voxels},
          {"min_transmittance", F::kFloat, &o.render.min_transmittance},
          {"ignore_near_field", F::kBool, &o.ignore_near_field},
          {"lobes", F::kInt, &o.lobes},
          {"dictionary_levels", F::kInt, &o.dictionary_levels},
          {"dictionary_base", F::kInt, &o.dictionary_base},
          {"dictionary_sharpness", F::kDouble, &o.dictionary_sharpness},
          {"iterations", F::kInt, &o.iterations},
          {"albedo_cell_m", F::kDouble, &o.albedo_cell_m},
          {"albedo_prior", F::kDouble, &o.albedo_prior},
          {"albedo_prior_weight", F::kDouble, &o.albedo_prior_weight},
          {"loss_epsilon", F::kDouble, &o.loss_epsilon},
          {"robust_scale", F::kDouble, &o.robust_scale},
          {"normal_balance", F::kDouble, &o.normal_balance},
          {"light_energy_weight", F::kDouble, &o.light_energy_weight},
          {"near_field_gain_max", F::kDouble, &o.near_field_gain_max},
          {"negligible_ratio", F::kDouble, &o.negligible_ratio},
          {"seed", F::kU64, &o.seed}};
}

}  // namespace

SeenRadianceOptions SeenOptions(const EnvEstimateOptions& o) {
  SeenRadianceOptions seen;
  seen.min_elevation_deg = std::max(0.0, o.min_view_elevation_deg);
  seen.views = o.seen_radiance_views;
  return seen;
}

EnvEstimateOptions EnvEstimateOptions::Preset(const std::string& name) {
  EnvEstimateOptions o;
  if (name == "balanced") return o;
  if (name == "fast") {
    o.views = 50;
    o.pixels_per_view = 48;
    o.rays_per_point = 128;
    o.dictionary_levels = 2;
    o.iterations = 8;
    o.max_view_attempts = 200;
    return o;
  }
  if (name == "accurate") {
    o.pixels_per_view = 128;
    o.rays_per_point = 512;
    o.iterations = 20;
    o.view_width = 160;
    o.view_height = 120;
    return o;
  }
  ThrowInputError("--preset", "is \"" + name + "\" (expected fast, balanced or accurate)");
}

std::vector<std::string> EnvEstimateOptions::Validate() const {
  std::vector<std::string> p;
  auto range = [&p](const char* name, double v, double lo, double hi) {
    if (!(v >= lo && v <= hi))
      p.push_back(std::string(name) + ": is " + std::to_string(v) + " (expected " + std::to_string(lo) + " to " +
                  std::to_string(hi) + ")");
  };
  range("views", views, 1, 10000);
  range("pixels_per_view", pixels_per_view, 1, 100000);
  range("view_width", view_width, 16, 4096);
  range("view_height", view_height, 16, 4096);
  range("view_fov_deg", view_fov_deg, 1, 170);
  range("view_distance_scale", view_distance_scale, 0.1, 100);
  range("min_view_elevation_deg", min_view_elevation_deg, -90, 89);
  range("brisque_max", brisque_max, 0, 1e9);
  range("max_view_attempts", max_view_attempts, views, 1e6);
  range("min_pixel_opacity", min_pixel_opacity, 0, 1);
  range("min_view_cosine", min_view_cosine, 0, 1);
  range("max_surface_spread_voxels", max_surface_spread_voxels, 0.1, 1e6);
  range("surface_step_voxels", surface_step_voxels, 0.05, 10);
  range("max_pixel_tries_factor", max_pixel_tries_factor, 1, 1e6);
  range("normal_baseline_px", normal_baseline_px, 0.25, 64);
  range("normal_scale_voxels", normal_scale_voxels, 0.25, 64);
  range("rays_per_point", rays_per_point, 8, 65536);
  range("ray_offset_voxels", ray_offset_voxels, 0, 100);
  range("near_field_pool_m", near_field_pool_m, 0, 10);
  range("seen_radiance_views", seen_radiance_views, 1, 1024);
  range("step_voxels", render.step_voxels, 0.01, 10);
  range("min_transmittance", render.min_transmittance, 0, 1);
  range("lobes", lobes, 1, kMaxSgLobes);
  range("dictionary_levels", dictionary_levels, 1, 5);
  range("dictionary_base", dictionary_base, 4, 4096);
  range("dictionary_sharpness", dictionary_sharpness, 1e-2, 1e3);
  if (dictionary_levels >= 1 && dictionary_base >= 1 &&
      dictionary_base * ((std::pow(4.0, dictionary_levels) - 1) / 3) > 8192)
    p.push_back("dictionary_base: gives more than 8192 dictionary lobes (expected fewer levels or a smaller base)");
  range("iterations", iterations, 1, 1000);
  range("albedo_cell_m", albedo_cell_m, 0, 100);
  range("albedo_prior", albedo_prior, 0.01, 1);
  range("albedo_prior_weight", albedo_prior_weight, 0, 1e6);
  range("loss_epsilon", loss_epsilon, 1e-6, 1e3);
  range("robust_scale", robust_scale, 1e-3, 1e6);
  range("normal_balance", normal_balance, 0, 1);
  range("light_energy_weight", light_energy_weight, 0, 1e3);
  range("near_field_gain_max", near_field_gain_max, 1, 1e3);
  range("negligible_ratio", negligible_ratio, 0, 1);
  return p;
}

std::string EnvEstimateOptions::ToJson() const {
  Json doc = Json::object();
  EnvEstimateOptions copy = *this;
  for (const OptionField& f : Fields(copy)) {
    switch (f.kind) {
      case OptionField::kInt:
        doc[f.name] = *static_cast<int*>(f.ptr);
        break;
      case OptionField::kDouble:
        doc[f.name] = *static_cast<double*>(f.ptr);
        break;
      case OptionField::kFloat:
        doc[f.name] = *static_cast<float*>(f.ptr);
        break;
      case OptionField::kBool:
        doc[f.name] = *static_cast<bool*>(f.ptr);
        break;
      case OptionField::kU64:
        doc[f.name] = *static_cast<uint64_t*>(f.ptr);
        break;
    }
  }
  return DumpJson(doc, -1);
}

void EnvEstimateOptions::Set(const std::string& key_value) {
  const size_t eq = key_value.find('=');
  if (eq == std::string::npos) ThrowInputError("--set " + key_value, "has no '=' (expected key=value)");
  const std::string key = key_value.substr(0, eq), value = key_value.substr(eq + 1);
  for (const OptionField& f : Fields(*this)) {
    if (key != f.name) continue;
    try {
      size_t used = 0;
      switch (f.kind) {
        case OptionField::kInt:
          *static_cast<int*>(f.ptr) = std::stoi(value, &used);
          break;
        case OptionField::kDouble:
          *static_cast<double*>(f.ptr) = std::stod(value, &used);
          break;
        case OptionField::kFloat:
          *static_cast<float*>(f.ptr) = std::stof(value, &used);
          break;
        case OptionField::kU64:
          *static_cast<uint64_t*>(f.ptr) = std::stoull(value, &used);
          break;
        case OptionField::kBool:
          if (value != "true" && value != "false") throw std::invalid_argument("bool");
          *static_cast<bool*>(f.ptr) = value == "true";
          used = value.size();
          break;
      }
      if (used != value.size()) throw std::invalid_argument("trailing");
    } catch (const std::exception&) {
      ThrowInputError(
          "--set " + key_value,
          "has a bad value (expected a " + std::string(f.kind == OptionField::kBool ? "true/false" : "number") + ")");
    }
    return;
  }
  ThrowInputError("--set " + key_value, "names no option (expected one of the keys of the logged options)");
}

// -------------------------------------------------------------- view sampling
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
  const float quantiles[3] = {0.25f, 0.5f, 0.75f};
  float* dest[3] = {&out.t25, &out.t50, &out.t75};
  for (int q = 0; q < 3; ++q) {
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
};

}  // namespace

EnvSurfaceSamples SampleSurfaces(const NerfField& field, const EnvEstimateOptions& options, EnvViewReport* report,
                                 const EnvProgress& progress) {
  const std::vector<std::string> problems = options.Validate();
  if (!problems.empty()) ThrowInputError("env options", problems.front());
  NERFAR_CHECK(!field.empty());
  const Vec3 centre = (field.aabb.min + field.aabb.max) * 0.5;
  const double radius = options.view_distance_scale * 0.5 * Length(field.aabb.max - field.aabb.min);
  CameraIntrinsics camera;
  camera.width = options.view_width;
  camera.height = options.view_height;
  camera.fx = camera.fy = 0.5 * camera.width / std::tan(0.5 * options.view_fov_deg * kPi / 180);
  camera.cx = 0.5 * camera.width;
  camera.cy = 0.5 * camera.height;
  const bool use_brisque = options.brisque_max < 100;
  std::unique_ptr<BrisqueScorer> scorer;
  if (use_brisque) scorer = std::make_unique<BrisqueScorer>();
  const double z_min = std::sin(options.min_view_elevation_deg * kPi / 180);

  std::vector<ViewPick> views;
  EnvViewReport local;
  int accepted = 0;
  for (int a = 0; a < options.max_view_attempts && accepted < options.views; ++a) {
    const double z = z_min + (1 - z_min) * Uniform(options.seed, kViewDir, a, 0);
    const double phi = 2 * kPi * Uniform(options.seed, kViewDir, a, 1);
    const double r = std::sqrt(std::max(0.0, 1 - z * z));
    const Vec3 eye = centre + Vec3{r * std::cos(phi), r * std::sin(phi), z} * radius;
    const Pose pose = LookAt(eye, centre);
    const std::vector<NerfRay> rays = CameraRays(camera, pose, field.aabb);
    std::vector<NerfRayResult> results(rays.size());
    field.RenderRays(rays.data(), rays.size(), results.data(), options.render);

    ViewPick pick;
    if (use_brisque) {
      ImageF color(camera.width, camera.height, 3);
      for (size_t i = 0; i < results.size(); ++i)
        for (int c = 0; c < 3; ++c) color.pixels[i * 3 + c] = results[i].color[c];
      pick.score = scorer->ScoreLinear(color);
    }
    std::vector<uint32_t> eligible;
    for (size_t i = 0; i < results.size(); ++i)
      if (results[i].opacity > options.min_pixel_opacity && rays[i].t_far > rays[i].t_near)
        eligible.push_back(static_cast<uint32_t>(i));
    // Partial Fisher-Yates with counter-based draws: a random order of the
    // first `tries` eligible pixels, taken in that order until P are accepted.
    const size_t per_view = static_cast<size_t>(options.pixels_per_view);
    const size_t tries = std::min(eligible.size(), static_cast<size_t>(options.max_pixel_tries_factor) * per_view);
    for (size_t k = 0; k < tries; ++k) {
      const size_t j = k + static_cast<size_t>(Uniform(options.seed, kPixelPick, a, k) * (eligible.size() - k));
      std::swap(eligible[k], eligible[std::min(j, eligible.size() - 1)]);
    }
    enum Outcome { kAccepted, kNotSurface, kNoNormal, kGrazing, kNotFinite };
    struct Candidate {
      Outcome outcome = kNotFinite;
      Vec3f x, n, radiance;
    };
    const auto evaluate = [&](size_t k, Candidate& c) {
      const NerfRay& ray = rays[eligible[k]];
      const NerfRayResult& res = results[eligible[k]];
      // The surface: the median of the ray's opacity (see MarchSurface),
      // kept only where the opacity builds up within a few voxels.
      const RaySurface surf = MarchSurface(field, ray, options.surface_step_voxels);
      if (!surf.valid || surf.t75 - surf.t25 > options.max_surface_spread_voxels * field.voxel_m) {
        c.outcome = kNotSurface;
        return;
      }
      c.x = ray.origin + ray.dir * surf.t50;
      if (options.normal_from_depth) {
        const double px = eligible[k] % camera.width + 0.5, py = eligible[k] / camera.width + 0.5;
        if (!DepthNormal(field, camera, pose, px, py, c.x, ray.dir, options, &c.n)) {
          c.outcome = kNoNormal;
          return;
        }
      } else {
        if (!SmoothedNormal(field, c.x, static_cast<float>(options.normal_scale_voxels), &c.n)) {
          c.outcome = kNoNormal;
          return;
        }
        if (Dot(c.n, ray.dir) > 0) c.n = -c.n;  // the camera sees the surface: face it
      }
      // A surface seen at a grazing angle is where a noisy density gradient
      // most often gives a wrong normal (e.g. the table top's normal turned
      // sideways or down); such samples drive light from below the horizon.
      if (-Dot(c.n, ray.dir) < options.min_view_cosine) {
        c.outcome = kGrazing;
        return;
      }
      // Observed radiance: the pixel as rendered (what the camera saw; the
      // scenes' background is black, so a translucent trained surface's pixel
      // is its radiance), or divided by the opacity (partial coverage).
      c.radiance = options.radiance_over_opacity ? res.color * (1.0f / res.opacity) : res.color;
      c.outcome = std::isfinite(c.radiance.x + c.radiance.y + c.radiance.z) ? kAccepted : kNotFinite;
    };
    // Candidates are evaluated in parallel, a batch at a time, and taken in
    // order: the result does not depend on the thread count.
    for (size_t next = 0; next < tries && pick.positions.size() < per_view;) {
      const size_t end = std::min(tries, next + std::max<size_t>(per_view - pick.positions.size(), 16));
      std::vector<Candidate> batch(end - next);
      ParallelFor(
          batch.size(), [&](size_t i) { evaluate(next + i, batch[i]); }, 1);
      for (const Candidate& c : batch) {
        if (pick.positions.size() >= per_view) break;
        ++pick.tried;
        switch (c.outcome) {
          case kAccepted:
            pick.positions.push_back(c.x);
            pick.normals.push_back(c.n);
            pick.radiance.push_back(c.radiance);
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
      next = end;
    }
    const bool ok = !use_brisque || pick.score <= options.brisque_max;
    local.scores.push_back(pick.score);
    local.kept.push_back(ok);
    if (ok) ++accepted;
    views.push_back(std::move(pick));
    if (progress) progress("views", static_cast<size_t>(accepted), static_cast<size_t>(options.views));
  }
  local.rendered = static_cast<int>(views.size());
  if (accepted < options.views) {
    const int passed = accepted;
    // Too few views passed: take the best-scoring of the rest (the paper repeats
    // until 100 pass; a bounded budget must end).
    std::vector<size_t> rest;
    for (size_t v = 0; v < views.size(); ++v)
      if (!local.kept[v]) rest.push_back(v);
    std::stable_sort(rest.begin(), rest.end(), [&](size_t a, size_t b) { return views[a].score < views[b].score; });
    for (size_t i = 0; i < rest.size() && accepted < options.views; ++i, ++accepted) local.kept[rest[i]] = true;
    LogWarning("env: only " + std::to_string(passed) + " of " + std::to_string(local.rendered) + " views scored <= " +
               std::to_string(options.brisque_max) + " by BRISQUE; the best-scoring others were kept");
  }
  local.accepted = accepted;
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
  }
  if (report) *report = std::move(local);
  return samples;
}

// ---------------------------------------------------------------- near field
void ComputeNearField(const NerfField& field, const EnvEstimateOptions& options, EnvSurfaceSamples& samples,
                      const EnvProgress& progress) {
  const int R = options.rays_per_point;
  const size_t n = samples.size();
  const std::vector<Vec3> local = CosineHemisphere(R);
  samples.rays_per_point = R;
  samples.ray_dirs.assign(n * R, Vec3f{});
  samples.opacity.assign(n * R, 0.0f);
  samples.e_nerf.assign(n, Vec3f{});
  const float offset = static_cast<float>(options.ray_offset_voxels) * field.voxel_m;
  // Chunks of samples: their rays are rendered together so that the
  // seen-radiance look-ups (one per voxel) are shared within a chunk.
  const size_t chunk = 512;
  std::vector<NerfRay> rays;
  std::vector<NerfRayResult> results;
  for (size_t begin = 0; begin < n; begin += chunk) {
    const size_t end = std::min(n, begin + chunk);
    rays.assign((end - begin) * R, NerfRay{});
    results.assign((end - begin) * R, NerfRayResult{});
    ParallelFor(
        end - begin,
        [&](size_t k) {
          const size_t i = begin + k;
          const Vec3 normal = ToD(samples.normals[i]);
          Vec3 t, b;
          OrthonormalBasis(normal, t, b);
          const double turn = 2 * kPi * Uniform(options.seed, kRayTurn, i, 0);
          const double ct = std::cos(turn), st = std::sin(turn);
          const Vec3f origin = samples.positions[i] + samples.normals[i] * offset;
          for (int j = 0; j < R; ++j) {
            const Vec3& l = local[j];
            const double lx = ct * l.x - st * l.y, ly = st * l.x + ct * l.y;
            const Vec3f dir(Normalized(t * lx + b * ly + normal * l.z));
            samples.ray_dirs[i * R + j] = dir;
            if (options.ignore_near_field) continue;
            NerfRay& ray = rays[k * R + j];
            ray = NerfRay{origin, dir, 0, 0};
            if (!IntersectAabb(field.aabb, origin, dir, ray.t_near, ray.t_far)) continue;
            results[k * R + j] = field.RenderRay(ray, options.render);
          }
        },
        1);
    if (!options.ignore_near_field && options.near_field_seen_radiance)
      ApplySeenRadiance(field, rays, results, SeenOptions(options), options.render);
    for (size_t i = begin; i < end; ++i) {
      Vec3 sum;
      for (int j = 0; j < R; ++j) {
        const NerfRayResult& res = results[(i - begin) * R + j];
        samples.opacity[i * R + j] = std::clamp(res.opacity, 0.0f, 1.0f);
        sum += ToD(res.color);
      }
      samples.e_nerf[i] = Vec3f(sum * (kPi / R));
    }
    if (progress) progress("rays", end, n);
  }
  // Pool E_nerf over nearby samples facing the same way: a small bright
  // source is hit by few of a point's R rays, so one point's estimate is
  // quantised noise, which the fit would fill with environment light; the
  // pooled estimate uses the rays of all neighbours (bias only across shadow
  // edges narrower than the radius). Visibility stays per point.
  const double radius = options.near_field_pool_m;
  if (radius > 0 && !options.ignore_near_field) {
    std::vector<Vec3f> pooled(n);
    ParallelFor(
        n,
        [&](size_t i) {
          Vec3 sum;
          double count = 0;
          for (size_t j = 0; j < n; ++j) {
            const Vec3f d = samples.positions[j] - samples.positions[i];
            if (Dot(d, d) > radius * radius || Dot(samples.normals[i], samples.normals[j]) < 0.95f) continue;
            sum += ToD(samples.e_nerf[j]);
            count += 1;
          }
          pooled[i] = Vec3f(sum / count);
        },
        16);
    samples.e_nerf = std::move(pooled);
  }
}

// ----------------------------------------------------------------------- fit
namespace {

constexpr float kOccludedMin = 1e-3f;  // directions with less opacity are treated as open

struct Dictionary {
  std::vector<Vec3> axes;
  std::vector<double> sharpness;
  size_t size() const { return axes.size(); }
};

Dictionary MakeDictionary(const EnvEstimateOptions& o) {
  Dictionary d;
  int count = o.dictionary_base;
  double lambda = o.dictionary_sharpness;
  for (int l = 0; l < o.dictionary_levels; ++l, count *= 4, lambda *= 4) {
    for (const Vec3& p : FibonacciSphere(count)) {
      d.axes.push_back(p);
      d.sharpness.push_back(lambda);
    }
  }
  return d;
}

// A(i, k): irradiance at sample i from unit-amplitude lobe k through the
// NeRF's visibility: the exact unoccluded irradiance U(p·n, λ) times the
// lobe's open fraction over the cached directions,
//   V_k = Σ_j (1 − Ô_j) G_k(d_j) / Σ_j G_k(d_j)
// (the directions are cosine distributed, so this is the cosine-weighted
// visibility of the lobe). A ratio rather than U − Σ Ô G: exactly 0 for a
// lobe hidden behind the NeRF and exactly U for an open one, even when the
// lobe is sharper than the spacing of the cached directions (weights are
// normalised by their largest term, so nothing underflows).
Eigen::MatrixXd LobeIrradianceMatrix(const EnvSurfaceSamples& s, const std::vector<Vec3>& axes,
                                     const std::vector<double>& sharpness) {
  const size_t n = s.size(), d = axes.size();
  const int R = s.rays_per_point;
  std::vector<SgTableRow> rows(d);
  for (size_t k = 0; k < d; ++k) rows[k] = PrepareIrradiance(sharpness[k]);
  Eigen::MatrixXd A(n, d);
  ParallelFor(
      n,
      [&](size_t i) {
        const Vec3 normal = ToD(s.normals[i]);
        bool any_occluded = false;
        for (int j = 0; j < R && !any_occluded; ++j) any_occluded = s.opacity[i * R + j] > kOccludedMin;
        std::vector<double> exponent(R);
        for (size_t k = 0; k < d; ++k) {
          const double open = UnitIrradiancePrepared(rows[k], static_cast<float>(Dot(axes[k], normal)));
          double visible = 1;
          if (any_occluded) {
            double top = -1e300;
            for (int j = 0; j < R; ++j) {
              const Vec3 dir = ToD(s.ray_dirs[i * R + j]);
              exponent[j] = -0.5 * sharpness[k] * Dot(dir - axes[k], dir - axes[k]);  // λ(d·p − 1)
              top = std::max(top, exponent[j]);
            }
            double num = 0, den = 0;
            for (int j = 0; j < R; ++j) {
              const double g = std::exp(exponent[j] - top);
              den += g;
              num += g * (1.0 - s.opacity[i * R + j]);
            }
            visible = den > 0 ? num / den : 1.0;
          }
          A(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(k)) = std::max(0.0, open * visible);
        }
      },
      16);
  return A;
}

// min ‖Bx − y‖² s.t. x ≥ 0 from the normal equations G = BᵀB, h = Bᵀy
// (Lawson-Hanson active set).
Eigen::VectorXd Nnls(const Eigen::MatrixXd& G, const Eigen::VectorXd& h) {
  const Eigen::Index d = G.rows();
  Eigen::VectorXd x = Eigen::VectorXd::Zero(d);
  std::vector<bool> passive(d, false);
  const double tol = 1e-12 * std::max(1.0, G.diagonal().maxCoeff());
  for (int outer = 0; outer < 3 * d + 10; ++outer) {
    const Eigen::VectorXd w = h - G * x;
    Eigen::Index best = -1;
    double best_w = tol;
    for (Eigen::Index k = 0; k < d; ++k)
      if (!passive[k] && w[k] > best_w) best_w = w[k], best = k;
    if (best < 0) break;
    passive[best] = true;
    for (int inner = 0; inner < 3 * d + 10; ++inner) {
      std::vector<Eigen::Index> idx;
      for (Eigen::Index k = 0; k < d; ++k)
        if (passive[k]) idx.push_back(k);
      const Eigen::Index m = static_cast<Eigen::Index>(idx.size());
      Eigen::MatrixXd Gp(m, m);
      Eigen::VectorXd hp(m);
      for (Eigen::Index a = 0; a < m; ++a) {
        hp[a] = h[idx[a]];
        for (Eigen::Index b = 0; b < m; ++b) Gp(a, b) = G(idx[a], idx[b]);
      }
      Gp.diagonal().array() += 1e-12 * std::max(1.0, Gp.diagonal().maxCoeff());
      const Eigen::VectorXd z = Gp.ldlt().solve(hp);
      bool feasible = true;
      for (Eigen::Index a = 0; a < m; ++a) feasible = feasible && z[a] > 0;
      if (feasible) {
        x.setZero();
        for (Eigen::Index a = 0; a < m; ++a) x[idx[a]] = z[a];
        break;
      }
      double alpha = 1;
      for (Eigen::Index a = 0; a < m; ++a)
        if (z[a] <= 0) alpha = std::min(alpha, x[idx[a]] / std::max(1e-300, x[idx[a]] - z[a]));
      for (Eigen::Index a = 0; a < m; ++a) {
        x[idx[a]] += alpha * (z[a] - x[idx[a]]);
        if (x[idx[a]] <= 1e-15) {
          x[idx[a]] = 0;
          passive[idx[a]] = false;
        }
      }
    }
  }
  return x;
}

struct FitState {
  const EnvSurfaceSamples* s = nullptr;
  Eigen::MatrixXd A;            // n × D
  Eigen::MatrixXd mu;           // D × 3
  std::vector<int> cell;        // per sample
  std::vector<Vec3> albedo;     // per cell
  std::vector<double> robust;   // per sample IRLS weight (times balance)
  std::vector<double> balance;  // per sample weight of its normal's direction (NormalBalanceWeights)
  std::vector<Vec3> inv_scale;  // per sample and channel 1/(L + ε)
  double prior = 0.5, prior_weight = 0, robust_scale = 0.3;
  double energy_weight = 0, typical_irradiance = 1;
  Vec3 eps;                           // loss floor per channel
  std::vector<double> lobe_integral;  // ∫ G_k over the sphere per unit amplitude
  // g: the near field enters the model as g·E_nerf, g in [1, gain_max] (see
  // EnvEstimateOptions::near_field_gain_max).
  double gain = 1, gain_max = 1;
};

double Channel(const Vec3f& v, int c) { return v[c]; }

// Model shading S_ic = E_nerf + A μ (without albedo).
Eigen::MatrixXd Shading(const FitState& st) {
  Eigen::MatrixXd S = st.A * st.mu;
  for (size_t i = 0; i < st.s->size(); ++i)
    for (int c = 0; c < 3; ++c) S(i, c) += st.gain * Channel(st.s->e_nerf[i], c);
  return S;
}

double Loss(const FitState& st, const Eigen::MatrixXd& S, bool update_robust, FitState* mutable_st) {
  double total = 0;
  const size_t n = st.s->size();
  for (size_t i = 0; i < n; ++i) {
    double r2 = 0;
    for (int c = 0; c < 3; ++c) {
      // Log residual for the robust weight: an emitter (L far above any
      // a/π·E) is as far out as it is, while a relative residual would saturate at −1.
      const double eps = st.eps[c];
      const double model = st.albedo[st.cell[i]][c] / kPi * S(i, c);
      const double r = std::log((std::max(0.0, model) + eps) / (std::max(0.0, Channel(st.s->radiance[i], c)) + eps));
      r2 += r * r / 3;
    }
    const double q = r2 / (st.robust_scale * st.robust_scale);
    total += std::log1p(q);  // Cauchy
    if (update_robust) mutable_st->robust[i] = st.balance[i] / (1.0 + q);
  }
  return total * st.robust_scale * st.robust_scale / std::max<size_t>(n, 1);
}

void SolveLight(FitState& st) {
  const size_t n = st.s->size();
  const Eigen::Index d = st.A.cols();
  for (int c = 0; c < 3; ++c) {
    Eigen::MatrixXd B(n, d);
    Eigen::VectorXd y(n);
    for (size_t i = 0; i < n; ++i) {
      const double w = std::sqrt(st.robust[i]) * st.inv_scale[i][c];
      const double a = st.albedo[st.cell[i]][c] / kPi;
      B.row(i) = st.A.row(i) * (w * a);
      y[i] = w * (Channel(st.s->radiance[i], c) - a * st.gain * Channel(st.s->e_nerf[i], c));
    }
    const Eigen::MatrixXd G = B.transpose() * B;
    Eigen::VectorXd h = B.transpose() * y;
    // Minimum-energy prior: + 2β Σ_k μ_k ∫G_k, so light the data cannot see
    // (below the floor, behind walls) stays dark instead of growing freely.
    // β relative to the data: w_e · |y|² per unit of typical irradiance.
    const double beta = st.energy_weight * y.squaredNorm() / std::max(1e-30, st.typical_irradiance);
    for (Eigen::Index k = 0; k < d; ++k) h[k] -= beta * st.lobe_integral[k];
    st.mu.col(c) = Nnls(G, h);
  }
}

void SolveAlbedo(FitState& st, const Eigen::MatrixXd& S) {
  const size_t cells = st.albedo.size();
  std::vector<Vec3> num(cells), den(cells);
  std::vector<double> weight(cells, 0);
  for (size_t i = 0; i < st.s->size(); ++i)
    for (int c = 0; c < 3; ++c) {
      const double w = st.robust[i] * st.inv_scale[i][c] * st.inv_scale[i][c];
      const double s = S(i, c) / kPi;
      num[st.cell[i]][c] += w * s * Channel(st.s->radiance[i], c);
      den[st.cell[i]][c] += w * s * s;
      weight[st.cell[i]] += st.robust[i] / 3;
    }
  for (size_t k = 0; k < cells; ++k)
    for (int c = 0; c < 3; ++c) {
      // Prior weight relative to the cell's data: γ (a − a0)² with γ = weight·den/count.
      const double gamma = st.prior_weight * den[k][c] / std::max(1.0, weight[k]) + 1e-30;
      st.albedo[k][c] = std::clamp((num[k][c] + gamma * st.prior) / (den[k][c] + gamma), 0.005, 1.0);
    }
}

// The global scale that the data leaves free when the near field is weak:
// a → a·t, μ → μ/t keeps a·Aμ and scales a·E_nerf by t. Both the data and the
// prior are quadratic in t: solved exactly.
void SolveScale(FitState& st) {
  const Eigen::MatrixXd Amu = st.A * st.mu;
  double qa = 0, qb = 0;  // minimise qa t² − 2 qb t
  for (size_t i = 0; i < st.s->size(); ++i)
    for (int c = 0; c < 3; ++c) {
      const double w = st.robust[i] * st.inv_scale[i][c] * st.inv_scale[i][c];
      const double a = st.albedo[st.cell[i]][c] / kPi;
      const double e = a * st.gain * Channel(st.s->e_nerf[i], c), rest = Channel(st.s->radiance[i], c) - a * Amu(i, c);
      qa += w * e * e;
      qb += w * e * rest;
    }
  // Prior Σ γ (a t − a0)², γ per cell relative to the samples' mean weight.
  double mean_w = 0;
  for (size_t i = 0; i < st.s->size(); ++i)
    for (int c = 0; c < 3; ++c) mean_w += st.robust[i] * st.inv_scale[i][c] * st.inv_scale[i][c];
  mean_w /= std::max<size_t>(1, 3 * st.s->size());
  // In units of one sample's data term at the typical irradiance, so that
  // the prior's pull does not depend on the radiance scale (HDR: 1e-3..1e3).
  const double typical = mean_w * std::pow(st.prior / kPi * st.typical_irradiance, 2);
  std::vector<double> count(st.albedo.size(), 0);
  for (size_t i = 0; i < st.s->size(); ++i) count[st.cell[i]] += 1;
  for (size_t k = 0; k < st.albedo.size(); ++k)
    for (int c = 0; c < 3; ++c) {
      const double gamma = st.prior_weight * count[k] * typical * 1e2;
      qa += gamma * st.albedo[k][c] * st.albedo[k][c];
      qb += gamma * st.albedo[k][c] * st.prior;
    }
  if (!(qa > 0)) return;
  double t = qb / qa;
  if (!(t > 0) || !std::isfinite(t)) return;
  // Keep albedos ≤ 1: a larger t would clip them.
  double a_max = 0;
  for (const Vec3& a : st.albedo) a_max = std::max({a_max, a.x, a.y, a.z});
  if (a_max > 0) t = std::min(t, 1.0 / a_max);
  t = std::clamp(t, 0.1, 10.0);  // one step at most a decade: the alternation does the rest
  for (Vec3& a : st.albedo) a = a * t;
  st.mu /= t;
}

// The near-field gain g for fixed albedo and light: the data term is
// quadratic in g, solved exactly and clamped to [1, gain_max].
void SolveGain(FitState& st) {
  if (!(st.gain_max > 1)) return;
  const Eigen::MatrixXd Amu = st.A * st.mu;
  double qa = 0, qb = 0;
  for (size_t i = 0; i < st.s->size(); ++i)
    for (int c = 0; c < 3; ++c) {
      const double w = st.robust[i] * st.inv_scale[i][c] * st.inv_scale[i][c];
      const double a = st.albedo[st.cell[i]][c] / kPi;
      const double e = a * Channel(st.s->e_nerf[i], c), rest = Channel(st.s->radiance[i], c) - a * Amu(i, c);
      qa += w * e * e;
      qb += w * e * rest;
    }
  if (qa > 0 && std::isfinite(qb / qa)) st.gain = std::clamp(qb / qa, 1.0, st.gain_max);
}

}  // namespace

std::vector<double> NormalBalanceWeights(const std::vector<Vec3f>& normals, double power,
                                         const std::vector<Vec3f>* radiance) {
  std::vector<double> w(normals.size(), 1.0);
  if (!(power > 0) || normals.empty()) return w;
  const std::vector<Vec3> bins = FibonacciSphere(kNormalBalanceBins);
  std::vector<int> bin(normals.size());
  std::vector<double> count(bins.size(), 0);
  for (size_t i = 0; i < normals.size(); ++i) {
    int best = 0;
    double best_dot = -2;
    for (size_t b = 0; b < bins.size(); ++b) {
      const double d = Dot(ToD(normals[i]), bins[b]);
      if (d > best_dot) best_dot = d, best = static_cast<int>(b);
    }
    bin[i] = best;
    count[best] += 1;
  }
  double sum = 0;
  for (size_t i = 0; i < normals.size(); ++i) sum += w[i] = std::pow(1.0 / count[bin[i]], power);
  for (double& x : w) x *= static_cast<double>(normals.size()) / sum;  // mean 1
  if (radiance != nullptr && radiance->size() == normals.size()) {
    // Emitter-like samples (luminance above kEmitterLikeFactor x the median)
    // are not weighted up: a lamp's own surface, seen from its sides, fills
    // sparse normal bins, and the fit would explain its glow with light.
    std::vector<double> y;
    for (const Vec3f& l : *radiance) y.push_back(LuminanceOf(ToD(l)));
    std::vector<double> sorted = y;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double limit = kEmitterLikeFactor * sorted[sorted.size() / 2];
    for (size_t i = 0; i < w.size(); ++i)
      if (y[i] > limit) w[i] = std::min(w[i], 1.0);
  }
  return w;
}

namespace {

std::vector<int> AlbedoCells(const EnvSurfaceSamples& s, const Aabb& aabb, double cell_m, size_t* count) {
  const Vec3 ext = aabb.max - aabb.min;
  const double h = cell_m > 0 ? cell_m : std::max({ext.x, ext.y, ext.z}) / 8;
  std::map<std::array<int, 3>, int> ids;
  std::vector<int> cell(s.size());
  for (size_t i = 0; i < s.size(); ++i) {
    const Vec3 p = (ToD(s.positions[i]) - aabb.min) / h;
    const std::array<int, 3> key{static_cast<int>(std::floor(p.x)), static_cast<int>(std::floor(p.y)),
                                 static_cast<int>(std::floor(p.z))};
    const auto it = ids.emplace(key, static_cast<int>(ids.size())).first;
    cell[i] = it->second;
  }
  *count = ids.size();
  return cell;
}

}  // namespace

SgMixture FitEnvironment(const EnvSurfaceSamples& samples, const Aabb& aabb, const EnvEstimateOptions& options,
                         EnvFitReport* report, const EnvProgress& progress) {
  const std::vector<std::string> problems = options.Validate();
  if (!problems.empty()) ThrowInputError("env options", problems.front());
  NERFAR_CHECK_EQ(samples.e_nerf.size(), samples.size());
  NERFAR_CHECK_EQ(samples.opacity.size(), samples.size() * samples.rays_per_point);
  EnvFitReport local;
  if (samples.size() == 0) {
    if (report) *report = local;
    return {};
  }
  const Dictionary dict = MakeDictionary(options);
  local.dictionary_size = static_cast<int>(dict.size());
  FitState st;
  st.s = &samples;
  st.prior = options.albedo_prior;
  st.prior_weight = options.albedo_prior_weight;
  st.robust_scale = options.robust_scale;
  st.gain_max = options.ignore_near_field ? 1.0 : options.near_field_gain_max;
  size_t cells = 0;
  st.cell = AlbedoCells(samples, aabb, options.albedo_cell_m, &cells);
  st.albedo.assign(cells, Vec3{1, 1, 1} * options.albedo_prior);
  st.balance = NormalBalanceWeights(samples.normals, options.normal_balance, &samples.radiance);
  st.robust = st.balance;
  double mean_y = 0;
  for (const Vec3f& l : samples.radiance) mean_y += Y(ToD(l));
  mean_y /= samples.size();
  const double eps = options.loss_epsilon * std::max(mean_y, 1e-12);
  st.eps = Vec3{eps, eps, eps};
  st.inv_scale.resize(samples.size());
  for (size_t i = 0; i < samples.size(); ++i)
    for (int c = 0; c < 3; ++c) st.inv_scale[i][c] = 1.0 / (std::max(0.0, Channel(samples.radiance[i], c)) + eps);

  st.A = LobeIrradianceMatrix(samples, dict.axes, dict.sharpness);
  st.energy_weight = options.light_energy_weight;
  st.typical_irradiance = kPi * mean_y / options.albedo_prior;
  for (size_t k = 0; k < dict.size(); ++k) st.lobe_integral.push_back(SgUnitIntegral(dict.sharpness[k]));
  st.mu = Eigen::MatrixXd::Zero(st.A.cols(), 3);
  const int total_steps = options.iterations + std::max(3, options.iterations / 2);
  // Start: albedo at the prior, robust weights from the near field alone.
  local.initial_loss = Loss(st, Shading(st), true, &st);
  int step = 0;
  auto iterate = [&](int count) {
    for (int it = 0; it < count; ++it, ++step) {
      // The gain first: at the start (no light yet) it takes all that the
      // near field's pattern explains before any lobe can.
      SolveGain(st);
      SolveLight(st);
      SolveAlbedo(st, Shading(st));
      SolveScale(st);
      const double loss = Loss(st, Shading(st), true, &st);
      double albedo = 0, light = 0;
      for (size_t i = 0; i < samples.size(); ++i) albedo += Y(st.albedo[st.cell[i]]) / samples.size();
      for (Eigen::Index k = 0; k < st.mu.rows(); ++k) light += st.mu(k, 1) * st.lobe_integral[k];
      LogVerbose("env fit: step " + std::to_string(step) + " loss " + std::to_string(loss) + " mean albedo " +
                 std::to_string(albedo) + " light green integral " + std::to_string(light));
      if (progress) progress("fit", static_cast<size_t>(step + 1), static_cast<size_t>(total_steps));
    }
  };
  iterate(options.iterations);

  // Keep the M lobes carrying the most energy and re-solve with them only.
  std::vector<Eigen::Index> order(st.A.cols());
  std::iota(order.begin(), order.end(), 0);
  std::vector<double> energy(st.A.cols());
  for (Eigen::Index k = 0; k < st.A.cols(); ++k)
    energy[k] = Y(Vec3{st.mu(k, 0), st.mu(k, 1), st.mu(k, 2)}) * SgUnitIntegral(dict.sharpness[k]);
  std::stable_sort(order.begin(), order.end(), [&](Eigen::Index a, Eigen::Index b) { return energy[a] > energy[b]; });
  order.resize(std::min<size_t>(order.size(), static_cast<size_t>(options.lobes)));
  std::sort(order.begin(), order.end());
  Eigen::MatrixXd A_kept(st.A.rows(), static_cast<Eigen::Index>(order.size()));
  Eigen::MatrixXd mu_kept(static_cast<Eigen::Index>(order.size()), 3);
  std::vector<double> kept_integral;
  for (size_t k = 0; k < order.size(); ++k) {
    kept_integral.push_back(st.lobe_integral[order[k]]);
    A_kept.col(k) = st.A.col(order[k]);
    mu_kept.row(k) = st.mu.row(order[k]);
  }
  st.A = std::move(A_kept);
  st.mu = std::move(mu_kept);
  st.lobe_integral = kept_integral;
  iterate(total_steps - options.iterations);

  SgMixture result;
  for (size_t k = 0; k < order.size(); ++k) {
    const Vec3 mu{st.mu(k, 0), st.mu(k, 1), st.mu(k, 2)};
    if (!(mu.x > 0 || mu.y > 0 || mu.z > 0)) continue;
    result.push_back({dict.axes[order[k]], dict.sharpness[order[k]], mu});
  }
  const Eigen::MatrixXd S = Shading(st);
  local.final_loss = Loss(st, S, false, nullptr);
  local.active_lobes = static_cast<int>(result.size());
  double albedo_sum = 0, err2 = 0, ref2 = 0;
  for (size_t i = 0; i < samples.size(); ++i) {
    const Vec3& a = st.albedo[st.cell[i]];
    albedo_sum += Y(a);
    const Vec3 model{a.x / kPi * S(i, 0), a.y / kPi * S(i, 1), a.z / kPi * S(i, 2)};
    const double obs = Y(ToD(samples.radiance[i]));
    err2 += std::pow(Y(model) - obs, 2);
    ref2 += obs * obs;
  }
  local.mean_albedo = albedo_sum / samples.size();
  local.relative_rms = ref2 > 0 ? std::sqrt(err2 / ref2) : 0;
  local.near_field_gain = st.gain;
  if (report) *report = local;
  return result;
}

std::vector<Vec3> EnvironmentIrradiance(const EnvSurfaceSamples& samples, const SgMixture& light) {
  std::vector<Vec3> axes;
  std::vector<double> sharpness;
  for (const Sg& g : light) {
    axes.push_back(g.axis);
    sharpness.push_back(g.sharpness);
  }
  const Eigen::MatrixXd A = LobeIrradianceMatrix(samples, axes, sharpness);
  std::vector<Vec3> e(samples.size());
  for (size_t i = 0; i < samples.size(); ++i)
    for (size_t k = 0; k < light.size(); ++k) e[i] += light[k].amplitude * A(i, k);
  return e;
}

NerfIncident NerfIncidentAt(const NerfField& field, const Vec3& point, int directions, const NerfRenderOptions& render,
                            const SeenRadianceOptions* seen) {
  NerfIncident in;
  std::vector<Vec3f> dirs;
  for (const Vec3& d : FibonacciSphere(directions)) dirs.push_back(Vec3f(d));
  const std::vector<NerfRay> rays = PointRays(Vec3f(point), dirs, field.aabb);
  std::vector<NerfRayResult> res(rays.size());
  field.RenderRays(rays.data(), rays.size(), res.data(), render);
  if (seen != nullptr) ApplySeenRadiance(field, rays, res, *seen, render);
  for (size_t j = 0; j < dirs.size(); ++j) {
    const bool inside = rays[j].t_far > rays[j].t_near;
    in.dirs.push_back(ToD(dirs[j]));
    in.color.push_back(inside ? ToD(res[j].color) : Vec3{});
    in.opacity.push_back(inside ? std::clamp(static_cast<double>(res[j].opacity), 0.0, 1.0) : 0.0);
  }
  return in;
}

Vec3 NerfIncident::NearIrradiance(const Vec3& normal) const {
  Vec3 e;
  for (size_t j = 0; j < dirs.size(); ++j) e += color[j] * std::max(0.0, Dot(normal, dirs[j]));
  return e * (4 * kPi / std::max<size_t>(1, dirs.size()));
}

Vec3 NerfIncident::DistantIrradiance(const std::function<Vec3(const Vec3&)>& light, const Vec3& normal) const {
  Vec3 e;
  for (size_t j = 0; j < dirs.size(); ++j) {
    const double c = Dot(normal, dirs[j]);
    if (c > 0 && opacity[j] < 1) e += light(dirs[j]) * ((1 - opacity[j]) * c);
  }
  return e * (4 * kPi / std::max<size_t>(1, dirs.size()));
}

double EnvToNearRatioAt(const NerfField& field, const SgMixture& light, const Vec3& point, int directions, int normals,
                        const NerfRenderOptions& render, const SeenRadianceOptions* seen) {
  const NerfIncident in = NerfIncidentAt(field, point, directions, render, seen);
  const auto env_light = [&light](const Vec3& d) { return Evaluate(light, d); };
  double env = 0, nerf = 0;
  for (const Vec3& n : FibonacciSphere(normals)) {
    env += Y(in.DistantIrradiance(env_light, n));
    nerf += Y(in.NearIrradiance(n));
  }
  if (nerf > 0) return env / nerf;
  return env > 0 ? std::numeric_limits<double>::infinity() : 0.0;
}

EnvLight EstimateEnvironment(const NerfField& field, const EnvEstimateOptions& options, EnvEstimateReport* report,
                             const EnvProgress& progress) {
  const std::vector<std::string> problems = options.Validate();
  if (!problems.empty()) {
    Problems list("env options");
    for (const std::string& p : problems) list.Add("", p);
    list.ThrowIfAny();
  }
  EnvEstimateReport local;
  local.keep_samples = report != nullptr && report->keep_samples;
  const auto clock_start = std::chrono::steady_clock::now();
  const auto elapsed = [&clock_start] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - clock_start).count();
  };
  double t0 = elapsed();
  EnvSurfaceSamples samples = SampleSurfaces(field, options, &local.views, progress);
  local.seconds_views = elapsed() - t0;
  local.samples = samples.size();
  t0 = elapsed();
  ComputeNearField(field, options, samples, progress);
  local.seconds_near_field = elapsed() - t0;
  t0 = elapsed();
  EnvLight env;
  env.lobes = FitEnvironment(samples, field.aabb, options, &local.fit, progress);
  local.seconds_fit = elapsed() - t0;

  const std::vector<Vec3> e_env = EnvironmentIrradiance(samples, env.lobes);
  double sum_env = 0, sum_nerf = 0;
  for (size_t i = 0; i < samples.size(); ++i) {
    sum_env += Y(e_env[i]);
    sum_nerf += Y(ToD(samples.e_nerf[i]));
  }
  env.env_to_near_surface = sum_nerf > 0 ? sum_env / sum_nerf : (sum_env > 0 ? 1e30 : 0.0);
  const SeenRadianceOptions seen = SeenOptions(options);
  const double centre_ratio = EnvToNearRatioAt(field, env.lobes, (field.aabb.min + field.aabb.max) * 0.5, 1024, 64,
                                               options.render, options.near_field_seen_radiance ? &seen : nullptr);
  env.env_to_near_center = std::isfinite(centre_ratio) ? std::min(centre_ratio, 1e30) : 1e30;
  env.threshold = options.negligible_ratio;
  env.negligible = env.env_to_near_surface < env.threshold && env.env_to_near_center < env.threshold;
  env.options_json = options.ToJson();
  if (local.keep_samples) {
    local.surface = std::move(samples);
    local.e_env = e_env;
  }
  if (report) *report = std::move(local);
  return env;
}

double RelativeIrradianceRms(const std::vector<Vec3>& estimate, const std::vector<Vec3>& reference) {
  NERFAR_CHECK_EQ(estimate.size(), reference.size());
  double err = 0, ref = 0;
  for (size_t i = 0; i < estimate.size(); ++i) {
    err += std::pow(Y(estimate[i]) - Y(reference[i]), 2);
    ref += std::pow(Y(reference[i]), 2);
  }
  return ref > 0 ? std::sqrt(err / ref) : (err > 0 ? std::numeric_limits<double>::infinity() : 0.0);
}

}  // namespace nerfar
