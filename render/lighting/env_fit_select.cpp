// The environment fit's model selection steps (env_fit_internal.h): sharp
// sources added one at a time and re-tested once the whole dictionary is in,
// and per-lobe chroma; each change kept only when its log-likelihood gain
// beats BIC's penalty for the parameters it adds.
#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "calib/core/log.h"
#include "render/lighting/env_fit.h"
#include "render/lighting/env_fit_internal.h"
#include "render/lighting/env_internal.h"
#include "render/sg/sg.h"

namespace nerfar::env_internal {
namespace {

// BIC's penalty (k/2)·ln n for k more parameters, times the options' factor.
double BicPenalty(const FitState& st, const EnvEstimateOptions& o, int parameters) {
  return o.evidence_bic_factor * 0.5 * parameters * std::log(static_cast<double>(st.s->size()));
}

// Both models take the same alternation steps; then the log-likelihood gain
// of `with` over `without` (ReflectingGain).
double GainAfterSteps(FitState& without, FitState& with, int steps) {
  int a = 0, b = 0;
  Iterate(without, steps, &a, 0, nullptr);
  Iterate(with, steps, &b, 0, nullptr);
  return ReflectingGain(without, with);
}

// The sharpest lobes of the dictionary (MakeDictionary's last level): the
// broadest light the rest of the model imitates a source with.
double DictionarySharpnessMax(const EnvEstimateOptions& o) {
  return o.dictionary_sharpness * std::pow(4.0, o.dictionary_levels - 1);
}

// Appends a lobe (amplitude 0) as a column of the fit.
void AppendLobe(FitState& st, const Vec3& axis, double sharpness, double distance, bool source,
                const EnvShadowRays& shadow, const EnvEstimateOptions& o) {
  const Eigen::MatrixXd column =
      LobeIrradianceMatrix(*st.s, {axis}, {sharpness}, shadow, o.source_bundle_rays, o.seed, {distance});
  st.A.conservativeResize(Eigen::NoChange, st.A.cols() + 1);
  st.A.col(st.A.cols() - 1) = column.col(0);
  st.mu.conservativeResize(st.mu.rows() + 1, Eigen::NoChange);
  st.mu.row(st.mu.rows() - 1).setZero();
  st.lobe_integral.push_back(SgUnitIntegral(sharpness));
  st.lobes.Add(axis, sharpness, source, false, distance);
}

// Removes column k of the fit.
void RemoveLobe(FitState& st, Eigen::Index k) {
  const Eigen::Index d = st.A.cols();
  st.A.block(0, k, st.A.rows(), d - k - 1) = st.A.rightCols(d - k - 1).eval();
  st.A.conservativeResize(Eigen::NoChange, d - 1);
  st.mu.block(k, 0, d - k - 1, 3) = st.mu.bottomRows(d - k - 1).eval();
  st.mu.conservativeResize(d - 1, Eigen::NoChange);
  st.lobe_integral.erase(st.lobe_integral.begin() + k);
  st.lobes.axes.erase(st.lobes.axes.begin() + k);
  st.lobes.sharpness.erase(st.lobes.sharpness.begin() + k);
  st.lobes.distance.erase(st.lobes.distance.begin() + k);
  st.lobes.source.erase(st.lobes.source.begin() + k);
  st.lobes.coloured.erase(st.lobes.coloured.begin() + k);
}

// The model trained for `steps` on the samples of half the albedo cells
// (`fold`: those of index parity fold; the others weighted 0), then its light
// held while every cell's albedo is re-solved for it, as a fit that had not
// seen the other half would give their albedos.
FitState TrainedOnFold(FitState m, int fold, int steps) {
  const std::vector<double> balance = m.balance;
  for (size_t i = 0; i < m.balance.size(); ++i)
    if (m.cell[i] % 2 != fold) m.balance[i] = 0;
  Loss(m, Shading(m), true, &m);
  int step = 0;
  Iterate(m, steps, &step, 0, nullptr);
  m.balance = balance;
  for (int k = 0; k < steps; ++k) {
    Loss(m, Shading(m), true, &m);
    SolveAlbedo(m, Shading(m));
  }
  return m;
}

// The model without a change, trained on each fold (TrainedOnFold): what
// every held-out test of one state of the fit compares against.
std::array<FitState, 2> FoldBaselines(const FitState& st, int steps) {
  return {TrainedOnFold(st, 0, steps), TrainedOnFold(st, 1, steps)};
}

// The log-likelihood gain of lobe k's colour on the albedo cells it was not
// fitted to, summed over the two folds (two-fold cross-validation over the
// cells; `grey`: FoldBaselines of st): a colour that explains one surface's
// own material within its cells (leaves facing up, sharing a cell with a sand
// table, under a "green" zenith) does not carry to other cells, a coloured
// light does (a blue sky in the shadows all over the table).
double HeldOutChromaGain(const FitState& st, const std::array<FitState, 2>& grey, Eigen::Index k, int steps) {
  double gain = 0;
  for (int fold = 0; fold < 2; ++fold) {
    FitState coloured = st;
    coloured.lobes.coloured[k] = true;
    coloured = TrainedOnFold(std::move(coloured), fold, steps);
    std::vector<bool> skip = st.emitter;
    for (size_t i = 0; i < skip.size(); ++i) skip[i] = skip[i] || st.cell[i] % 2 == fold;
    gain += GainOn(grey[fold], coloured, skip);
  }
  return gain;
}

// Tries one light of the search as a sharp source (AddSources): appends it,
// re-solves, and tells whether the data supports it; if so `st` takes it.
// `without`: st re-solved alike without it (one per round: every candidate
// is compared with the same); `rank`: the candidates of this round tried before it.
bool TrySource(FitState& st, const FitState& without, const SourceCandidate& found, size_t rank,
               const EnvShadowRays& shadow, const EnvEstimateOptions& o) {
  const double one_parameter = BicPenalty(st, o, 1);
  const double penalty = BicPenalty(st, o, kSgLobeParameters) + (found.distance > 0 ? one_parameter : 0) +
                         std::log(static_cast<double>(rank + 1));
  FitState trial = st;  // st stays as it is unless the source is kept
  AppendLobe(trial, found.axis, found.sharpness, found.distance, true, shadow, o);
  int steps = 0;
  Iterate(trial, o.source_steps, &steps, 0, nullptr);
  const double gain = ReflectingGain(without, trial);
  const double broad_sharpness = DictionarySharpnessMax(o);
  double sharpness_gain = 0;
  if (found.sharpness > broad_sharpness) {
    FitState broad = st;
    AppendLobe(broad, found.axis, broad_sharpness, found.distance, false, shadow, o);
    steps = 0;
    Iterate(broad, o.source_steps, &steps, 0, nullptr);
    sharpness_gain = ReflectingGain(broad, trial);
  }
  const double sharpness_penalty = one_parameter + std::log(std::max(1.0, found.sharpness / broad_sharpness));
  const bool supported = gain > penalty && (found.sharpness <= broad_sharpness || sharpness_gain > sharpness_penalty);
  const double elevation = std::asin(std::clamp(found.axis.z, -1.0, 1.0)) * 180 / kPi;
  const double azimuth = std::atan2(found.axis.y, found.axis.x) * 180 / kPi;
  LogInfo("env fit: source " + std::to_string(CountSources(st) + 1) + ", candidate " + std::to_string(rank + 1) +
          ", at azimuth " + std::to_string(azimuth) + " elevation " + std::to_string(elevation) + " deg, " +
          (found.distance > 0 ? std::to_string(found.distance) + " m away" : std::string("distant")) + ", sharpness " +
          std::to_string(found.sharpness) + ": log-likelihood gain " + std::to_string(gain) + ", BIC penalty " +
          std::to_string(penalty) + "; over a lobe of sharpness " + std::to_string(broad_sharpness) + " " +
          std::to_string(sharpness_gain) + ", penalty " + std::to_string(sharpness_penalty) +
          (supported ? " (kept)" : " (not supported)"));
  if (supported) st = std::move(trial);
  return supported;
}

}  // namespace

int CountSources(const FitState& st) {
  return static_cast<int>(std::count(st.lobes.source.begin(), st.lobes.source.end(), true));
}

// Sharp sources, one at a time: the search's best few lights (env_sources.cpp:
// distant or at a distance, each at its best size), best first, are each
// added as a lobe and the whole model re-solved for a few steps; the first
// whose log-likelihood gain (the robust loss as a Cauchy likelihood, as the
// environment's own model selection) exceeds BIC's penalty for one lobe's
// parameters (and its distance's, when it has one) is kept, and the search
// goes on; when none is, the search stops. The search scores lights on the
// linearised fit, so its best can fail once re-solved (a point at the
// horizon that only grazing samples see) where the next one, a real light,
// passes; the k-th tried pays ln k more, about what the largest of k gains
// adds under pure noise. A source sharper than the dictionary must also owe
// its gain to its sharpness (its shadows and their penumbrae): against the
// dictionary's sharpest lobe on the same axis, re-solved alike, it must gain
// more than BIC's penalty for the one parameter it adds (the sharpness) and
// for its direction's search: within the broad lobe's extent the search
// chose the best of about λ/λ_broad distinguishable directions of the sharp
// one (their solid angles ~2π/λ), and the largest of K independent
// log-likelihood gains of one parameter each (χ²₁/2, tail ~e^−t) is about
// ln K under pure noise. Brightness alone (light that some samples ask for
// from that side) a broad lobe gives as well, and the dictionary's lobes
// will. Returns the sources kept.
int AddSources(FitState& st, const EnvShadowRays& shadow, const EnvEstimateOptions& o, const EnvProgress& progress) {
  int kept = 0;
  for (; kept < o.sources_max; ++kept) {
    if (progress) progress("sources", static_cast<size_t>(kept), static_cast<size_t>(o.sources_max));
    const std::vector<SourceCandidate> found = FindSources(st, shadow, o);
    if (found.empty()) break;
    FitState without = st;
    int steps = 0;
    Iterate(without, o.source_steps, &steps, 0, nullptr);
    bool added = false;
    for (size_t rank = 0; rank < found.size() && !added; ++rank)
      added = TrySource(st, without, found[rank], rank, shadow, o);
    if (added) continue;
    // Nothing kept: the fit goes on as the tests' baseline did (source_steps more).
    st = std::move(without);
    break;
  }
  if (progress) progress("sources", static_cast<size_t>(o.sources_max), static_cast<size_t>(o.sources_max));
  return kept;
}

// Each source again, once the whole dictionary is in the model: removed when
// keeping it no longer gains more log-likelihood than BIC's penalty (the
// finer lobes may now explain what it did). Returns the sources left.
int KeepSupportedSources(FitState& st, const EnvEstimateOptions& o) {
  const double penalty = BicPenalty(st, o, kSgLobeParameters);
  for (Eigen::Index k = st.A.cols() - 1; k >= 0; --k) {
    if (!st.lobes.source[k]) continue;
    FitState trial = st;
    RemoveLobe(trial, k);
    const double gain = GainAfterSteps(trial, st, o.source_steps);
    LogVerbose("env fit: source at column " + std::to_string(k) + " with the whole dictionary: log-likelihood gain " +
               std::to_string(gain) + ", BIC penalty " + std::to_string(penalty));
    if (!(gain > penalty)) st = std::move(trial);
  }
  return CountSources(st);
}

// Per-lobe chroma, one lobe at a time: the lobe is given an RGB amplitude
// (from grey) and the model re-solved for a few steps, as is the model
// without the change; it keeps its colour when the log-likelihood gain
// exceeds BIC's penalty for the chroma's two parameters and the colour also
// explains albedo cells it was not fitted to (HeldOutChromaGain). Albedo and light
// trade colour freely, so a neutral scene gives no lobe the evidence (its
// light stays grey) while a coloured source beside another (a blue sky beside
// a white sun: the shadows bluer than the lit table) does. Only the lights'
// relative colour is seen (a common tint goes to the albedo unless the near
// field pins it), so the lobes are tried from the weakest up: the strongest,
// tried last, stays the white point unless the data still asks otherwise,
// as a camera white-balances to the dominant light.
// Returns the lobes made coloured.
int FreeChroma(FitState& st, const EnvEstimateOptions& o) {
  const double penalty = BicPenalty(st, o, kChromaParameters);
  std::vector<Eigen::Index> order;
  for (Eigen::Index k = 0; k < st.mu.rows(); ++k)
    if (st.mu.row(k).maxCoeff() > 0) order.push_back(k);
  const auto energy = [&](Eigen::Index k) { return st.mu.row(k).sum() * st.lobe_integral[k]; };
  std::stable_sort(order.begin(), order.end(), [&](Eigen::Index a, Eigen::Index b) { return energy(a) < energy(b); });
  int coloured = 0;
  std::optional<std::array<FitState, 2>> grey;  // of st as it stands; the in-sample test below iterates st
  for (Eigen::Index k : order) {
    FitState trial = st;
    trial.lobes.coloured[k] = true;
    if (!grey) grey = FoldBaselines(st, o.chroma_steps);
    const double held_out = HeldOutChromaGain(st, *grey, k, o.chroma_steps);
    LogVerbose("env fit: lobe " + std::to_string(k) + "'s colour, gain on the cells it was not fitted to " +
               std::to_string(held_out));
    if (!(held_out > 0)) continue;
    grey.reset();
    if (!(GainAfterSteps(st, trial, o.chroma_steps) > penalty)) continue;
    st = std::move(trial);
    ++coloured;
  }
  return coloured;
}

}  // namespace nerfar::env_internal
