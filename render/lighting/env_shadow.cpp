#include "render/lighting/env_shadow.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "calib/core/parallel.h"
#include "render/lighting/env_internal.h"
#include "render/sg/visibility.h"

namespace nerfar {

using env_internal::kBundleTurn;
using env_internal::OrthonormalBasis;
using env_internal::ToD;
using env_internal::Uniform;

EnvSurfaceRay SurfaceRay(const EnvSurfaceSamples& samples, size_t i, const Vec3f& dir) {
  const float layer = i < samples.layer_m.size() ? samples.layer_m[i] : 0.0f;
  const float slant = 1.0f / std::max(Dot(samples.normals[i], dir), 1.0f / kLayerSlant);
  return {samples.positions[i] + dir * (samples.ray_offset_m * slant), dir, layer * slant};
}

NerfRayResult RenderSurfaceRay(const NerfField& field, const EnvSurfaceRay& surface_ray,
                               const NerfRenderOptions& render, const NerfRenderOptions& through_layer) {
  NerfRay ray{surface_ray.origin, surface_ray.dir, 0, 0};
  if (!IntersectAabb(field.aabb, ray.origin, ray.dir, ray.t_near, ray.t_far)) return {};
  const float split = std::clamp(surface_ray.layer_length, ray.t_near, ray.t_far);
  NerfRay near = ray, far = ray;
  near.t_far = split;
  far.t_near = split;
  const NerfRayResult a = split > ray.t_near ? field.RenderRay(near, through_layer) : NerfRayResult{};
  if (!(a.opacity < 1.0f) || !(far.t_far > far.t_near)) return a;
  const NerfRayResult b = field.RenderRay(far, render);
  const float t_a = 1.0f - a.opacity;
  NerfRayResult out;
  out.color = a.color + b.color * t_a;
  out.opacity = 1.0f - t_a * (1.0f - b.opacity);
  out.depth = out.opacity > 0 ? (a.opacity * a.depth + t_a * b.opacity * b.depth) / out.opacity : 0.0f;
  // Where the transmittance crosses 1/2: in the layer stretch, else (about) where the rest's does.
  out.surface_depth = a.opacity >= 0.5f ? a.surface_depth : out.opacity >= 0.5f ? b.surface_depth : out.depth;
  out.samples = a.samples + b.samples;
  out.color_samples = a.color_samples + b.color_samples;
  return out;
}

NerfRenderOptions PassingFog(NerfRenderOptions render, double sigma, double voxel_m) {
  const double alpha = -std::expm1(-sigma * render.step_voxels * voxel_m);
  render.min_alpha = static_cast<float>(std::clamp(alpha, static_cast<double>(render.min_alpha), 0.5));
  return render;
}

EnvShadowRays NerfShadowRays(const NerfField& field, const NerfRenderOptions& render, float fog_density) {
  const NerfRenderOptions through_layer = PassingFog(render, fog_density, field.voxel_m);
  return [&field, render, through_layer](const std::vector<EnvSurfaceRay>& rays, std::vector<float>* transmittance) {
    transmittance->assign(rays.size(), 1.0f);
    ParallelFor(
        rays.size(),
        [&](size_t k) {
          const float opacity = RenderSurfaceRay(field, rays[k], render, through_layer).opacity;
          (*transmittance)[k] = std::clamp(1.0f - opacity, 0.0f, 1.0f);
        },
        256);
  };
}

double CacheSharpnessLimit(int rays_per_point) { return rays_per_point / kPi; }

std::vector<uint32_t> AllSamples(const EnvSurfaceSamples& samples) {
  std::vector<uint32_t> all(samples.size());
  std::iota(all.begin(), all.end(), 0u);
  return all;
}

namespace {

// Stratified directions of a lobe (von Mises-Fisher of concentration λ, the
// SG's own distribution): cos θ_j from the inverse CDF at (j + ½)/K, the
// azimuths a golden-angle spiral turned by `turn` (radians).
void LobeDirections(const Vec3& axis, double sharpness, int bundle, double turn, std::vector<Vec3>* dirs) {
  Vec3 u, v;
  OrthonormalBasis(axis, u, v);
  dirs->resize(bundle);
  if (bundle == 1) {
    (*dirs)[0] = axis;
    return;
  }
  const double golden = kPi * (3.0 - std::sqrt(5.0)), tail = std::exp(-2.0 * sharpness);
  for (int j = 0; j < bundle; ++j) {
    const double xi = (j + 0.5) / bundle;
    const double w = std::clamp(1.0 + std::log(xi + (1.0 - xi) * tail) / sharpness, -1.0, 1.0);
    const double r = std::sqrt(std::max(0.0, 1.0 - w * w)), phi = turn + golden * j;
    (*dirs)[j] = Normalized(axis * w + u * (r * std::cos(phi)) + v * (r * std::sin(phi)));
  }
}

}  // namespace

Vec3 AimAt(const Vec3& axis, double distance, const Vec3& point, double* falloff) {
  *falloff = 1;
  if (!(distance > 0)) return axis;
  const Vec3 to = axis * distance - point;
  const double length = std::sqrt(Dot(to, to));
  *falloff = (distance / length) * (distance / length);
  return to * (1.0 / length);
}

std::vector<std::vector<double>> BundleIrradiance(const EnvSurfaceSamples& samples, const EnvShadowRays& shadow,
                                                  const std::vector<uint32_t>& subset, const std::vector<Vec3>& axes,
                                                  const std::vector<double>& sharpness, int bundle, uint64_t seed,
                                                  const std::vector<double>& distance) {
  const size_t lobes = axes.size(), m = subset.size();
  // Per (lobe, sample): the open irradiance, and the bundle's rays with their cosines.
  std::vector<std::vector<double>> open(lobes, std::vector<double>(m, 0.0));
  std::vector<std::vector<double>> cosine(lobes, std::vector<double>(m * bundle, 0.0));
  std::vector<std::vector<Vec3>> dirs(lobes, std::vector<Vec3>(m * bundle));
  for (size_t k = 0; k < lobes; ++k) {
    const SgTableRow row = PrepareIrradiance(sharpness[k]);
    ParallelFor(
        m,
        [&](size_t a) {
          const uint32_t i = subset[a];
          const Vec3 normal = ToD(samples.normals[i]);
          double scale = 1;
          const Vec3 axis = distance.empty() ? axes[k] : AimAt(axes[k], distance[k], ToD(samples.positions[i]), &scale);
          open[k][a] = scale * std::max(0.0f, UnitIrradiancePrepared(row, static_cast<float>(Dot(axis, normal))));
          if (!(open[k][a] > 0)) return;
          std::vector<Vec3> lobe;
          LobeDirections(axis, sharpness[k], bundle, 2 * kPi * Uniform(seed, kBundleTurn, i, k), &lobe);
          for (int j = 0; j < bundle; ++j) {
            dirs[k][a * bundle + j] = lobe[j];
            cosine[k][a * bundle + j] = std::max(0.0, Dot(lobe[j], normal));
          }
        },
        64);
  }
  // One batch of rays: those with a positive cosine.
  std::vector<EnvSurfaceRay> rays;
  for (size_t k = 0; k < lobes; ++k)
    for (size_t a = 0; a < m; ++a)
      for (int j = 0; j < bundle; ++j)
        if (cosine[k][a * bundle + j] > 0)
          rays.push_back(SurfaceRay(samples, subset[a], Vec3f(dirs[k][a * bundle + j])));
  std::vector<float> transmittance;
  if (!rays.empty()) shadow(rays, &transmittance);
  std::vector<std::vector<double>> column(lobes, std::vector<double>(m, 0.0));
  size_t next = 0;
  for (size_t k = 0; k < lobes; ++k)
    for (size_t a = 0; a < m; ++a) {
      double num = 0, den = 0;
      for (int j = 0; j < bundle; ++j) {
        const double c = cosine[k][a * bundle + j];
        if (!(c > 0)) continue;
        num += c * transmittance[next++];
        den += c;
      }
      column[k][a] = den > 0 ? open[k][a] * num / den : 0.0;
    }
  return column;
}

std::vector<double> BundleIrradiance(const EnvSurfaceSamples& samples, const EnvShadowRays& shadow,
                                     const std::vector<uint32_t>& subset, const Vec3& axis, double sharpness,
                                     int bundle, uint64_t seed) {
  return BundleIrradiance(samples, shadow, subset, std::vector<Vec3>{axis}, std::vector<double>{sharpness}, bundle,
                          seed)
      .front();
}

}  // namespace nerfar
