// Estimating the distant environment light from an HDR NeRF by inverse
// rendering (paper §4.2). Views are sampled on a sphere around the NeRF
// volume's centre and looking at it; views whose rendering BRISQUE scores
// above a limit are rejected. Pixels through the NeRF give surface points
// x = o + D·d with normals −∇σ/|∇σ| and observed radiance L_o. At each point R
// rays leave in cosine-distributed directions over the normal's hemisphere
// (a Fibonacci disk lifted to the hemisphere, randomly turned about n per
// point): they give the near-field irradiance E_nerf = π/R Σ Ĉ_j (paper
// §4.2, computed once) and the NeRF opacity Ô_j towards each direction, kept
// as the per-point visibility cache. The environment's irradiance is
//   E_env(x) = ∫ (1 − Ô) L_env max(n·d, 0) dd
//            ≈ Σ_k μ_k U(p_k·n, λ_k) · Σ_j (1 − Ô_j) G_k(d_j) / Σ_j G_k(d_j),
// the unoccluded irradiance exact (render/sg UnitIrradiance tables, right for
// sharp lobes) times the lobe's open fraction by the deterministic quadrature over the
// cached directions (noise free; points with no occluded direction cost nothing).
// The model L_o = a(x)/π (E_nerf + E_env) (paper eq. 3) is fitted with a
// piecewise-constant albedo on a coarse grid (a smooth albedo, as the paper's
// MLP, solved in closed form per cell) and the lobes chosen from a
// multi-scale dictionary of SGs by non-negative least squares, alternating,
// under a robust relative (HDR) loss; small bright sources beyond the
// dictionary (a sun: sharpness up to 1e4) are found from the shadows they
// cast through NeRF shadow rays and placed continuously; the sources and the
// best other lobes, 32 in all, are then re-solved, grey unless the data
// supports a lobe's colour. World frame, metres, linear RGB radiance.
// The pieces, one job each: env_options.h (options), env_samples.h (views,
// surface samples), env_near_field.h (E_nerf, visibility cache, the NeRF seen
// from a point), env_shadow.h (shadow rays, sharp lobes' irradiance), env_fit.h
// (SG + albedo fit, sources, chroma); env_light.h (env.json, preview).
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "calib/core/math.h"
#include "render/lighting/env_fit.h"
#include "render/lighting/env_light.h"
#include "render/lighting/env_near_field.h"
#include "render/lighting/env_options.h"
#include "render/lighting/env_samples.h"
#include "render/nerf/nerf_field.h"
#include "render/sg/sg.h"

namespace nerfar {

struct EnvEstimateReport {
  EnvViewReport views;
  EnvFitReport fit;
  size_t samples = 0;
  double seconds_views = 0, seconds_near_field = 0, seconds_fit = 0;
  // Set keep_samples before the call to get the samples (with their near
  // field) and the fitted environment's irradiance at each (diagnostics).
  bool keep_samples = false;
  EnvSurfaceSamples surface;
  std::vector<Vec3> e_env;
};

// The whole estimate: samples, near field, fit, energy ratios and the negligible flag.
EnvLight EstimateEnvironment(const NerfField& field, const EnvEstimateOptions& options,
                             EnvEstimateReport* report = nullptr, const EnvProgress& progress = nullptr);

// Relative RMS of irradiance (luminance) between two lights over the unit
// normals given: sqrt(Σ (E_a − E_b)²) / sqrt(Σ E_b²), b the reference.
double RelativeIrradianceRms(const std::vector<Vec3>& estimate, const std::vector<Vec3>& reference);

}  // namespace nerfar
