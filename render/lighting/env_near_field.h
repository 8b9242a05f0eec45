// The near field of the environment estimate (paper §4.2): E_nerf at each
// surface sample by Monte Carlo from the NeRF (computed once) and the NeRF's
// opacity towards each ray, kept per sample as the visibility cache; and the
// NeRF seen from one point (what E_env / E_nerf at a point is measured with).
#pragma once

#include <functional>
#include <vector>

#include "calib/core/math.h"
#include "render/lighting/env_options.h"
#include "render/lighting/env_samples.h"
#include "render/lighting/seen_radiance.h"
#include "render/nerf/nerf_field.h"
#include "render/sg/sg.h"

namespace nerfar {

// E_nerf and the visibility cache for every sample (ray casting through the field).
void ComputeNearField(const NerfField& field, const EnvEstimateOptions& options, EnvSurfaceSamples& samples,
                      const EnvProgress& progress = nullptr);

// The NeRF seen from a point: its radiance Ĉ and opacity Ô towards N
// Fibonacci directions (each standing for 4π/N sr).
struct NerfIncident {
  std::vector<Vec3> dirs;
  std::vector<Vec3> color;
  std::vector<double> opacity;
  // Near-field irradiance Σ Ĉ max(n·d, 0) 4π/N.
  Vec3 NearIrradiance(const Vec3& normal) const;
  // A distant light L(d) seen through the NeRF: Σ (1 − Ô) L(d) max(n·d, 0) 4π/N.
  Vec3 DistantIrradiance(const std::function<Vec3(const Vec3&)>& light, const Vec3& normal) const;
};
// `seen`: the rays' radiance corrected as ApplySeenRadiance does (nullptr: the NeRF's own).
NerfIncident NerfIncidentAt(const NerfField& field, const Vec3& point, int directions = 1024,
                            const NerfRenderOptions& render = {}, const SeenRadianceOptions* seen = nullptr);

// E_env / E_nerf (luminance) at a point: rays in `directions` Fibonacci
// directions from `point`, both irradiances averaged over `normals` normals
// spread over the sphere. +inf when the near field is black and the
// environment is not, 0 when both are.
double EnvToNearRatioAt(const NerfField& field, const SgMixture& light, const Vec3& point, int directions = 1024,
                        int normals = 64, const NerfRenderOptions& render = {},
                        const SeenRadianceOptions* seen = nullptr);

}  // namespace nerfar
