#include "render/lighting/incident_light.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>
#include <tuple>

#include "calib/core/error.h"
#include "calib/core/parallel.h"

namespace nerfar {

namespace {
double MillisecondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

const std::vector<const char*>& LightSourceNames() {
  static const std::vector<const char*> kNames = {"full", "near", "env"};
  return kNames;
}

const char* LightSourceName(LightSource source) { return LightSourceNames().at(static_cast<size_t>(source)); }

std::vector<std::string> IncidentLightOptions::Validate() const {
  std::vector<std::string> problems;
  if (directions < 16 || directions > (1 << 20))
    problems.push_back("light_directions: " + std::to_string(directions) + " is out of range (expected 16 to 1048576)");
  if (!(move_threshold_m >= 0.0) || !std::isfinite(move_threshold_m))
    problems.push_back("light_move_threshold_m: must be a finite number >= 0");
  if (!(start_tolerance_m >= 0.0) || !std::isfinite(start_tolerance_m))
    problems.push_back("light_start_tolerance_m: must be a finite number >= 0");
  if (refine_rays < 0 || refine_rays > 1024)
    problems.push_back("light_refine_rays: " + std::to_string(refine_rays) + " is out of range (expected 0 to 1024)");
  if (!(refine_contrast > 1.0) || !std::isfinite(refine_contrast))
    problems.push_back("light_refine_contrast: must be a finite number > 1");
  if (lobe_bundle_rays < 1 || lobe_bundle_rays > 1024)
    problems.push_back("lobe_bundle_rays: " + std::to_string(lobe_bundle_rays) +
                       " is out of range (expected 1 to 1024)");
  if (!(parallax_min_sharpness > 0.0) || !std::isfinite(parallax_min_sharpness))
    problems.push_back("parallax_min_sharpness: must be a finite number > 0");
  for (const std::string& p : fit.Validate()) problems.push_back("fit." + p);
  return problems;
}

namespace {
// Renders the light rays center + t·d over [max(box entry, start), box exit]
// in chunks over the threads (one batch per chunk: RenderLightRays is const
// and shares no scratch).
SceneSamples RenderFromCenter(const SceneField& scene, const Vec3& center, const std::vector<Vec3>& directions,
                              const std::vector<float>& starts) {
  const size_t n = directions.size();
  // A field that splits the batch itself gets every ray at once (its
  // seen-radiance pass then groups points across the whole batch).
  const size_t chunk = scene.ParallelLightRays() ? std::max<size_t>(n, 1) : 128;
  const size_t chunks = (n + chunk - 1) / chunk;
  SceneSamples field;
  field.Resize(n);
  const Aabb box = scene.Box();
  ParallelFor(
      chunks,
      [&](size_t c) {
        SceneRays rays;
        SceneSamples out;
        const size_t begin = c * chunk, end = std::min(n, begin + chunk);
        rays.Reserve(end - begin);
        for (size_t i = begin; i < end; ++i) {
          const auto range = IntersectBox(box, center, directions[i]);
          float t0 = range ? static_cast<float>(range->first) : 0.0f;
          const float t1 = range ? static_cast<float>(range->second) : 0.0f;
          if (i < starts.size() && std::isfinite(starts[i])) t0 = std::max(t0, starts[i]);
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
  return field;
}

// Ĉ + (1 − Ô)·L_env (per source), non-finite or negative parts as 0.
Vec3 BlendLight(const Vec3f& colour, float opacity, const SgMixture& environment, const Vec3& direction,
                LightSource source, float* clamped_opacity) {
  Vec3 near{};
  float o = 0.0f;
  if (source != LightSource::kEnvironmentOnly) {
    near = Vec3(colour);
    o = std::clamp(opacity, 0.0f, 1.0f);
    if (!std::isfinite(o)) o = 0.0f;
  }
  Vec3 env{};
  if (source != LightSource::kNearFieldOnly && !environment.empty()) env = Evaluate(environment, direction) * (1.0 - o);
  Vec3 l = near + env;
  for (int c = 0; c < 3; ++c)
    if (!std::isfinite(l[c]) || l[c] < 0.0) l[c] = 0.0;
  if (clamped_opacity) *clamped_opacity = o;
  return l;
}
}  // namespace

RadianceSamples SampleIncidentLight(const SceneField& scene, const SgMixture& environment, const Vec3& center,
                                    const std::vector<Vec3>& directions, LightSource source,
                                    std::vector<float>* opacity, std::vector<float>* depth,
                                    const std::vector<float>* start, int refine_rays, double refine_contrast,
                                    size_t* refined, const SgMixture* beside) {
  const size_t n = directions.size();
  RadianceSamples samples;
  samples.directions = directions;
  samples.radiance.assign(n, Vec3{});
  samples.solid_angles.assign(n, n > 0 ? 4.0 * kPi / static_cast<double>(n) : 0.0);
  if (opacity) opacity->assign(n, 0.0f);
  if (depth) depth->assign(n, 0.0f);
  if (refined) *refined = 0;
  const std::vector<float> no_starts;
  const std::vector<float>& starts = start ? *start : no_starts;
  SceneSamples field;
  if (source != LightSource::kEnvironmentOnly) field = RenderFromCenter(scene, center, directions, starts);
  std::vector<float> o(n, 0.0f);
  for (size_t i = 0; i < n; ++i) {
    samples.radiance[i] = source != LightSource::kEnvironmentOnly
                              ? BlendLight(field.colour[i], field.opacity[i], environment, directions[i], source, &o[i])
                              : BlendLight({}, 0.0f, environment, directions[i], source, &o[i]);
    if (depth && source != LightSource::kEnvironmentOnly && std::isfinite(field.depth[i]) && field.depth[i] > 0.0f)
      (*depth)[i] = field.depth[i];
  }
  // Cells where the light changes faster than the directions resolve.
  if (refine_rays > 0 && n >= 16 && source != LightSource::kEnvironmentOnly) {
    std::vector<double> y(n);
    double mean = 0.0;
    for (size_t i = 0; i < n; ++i) mean += (y[i] = LuminanceOf(samples.radiance[i])) / static_cast<double>(n);
    if (beside) mean += LuminanceOf(Integral(*beside)) / (4.0 * kPi);
    // Neighbours: within 1.8 spacings of an even set (spacing √(4π/N)),
    // found in the z band of that width (directions sorted by z).
    const double spacing = std::sqrt(4.0 * kPi / static_cast<double>(n));
    const double reach = 1.8 * spacing, cos_reach = std::cos(reach);
    std::vector<uint32_t> order(n);
    for (size_t i = 0; i < n; ++i) order[i] = static_cast<uint32_t>(i);
    std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return directions[a].z < directions[b].z; });
    std::vector<double> sorted_z(n);
    for (size_t k = 0; k < n; ++k) sorted_z[k] = directions[order[k]].z;
    std::vector<uint32_t> marked;
    for (size_t i = 0; i < n; ++i) {
      const double z = directions[i].z;
      const size_t first = std::lower_bound(sorted_z.begin(), sorted_z.end(), z - reach) - sorted_z.begin();
      const size_t last = std::upper_bound(sorted_z.begin(), sorted_z.end(), z + reach) - sorted_z.begin();
      bool mark = false;
      for (size_t k = first; k < last && !mark; ++k) {
        const uint32_t j = order[k];
        if (j == i || Dot(directions[i], directions[j]) < cos_reach) continue;
        const double hi = std::max(y[i], y[j]), lo = std::min(y[i], y[j]);
        mark = hi > mean && hi > refine_contrast * lo;
      }
      if (mark) marked.push_back(static_cast<uint32_t>(i));
    }
    // Sub-rays over each marked cell: a Vogel disc of the cell's equal-area
    // radius 2/√N in the tangent plane, turned per cell (no pattern shared
    // by neighbouring cells).
    const double radius = 2.0 / std::sqrt(static_cast<double>(n));
    const double golden = kPi * (3.0 - std::sqrt(5.0));
    const size_t k_rays = static_cast<size_t>(refine_rays);
    std::vector<Vec3> sub(marked.size() * k_rays);
    std::vector<float> sub_starts(sub.size());
    for (size_t m = 0; m < marked.size(); ++m) {
      const Vec3& d = directions[marked[m]];
      const Vec3 a = std::abs(d.x) < 0.9 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
      const Vec3 t1 = Normalized(Cross(d, a)), t2 = Cross(d, t1);
      const double turn = golden * 0.618 * static_cast<double>(marked[m]);
      for (size_t k = 0; k < k_rays; ++k) {
        const double r = radius * std::sqrt((k + 0.5) / static_cast<double>(k_rays));
        const double phi = turn + golden * static_cast<double>(k);
        sub[m * k_rays + k] = Normalized(d + (t1 * std::cos(phi) + t2 * std::sin(phi)) * r);
        sub_starts[m * k_rays + k] = marked[m] < starts.size() ? starts[marked[m]] : 0.0f;
      }
    }
    const SceneSamples sub_field = RenderFromCenter(scene, center, sub, sub_starts);
    for (size_t m = 0; m < marked.size(); ++m) {
      Vec3 sum{};
      double sum_o = 0.0;
      for (size_t k = 0; k < k_rays; ++k) {
        const size_t s = m * k_rays + k;
        float ok = 0.0f;
        sum += BlendLight(sub_field.colour[s], sub_field.opacity[s], environment, sub[s], source, &ok);
        sum_o += ok;
      }
      samples.radiance[marked[m]] = sum / static_cast<double>(k_rays);
      o[marked[m]] = static_cast<float>(sum_o / static_cast<double>(k_rays));
    }
    if (refined) *refined = marked.size();
  }
  if (opacity) *opacity = o;
  return samples;
}

void SplitCompactLobes(const SgMixture& environment, int directions, int max_compact, SgMixture* broad,
                       SgMixture* compact, std::vector<size_t>* compact_index) {
  broad->clear();
  compact->clear();
  if (compact_index) compact_index->clear();
  const double sharp = CompactSharpness(directions);
  // The compact candidates by energy, most first (ties: original order).
  std::vector<size_t> candidates;
  for (size_t k = 0; k < environment.size(); ++k)
    if (environment[k].sharpness > sharp) candidates.push_back(k);
  const auto energy = [&](size_t k) { return LuminanceOf(Integral(environment[k])); };
  std::stable_sort(candidates.begin(), candidates.end(), [&](size_t a, size_t b) { return energy(a) > energy(b); });
  std::vector<char> is_compact(environment.size(), 0);
  for (size_t i = 0; i < candidates.size() && i < static_cast<size_t>(std::max(max_compact, 0)); ++i)
    is_compact[candidates[i]] = 1;
  for (size_t k = 0; k < environment.size(); ++k) {
    (is_compact[k] ? compact : broad)->push_back(environment[k]);
    if (is_compact[k] && compact_index) compact_index->push_back(k);
  }
}

std::vector<double> LobeTransmittance(const SceneField& scene, const Vec3& center, const SgMixture& lobes, int rays,
                                      const LightObjectVolume* volume) {
  const size_t per = static_cast<size_t>(std::max(rays, 1));
  std::vector<Vec3> directions;
  directions.reserve(lobes.size() * per);
  for (const Sg& lobe : lobes) {
    const std::vector<Vec3> bundle = SgQuadrature(lobe.axis, lobe.sharpness, static_cast<int>(per));
    directions.insert(directions.end(), bundle.begin(), bundle.end());
  }
  std::vector<float> starts;
  if (volume != nullptr) starts = ObjectExitDistances(*volume, center, directions);
  const SceneSamples field = RenderFromCenter(scene, center, directions, starts);
  std::vector<double> transmittance(lobes.size(), 1.0);
  for (size_t k = 0; k < lobes.size(); ++k) {
    double sum = 0.0;
    for (size_t j = k * per; j < (k + 1) * per && j < field.opacity.size(); ++j) {
      const float o = field.opacity[j];
      sum += 1.0 - (std::isfinite(o) ? std::clamp(o, 0.0f, 1.0f) : 0.0f);
    }
    transmittance[k] = sum / static_cast<double>(per);
  }
  return transmittance;
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
  constexpr double kSlack = 1e-6;  // rad and z: rounding of the cone and the band, far below a facet
  // Triangles in chunks over the threads, each chunk its own farthest
  // crossing per direction, merged by the maximum (the same in any order).
  const size_t triangles = mesh.triangles.size();
  const size_t chunks = std::min<size_t>(triangles, 8);
  std::vector<std::vector<double>> chunk_farthest(chunks, std::vector<double>(directions.size(), 0.0));
  ParallelFor(
      chunks,
      [&](size_t chunk) {
        std::vector<double>& farthest = chunk_farthest[chunk];
        for (size_t t = chunk * triangles / chunks; t < (chunk + 1) * triangles / chunks; ++t) {
          const auto& tri = mesh.triangles[t];
          const Vec3 a(mesh.positions[tri[0]]), b(mesh.positions[tri[1]]), c(mesh.positions[tri[2]]);
          double z_low = -2.0, z_high = 2.0;  // every direction, unless the cone is narrow
          double cos_cone = -2.0;             // the cone itself: directions farther from its axis miss
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
            cos_cone = std::cos(half) - kSlack;
          }
          const size_t first = std::lower_bound(sorted_z.begin(), sorted_z.end(), z_low) - sorted_z.begin();
          const size_t last = std::upper_bound(sorted_z.begin(), sorted_z.end(), z_high) - sorted_z.begin();
          for (size_t k = first; k < last; ++k) {
            const uint32_t i = order[k];
            // The z band is a ring around the pole; the triangle covers a small
            // part of it: a direction outside the cone cannot cross it.
            if (Dot(local[i], axis) < cos_cone) continue;
            farthest[i] = std::max(farthest[i], CrossingDistance(o, local[i], a, b, c));
          }
        }
      },
      1);
  std::vector<double> farthest(directions.size(), 0.0);
  for (const std::vector<double>& f : chunk_farthest)
    for (size_t i = 0; i < f.size(); ++i) farthest[i] = std::max(farthest[i], f[i]);
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
// Where the source of `lobe`, taken at `from`, lies: `distance` along its
// axis; none without a finite positive distance (a distant lobe).
std::optional<Vec3> SourceOf(const Sg& lobe, const Vec3& from, double distance) {
  if (!std::isfinite(distance) || !(distance > 0.0)) return std::nullopt;
  return from + lobe.axis * distance;
}
// `lobe` taken at `from` with its source `distance` away along its axis, as
// seen from p, re-aimed by `weight` in [0, 1] (ReaimLight). The ratio of new
// to old distance is clamped to [1/4, 4]; a lobe without a finite positive
// distance, or of weight 0, is returned unchanged. `distance_from_p`
// (optional): how far the source is from p (+infinity without a distance).
Sg ReaimLobe(const Sg& lobe, const Vec3& from, double distance, double weight, const Vec3& p,
             double* distance_from_p = nullptr) {
  if (distance_from_p) *distance_from_p = std::numeric_limits<double>::infinity();
  const std::optional<Vec3> source = SourceOf(lobe, from, distance);
  if (!source) return lobe;
  const Vec3 to_source = *source - p;
  const double d_new = Length(to_source);
  if (distance_from_p) *distance_from_p = d_new;
  if (!(weight > 0.0) || !(d_new > 0.0) || !std::isfinite(d_new)) return lobe;
  const double ratio = std::clamp(d_new / distance, 0.25, 4.0);
  const Vec3 axis = Normalized(lobe.axis * (1.0 - weight) + (to_source / d_new) * weight);
  if (!(Length(axis) > 0.5)) return lobe;  // opposite directions blended to nothing: keep the lobe
  Sg out = lobe;
  out.axis = axis;
  out.sharpness = lobe.sharpness * (1.0 + weight * (ratio * ratio - 1.0));
  return out;
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

std::vector<double> NearInverseDistances(const SgMixture& light, const std::vector<Vec3>& directions,
                                         const std::vector<float>& opacity, const std::vector<float>& depth,
                                         const std::vector<Vec3>& near_radiance) {
  const size_t n = std::min({directions.size(), opacity.size(), depth.size()});
  const bool shares = !light.empty() && near_radiance.size() >= n;
  std::vector<double> inverse(n, 0.0);
  for (size_t i = 0; i < n; ++i) {
    // A surface where the opacity reaches one half (as for κ receivers):
    // thin fog in front of the distant light does not make it near.
    if (!(opacity[i] >= kSurfaceOpacity && depth[i] > 0.0f && std::isfinite(depth[i]))) continue;
    double share = 1.0;  // the near share of the direction's light
    if (shares) {
      const double all = LuminanceOf(Evaluate(light, directions[i]));
      const double near = LuminanceOf(near_radiance[i]);
      share = all > 0.0 && std::isfinite(near) ? std::clamp(near / all, 0.0, 1.0) : 0.0;
    }
    inverse[i] = share / depth[i];
  }
  return inverse;
}

std::vector<double> LobeDistances(const SgMixture& light, const std::vector<Vec3>& directions,
                                  const std::vector<float>& opacity, const std::vector<float>& depth,
                                  const std::vector<Vec3>& near_radiance) {
  std::vector<double> distance(light.size(), std::numeric_limits<double>::infinity());
  const std::vector<double> near_inverse = NearInverseDistances(light, directions, opacity, depth, near_radiance);
  for (size_t k = 0; k < light.size(); ++k) {
    const Sg& lobe = light[k];
    const double mu = LuminanceOf(lobe.amplitude);
    if (!(mu > 0.0) || !std::isfinite(mu)) continue;
    double weight = 0.0, inverse = 0.0;
    for (size_t i = 0; i < near_inverse.size(); ++i) {
      const double w = std::exp(lobe.sharpness * (Dot(lobe.axis, directions[i]) - 1.0));
      if (!(w > 1e-6)) continue;  // beyond ~3.7 widths: no say
      weight += w;
      inverse += w * near_inverse[i];
    }
    if (weight > 0.0 && inverse > 0.0) distance[k] = weight / inverse;
  }
  return distance;
}

SgMixture ReaimLight(const SgMixture& light, const LightParallax& parallax, const Vec3& p,
                     const Vec3* receiver_normal) {
  SgMixture out = light;
  if (parallax.distance.size() != light.size()) return out;
  for (size_t k = 0; k < light.size(); ++k) {
    const double weight = ParallaxWeight(light[k].sharpness, parallax.min_sharpness);
    const double distance = parallax.distance[k];
    out[k] = ReaimLobe(light[k], parallax.center, distance, weight, p);
    const std::optional<Vec3> source = SourceOf(light[k], parallax.center, distance);
    if (receiver_normal == nullptr || !(weight > 0.0) || !source) continue;
    // The source's height above p's tangent plane, in units of its own
    // extent (the lobe's width 1/√λ at its distance): none of it lights p
    // at or below the plane, all of it from one extent above, and linearly
    // in between, so that κ does not jump where a receiver's plane passes
    // through the source (a patch of the table under a receiver on it).
    const double extent = distance / std::sqrt(light[k].sharpness);
    const double height = Dot(*source - p, *receiver_normal);
    const double lit = std::clamp(height / extent, 0.0, 1.0);
    if (lit < 1.0) out[k].amplitude = out[k].amplitude * lit;
  }
  return out;
}

SgMixture EnvironmentSeenFrom(const SgMixture& environment, const std::vector<double>& distance_m, const Vec3& p,
                              std::vector<double>* distance_from_p) {
  SgMixture out = environment;
  const bool placed = distance_m.size() == environment.size();
  if (distance_from_p) distance_from_p->assign(environment.size(), std::numeric_limits<double>::infinity());
  for (size_t k = 0; placed && k < environment.size(); ++k)
    out[k] =
        ReaimLobe(environment[k], Vec3{}, distance_m[k], 1.0, p, distance_from_p ? &(*distance_from_p)[k] : nullptr);
  return out;
}

void IncidentLight::Reset() {
  valid_ = false;
  light_.clear();
  fitted_.clear();
  compact_.clear();
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

IncidentLight::Update IncidentLight::Refresh(const SceneField& scene, const SgMixture& environment_at_origin,
                                             const Vec3& center, const IncidentLightOptions& options,
                                             const LightObjectVolume* volume,
                                             const std::vector<double>& environment_distance_m) {
  Update update;
  // Whether the rays would start elsewhere than last time (the object turned
  // into a different shape along some ray).
  const std::vector<float>* starts = Starts(center, options, volume);
  const bool same_starts = SameStarts(starts, fitted_starts_, options.start_tolerance_m);
  const bool analytic = options.analytic_compact_lobes && options.source != LightSource::kNearFieldOnly;
  const bool same_setup = valid_ && directions_ == options.directions && source_ == options.source &&
                          lobes_ == options.fit.lobes && same_starts && refine_rays_ == options.refine_rays &&
                          refine_contrast_ == options.refine_contrast && analytic_ == analytic &&
                          bundle_rays_ == options.lobe_bundle_rays;
  const bool same_parallax = options.parallax == !distances_.empty() || light_.empty();
  if (same_setup && same_parallax && Length(center - center_) <= options.move_threshold_m) return update;
  update.recomputed = true;
  if (static_cast<int>(dirs_.size()) != options.directions) dirs_ = FibonacciSphere(options.directions);
  // The environment as the centre sees it (its lights at a distance turned
  // towards where they stand), with each lobe's distance from the centre.
  std::vector<double> distance_from_center;
  const SgMixture environment =
      EnvironmentSeenFrom(environment_at_origin, environment_distance_m, center, &distance_from_center);
  // The compact lobes pass analytically; the directions carry the rest, and
  // the fit gets the lobes they leave of the budget (at least half of it).
  SgMixture broad = environment;
  compact_.clear();
  std::vector<size_t> compact_index;
  if (analytic)
    SplitCompactLobes(environment, options.directions, options.fit.lobes / 2, &broad, &compact_, &compact_index);
  auto t0 = std::chrono::steady_clock::now();
  if (!compact_.empty() && options.source == LightSource::kFull) {
    const std::vector<double> seen =
        LobeTransmittance(scene, center, compact_, options.lobe_bundle_rays, starts != nullptr ? volume : nullptr);
    for (size_t k = 0; k < compact_.size(); ++k) compact_[k].amplitude = compact_[k].amplitude * seen[k];
  }
  samples_ = SampleIncidentLight(scene, broad, center, dirs_, options.source, &opacity_, &depth_, starts,
                                 options.refine_rays, options.refine_contrast, &refined_, &compact_);
  update.sample_ms = MillisecondsSince(t0);
  double total = 0.0;
  for (const Vec3& l : samples_.radiance) total += LuminanceOf(l);
  if (options.source == LightSource::kEnvironmentOnly) {
    light_ = environment;  // already SGs: nothing to fit
    fitted_.clear();
  } else if (!(total > 0.0)) {
    fitted_.clear();  // darkness (e.g. the centre inside opaque geometry): no lobe to fit
  } else {
    t0 = std::chrono::steady_clock::now();
    SgFitOptions fit = options.fit;
    fit.lobes = options.fit.lobes - static_cast<int>(compact_.size());
    const bool warm = same_setup && static_cast<int>(fitted_.size()) == fit.lobes;
    fitted_ = FitSg(samples_, fit, warm ? &fitted_ : nullptr, &update.report);
    update.fit_ms = MillisecondsSince(t0);
  }
  if (options.source != LightSource::kEnvironmentOnly) {
    light_ = fitted_;
    light_.insert(light_.end(), compact_.begin(), compact_.end());
  }
  distances_.clear();
  if (options.parallax && !light_.empty()) {
    if (options.source == LightSource::kEnvironmentOnly) {
      // The environment's own lobes: distant unless placed at a distance.
      distances_ = distance_from_center;
    } else {
      // The fitted lobes' distances from the scene, with Ĉ (the scene's own
      // radiance) the near-field part of each sample; then the compact
      // environment lobes', as the environment's own.
      std::vector<Vec3> near(samples_.radiance.size());
      for (size_t i = 0; i < near.size(); ++i)
        near[i] = samples_.radiance[i] - (broad.empty() || options.source == LightSource::kNearFieldOnly
                                              ? Vec3{}
                                              : Evaluate(broad, dirs_[i]) * (1.0 - opacity_[i]));
      distances_ = LobeDistances(fitted_, dirs_, opacity_, depth_, near);
      distances_.resize(fitted_.size(), std::numeric_limits<double>::infinity());
      for (const size_t k : compact_index) distances_.push_back(distance_from_center[k]);
    }
  }
  valid_ = true;
  fitted_starts_ = starts != nullptr ? *starts : std::vector<float>{};
  center_ = center;
  directions_ = options.directions;
  source_ = options.source;
  lobes_ = options.fit.lobes;
  refine_rays_ = options.refine_rays;
  refine_contrast_ = options.refine_contrast;
  analytic_ = analytic;
  bundle_rays_ = options.lobe_bundle_rays;
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

ImageF SamplesPanorama(const RadianceSamples& samples, int width, int height) {
  ImageF out(std::max(width, 0), std::max(height, 0), 3);
  const size_t n = std::min(samples.directions.size(), samples.radiance.size());
  if (n == 0 || out.empty()) return out;
  // Samples sorted by z: the nearest one to a pixel lies within the z band
  // of a few sample spacings (even point sets), searched first; the whole
  // set where that band holds none.
  std::vector<uint32_t> order(n);
  for (size_t i = 0; i < n; ++i) order[i] = static_cast<uint32_t>(i);
  std::sort(order.begin(), order.end(),
            [&](uint32_t a, uint32_t b) { return samples.directions[a].z < samples.directions[b].z; });
  std::vector<double> sorted_z(n);
  for (size_t k = 0; k < n; ++k) sorted_z[k] = samples.directions[order[k]].z;
  const double band = std::min(2.0, 4.0 * std::sqrt(4.0 * kPi / static_cast<double>(n)));
  ParallelFor(
      static_cast<size_t>(out.height),
      [&](size_t row) {
        for (int x = 0; x < out.width; ++x) {
          const Vec3 d = EquirectDirection((x + 0.5) / out.width, (row + 0.5) / out.height);
          const auto nearest = [&](size_t first, size_t last) {
            double best = -2.0;
            size_t best_i = SIZE_MAX;
            for (size_t k = first; k < last; ++k) {
              const double c = Dot(d, samples.directions[order[k]]);
              if (c > best) best = c, best_i = order[k];
            }
            return std::make_pair(best, best_i);
          };
          const size_t first = std::lower_bound(sorted_z.begin(), sorted_z.end(), d.z - band) - sorted_z.begin();
          const size_t last = std::upper_bound(sorted_z.begin(), sorted_z.end(), d.z + band) - sorted_z.begin();
          auto [cos_best, i] = nearest(first, last);
          // The band holds every direction within acos(1 − band) ≥ band of d:
          // a nearer sample outside it is impossible once one is that close.
          if (i == SIZE_MAX || cos_best < 1.0 - band) std::tie(cos_best, i) = nearest(0, n);
          for (int c = 0; c < 3; ++c) out.at(x, static_cast<int>(row), c) = static_cast<float>(samples.radiance[i][c]);
        }
      },
      4);
  return out;
}

bool SphereRegion::Contains(const Vec3& d) const {
  const double elevation = std::asin(std::clamp(d.z, -1.0, 1.0)) * 180.0 / kPi;
  double azimuth = std::atan2(d.y, d.x) * 180.0 / kPi;
  if (azimuth >= 180.0) azimuth -= 360.0;
  const bool top = elevation_max_deg >= 90.0 && elevation >= 90.0;  // the pole belongs to the top band
  return elevation >= elevation_min_deg && (elevation < elevation_max_deg || top) && azimuth >= azimuth_min_deg &&
         azimuth < azimuth_max_deg;
}

std::vector<SphereRegion> LightReportRegions(const ImageF& truth, double source_factor, double source_margin_deg) {
  std::vector<SphereRegion> regions;
  const auto band = [](std::string name, double lo, double hi, double az_lo = -180.0, double az_hi = 180.0) {
    SphereRegion r;
    r.name = std::move(name);
    r.elevation_min_deg = lo;
    r.elevation_max_deg = hi;
    r.azimuth_min_deg = az_lo;
    r.azimuth_max_deg = az_hi;
    return r;
  };
  regions.push_back(band("all", -90.0, 90.0));
  regions.push_back(band("above 15 deg", 15.0, 90.0));
  regions.push_back(band("horizon +-15 deg", -15.0, 15.0));
  regions.push_back(band("below -15 deg", -90.0, -15.0));
  for (int e = 0; e < 6; ++e)
    for (int a = 0; a < 4; ++a) {
      const double lo = 60.0 - 30.0 * e, az = -180.0 + 90.0 * a;
      regions.push_back(band("el " + std::to_string(int(lo)) + ".." + std::to_string(int(lo + 30)) + " az " +
                                 std::to_string(int(az)) + ".." + std::to_string(int(az + 90)),
                             lo, lo + 30.0, az, az + 90.0));
    }
  if (truth.empty() || truth.channels < 3) return regions;
  // The truth's compact sources, widened by the margin.
  const int w = truth.width, h = truth.height;
  double mean = 0.0, area = 0.0;
  for (int y = 0; y < h; ++y) {
    const double omega = EquirectPixelSolidAngle(w, h, y);
    for (int x = 0; x < w; ++x) {
      const float* p = truth.Pixel(x, y);
      mean += LuminanceOf(Vec3{p[0], p[1], p[2]}) * omega;
      area += omega;
    }
  }
  mean = area > 0.0 ? mean / area : 0.0;
  std::vector<Vec3> bright;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float* p = truth.Pixel(x, y);
      if (mean > 0.0 && LuminanceOf(Vec3{p[0], p[1], p[2]}) > source_factor * mean)
        bright.push_back(EquirectDirection((x + 0.5) / w, (y + 0.5) / h));
    }
  if (bright.empty()) return regions;
  SphereRegion sources;
  sources.name = "sources (truth > " + std::to_string(int(source_factor)) + "x mean, +" +
                 std::to_string(int(source_margin_deg)) + " deg)";
  sources.mask.assign(static_cast<size_t>(w) * h, 0);
  const double cos_margin = std::cos(source_margin_deg * kPi / 180.0);
  ParallelFor(
      static_cast<size_t>(h),
      [&](size_t y) {
        for (int x = 0; x < w; ++x) {
          const Vec3 d = EquirectDirection((x + 0.5) / w, (y + 0.5) / h);
          for (const Vec3& b : bright)
            if (Dot(d, b) >= cos_margin) {
              sources.mask[y * w + x] = 1;
              break;
            }
        }
      },
      4);
  SphereRegion rest = band("rest (not sources)", -90.0, 90.0);
  rest.mask = sources.mask;
  for (unsigned char& m : rest.mask) m = m ? 0 : 1;
  regions.push_back(std::move(sources));
  regions.push_back(std::move(rest));
  return regions;
}

double RegionFlux(const ImageF& panorama, const SphereRegion& region) {
  if (panorama.empty() || panorama.channels < 3) return 0.0;
  const int w = panorama.width, h = panorama.height;
  const bool masked = !region.mask.empty();
  if (masked && region.mask.size() != static_cast<size_t>(w) * h)
    ThrowInputError("light report", "region '" + region.name + "' mask is " + std::to_string(region.mask.size()) +
                                        " pixels (expected " + std::to_string(w) + "x" + std::to_string(h) + ")");
  double flux = 0.0;
  for (int y = 0; y < h; ++y) {
    const double omega = EquirectPixelSolidAngle(w, h, y);
    for (int x = 0; x < w; ++x) {
      const bool in = masked ? region.mask[static_cast<size_t>(y) * w + x] != 0
                             : region.Contains(EquirectDirection((x + 0.5) / w, (y + 0.5) / h));
      if (!in) continue;
      const float* p = panorama.Pixel(x, y);
      flux += LuminanceOf(Vec3{p[0], p[1], p[2]}) * omega;
    }
  }
  return flux;
}

}  // namespace nerfar
