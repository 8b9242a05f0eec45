// Fitting M SG lobes (1..64, default 32) to radiance samples on the sphere
// (paper §4.4 "SG updating"). Loss: Σ_i ω_i Σ_c (L_c(d_i) − y_ic)² / (τ + Y_i)²,
// ω_i the sample's solid angle, Y_i its luminance and τ = hdr_floor × the mean
// luminance: a relative error where the light is bright, an absolute one in
// the dark, so a window 1000× brighter than the sky does not drown the sky.
// Amplitudes stay ≥ 0, results are deterministic (single thread, fixed order),
// and a previous fit can seed the next one (warm start).
#pragma once

#include <string>
#include <vector>

#include "render/sg/sg.h"
#include "render/sg/sphere.h"

namespace nerfar {

// How the non-linear parameters (axes, sharpness) are optimised; amplitudes
// are always solved exactly by non-negative least squares in between, except
// for kAdam, which descends on everything. docs/SG.md has the measurement that
// picked the default.
enum class SgFitMethod {
  kAlternatingBlock,  // NNLS + Gauss-Newton/LM per lobe (3×3 blocks): default
  kAlternatingDense,  // NNLS + LM on all axes and sharpness jointly (3M×3M)
  kAdam,              // first-order, all parameters (μ through a softplus)
};
// The methods' names in the enum's order ("block", "dense", "adam"): `--set
// sg_method=NAME` (InsertOptions::Fields) and the SG bench's labels.
const std::vector<const char*>& SgFitMethodNames();

struct SgFitOptions {
  int lobes = 32;            // M, 1..64: more lobes, sharper detail, more time
  int cold_iterations = 30;  // outer iterations from scratch (budget ≤ 80 ms at 2048 samples)
  int warm_iterations = 1;   // outer iterations from a previous fit (budget ≤ 3 ms)
  double hdr_floor = 30.0;   // τ in units of the mean luminance: relative error only above 30× the mean (the lights);
                             // lower favours dim detail, higher the irradiance
  double min_sharpness = 0.5;  // λ lower bound: broader lobes would be nearly constant
  double max_sharpness = 1e4;  // λ upper bound (DESIGN.md range)
  double tolerance = 1e-5;     // stop when an iteration lowers the loss by less than this fraction
  SgFitMethod method = SgFitMethod::kAlternatingBlock;
  int adam_iterations = 400;  // kAdam only: steps from scratch (warm: a quarter)
  double adam_step = 0.02;    // kAdam only: learning rate

  // Every problem as "field: what is wrong (what was expected)".
  std::vector<std::string> Validate() const;
  // "fast" (16 lobes, 12 iterations, 1 warm), "balanced" (the defaults),
  // "accurate" (48 lobes, 60 iterations, 4 warm). InputError for other names.
  static SgFitOptions Preset(const std::string& name);
};

struct SgFitReport {
  double initial_loss = 0;  // loss of the starting point (after the first amplitude solve)
  double final_loss = 0;    // loss at the end (units: the normalised loss above, per sr)
  int iterations = 0;       // outer iterations run
  bool warm = false;        // started from a previous fit
};

// Fits options.lobes lobes to the samples. With `warm_start` (a previous
// result with the same lobe count) only warm_iterations run from it; without,
// the lobes are placed greedily on the largest relative residuals first.
// InputError for invalid options or samples (sizes, non-finite values).
SgMixture FitSg(const RadianceSamples& samples, const SgFitOptions& options, const SgMixture* warm_start = nullptr,
                SgFitReport* report = nullptr);

// The loss above for a given mixture (for reports and tests).
double SgFitLoss(const RadianceSamples& samples, const SgMixture& mixture, double hdr_floor);

}  // namespace nerfar
