// Pieces of the environment fit shared by env_fit.cpp, env_fit_steps.cpp and
// env_lobes.cpp; not part of the module's interface.
#pragma once

#include <Eigen/Dense>
#include <vector>

#include "calib/core/math.h"
#include "render/lighting/env_options.h"
#include "render/lighting/env_samples.h"

namespace nerfar::env_internal {

struct Dictionary {
  std::vector<Vec3> axes;
  std::vector<double> sharpness;
  size_t size() const { return axes.size(); }
};
// Level l: dictionary_base·4^l lobes on a Fibonacci sphere, sharpness dictionary_sharpness·4^l.
Dictionary MakeDictionary(const EnvEstimateOptions& o);

// A(i, k): irradiance at sample i from unit-amplitude lobe k through the
// NeRF's visibility cache (see env_lobes.cpp).
Eigen::MatrixXd LobeIrradianceMatrix(const EnvSurfaceSamples& s, const std::vector<Vec3>& axes,
                                     const std::vector<double>& sharpness);

// min ‖Bx − y‖² s.t. x ≥ 0 from the normal equations G = BᵀB, h = Bᵀy
// (Lawson-Hanson active set).
Eigen::VectorXd Nnls(const Eigen::MatrixXd& G, const Eigen::VectorXd& h);

// The alternation's unknowns and fixed data.
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

// Model shading S_ic = g·E_nerf + A μ (without albedo).
Eigen::MatrixXd Shading(const FitState& st);
// Robust (Cauchy on the log residual) loss per sample; with update_robust the
// IRLS weights of `mutable_st` are refreshed.
double Loss(const FitState& st, const Eigen::MatrixXd& S, bool update_robust, FitState* mutable_st);
// The lobes' amplitudes for fixed albedo and gain (NNLS per channel, minimum-energy prior).
void SolveLight(FitState& st);
// The albedo per cell for fixed shading (closed form, grey-world prior).
void SolveAlbedo(FitState& st, const Eigen::MatrixXd& S);
// The global scale a → a·t, μ → μ/t that the data leaves free when the near field is weak.
void SolveScale(FitState& st);
// The near-field gain g for fixed albedo and light, clamped to [1, gain_max].
void SolveGain(FitState& st);

}  // namespace nerfar::env_internal
