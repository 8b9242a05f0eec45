// Shadow rays of the environment estimate: the transmittance from the surface
// samples towards given directions (through the NeRF, or any other occluder
// in tests), and the irradiance of SG lobes at the samples through it. The
// visibility cache (R cosine-distributed rays per sample, env_samples.h)
// resolves lobes no sharper than about R/π (its ray spacing); sharper lobes,
// up to a sun of under a degree, are seen through bundles of shadow rays
// spread over each lobe. World frame, metres; directions unit vectors.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "calib/core/math.h"
#include "render/lighting/env_samples.h"
#include "render/nerf/nerf_field.h"

namespace nerfar {

// A ray leaving a surface sample: origin + t·dir, t ≥ 0; its first
// `layer_length` metres cross the sample's own translucent layer
// (EnvSurfaceSamples::layer_m), where density up to the samples' fog density
// passes as empty.
struct EnvSurfaceRay {
  Vec3f origin, dir;
  float layer_length = 0;
};
// The ray from sample i along `dir` (n·dir > 0). It starts on the line from
// the sample's position towards `dir`, where that line has risen
// ray_offset_m above the surface (t = ray_offset_m / n·dir): off the surface
// and its own fog, yet aimed from the sample itself, so that a shadow's edge
// is where the occluder's silhouette is seen from the sample. (A start lifted
// along the normal would see every occluder from ray_offset_m higher up:
// shadows on a table shortened by ray_offset_m / tan(elevation), and a light
// fitted to them placed too high.) The slant 1/(n·dir) is capped at
// kLayerSlant, for the start and for the layer's length: near grazing the
// cosine weights a ray little, and a long stretch could pass a real occluder.
// The layer is the sample's own (EnvSurfaceSamples::layer_m) beyond the
// start, over n·dir.
inline constexpr float kLayerSlant = 4.0f;
EnvSurfaceRay SurfaceRay(const EnvSurfaceSamples& samples, size_t i, const Vec3f& dir);

// The NeRF along a surface ray (clipped to the aabb): its layer stretch with
// `through_layer`, the rest with `render`; colour, opacity and depths combined.
NerfRayResult RenderSurfaceRay(const NerfField& field, const EnvSurfaceRay& ray, const NerfRenderOptions& render,
                               const NerfRenderOptions& through_layer);

// Render options whose rays pass density up to `sigma` (1/m) as empty: the
// renderer skips samples of opacity below min_alpha entirely (they neither dim
// the ray nor add colour), so min_alpha is raised to the opacity of one step
// through that density (at most 1/2).
NerfRenderOptions PassingFog(NerfRenderOptions render, double sigma, double voxel_m);

// Transmittance in [0, 1] of each ray out of the volume; `transmittance` is
// resized to the rays' count.
using EnvShadowRays = std::function<void(const std::vector<EnvSurfaceRay>& rays, std::vector<float>* transmittance)>;

// 1 − Ô of the NeRF along each ray (RenderSurfaceRay; rays that miss the aabb are open).
EnvShadowRays NerfShadowRays(const NerfField& field, const NerfRenderOptions& render, float fog_density);

// The sharpest lobe the visibility cache of `rays_per_point` rays resolves:
// its width 1/√λ reaches the rays' spacing √(π/R) at λ = R/π.
double CacheSharpnessLimit(int rays_per_point);

// Irradiance at the samples `subset` (indices into `samples`) from a unit-
// amplitude lobe (axis, sharpness) through shadow rays: the open irradiance
// U(p·n, λ) times the lobe's cosine-weighted mean transmittance over `bundle`
// directions drawn from the lobe (stratified, turned about the axis per
// sample by `seed`). bundle 1: the axis alone (a point source's shadow).
// Rays are SurfaceRay's; samples facing away cost nothing.
std::vector<double> BundleIrradiance(const EnvSurfaceSamples& samples, const EnvShadowRays& shadow,
                                     const std::vector<uint32_t>& subset, const Vec3& axis, double sharpness,
                                     int bundle, uint64_t seed);

// The same for several lobes at once (one batch of shadow rays): column k for
// lobe k. `distance` (empty: all distant): per lobe, how far from the world
// origin along its axis the light is, in metres (0: distant). A light at a
// finite distance is aimed at from each sample (AimAt): its direction and
// falloff change over the volume (parallax), its amplitude is as seen from
// the origin.
std::vector<std::vector<double>> BundleIrradiance(const EnvSurfaceSamples& samples, const EnvShadowRays& shadow,
                                                  const std::vector<uint32_t>& subset, const std::vector<Vec3>& axes,
                                                  const std::vector<double>& sharpness, int bundle, uint64_t seed,
                                                  const std::vector<double>& distance = {});

// The direction from `point` to a light `distance` metres from the origin
// along `axis` (0: distant, the axis itself), and in `falloff` its irradiance
// there relative to the origin's, (distance / range)² (1 when distant).
Vec3 AimAt(const Vec3& axis, double distance, const Vec3& point, double* falloff);

// Every sample's index, 0 .. n−1.
std::vector<uint32_t> AllSamples(const EnvSurfaceSamples& samples);

}  // namespace nerfar
