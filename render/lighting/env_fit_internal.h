// Pieces of the environment fit shared by env_fit.cpp, env_fit_steps.cpp,
// env_lobes.cpp and env_sources.cpp; not part of the module's interface.
#pragma once

#include <Eigen/Dense>
#include <vector>

#include "calib/core/math.h"
#include "render/lighting/env_options.h"
#include "render/lighting/env_samples.h"
#include "render/lighting/env_shadow.h"

namespace nerfar::env_internal {

// The lobes of the model: axis and sharpness per column of the fit's matrix;
// `source` marks the sharp sources found by the search (env_sources.cpp);
// `coloured` the lobes with an RGB amplitude (the others are grey: one
// amplitude for the three channels, see SolveLight); `distance` how far from
// the origin a source is (0: distant; BundleIrradiance).
struct Dictionary {
  std::vector<Vec3> axes;
  std::vector<double> sharpness, distance;
  std::vector<bool> source, coloured;
  size_t size() const { return axes.size(); }
  void Add(const Vec3& axis, double lambda, bool is_source, bool is_coloured = false, double at = 0) {
    axes.push_back(axis);
    sharpness.push_back(lambda);
    source.push_back(is_source);
    coloured.push_back(is_coloured);
    distance.push_back(at);
  }
};
// Level l: dictionary_base·4^l lobes on a Fibonacci sphere, sharpness dictionary_sharpness·4^l.
Dictionary MakeDictionary(const EnvEstimateOptions& o);

// A(i, k): irradiance at sample i from unit-amplitude lobe k: through the
// NeRF's visibility cache for lobes it resolves (CacheSharpnessLimit), through
// bundles of `bundle` shadow rays for sharper ones and for lights at a
// distance (`distance`, empty: all distant; BundleIrradiance) when `shadow`
// is given (see env_lobes.cpp).
Eigen::MatrixXd LobeIrradianceMatrix(const EnvSurfaceSamples& s, const std::vector<Vec3>& axes,
                                     const std::vector<double>& sharpness, const EnvShadowRays& shadow = nullptr,
                                     int bundle = 1, uint64_t seed = 0, const std::vector<double>& distance = {});

// min ‖Bx − y‖² s.t. x ≥ 0 from the normal equations G = BᵀB, h = Bᵀy
// (Lawson-Hanson active set).
Eigen::VectorXd Nnls(const Eigen::MatrixXd& G, const Eigen::VectorXd& h);

// The alternation's unknowns and fixed data.
struct FitState {
  const EnvSurfaceSamples* s = nullptr;
  Aabb volume;                  // the NeRF's: sources lie outside it
  Dictionary lobes;             // the columns of A
  Eigen::MatrixXd A;            // n × D
  Eigen::MatrixXd mu;           // D × 3
  std::vector<int> cell;        // per sample
  std::vector<Vec3> albedo;     // per cell
  std::vector<double> robust;   // per sample IRLS weight (times balance)
  std::vector<double> balance;  // per sample weight of its normal's direction (NormalBalanceWeights)
  std::vector<bool> emitter;    // per sample: emitter-like (EmitterLikeSamples)
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
// The data term linearised about the current model M_ic = a_ic/π S_ic (S
// from Shading): the loss is robust in the log residual
// r = ln((M + ε)/(L + ε)), whose Gauss-Newton step about M is the weighted
// least squares Σ weight_ic (target_ic − M'_ic)² in the new model M' with
// weight = 1/(M + ε)² and target = M + (M + ε)·ln((L + ε)/(M + ε)). Every
// solve of the alternation takes its step on these (times the robust
// weights), so each lowers the log loss itself. (Weights from the
// observation instead, 1/(L + ε)² about L, are the same step only where the
// model already matches: elsewhere a dark observation the model
// over-predicts counts (M/L)² times more than a bright one it
// under-predicts by the same factor, and the fit settles too dark, a cell's
// albedo and the lights' energy held down by its darkest samples: tag ink,
// misplaced shadows.)
struct Linearised {
  Eigen::MatrixXd weight, target;  // n × 3
};
Linearised LineariseAtModel(const FitState& st, const Eigen::MatrixXd& S);
// Robust (Cauchy on the log residual) loss per sample; with update_robust the
// IRLS weights of `mutable_st` are refreshed. With `skip`, the samples it
// marks add nothing (still counted in the per-sample mean). The IRLS weights
// of emitter-like samples are 0: the solves minimise the likelihood that the
// model selection compares (ReflectingGain), which leaves them out. (Their
// glow is no reflection; their log residual is large, and the log loss's
// Gauss-Newton step, weighted by the model, not the observation, would
// still let them pull light onto the emitter from wherever its normals face.)
double Loss(const FitState& st, const Eigen::MatrixXd& S, bool update_robust, FitState* mutable_st,
            const std::vector<bool>* skip = nullptr);
// Sample i's squared log residual over the robust scale², q (its loss is ln(1 + q)).
double ScaledSquaredLogResidual(const FitState& st, const Eigen::MatrixXd& S, size_t i);
// The log-likelihood gain of `with` over `without` (the robust loss as a
// Cauchy likelihood) on the reflecting samples: emitter-like ones glow with
// light no reflection explains, and a lobe that lights them is no evidence of
// a light outside.
double ReflectingGain(const FitState& without, const FitState& with);
// The same gain on the samples `skip` does not mark (it marks the emitter-like ones too).
double GainOn(const FitState& without, const FitState& with, const std::vector<bool>& skip);
// The lobes' amplitudes for fixed albedo and gain (NNLS over the three
// channels at once: a grey lobe's one amplitude serves all three, a coloured
// lobe has one per channel; minimum-energy prior).
void SolveLight(FitState& st);
// The albedo per cell for fixed shading (closed form, grey-world prior).
void SolveAlbedo(FitState& st, const Eigen::MatrixXd& S);
// One alternation step (gain, light, albedo, scale, robust weights); its robust loss.
double AlternationStep(FitState& st);
// `count` steps; progress ("fit", *step + 1, total_steps) after each when given.
void Iterate(FitState& st, int count, int* step, int total_steps, const EnvProgress& progress);
// The global scale a → a·t, μ → μ/t that the data leaves free when the near field is weak.
void SolveScale(FitState& st);
// The near-field gain g for fixed albedo and light, clamped to [1, gain_max].
void SolveGain(FitState& st);

// What one more neutral lobe of irradiance b_i per unit amplitude, re-solved
// jointly with the lobes already lit (the active set, A) and with the albedo
// cells, would take from the data term Σ_ic w_ic (L_ic − a_ic/π S_ic)²
// (linearised about the current fit): the term drops by ⟨b⊥, r⟩² / ⟨b⊥, b⊥⟩,
// r the residual and b⊥ the column's change of the model, f_ic b_i
// (f = a/π), minus its projection on the active lobes' changes f_ic A_ik and
// the albedos' (f_ic S_ic on the samples of one cell and channel), in the
// inner product ⟨x, y⟩ = Σ_ic w_ic x_ic y_ic (orthogonal least squares).
// Hence a sharp column that the broad lobes already explain but for its
// shadows scores by those shadows alone, and only by the part of them that
// an albedo cell cannot take: a cell that lies all in a shadow is as well
// explained by a dark albedo (which the fit without the source has already
// given it), so the evidence is the contrast within cells, and the score
// does not depend on how much of the shadows the current albedos absorbed.
// The weights and the residual are the log loss's own, linearised about the
// current fit (LineariseAtModel), every sample alike: neither the normal balance (it would hand a few objects' sides
// the choice over the thousands of table samples that show the shadows) nor the robust weights of the current fit (they
// discount exactly the shadowed samples a model without the source cannot explain). The source is then kept or not on
// the robust likelihood itself (env_fit.cpp AddSources). On a subset of the samples.
class ResidualPull {
 public:
  ResidualPull(const FitState& st, std::vector<uint32_t> subset);
  const std::vector<uint32_t>& subset() const { return subset_; }
  // b per subset entry; 0 when the drop is nil or the amplitude would be negative.
  double Score(const std::vector<double>& b) const;

 private:
  // Σ over each (cell, channel) of the subset of f² w S x: the column's
  // projection on the albedo directions (unnormalised), cell-major.
  Eigen::VectorXd AlbedoSums(const double* x) const;
  std::vector<uint32_t> subset_;
  std::vector<uint32_t> slot_;   // per subset entry: its cell's index among the subset's cells
  Eigen::VectorXd p_, q_;        // Σ_c w f r and Σ_c w f² per entry
  Eigen::MatrixXd wfs_;          // per entry and channel: w f² S
  Eigen::VectorXd inv_d_;        // per (cell, channel): 1 / Σ w f² S² (0 for an empty one)
  Eigen::VectorXd albedo_pull_;  // per (cell, channel): Σ w f S r
  Eigen::MatrixXd active_;       // subset × active lobes
  Eigen::MatrixXd active_sums_;  // AlbedoSums of each active column
  Eigen::LDLT<Eigen::MatrixXd> gram_;
  Eigen::VectorXd active_pull_;  // ⟨A⊥, r⟩
};

// A sharp source: where the search placed it and how much it lowers the data term.
struct SourceCandidate {
  Vec3 axis;
  double sharpness = 0;
  double distance = 0;  // from the origin along the axis (0: distant)
  double score = 0;
};
// The lights that the current fit's residual asks for most (env_sources.cpp):
// for each distance model (distant, and a ladder of distances outside the
// volume), a coarse search over directions (a point source's shadows and
// shading on a subset of samples), a continuous refinement of its best few
// local maxima, then each one's size (sharpness) that fits the penumbrae
// best; of all those that lower the data term, the best few, best first
// (empty: none helps).
std::vector<SourceCandidate> FindSources(const FitState& st, const EnvShadowRays& shadow, const EnvEstimateOptions& o);

// The sharp sources among the fit's lobes (env_fit_select.cpp).
int CountSources(const FitState& st);

// Model selection (env_fit_select.cpp). Sharp sources, one at a time: the
// search's lights, best first, each added as a lobe and the model re-solved
// for source_steps; the first whose log-likelihood gain beats BIC's penalty
// is kept; when none is, the search ends. Returns the sources added.
int AddSources(FitState& st, const EnvShadowRays& shadow, const EnvEstimateOptions& o, const EnvProgress& progress);
// Each source re-tested by removal; returns the sources left.
int KeepSupportedSources(FitState& st, const EnvEstimateOptions& o);
// Per-lobe chroma (grey unless the data supports a colour); returns the lobes made coloured.
int FreeChroma(FitState& st, const EnvEstimateOptions& o);

}  // namespace nerfar::env_internal
