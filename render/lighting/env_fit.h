// The environment fit (paper §4.2, eq. 3): L_o = a(x)/π (E_nerf + E_env)
// with a piecewise-constant albedo on a coarse grid (solved in closed form per
// cell: the smooth albedo model) and the lobes chosen from a multi-scale
// dictionary of SGs by non-negative least squares, alternating, under a
// robust relative (HDR) loss. Then sharp sources (a sun, a lamp: sharpness up
// to ~1e4, beyond the dictionary and the visibility cache) are searched for
// one at a time from the residual, placed continuously and seen through
// shadow rays, each re-solved jointly with the rest and kept while the model
// selection supports it; the sources and the dictionary's most energetic
// lobes, M in all, are then re-solved. env_fit.cpp drives it;
// env_fit_steps.cpp holds the solves, env_lobes.cpp the lobes' irradiance,
// env_sources.cpp the search, env_shadow.h the shadow rays.
#pragma once

#include <vector>

#include "calib/core/math.h"
#include "render/lighting/env_options.h"
#include "render/lighting/env_samples.h"
#include "render/lighting/env_shadow.h"
#include "render/sg/sg.h"

namespace nerfar {

// Where a sharp source's evidence lies: from its log-likelihood gain per
// reflecting sample (the robust loss without the lobe minus with it, the
// rest of the fit held), the fewest samples that hold half the positive
// gain, and where they lie. A light explains samples wherever it shines; a
// gain held by a few samples in one patch points to that patch's own
// brightness (a printed tag, a material finer than the albedo cells) rather
// than to a light.
struct SourceSupport {
  double half_share = 0;  // those samples' fraction of all the given samples (0: no positive gain)
  double radius_m = 0;    // the largest distance of one of them from `centre`
  Vec3 centre;            // their mean position, weighted by their gains
};
// SourceSupport from per-sample gains at the given positions (same length).
SourceSupport SupportOfGains(const std::vector<Vec3f>& positions, const std::vector<double>& gain);

struct EnvFitReport {
  double initial_loss = 0, final_loss = 0;  // robust loss per sample
  int dictionary_size = 0;
  int active_lobes = 0;  // lobes with non-zero amplitude at the end
  int sources = 0;       // sharp sources found and kept (among the active lobes)
  // Per returned lobe, the distance of its light from the origin along its
  // axis in metres (0: distant, as every lobe but a source placed at a
  // distance); the lobe holds that light as seen from the origin.
  std::vector<double> lobe_distance_m;
  // Per returned lobe, where its evidence lies when it is a sharp source
  // (SourceSupport; all 0 for the dictionary's lobes).
  std::vector<SourceSupport> lobe_support;
  int coloured_lobes = 0;      // active lobes whose chroma the data supports (the others are grey)
  double mean_albedo = 0;      // luminance of the fitted albedo, mean over samples
  double relative_rms = 0;     // RMS of (model − L_o)/L_o over samples (luminance)
  double near_field_gain = 1;  // g fitted (1 when near_field_gain_max is 1)
  // Model selection (EnvEstimateOptions::evidence_bic_factor; all 0 and
  // supported when it is off or the near field is ignored):
  double near_only_loss = 0;          // robust loss per sample of the best fit without environment
  double evidence = 0;                // n·(near_only_loss − final_loss)/s²: the environment's log-likelihood gain
  double evidence_needed = 0;         // evidence_bic_factor · (k/2)·ln n, k the active lobes' parameters
  bool environment_supported = true;  // evidence > evidence_needed
  double near_only_relative_rms = 0;  // relative_rms of that fit without environment (0 when it was not run)
  // Per sample: the fitted model's radiance a/π·(g·E_nerf + E_env), what it predicts for L_o.
  std::vector<Vec3f> modelled;
};

// Free parameters of one SG lobe in the model selection: axis 2, sharpness 1,
// amplitude 1 for a neutral (grey) lobe; a coloured lobe's chroma adds 2.
constexpr int kSgLobeParameters = 4;
constexpr int kChromaParameters = 2;

// Fits the environment (lobes only; the ratios and flag are set by EstimateEnvironment).
// `aabb` sets the albedo grid. Without `shadow` no sharp source is searched
// for (the dictionary alone). InputError for invalid options.
SgMixture FitEnvironment(const EnvSurfaceSamples& samples, const Aabb& aabb, const EnvEstimateOptions& options,
                         EnvFitReport* report = nullptr, const EnvProgress& progress = nullptr,
                         const EnvShadowRays& shadow = nullptr);

// Per-sample weights of FitEnvironment's data term from the normals'
// directions (see EnvEstimateOptions::normal_balance), mean 1; all 1 at power 0.
// With `radiance` (observed, per sample), samples brighter than
// kEmitterLikeFactor x the median luminance keep at most weight 1.
constexpr int kNormalBalanceBins = 32;
constexpr double kEmitterLikeFactor = 10;
// Samples brighter than kEmitterLikeFactor x the median luminance: emitters
// (they glow with light no reflection explains).
std::vector<bool> EmitterLikeSamples(const std::vector<Vec3f>& radiance);
std::vector<double> NormalBalanceWeights(const std::vector<Vec3f>& normals, double power,
                                         const std::vector<Vec3f>* radiance = nullptr);

// Irradiance E_env(x) = ∫ (1 − Ô) L_env max(n·d, 0) dd of each sample as the
// fit models it: from its cache, and for lobes sharper than the cache resolves
// through `bundle` shadow rays each (when `shadow` is given). `distance`
// (one per lobe, or empty: all distant): a lobe's light stands at that
// distance from the origin along its axis (EnvFitReport::lobe_distance_m).
std::vector<Vec3> EnvironmentIrradiance(const EnvSurfaceSamples& samples, const SgMixture& light,
                                        const EnvShadowRays& shadow = nullptr, int bundle = 1, uint64_t seed = 0,
                                        const std::vector<double>& distance = {});

}  // namespace nerfar
