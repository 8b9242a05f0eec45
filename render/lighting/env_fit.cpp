#include "render/lighting/env_fit.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numeric>

#include "calib/core/error.h"
#include "calib/core/log.h"
#include "render/lighting/env_fit_internal.h"
#include "render/lighting/env_internal.h"
#include "render/sg/sphere.h"

namespace nerfar {

using env_internal::AddSources;
using env_internal::Channel;
using env_internal::CountSources;
using env_internal::FitState;
using env_internal::FreeChroma;
using env_internal::Iterate;
using env_internal::KeepSupportedSources;
using env_internal::LobeIrradianceMatrix;
using env_internal::Loss;
using env_internal::MakeDictionary;
using env_internal::ScaledSquaredLogResidual;
using env_internal::Shading;
using env_internal::SolveAlbedo;
using env_internal::SolveGain;
using env_internal::SolveLight;
using env_internal::SolveScale;
using env_internal::ToD;
using env_internal::Y;

std::vector<bool> EmitterLikeSamples(const std::vector<Vec3f>& radiance) {
  std::vector<bool> emitter(radiance.size(), false);
  if (radiance.empty()) return emitter;
  std::vector<double> y;
  for (const Vec3f& l : radiance) y.push_back(LuminanceOf(ToD(l)));
  std::vector<double> sorted = y;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double limit = kEmitterLikeFactor * sorted[sorted.size() / 2];
  for (size_t i = 0; i < y.size(); ++i) emitter[i] = y[i] > limit;
  return emitter;
}

std::vector<double> NormalBalanceWeights(const std::vector<Vec3f>& normals, double power,
                                         const std::vector<Vec3f>* radiance) {
  std::vector<double> w(normals.size(), 1.0);
  if (!(power > 0) || normals.empty()) return w;
  const std::vector<Vec3> bins = FibonacciSphere(kNormalBalanceBins);
  std::vector<int> bin(normals.size());
  std::vector<double> count(bins.size(), 0);
  for (size_t i = 0; i < normals.size(); ++i) {
    int best = 0;
    double best_dot = -2;
    for (size_t b = 0; b < bins.size(); ++b) {
      const double d = Dot(ToD(normals[i]), bins[b]);
      if (d > best_dot) best_dot = d, best = static_cast<int>(b);
    }
    bin[i] = best;
    count[best] += 1;
  }
  double sum = 0;
  for (size_t i = 0; i < normals.size(); ++i) sum += w[i] = std::pow(1.0 / count[bin[i]], power);
  for (double& x : w) x *= static_cast<double>(normals.size()) / sum;  // mean 1
  if (radiance != nullptr && radiance->size() == normals.size()) {
    // Emitter-like samples are not weighted up: a lamp's own surface, seen
    // from its sides, fills sparse normal bins, and the fit would explain its
    // glow with light.
    const std::vector<bool> emitter = EmitterLikeSamples(*radiance);
    for (size_t i = 0; i < w.size(); ++i)
      if (emitter[i]) w[i] = std::min(w[i], 1.0);
  }
  return w;
}

namespace {

std::vector<int> AlbedoCells(const EnvSurfaceSamples& s, const Aabb& aabb, double cell_m, size_t* count) {
  const Vec3 ext = aabb.max - aabb.min;
  const double h = cell_m > 0 ? cell_m : std::max({ext.x, ext.y, ext.z}) / 8;
  std::map<std::array<int, 3>, int> ids;
  std::vector<int> cell(s.size());
  for (size_t i = 0; i < s.size(); ++i) {
    const Vec3 p = (ToD(s.positions[i]) - aabb.min) / h;
    const std::array<int, 3> key{static_cast<int>(std::floor(p.x)), static_cast<int>(std::floor(p.y)),
                                 static_cast<int>(std::floor(p.z))};
    const auto it = ids.emplace(key, static_cast<int>(ids.size())).first;
    cell[i] = it->second;
  }
  *count = ids.size();
  return cell;
}

// SupportOfGains for lobe k of the fit: each reflecting sample's loss
// without the lobe (S less its column) minus with it (`loss`: per sample,
// ln(1 + q) of the whole model S, shared by every lobe's call).
SourceSupport SupportOfLobe(const FitState& st, const Eigen::MatrixXd& S, const std::vector<double>& loss,
                            Eigen::Index k) {
  const Eigen::MatrixXd without = S - st.A.col(k) * st.mu.row(k);
  std::vector<Vec3f> positions;
  std::vector<double> gain;
  for (size_t i = 0; i < st.s->size(); ++i) {
    if (st.emitter[i]) continue;
    positions.push_back(st.s->positions[i]);
    gain.push_back(std::log1p(ScaledSquaredLogResidual(st, without, i)) - loss[i]);
  }
  return SupportOfGains(positions, gain);
}

// The fit's state before any light: albedo cells at the prior, the data
// term's per-sample scales and balance weights.
FitState PrepareFit(const EnvSurfaceSamples& samples, const Aabb& aabb, const EnvEstimateOptions& options) {
  FitState st;
  st.s = &samples;
  st.volume = aabb;
  st.prior = options.albedo_prior;
  st.prior_weight = options.albedo_prior_weight;
  st.robust_scale = options.robust_scale;
  st.gain_max = options.ignore_near_field ? 1.0 : options.near_field_gain_max;
  size_t cells = 0;
  st.cell = AlbedoCells(samples, aabb, options.albedo_cell_m, &cells);
  st.albedo.assign(cells, Vec3{1, 1, 1} * options.albedo_prior);
  st.balance = NormalBalanceWeights(samples.normals, options.normal_balance, &samples.radiance);
  st.emitter = EmitterLikeSamples(samples.radiance);
  st.robust = st.balance;
  for (size_t i = 0; i < samples.size(); ++i)
    if (st.emitter[i]) st.robust[i] = 0;  // see Loss
  double mean_y = 0;
  for (const Vec3f& l : samples.radiance) mean_y += Y(ToD(l));
  mean_y /= samples.size();
  const double eps = options.loss_epsilon * std::max(mean_y, 1e-12);
  st.eps = Vec3{eps, eps, eps};

  st.energy_weight = options.light_energy_weight;
  st.typical_irradiance = kPi * mean_y / options.albedo_prior;
  return st;
}

// The model's radiance L = a/π · S per sample (what it predicts for L_o).
std::vector<Vec3f> ModelledRadiance(const FitState& st, const Eigen::MatrixXd& S) {
  std::vector<Vec3f> model(st.s->size());
  for (size_t i = 0; i < model.size(); ++i) {
    const Vec3& a = st.albedo[st.cell[i]];
    model[i] = Vec3f(Vec3{a.x / kPi * S(i, 0), a.y / kPi * S(i, 1), a.z / kPi * S(i, 2)});
  }
  return model;
}

// RMS of (model − L_o) over RMS of L_o, in luminance.
double RelativeRms(const std::vector<Vec3f>& model, const std::vector<Vec3f>& observed) {
  double err2 = 0, ref2 = 0;
  for (size_t i = 0; i < observed.size(); ++i) {
    const double obs = Y(ToD(observed[i]));
    err2 += std::pow(Y(ToD(model[i])) - obs, 2);
    ref2 += obs * obs;
  }
  return ref2 > 0 ? std::sqrt(err2 / ref2) : 0;
}

// The same model without environment (L_o = a/π · g·E_nerf), fitted by the
// same alternation; its robust loss per sample and its relative RMS.
double NearFieldOnlyLoss(const EnvSurfaceSamples& samples, const Aabb& aabb, const EnvEstimateOptions& options,
                         int steps, double* relative_rms) {
  FitState st = PrepareFit(samples, aabb, options);
  st.A = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(samples.size()), 0);
  st.mu = Eigen::MatrixXd::Zero(0, 3);
  Loss(st, Shading(st), true, &st);
  for (int it = 0; it < steps; ++it) {
    SolveGain(st);
    SolveAlbedo(st, Shading(st));
    SolveScale(st);
    Loss(st, Shading(st), true, &st);
  }
  const Eigen::MatrixXd S = Shading(st);
  *relative_rms = RelativeRms(ModelledRadiance(st, S), samples.radiance);
  return Loss(st, S, false, nullptr);
}

// Appends dictionary lobes [begin, end) (amplitude 0) with their columns.
void AppendColumns(FitState& st, const env_internal::Dictionary& dict, const Eigen::MatrixXd& A_dict, size_t begin,
                   size_t end) {
  const Eigen::Index have = st.A.cols(), add = static_cast<Eigen::Index>(end - begin);
  st.A.conservativeResize(Eigen::NoChange, have + add);
  st.A.rightCols(add) = A_dict.middleCols(static_cast<Eigen::Index>(begin), add);
  st.mu.conservativeResize(have + add, Eigen::NoChange);
  st.mu.bottomRows(add).setZero();
  for (size_t k = begin; k < end; ++k) {
    st.lobe_integral.push_back(SgUnitIntegral(dict.sharpness[k]));
    st.lobes.Add(dict.axes[k], dict.sharpness[k], false);
  }
}

// Keeps the sources and the most energetic other lobes, `count` in all.
void KeepStrongest(FitState& st, int count) {
  const Eigen::Index d = st.A.cols();
  std::vector<Eigen::Index> order(d);
  std::iota(order.begin(), order.end(), 0);
  std::vector<double> energy(d);
  for (Eigen::Index k = 0; k < d; ++k)
    energy[k] = st.lobes.source[k] ? 1e300 : Y(Vec3{st.mu(k, 0), st.mu(k, 1), st.mu(k, 2)}) * st.lobe_integral[k];
  std::stable_sort(order.begin(), order.end(), [&](Eigen::Index a, Eigen::Index b) { return energy[a] > energy[b]; });
  order.resize(std::min<size_t>(order.size(), static_cast<size_t>(count)));
  std::sort(order.begin(), order.end());
  FitState kept = st;
  kept.A.resize(st.A.rows(), static_cast<Eigen::Index>(order.size()));
  kept.mu.resize(static_cast<Eigen::Index>(order.size()), 3);
  kept.lobe_integral.clear();
  kept.lobes = {};
  for (size_t k = 0; k < order.size(); ++k) {
    kept.A.col(k) = st.A.col(order[k]);
    kept.mu.row(k) = st.mu.row(order[k]);
    kept.lobe_integral.push_back(st.lobe_integral[order[k]]);
    kept.lobes.Add(st.lobes.axes[order[k]], st.lobes.sharpness[order[k]], st.lobes.source[order[k]],
                   st.lobes.coloured[order[k]], st.lobes.distance[order[k]]);
  }
  st = std::move(kept);
}

}  // namespace

SourceSupport SupportOfGains(const std::vector<Vec3f>& positions, const std::vector<double>& gain) {
  NERFAR_CHECK_EQ(positions.size(), gain.size());
  std::vector<size_t> order;
  double positive = 0;
  for (size_t i = 0; i < gain.size(); ++i)
    if (gain[i] > 0) {
      order.push_back(i);
      positive += gain[i];
    }
  SourceSupport support;
  if (!(positive > 0)) return support;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return gain[a] > gain[b]; });
  double held = 0, weight = 0;
  size_t count = 0;
  while (count < order.size() && held < 0.5 * positive) held += gain[order[count++]];
  for (size_t k = 0; k < count; ++k) {
    support.centre += ToD(positions[order[k]]) * gain[order[k]];
    weight += gain[order[k]];
  }
  support.centre = support.centre * (1.0 / weight);
  for (size_t k = 0; k < count; ++k)
    support.radius_m = std::max(support.radius_m, Length(ToD(positions[order[k]]) - support.centre));
  support.half_share = static_cast<double>(count) / static_cast<double>(gain.size());
  return support;
}

SgMixture FitEnvironment(const EnvSurfaceSamples& samples, const Aabb& aabb, const EnvEstimateOptions& options,
                         EnvFitReport* report, const EnvProgress& progress, const EnvShadowRays& shadow) {
  const std::vector<std::string> problems = options.Validate();
  if (!problems.empty()) ThrowInputError("env options", problems.front());
  NERFAR_CHECK_EQ(samples.e_nerf.size(), samples.size());
  NERFAR_CHECK_EQ(samples.opacity.size(), samples.size() * samples.rays_per_point);
  EnvFitReport local;
  if (samples.size() == 0) {
    if (report) *report = local;
    return {};
  }
  FitState st = PrepareFit(samples, aabb, options);
  const int broad_steps = std::max(1, options.iterations / 2), final_steps = std::max(3, options.iterations / 2);
  const int total_steps = broad_steps + options.iterations + final_steps;
  // Start: albedo at the prior, robust weights from the near field alone.
  st.A = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(samples.size()), 0);
  st.mu = Eigen::MatrixXd::Zero(0, 3);
  local.initial_loss = Loss(st, Shading(st), true, &st);
  int step = 0;
  const env_internal::Dictionary dict = MakeDictionary(options);
  local.dictionary_size = static_cast<int>(dict.size());
  const Eigen::MatrixXd A_dict = LobeIrradianceMatrix(samples, dict.axes, dict.sharpness);
  // Sharp sources are searched for against the fit of the dictionary's first
  // level (broad lobes) alone: the finer levels, many lobes of narrower
  // sharpness, bend to imitate a source's light without its
  // shadows, and leave a residual that points nowhere.
  const size_t broad = std::min(dict.size(), static_cast<size_t>(options.dictionary_base));
  AppendColumns(st, dict, A_dict, 0, broad);
  Iterate(st, broad_steps, &step, total_steps, progress);
  if (shadow != nullptr) local.sources = AddSources(st, shadow, options, progress);
  AppendColumns(st, dict, A_dict, broad, dict.size());
  Iterate(st, options.iterations, &step, total_steps, progress);
  if (local.sources > 0) local.sources = KeepSupportedSources(st, options);
  KeepStrongest(st, options.lobes);
  Iterate(st, final_steps, &step, total_steps, progress);
  local.coloured_lobes = FreeChroma(st, options);

  SgMixture result;
  int parameters = 0;
  const Eigen::MatrixXd S = Shading(st);
  std::vector<double> sample_loss;  // ln(1 + q) per sample, for the sources' support
  if (CountSources(st) > 0)
    for (size_t i = 0; i < samples.size(); ++i) sample_loss.push_back(std::log1p(ScaledSquaredLogResidual(st, S, i)));
  for (Eigen::Index k = 0; k < st.mu.rows(); ++k) {
    const Vec3 mu{st.mu(k, 0), st.mu(k, 1), st.mu(k, 2)};
    if (!(mu.x > 0 || mu.y > 0 || mu.z > 0)) continue;
    result.push_back({st.lobes.axes[k], st.lobes.sharpness[k], mu});
    const bool near = st.lobes.distance[k] > 0;
    local.lobe_distance_m.push_back(st.lobes.distance[k]);
    local.lobe_support.push_back(st.lobes.source[k] ? SupportOfLobe(st, S, sample_loss, k) : SourceSupport{});
    parameters += kSgLobeParameters + (st.lobes.coloured[k] ? kChromaParameters : 0) + (near ? 1 : 0);
  }
  local.final_loss = Loss(st, S, false, nullptr);
  local.active_lobes = static_cast<int>(result.size());
  double albedo_sum = 0;
  for (size_t i = 0; i < samples.size(); ++i) albedo_sum += Y(st.albedo[st.cell[i]]);
  local.mean_albedo = albedo_sum / samples.size();
  local.modelled = ModelledRadiance(st, S);
  local.relative_rms = RelativeRms(local.modelled, samples.radiance);
  local.near_field_gain = st.gain;
  // Model selection: the environment must explain what the near field
  // cannot by more than its own parameters would explain of noise. The loss
  // is a Cauchy negative log-likelihood at scale s (up to constants):
  // n·loss/s². The environment's log-likelihood gain over the near field
  // alone must exceed BIC's (k/2)·ln n, k the active lobes' parameters
  // (axis 2, sharpness 1, amplitude 1; a coloured lobe's chroma 2 more).
  if (!options.ignore_near_field && options.evidence_bic_factor > 0) {
    local.near_only_loss = NearFieldOnlyLoss(samples, aabb, options, total_steps, &local.near_only_relative_rms);
    const double n = static_cast<double>(samples.size()), s2 = options.robust_scale * options.robust_scale;
    local.evidence = n * (local.near_only_loss - local.final_loss) / s2;
    local.evidence_needed = options.evidence_bic_factor * 0.5 * parameters * std::log(n);
    local.environment_supported = local.active_lobes > 0 && local.evidence > local.evidence_needed;
  }
  if (report) *report = local;
  return result;
}

}  // namespace nerfar
