#include "render/insert/incident_light.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "calib/core/error.h"
#include "calib/core/parallel.h"

namespace nerfar {

namespace {
double MillisecondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

const char* LightSourceName(LightSource source) {
  switch (source) {
    case LightSource::kFull:
      return "full";
    case LightSource::kNearFieldOnly:
      return "near";
    case LightSource::kEnvironmentOnly:
      return "env";
  }
  return "?";
}

LightSource ParseLightSource(const std::string& name) {
  if (name == "full") return LightSource::kFull;
  if (name == "near") return LightSource::kNearFieldOnly;
  if (name == "env") return LightSource::kEnvironmentOnly;
  ThrowInputError("light source", "unknown value '" + name + "' (expected full, near or env)");
}

std::vector<std::string> IncidentLightOptions::Validate() const {
  std::vector<std::string> problems;
  if (directions < 16 || directions > (1 << 20))
    problems.push_back("light_directions: " + std::to_string(directions) + " is out of range (expected 16 to 1048576)");
  if (!(move_threshold_m >= 0.0) || !std::isfinite(move_threshold_m))
    problems.push_back("light_move_threshold_m: must be a finite number >= 0");
  if (!(start_tolerance_m >= 0.0) || !std::isfinite(start_tolerance_m))
    problems.push_back("light_start_tolerance_m: must be a finite number >= 0");
  if (!(parallax_min_sharpness > 0.0) || !std::isfinite(parallax_min_sharpness))
    problems.push_back("parallax_min_sharpness: must be a finite number > 0");
  for (const std::string& p : fit.Validate()) problems.push_back("fit." + p);
  return problems;
}

RadianceSamples SampleIncidentLight(const SceneField& scene, const SgMixture& environment, const Vec3& center,
                                    const std::vector<Vec3>& directions, LightSource source,
                                    std::vector<float>* opacity, std::vector<float>* depth,
                                    const std::vector<float>* start) {
  const size_t n = directions.size();
  RadianceSamples samples;
  samples.directions = directions;
  samples.radiance.assign(n, Vec3{});
  samples.solid_angles.assign(n, n > 0 ? 4.0 * kPi / static_cast<double>(n) : 0.0);
  if (opacity) opacity->assign(n, 0.0f);
  if (depth) depth->assign(n, 0.0f);
  SceneSamples field;
  if (source != LightSource::kEnvironmentOnly) {
    // One batch per chunk so that threads share no scratch (RenderRays is const).
    constexpr size_t kChunk = 128;
    const size_t chunks = (n + kChunk - 1) / kChunk;
    field.Resize(n);
    const Aabb box = scene.Box();
    ParallelFor(
        chunks,
        [&](size_t c) {
          SceneRays rays;
          SceneSamples out;
          const size_t begin = c * kChunk, end = std::min(n, begin + kChunk);
          rays.Reserve(end - begin);
          for (size_t i = begin; i < end; ++i) {
            const auto range = IntersectBox(box, center, directions[i]);
            float t0 = range ? static_cast<float>(range->first) : 0.0f;
            const float t1 = range ? static_cast<float>(range->second) : 0.0f;
            if (start && i < start->size() && std::isfinite((*start)[i])) t0 = std::max(t0, (*start)[i]);
            rays.Add(Vec3f(center), Vec3f(directions[i]), std::min(t0, t1), t1);
          }
          scene.RenderLightRays(rays, out);
          for (size_t i = begin; i < end; ++i) {
            field.colour[i] = out.colour[i - begin];
            field.opacity[i] = out.opacity[i - begin];
            field.depth[i] = out.depth[i - begin];
          }
        },
        1);
  }
  for (size_t i = 0; i < n; ++i) {
    Vec3 near{};
    float o = 0.0f;
    if (source != LightSource::kEnvironmentOnly) {
      near = Vec3(field.colour[i]);
      o = std::clamp(field.opacity[i], 0.0f, 1.0f);
      if (!std::isfinite(o)) o = 0.0f;
    }
    Vec3 env{};
    if (source != LightSource::kNearFieldOnly && !environment.empty())
      env = Evaluate(environment, directions[i]) * (1.0 - o);
    Vec3 l = near + env;
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite(l[c]) || l[c] < 0.0) l[c] = 0.0;
    samples.radiance[i] = l;
    if (opacity) (*opacity)[i] = o;
    if (depth && source != LightSource::kEnvironmentOnly && std::isfinite(field.depth[i]) && field.depth[i] > 0.0f)
      (*depth)[i] = field.depth[i];
  }
  return samples;
}

namespace {
// Distance t > 0 at which o + t·d crosses triangle (a, b, c), either face
// (the mesh need not be closed or wound); 0 where it misses (Möller-Trumbore).
double CrossingDistance(const Vec3& o, const Vec3& d, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 e1 = b - a, e2 = c - a;
  const Vec3 p = Cross(d, e2);
  const double det = Dot(e1, p);
  if (std::abs(det) < 1e-300) return 0.0;
  const double inv = 1.0 / det;
  const Vec3 q = o - a;
  const double u = Dot(q, p) * inv;
  if (u < 0.0 || u > 1.0) return 0.0;
  const Vec3 r = Cross(q, e1);
  const double v = Dot(d, r) * inv;
  if (v < 0.0 || u + v > 1.0) return 0.0;
  const double t = Dot(e2, r) * inv;
  return t > 0.0 && std::isfinite(t) ? t : 0.0;
}
}  // namespace

std::vector<float> ObjectExitDistances(const LightObjectVolume& volume, const Vec3& center,
                                       const std::vector<Vec3>& directions) {
  std::vector<float> exit(directions.size(), 0.0f);
  if (volume.mesh == nullptr || volume.mesh->triangles.empty() || !(std::abs(volume.scale) > 0.0)) return exit;
  const TriangleMesh& mesh = *volume.mesh;
  // In the object's frame: o + t'·d' with t' = t / scale (d' = R^T d).
  const Pose T_object_world = volume.T_world_object.Inverse();
  const double s = std::abs(volume.scale);
  const Vec3 o = T_object_world * center / s;
  for (const auto& tri : mesh.triangles)
    for (uint32_t v : tri)
      if (v >= mesh.positions.size()) return exit;  // a broken mesh skips nothing
  // Each triangle is tested only against the directions whose z lies in the
  // band its bounding cone (seen from o) spans: directions sorted by z, a
  // band found by bisection. A small triangle meets a few per cent of them.
  std::vector<Vec3> local(directions.size());
  std::vector<uint32_t> order(directions.size());
  std::vector<double> sorted_z(directions.size());
  for (size_t i = 0; i < directions.size(); ++i) {
    local[i] = T_object_world.Rotate(directions[i]);
    order[i] = static_cast<uint32_t>(i);
  }
  std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return local[a].z < local[b].z; });
  for (size_t k = 0; k < order.size(); ++k) sorted_z[k] = local[order[k]].z;
  std::vector<double> farthest(directions.size(), 0.0);
  constexpr double kSlack = 1e-6;  // rad and z: rounding of the cone and the band, far below a facet
  for (const auto& tri : mesh.triangles) {
    const Vec3 a(mesh.positions[tri[0]]), b(mesh.positions[tri[1]]), c(mesh.positions[tri[2]]);
    double z_low = -2.0, z_high = 2.0;  // every direction, unless the cone is narrow
    const Vec3 axis = Normalized((a + b + c) / 3.0 - o);
    double cos_half = 1.0;
    for (const Vec3& v : {a, b, c}) {
      const double len = Length(v - o);
      cos_half = len > 0.0 ? std::min(cos_half, Dot(axis, (v - o) / len)) : -1.0;
    }
    if (Length(axis) > 0.5 && cos_half > 0.0) {  // a convex cone under 90°: it holds the whole triangle
      const double polar = std::acos(std::clamp(axis.z, -1.0, 1.0));
      const double half = std::acos(std::min(cos_half, 1.0)) + kSlack;
      z_low = std::cos(std::min(kPi, polar + half)) - kSlack;
      z_high = std::cos(std::max(0.0, polar - half)) + kSlack;
    }
    const size_t first = std::lower_bound(sorted_z.begin(), sorted_z.end(), z_low) - sorted_z.begin();
    const size_t last = std::upper_bound(sorted_z.begin(), sorted_z.end(), z_high) - sorted_z.begin();
    for (size_t k = first; k < last; ++k) {
      const uint32_t i = order[k];
      farthest[i] = std::max(farthest[i], CrossingDistance(o, local[i], a, b, c));
    }
  }
  for (size_t i = 0; i < directions.size(); ++i) exit[i] = static_cast<float>(farthest[i] * s);
  return exit;
}

namespace {
constexpr float kSurfaceOpacity = 0.5f;
// How much of the re-aiming lobe k gets: 0 below the minimum sharpness, 1
// from twice it, linear in between (no jump as a refit changes λ).
double ParallaxWeight(double sharpness, double min_sharpness) {
  return std::clamp((sharpness - min_sharpness) / min_sharpness, 0.0, 1.0);
}
// Whether rays starting at `starts` (null: at the centre) sample the scene as
// the ones starting at `fitted` (empty: at the centre) did, to `tolerance`.
bool SameStarts(const std::vector<float>* starts, const std::vector<float>& fitted, double tolerance) {
  if (starts == nullptr) return fitted.empty();
  if (starts->size() != fitted.size()) return false;
  for (size_t i = 0; i < fitted.size(); ++i)
    if (!(std::abs((*starts)[i] - fitted[i]) <= tolerance)) return false;
  return true;
}
}  // namespace

bool LightParallax::Active(const SgMixture& light) const {
  if (distance.size() != light.size()) return false;
  for (size_t k = 0; k < light.size(); ++k)
    if (std::isfinite(distance[k]) && ParallaxWeight(light[k].sharpness, min_sharpness) > 0.0) return true;
  return false;
}

std::vector<double> LobeDistances(const SgMixture& light, const std::vector<Vec3>& directions,
                                  const std::vector<float>& opacity, const std::vector<float>& depth,
                                  const std::vector<Vec3>& near_radiance) {
  std::vector<double> distance(light.size(), std::numeric_limits<double>::infinity());
  const size_t n = std::min({directions.size(), opacity.size(), depth.size()});
  // The near share of each direction's light (1 without near_radiance).
  std::vector<double> share(n, 1.0);
  if (near_radiance.size() >= n)
    for (size_t i = 0; i < n; ++i) {
      const double all = LuminanceOf(Evaluate(light, directions[i]));
      const double near = LuminanceOf(near_radiance[i]);
      share[i] = all > 0.0 && std::isfinite(near) ? std::clamp(near / all, 0.0, 1.0) : 0.0;
    }
  for (size_t k = 0; k < light.size(); ++k) {
    const Sg& lobe = light[k];
    const double mu = LuminanceOf(lobe.amplitude);
    if (!(mu > 0.0) || !std::isfinite(mu)) continue;
    double weight = 0.0, inverse = 0.0;
    for (size_t i = 0; i < n; ++i) {
      const double w = std::exp(lobe.sharpness * (Dot(lobe.axis, directions[i]) - 1.0));
      if (!(w > 1e-6)) continue;  // beyond ~3.7 widths: no say
      weight += w;
      // A surface where the opacity reaches one half (as for κ receivers):
      // thin fog in front of the distant light does not make it near.
      if (opacity[i] >= kSurfaceOpacity && depth[i] > 0.0f && std::isfinite(depth[i]))
        inverse += w * share[i] / depth[i];
    }
    if (weight > 0.0 && inverse > 0.0) distance[k] = weight / inverse;
  }
  return distance;
}

SgMixture ReaimLight(const SgMixture& light, const LightParallax& parallax, const Vec3& p) {
  SgMixture out = light;
  if (parallax.distance.size() != light.size()) return out;
  for (size_t k = 0; k < light.size(); ++k) {
    const double d = parallax.distance[k];
    const double w = ParallaxWeight(light[k].sharpness, parallax.min_sharpness);
    if (!std::isfinite(d) || !(d > 0.0) || !(w > 0.0)) continue;
    const Vec3 to_source = parallax.center + light[k].axis * d - p;
    const double d_new = Length(to_source);
    if (!(d_new > 0.0) || !std::isfinite(d_new)) continue;
    const double ratio = std::clamp(d_new / d, 0.25, 4.0);
    const Vec3 axis = Normalized(light[k].axis * (1.0 - w) + (to_source / d_new) * w);
    if (!(Length(axis) > 0.5)) continue;  // opposite directions blended to nothing: keep the lobe
    out[k].axis = axis;
    out[k].sharpness = light[k].sharpness * (1.0 + w * (ratio * ratio - 1.0));
  }
  return out;
}

void IncidentLight::Reset() {
  valid_ = false;
  light_.clear();
}

const std::vector<float>* IncidentLight::Starts(const Vec3& center, const IncidentLightOptions& options,
                                                const LightObjectVolume* volume) {
  if (!options.start_outside_object || volume == nullptr || volume->mesh == nullptr) {
    starts_.clear();
    starts_mesh_ = nullptr;
    return nullptr;
  }
  const bool same = starts_mesh_ == volume->mesh && starts_scale_ == volume->scale &&
                    starts_pose_.rotation.m == volume->T_world_object.rotation.m &&
                    starts_pose_.translation == volume->T_world_object.translation && starts_center_ == center &&
                    starts_directions_ == options.directions;
  if (!same) {
    if (static_cast<int>(dirs_.size()) != options.directions) dirs_ = FibonacciSphere(options.directions);
    starts_ = ObjectExitDistances(*volume, center, dirs_);
    starts_mesh_ = volume->mesh;
    starts_pose_ = volume->T_world_object;
    starts_scale_ = volume->scale;
    starts_center_ = center;
    starts_directions_ = options.directions;
  }
  return &starts_;
}

IncidentLight::Update IncidentLight::Refresh(const SceneField& scene, const SgMixture& environment, const Vec3& center,
                                             const IncidentLightOptions& options, const LightObjectVolume* volume) {
  Update update;
  // Whether the rays would start elsewhere than last time (the object turned
  // into a different shape along some ray).
  const std::vector<float>* starts = Starts(center, options, volume);
  const bool same_starts = SameStarts(starts, fitted_starts_, options.start_tolerance_m);
  const bool same_setup = valid_ && directions_ == options.directions && source_ == options.source &&
                          lobes_ == options.fit.lobes && same_starts;
  const bool same_parallax = options.parallax == !distances_.empty() || light_.empty();
  if (same_setup && same_parallax && Length(center - center_) <= options.move_threshold_m) return update;
  update.recomputed = true;
  if (static_cast<int>(dirs_.size()) != options.directions) dirs_ = FibonacciSphere(options.directions);
  auto t0 = std::chrono::steady_clock::now();
  samples_ = SampleIncidentLight(scene, environment, center, dirs_, options.source, &opacity_, &depth_, starts);
  update.sample_ms = MillisecondsSince(t0);
  double total = 0.0;
  for (const Vec3& l : samples_.radiance) total += LuminanceOf(l);
  if (options.source == LightSource::kEnvironmentOnly) {
    light_ = environment;  // already SGs: nothing to fit
  } else if (!(total > 0.0)) {
    light_.clear();  // darkness (e.g. the centre inside opaque geometry): no lobe to fit
  } else {
    t0 = std::chrono::steady_clock::now();
    const bool warm = same_setup && static_cast<int>(light_.size()) == options.fit.lobes;
    light_ = FitSg(samples_, options.fit, warm ? &light_ : nullptr, &update.report);
    update.fit_ms = MillisecondsSince(t0);
  }
  distances_.clear();
  if (options.parallax && !light_.empty()) {
    // The near-field part of each sample: Ĉ (the scene's own radiance).
    std::vector<Vec3> near(samples_.radiance.size());
    if (options.source != LightSource::kEnvironmentOnly)
      for (size_t i = 0; i < near.size(); ++i)
        near[i] = samples_.radiance[i] - (environment.empty() || options.source == LightSource::kNearFieldOnly
                                              ? Vec3{}
                                              : Evaluate(environment, dirs_[i]) * (1.0 - opacity_[i]));
    distances_ = LobeDistances(light_, dirs_, opacity_, depth_, near);
  }
  valid_ = true;
  fitted_starts_ = starts != nullptr ? *starts : std::vector<float>{};
  center_ = center;
  directions_ = options.directions;
  source_ = options.source;
  lobes_ = options.fit.lobes;
  return update;
}

const std::vector<double>& IncidentLight::DistancesFor(const SceneField& scene, const SgMixture& light,
                                                       const Vec3& center, const IncidentLightOptions& options,
                                                       const LightObjectVolume* volume) {
  if (!options.parallax || light.empty()) {
    distances_.clear();
    given_valid_ = false;
    return distances_;
  }
  const auto same_lobes = [&] {
    if (given_light_.size() != light.size()) return false;
    for (size_t k = 0; k < light.size(); ++k)
      if (!(given_light_[k].axis == light[k].axis) || given_light_[k].sharpness != light[k].sharpness ||
          !(given_light_[k].amplitude == light[k].amplitude))
        return false;
    return true;
  };
  if (given_valid_ && given_directions_ == options.directions &&
      Length(center - given_center_) <= options.move_threshold_m && same_lobes())
    return distances_;
  if (static_cast<int>(dirs_.size()) != options.directions) dirs_ = FibonacciSphere(options.directions);
  // Only the scene's opacity and depth are needed: the near-field source.
  const std::vector<float>* starts = Starts(center, options, volume);
  const RadianceSamples near =
      SampleIncidentLight(scene, {}, center, dirs_, LightSource::kNearFieldOnly, &opacity_, &depth_, starts);
  distances_ = LobeDistances(light, dirs_, opacity_, depth_, near.radiance);
  given_light_ = light;
  given_center_ = center;
  given_directions_ = options.directions;
  given_valid_ = true;
  valid_ = false;  // the fitted light (Refresh) no longer matches distances_
  return distances_;
}

}  // namespace nerfar
