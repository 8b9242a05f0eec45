// The solves of the environment fit's alternation (env_fit_internal.h):
// light (NNLS), albedo, scale, near-field gain, the robust loss, and the
// alternation itself.
#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "calib/core/log.h"
#include "render/lighting/env_fit_internal.h"
#include "render/lighting/env_internal.h"

namespace nerfar::env_internal {

Eigen::VectorXd Nnls(const Eigen::MatrixXd& G, const Eigen::VectorXd& h) {
  const Eigen::Index d = G.rows();
  Eigen::VectorXd x = Eigen::VectorXd::Zero(d);
  if (d == 0) return x;
  std::vector<bool> passive(d, false);
  const double tol = 1e-12 * std::max(1.0, G.diagonal().maxCoeff());
  for (int outer = 0; outer < 3 * d + 10; ++outer) {
    const Eigen::VectorXd w = h - G * x;
    Eigen::Index best = -1;
    double best_w = tol;
    for (Eigen::Index k = 0; k < d; ++k)
      if (!passive[k] && w[k] > best_w) best_w = w[k], best = k;
    if (best < 0) break;
    passive[best] = true;
    for (int inner = 0; inner < 3 * d + 10; ++inner) {
      std::vector<Eigen::Index> idx;
      for (Eigen::Index k = 0; k < d; ++k)
        if (passive[k]) idx.push_back(k);
      const Eigen::Index m = static_cast<Eigen::Index>(idx.size());
      Eigen::MatrixXd Gp(m, m);
      Eigen::VectorXd hp(m);
      for (Eigen::Index a = 0; a < m; ++a) {
        hp[a] = h[idx[a]];
        for (Eigen::Index b = 0; b < m; ++b) Gp(a, b) = G(idx[a], idx[b]);
      }
      Gp.diagonal().array() += 1e-12 * std::max(1.0, Gp.diagonal().maxCoeff());
      const Eigen::VectorXd z = Gp.ldlt().solve(hp);
      bool feasible = true;
      for (Eigen::Index a = 0; a < m; ++a) feasible = feasible && z[a] > 0;
      if (feasible) {
        x.setZero();
        for (Eigen::Index a = 0; a < m; ++a) x[idx[a]] = z[a];
        break;
      }
      double alpha = 1;
      for (Eigen::Index a = 0; a < m; ++a)
        if (z[a] <= 0) alpha = std::min(alpha, x[idx[a]] / std::max(1e-300, x[idx[a]] - z[a]));
      for (Eigen::Index a = 0; a < m; ++a) {
        x[idx[a]] += alpha * (z[a] - x[idx[a]]);
        if (x[idx[a]] <= 1e-15) {
          x[idx[a]] = 0;
          passive[idx[a]] = false;
        }
      }
    }
  }
  return x;
}

// Model shading S_ic = E_nerf + A μ (without albedo).
Eigen::MatrixXd Shading(const FitState& st) {
  Eigen::MatrixXd S = st.A * st.mu;
  for (size_t i = 0; i < st.s->size(); ++i)
    for (int c = 0; c < 3; ++c) S(i, c) += st.gain * Channel(st.s->e_nerf[i], c);
  return S;
}

Linearised LineariseAtModel(const FitState& st, const Eigen::MatrixXd& S) {
  const Eigen::Index n = static_cast<Eigen::Index>(st.s->size());
  Linearised lin{Eigen::MatrixXd(n, 3), Eigen::MatrixXd(n, 3)};
  for (Eigen::Index i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) {
      const double model = std::max(0.0, st.albedo[st.cell[i]][c] / kPi * S(i, c));
      const double m = model + st.eps[c], l = std::max(0.0, Channel(st.s->radiance[i], c)) + st.eps[c];
      lin.weight(i, c) = 1.0 / (m * m);
      lin.target(i, c) = model + m * std::log(l / m);
    }
  return lin;
}

double ScaledSquaredLogResidual(const FitState& st, const Eigen::MatrixXd& S, size_t i) {
  double r2 = 0;
  for (int c = 0; c < 3; ++c) {
    // Log residual for the robust weight: an emitter (L far above any
    // a/π·E) is as far out as it is, while a relative residual would saturate at −1.
    const double eps = st.eps[c];
    const double model = st.albedo[st.cell[i]][c] / kPi * S(static_cast<Eigen::Index>(i), c);
    const double r = std::log((std::max(0.0, model) + eps) / (std::max(0.0, Channel(st.s->radiance[i], c)) + eps));
    r2 += r * r / 3;
  }
  return r2 / (st.robust_scale * st.robust_scale);
}

double Loss(const FitState& st, const Eigen::MatrixXd& S, bool update_robust, FitState* mutable_st,
            const std::vector<bool>* skip) {
  double total = 0;
  const size_t n = st.s->size();
  for (size_t i = 0; i < n; ++i) {
    const double q = ScaledSquaredLogResidual(st, S, i);
    if (skip == nullptr || !(*skip)[i]) total += std::log1p(q);  // Cauchy
    if (update_robust) mutable_st->robust[i] = st.emitter[i] ? 0.0 : st.balance[i] / (1.0 + q);
  }
  return total * st.robust_scale * st.robust_scale / std::max<size_t>(n, 1);
}

double GainOn(const FitState& without, const FitState& with, const std::vector<bool>& skip) {
  const double n = static_cast<double>(with.s->size()), s2 = with.robust_scale * with.robust_scale;
  return n *
         (Loss(without, Shading(without), false, nullptr, &skip) - Loss(with, Shading(with), false, nullptr, &skip)) /
         s2;
}

double ReflectingGain(const FitState& without, const FitState& with) { return GainOn(without, with, with.emitter); }

void SolveLight(FitState& st) {
  const size_t n = st.s->size();
  const Eigen::Index d = st.A.cols();
  // Unknowns: one per grey lobe, three per coloured lobe.
  std::vector<Eigen::Index> first(d);
  Eigen::Index m = 0;
  for (Eigen::Index k = 0; k < d; ++k) first[k] = std::exchange(m, m + (st.lobes.coloured[k] ? 3 : 1));
  const auto slot = [&](Eigen::Index k, int c) { return first[k] + (st.lobes.coloured[k] ? c : 0); };
  Eigen::MatrixXd G_all = Eigen::MatrixXd::Zero(m, m);
  Eigen::VectorXd h_all = Eigen::VectorXd::Zero(m);
  const Linearised lin = LineariseAtModel(st, Shading(st));
  for (int c = 0; c < 3; ++c) {
    Eigen::MatrixXd B(n, d);
    Eigen::VectorXd y(n);
    for (size_t i = 0; i < n; ++i) {
      const double w = std::sqrt(st.robust[i] * lin.weight(i, c));
      const double a = st.albedo[st.cell[i]][c] / kPi;
      B.row(i) = st.A.row(i) * (w * a);
      y[i] = w * (lin.target(i, c) - a * st.gain * Channel(st.s->e_nerf[i], c));
    }
    const Eigen::MatrixXd G = B.transpose() * B;
    Eigen::VectorXd h = B.transpose() * y;
    // Minimum-energy prior: + 2β Σ_k μ_k ∫G_k, so light the data cannot see
    // (below the floor, behind walls) stays dark instead of growing freely.
    // β relative to the data: w_e · |y|² per unit of typical irradiance.
    const double beta = st.energy_weight * y.squaredNorm() / std::max(1e-30, st.typical_irradiance);
    for (Eigen::Index k = 0; k < d; ++k) {
      h_all[slot(k, c)] += h[k] - beta * st.lobe_integral[k];
      for (Eigen::Index l = 0; l < d; ++l) G_all(slot(k, c), slot(l, c)) += G(k, l);
    }
  }
  const Eigen::VectorXd x = Nnls(G_all, h_all);
  for (Eigen::Index k = 0; k < d; ++k)
    for (int c = 0; c < 3; ++c) st.mu(k, c) = x[slot(k, c)];
}

void SolveAlbedo(FitState& st, const Eigen::MatrixXd& S) {
  const size_t cells = st.albedo.size();
  std::vector<Vec3> num(cells), den(cells);
  std::vector<double> weight(cells, 0);
  const Linearised lin = LineariseAtModel(st, S);
  for (size_t i = 0; i < st.s->size(); ++i)
    for (int c = 0; c < 3; ++c) {
      const double w = st.robust[i] * lin.weight(i, c);
      const double s = S(i, c) / kPi;
      num[st.cell[i]][c] += w * s * lin.target(i, c);
      den[st.cell[i]][c] += w * s * s;
      weight[st.cell[i]] += st.robust[i] / 3;
    }
  for (size_t k = 0; k < cells; ++k)
    for (int c = 0; c < 3; ++c) {
      // Prior weight relative to the cell's data: γ (a − a0)² with γ = weight·den/count.
      const double gamma = st.prior_weight * den[k][c] / std::max(1.0, weight[k]) + 1e-30;
      st.albedo[k][c] = std::clamp((num[k][c] + gamma * st.prior) / (den[k][c] + gamma), 0.005, 1.0);
    }
}

// The global scale that the data leaves free when the near field is weak:
// a → a·t, μ → μ/t keeps a·Aμ and scales a·E_nerf by t. Both the data and the
// prior are quadratic in t: solved exactly.
void SolveScale(FitState& st) {
  const Eigen::MatrixXd Amu = st.A * st.mu;
  const Linearised lin = LineariseAtModel(st, Shading(st));
  double qa = 0, qb = 0;  // minimise qa t² − 2 qb t
  for (size_t i = 0; i < st.s->size(); ++i)
    for (int c = 0; c < 3; ++c) {
      const double w = st.robust[i] * lin.weight(i, c);
      const double a = st.albedo[st.cell[i]][c] / kPi;
      const double e = a * st.gain * Channel(st.s->e_nerf[i], c), rest = lin.target(i, c) - a * Amu(i, c);
      qa += w * e * e;
      qb += w * e * rest;
    }
  // Prior Σ γ (a t − a0)², γ per cell relative to the samples' mean weight.
  double mean_w = 0;
  for (size_t i = 0; i < st.s->size(); ++i)
    for (int c = 0; c < 3; ++c) mean_w += st.robust[i] * lin.weight(i, c);
  mean_w /= std::max<size_t>(1, 3 * st.s->size());
  // In units of one sample's data term at the typical irradiance, so that
  // the prior's pull does not depend on the radiance scale (HDR: 1e-3..1e3).
  const double typical = mean_w * std::pow(st.prior / kPi * st.typical_irradiance, 2);
  std::vector<double> count(st.albedo.size(), 0);
  for (size_t i = 0; i < st.s->size(); ++i) count[st.cell[i]] += 1;
  for (size_t k = 0; k < st.albedo.size(); ++k)
    for (int c = 0; c < 3; ++c) {
      const double gamma = st.prior_weight * count[k] * typical * 1e2;
      qa += gamma * st.albedo[k][c] * st.albedo[k][c];
      qb += gamma * st.albedo[k][c] * st.prior;
    }
  if (!(qa > 0)) return;
  double t = qb / qa;
  if (!(t > 0) || !std::isfinite(t)) return;
  // Keep albedos ≤ 1: a larger t would clip them.
  double a_max = 0;
  for (const Vec3& a : st.albedo) a_max = std::max({a_max, a.x, a.y, a.z});
  if (a_max > 0) t = std::min(t, 1.0 / a_max);
  t = std::clamp(t, 0.1, 10.0);  // one step at most a decade: the alternation does the rest
  for (Vec3& a : st.albedo) a = a * t;
  st.mu /= t;
}

// The albedo's tint against the coloured lobes': per channel c, a_c → a_c·t_c
// in every cell and μ_kc → μ_kc/t_c for each coloured lobe k keeps a·A_k μ_k
// and scales the rest of the model (near field and grey lobes) by t_c: the
// data term is quadratic in t_c, solved exactly (the prior's pull on the
// albedo is the scale's, SolveScale, and left to it). Without it the
// alternation creeps along this valley: the light and the albedo solves each
// hold the other fixed.
void SolveTint(FitState& st) {
  std::vector<bool> coloured(st.mu.rows());
  bool any = false;
  for (Eigen::Index k = 0; k < st.mu.rows(); ++k) any = (coloured[k] = st.lobes.coloured[k]) || any;
  if (!any) return;
  Eigen::MatrixXd mu_coloured = st.mu, mu_rest = st.mu;
  for (Eigen::Index k = 0; k < st.mu.rows(); ++k) (coloured[k] ? mu_rest : mu_coloured).row(k).setZero();
  const Eigen::MatrixXd invariant = st.A * mu_coloured, scaled = st.A * mu_rest;
  const Linearised lin = LineariseAtModel(st, Shading(st));
  Vec3 qa, qb;
  for (size_t i = 0; i < st.s->size(); ++i)
    for (int c = 0; c < 3; ++c) {
      const double w = st.robust[i] * lin.weight(i, c);
      const double a = st.albedo[st.cell[i]][c] / kPi;
      const double e = a * (st.gain * Channel(st.s->e_nerf[i], c) + scaled(i, c));
      const double rest = lin.target(i, c) - a * invariant(i, c);
      qa[c] += w * e * e;
      qb[c] += w * e * rest;
    }
  double a_max[3] = {0, 0, 0};
  for (const Vec3& a : st.albedo)
    for (int c = 0; c < 3; ++c) a_max[c] = std::max(a_max[c], a[c]);
  for (int c = 0; c < 3; ++c) {
    if (!(qa[c] > 0) || !(a_max[c] > 0)) continue;
    double t = qb[c] / qa[c];
    if (!(t > 0) || !std::isfinite(t)) continue;
    t = std::clamp(std::min(t, 1.0 / a_max[c]), 0.1, 10.0);
    for (Vec3& a : st.albedo) a[c] *= t;
    for (Eigen::Index k = 0; k < st.mu.rows(); ++k)
      if (coloured[k]) st.mu(k, c) /= t;
  }
}

// The near-field gain g for fixed albedo and light: the data term is
// quadratic in g, solved exactly and clamped to [1, gain_max].
void SolveGain(FitState& st) {
  if (!(st.gain_max > 1)) return;
  const Eigen::MatrixXd Amu = st.A * st.mu;
  const Linearised lin = LineariseAtModel(st, Shading(st));
  double qa = 0, qb = 0;
  for (size_t i = 0; i < st.s->size(); ++i)
    for (int c = 0; c < 3; ++c) {
      const double w = st.robust[i] * lin.weight(i, c);
      const double a = st.albedo[st.cell[i]][c] / kPi;
      const double e = a * Channel(st.s->e_nerf[i], c), rest = lin.target(i, c) - a * Amu(i, c);
      qa += w * e * e;
      qb += w * e * rest;
    }
  if (qa > 0 && std::isfinite(qb / qa)) st.gain = std::clamp(qb / qa, 1.0, st.gain_max);
}

// One alternation step: gain, light, albedo, scale, robust weights. The gain
// first: at the start (no light yet) it takes all that the near field's
// pattern explains before any lobe can. Returns the robust loss.
double AlternationStep(FitState& st) {
  SolveGain(st);
  SolveLight(st);
  SolveAlbedo(st, Shading(st));
  SolveScale(st);
  SolveTint(st);
  return Loss(st, Shading(st), true, &st);
}

void Iterate(FitState& st, int count, int* step, int total_steps, const EnvProgress& progress) {
  for (int it = 0; it < count; ++it, ++*step) {
    const double loss = AlternationStep(st);
    double albedo = 0, light = 0;
    for (size_t i = 0; i < st.s->size(); ++i) albedo += Y(st.albedo[st.cell[i]]) / st.s->size();
    for (Eigen::Index k = 0; k < st.mu.rows(); ++k) light += st.mu(k, 1) * st.lobe_integral[k];
    LogVerbose("env fit: step " + std::to_string(*step) + " loss " + std::to_string(loss) + " mean albedo " +
               std::to_string(albedo) + " light green integral " + std::to_string(light));
    if (progress) progress("fit", static_cast<size_t>(*step + 1), static_cast<size_t>(total_steps));
  }
}

}  // namespace nerfar::env_internal
