#include "render/lighting/env_near_field.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "calib/core/parallel.h"
#include "render/lighting/env_internal.h"
#include "render/lighting/env_shadow.h"
#include "render/sg/sphere.h"

namespace nerfar {

using env_internal::kRayTurn;
using env_internal::OrthonormalBasis;
using env_internal::ToD;
using env_internal::Uniform;
using env_internal::Y;

namespace {

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

// The median density at the rays' start points (EnvSurfaceSamples::fog_density).
float SurfaceFogDensity(const NerfField& field, const EnvSurfaceSamples& samples, float offset) {
  if (samples.size() == 0) return 0.0f;
  std::vector<Vec3f> starts(samples.size());
  for (size_t i = 0; i < samples.size(); ++i) starts[i] = samples.positions[i] + samples.normals[i] * offset;
  std::vector<float> sigma(samples.size());
  field.QueryDensity(starts.data(), starts.size(), sigma.data());
  std::nth_element(sigma.begin(), sigma.begin() + sigma.size() / 2, sigma.end());
  return sigma[sigma.size() / 2];
}

}  // namespace

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
  samples.ray_offset_m = offset;
  samples.fog_density = options.ignore_near_field ? 0.0f : SurfaceFogDensity(field, samples, offset);
  const NerfRenderOptions through_layer = PassingFog(options.render, samples.fog_density, field.voxel_m);
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
          for (int j = 0; j < R; ++j) {
            const Vec3& l = local[j];
            const double lx = ct * l.x - st * l.y, ly = st * l.x + ct * l.y;
            const Vec3f dir(Normalized(t * lx + b * ly + normal * l.z));
            samples.ray_dirs[i * R + j] = dir;
            if (options.ignore_near_field) continue;
            const EnvSurfaceRay surface_ray = SurfaceRay(samples, i, dir);
            NerfRay& ray = rays[k * R + j];
            ray = NerfRay{surface_ray.origin, dir, 0, 0};
            if (!IntersectAabb(field.aabb, ray.origin, dir, ray.t_near, ray.t_far)) continue;
            results[k * R + j] = RenderSurfaceRay(field, surface_ray, options.render, through_layer);
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

}  // namespace nerfar
