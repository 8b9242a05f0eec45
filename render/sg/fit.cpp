// The fit alternates two steps (docs/SG.md explains the choice by measurement):
// * amplitudes: for fixed axes and sharpness the loss is a weighted linear
//   least-squares problem in μ with one Gram matrix G = Bᵀ W B shared by the
//   three channels (B_ik = exp(λ_k(d_i·p_k − 1)), W = diag(w_i)); it is solved
//   exactly under μ ≥ 0 by the Lawson-Hanson active-set method, warm-started
//   from the previous active set;
// * axes and sharpness: one damped Gauss-Newton (Levenberg-Marquardt) step on
//   (two tangent angles, log λ) per lobe, with the lobes' 3×3 blocks of JᵀJ
//   (kAlternatingBlock) or the whole 3M×3M matrix (kAlternatingDense). A step
//   is kept only if the loss after the next amplitude solve is lower;
//   otherwise the damping grows and the step is retried.
// Cold start: lobes placed one at a time on the sample with the largest
// relative residual, with the sharpness (from a fixed ladder) and amplitude
// that lower the loss most — a deterministic matching pursuit.
#include "render/sg/fit.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <string>

#include "calib/core/error.h"
#include "render/sg/fast_exp.h"

namespace nerfar {

namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

struct Data {
  int n = 0;
  std::vector<Vec3> d;
  std::vector<float> dx, dy, dz;  // the directions again, float structure of arrays (Basis)
  MatrixXd y;                     // n × 3
  VectorXd w;                     // ω_i / (τ + Y_i)²
  VectorXd sqrt_w;
  double norm = 1.0;  // Σ ω_i
};

Data MakeData(const RadianceSamples& s, double hdr_floor) {
  Data data;
  data.n = static_cast<int>(s.size());
  data.d = s.directions;
  data.y.resize(data.n, 3);
  data.w.resize(data.n);
  double sum_lum = 0.0, sum_omega = 0.0;
  for (int i = 0; i < data.n; ++i) {
    data.d[i] = Normalized(s.directions[i]);
    data.y(i, 0) = s.radiance[i].x;
    data.y(i, 1) = s.radiance[i].y;
    data.y(i, 2) = s.radiance[i].z;
    sum_lum += s.solid_angles[i] * LuminanceOf(s.radiance[i]);
    sum_omega += s.solid_angles[i];
  }
  const double tau = hdr_floor * sum_lum / sum_omega;
  for (int i = 0; i < data.n; ++i) {
    const double t = tau + LuminanceOf(s.radiance[i]);
    data.w[i] = t > 0.0 ? s.solid_angles[i] / (t * t) : 0.0;
  }
  data.sqrt_w = data.w.array().sqrt();
  data.dx.resize(data.n), data.dy.resize(data.n), data.dz.resize(data.n);
  for (int i = 0; i < data.n; ++i) {
    data.dx[i] = static_cast<float>(data.d[i].x);
    data.dy[i] = static_cast<float>(data.d[i].y);
    data.dz[i] = static_cast<float>(data.d[i].z);
  }
  data.norm = sum_omega;
  return data;
}

// Lobe geometry (axes, sharpness) and amplitudes (M × 3).
struct State {
  std::vector<Vec3> axis;
  std::vector<double> lambda;
  MatrixXd mu;  // M × 3
  int m() const { return static_cast<int>(axis.size()); }
};

// One column of the basis, b_i = exp(λ(d_i·p − 1)) = exp(−λ|d_i − p|²/2), in
// float with FastExp (relative error < 4e-7, far below the fit's tolerance;
// a loop over samples that vectorises), stored as double for the solves.
// Below e^{−60} a lobe has no influence and the value is 0.
void LobeColumn(const Data& data, const Vec3& axis, double lambda, double* __restrict out) {
  const float* __restrict dx = data.dx.data();
  const float* __restrict dy = data.dy.data();
  const float* __restrict dz = data.dz.data();
  const float px = static_cast<float>(axis.x), py = static_cast<float>(axis.y), pz = static_cast<float>(axis.z);
  const float half_l = static_cast<float>(0.5 * lambda);
  for (int i = 0; i < data.n; ++i) {
    const float ex = dx[i] - px, ey = dy[i] - py, ez = dz[i] - pz;
    out[i] = FastExpCut(-half_l * (ex * ex + ey * ey + ez * ez), -60.0f);
  }
}

// B_ik for every lobe.
void Basis(const Data& data, const State& st, MatrixXd& b) {
  b.resize(data.n, st.m());
  for (int k = 0; k < st.m(); ++k) LobeColumn(data, st.axis[k], st.lambda[k], b.col(k).data());
}

double Loss(const Data& data, const MatrixXd& b, const MatrixXd& mu) {
  const MatrixXd r = b * mu - data.y;
  return (r.rowwise().squaredNorm().array() * data.w.array()).sum() / data.norm;
}

// min ½xᵀGx − hᵀx subject to x ≥ 0 (Lawson-Hanson on the normal equations).
// x holds the warm start on entry (its positive entries seed the free set).
void Nnls(const MatrixXd& g, const VectorXd& h, VectorXd& x) {
  const int m = static_cast<int>(h.size());
  std::vector<char> free(m, 0);
  for (int j = 0; j < m; ++j) {
    if (x[j] > 0.0)
      free[j] = 1;
    else
      x[j] = 0.0;
  }
  const double scale = std::max(g.diagonal().maxCoeff(), 1e-300);
  const double tol = 1e-12 * scale * std::max(1.0, x.cwiseAbs().maxCoeff());
  auto solve_free = [&](VectorXd& z) {
    std::vector<int> idx;
    for (int j = 0; j < m; ++j)
      if (free[j]) idx.push_back(j);
    z.setZero(m);
    if (idx.empty()) return;
    const int f = static_cast<int>(idx.size());
    MatrixXd gf(f, f);
    VectorXd hf(f);
    for (int a = 0; a < f; ++a) {
      hf[a] = h[idx[a]];
      for (int c = 0; c < f; ++c) gf(a, c) = g(idx[a], idx[c]);
      gf(a, a) += 1e-12 * scale;  // coincident lobes: keep the system solvable
    }
    const VectorXd zf = gf.ldlt().solve(hf);
    for (int a = 0; a < f; ++a) z[idx[a]] = zf[a];
  };
  VectorXd z;
  for (int outer = 0; outer < 3 * m + 3; ++outer) {
    // Inner loop: move towards the unconstrained solution on the free set,
    // stopping at the first bound and releasing the variables that hit it.
    for (int inner = 0; inner < m + 1; ++inner) {
      solve_free(z);
      bool feasible = true;
      double step = 1.0;
      for (int j = 0; j < m; ++j)
        if (free[j] && z[j] <= 0.0) {
          feasible = false;
          const double denom = x[j] - z[j];
          if (denom > 0.0) step = std::min(step, x[j] / denom);
        }
      if (feasible) {
        x = z;
        break;
      }
      x += step * (z - x);
      for (int j = 0; j < m; ++j)
        if (free[j] && x[j] <= 1e-15 * std::max(1.0, std::abs(z[j]))) {
          free[j] = 0;
          x[j] = 0.0;
        }
    }
    // Optimality: the most promising bound variable with a descent direction.
    const VectorXd grad = h - g * x;
    int best = -1;
    double best_value = tol;
    for (int j = 0; j < m; ++j)
      if (!free[j] && grad[j] > best_value) {
        best_value = grad[j];
        best = j;
      }
    if (best < 0) break;
    free[best] = 1;
  }
  x = x.cwiseMax(0.0);
}

// Solves all amplitudes for the current geometry (warm-started from st.mu).
// The Gram matrix is formed over each pair's common support: a sharp lobe is
// zero (below e^{−60}) outside a band of the samples, which come in scan
// order, so each column's nonzero range [lo, hi) is found once and a pair's
// dot product runs over the overlap of two ranges (same sums as the dense
// product, minus exact zeros; 2-3× fewer operations on window/env.exr).
void SolveAmplitudes(const Data& data, const MatrixXd& b, State& st) {
  const int m = st.m(), n = data.n;
  const MatrixXd bw = b.array().colwise() * data.sqrt_w.array();
  std::vector<int> lo(m, n), hi(m, 0);
  for (int k = 0; k < m; ++k) {
    const double* col = b.col(k).data();
    int first = 0, last = n;
    while (first < n && col[first] == 0.0) ++first;
    while (last > first && col[last - 1] == 0.0) --last;
    lo[k] = first, hi[k] = last;
  }
  MatrixXd g(m, m);
  for (int k = 0; k < m; ++k)
    for (int j = 0; j <= k; ++j) {
      const int a = std::max(lo[j], lo[k]), e = std::min(hi[j], hi[k]);
      const double v = a < e ? bw.col(j).segment(a, e - a).dot(bw.col(k).segment(a, e - a)) : 0.0;
      g(k, j) = v, g(j, k) = v;
    }
  MatrixXd h(m, 3);  // Bᵀ W y
  for (int k = 0; k < m; ++k) {
    const int len = hi[k] - lo[k];
    for (int c = 0; c < 3; ++c)
      h(k, c) = len > 0 ? (b.col(k).segment(lo[k], len).array() * data.w.segment(lo[k], len).array() *
                           data.y.col(c).segment(lo[k], len).array())
                              .sum()
                        : 0.0;
  }
  for (int c = 0; c < 3; ++c) {
    VectorXd x = st.mu.col(c);
    Nnls(g, h.col(c), x);
    st.mu.col(c) = x;
  }
}

// Tangent frame (t1, t2) of a unit axis.
void Tangents(const Vec3& p, Vec3& t1, Vec3& t2) {
  const Vec3 a = std::abs(p.x) < 0.9 ? Vec3(1, 0, 0) : Vec3(0, 1, 0);
  t1 = Normalized(Cross(p, a));
  t2 = Cross(p, t1);
}

// One damped Gauss-Newton step on the geometry; returns the proposed state.
State GeometryStep(const Data& data, const MatrixXd& b, const State& st, double damping, bool dense,
                   const SgFitOptions& options) {
  const int m = st.m();
  const MatrixXd r = b * st.mu - data.y;  // n × 3
  std::vector<Vec3> t1(m), t2(m);
  for (int k = 0; k < m; ++k) Tangents(st.axis[k], t1[k], t2[k]);
  VectorXd delta(3 * m);
  if (!dense) {
    std::vector<Eigen::Matrix3d> hk(m, Eigen::Matrix3d::Zero());
    std::vector<Eigen::Vector3d> gk(m, Eigen::Vector3d::Zero());
    for (int k = 0; k < m; ++k) {
      const double l = st.lambda[k];
      const Eigen::Vector3d mu = st.mu.row(k).transpose();
      const double mu2 = mu.squaredNorm();
      if (!(mu2 > 0.0)) continue;
      for (int i = 0; i < data.n; ++i) {
        const double bik = b(i, k);
        if (bik < 1e-12) continue;  // no influence: skip (exp(−27.6))
        const Vec3& d = data.d[i];
        const Eigen::Vector3d g(bik * l * Dot(d, t1[k]), bik * l * Dot(d, t2[k]), bik * l * (Dot(d, st.axis[k]) - 1.0));
        const double wi = data.w[i];
        const double s = wi * (r(i, 0) * mu[0] + r(i, 1) * mu[1] + r(i, 2) * mu[2]);
        gk[k] += s * g;
        hk[k].noalias() += (wi * mu2) * g * g.transpose();
      }
    }
    for (int k = 0; k < m; ++k) {
      Eigen::Matrix3d a = hk[k];
      for (int j = 0; j < 3; ++j) a(j, j) += damping * hk[k](j, j) + 1e-12 * (1.0 + hk[k].trace());
      delta.segment<3>(3 * k) = a.ldlt().solve(-gk[k]);
    }
  } else {
    // J: (3n) × (3m), rows (i, c) = sqrt(w_i) μ_kc ∂b_ik/∂θ_k.
    MatrixXd j = MatrixXd::Zero(3 * data.n, 3 * m);
    VectorXd rv(3 * data.n);
    for (int i = 0; i < data.n; ++i)
      for (int c = 0; c < 3; ++c) rv[3 * i + c] = data.sqrt_w[i] * r(i, c);
    for (int k = 0; k < m; ++k) {
      const double l = st.lambda[k];
      for (int i = 0; i < data.n; ++i) {
        const double bik = b(i, k);
        if (bik < 1e-12) continue;
        const Vec3& d = data.d[i];
        const double g0 = bik * l * Dot(d, t1[k]), g1 = bik * l * Dot(d, t2[k]),
                     g2 = bik * l * (Dot(d, st.axis[k]) - 1.0);
        for (int c = 0; c < 3; ++c) {
          const double s = data.sqrt_w[i] * st.mu(k, c);
          j(3 * i + c, 3 * k) = s * g0;
          j(3 * i + c, 3 * k + 1) = s * g1;
          j(3 * i + c, 3 * k + 2) = s * g2;
        }
      }
    }
    MatrixXd h = MatrixXd::Zero(3 * m, 3 * m);
    h.selfadjointView<Eigen::Lower>().rankUpdate(j.transpose());
    h = h.selfadjointView<Eigen::Lower>();
    const VectorXd grad = j.transpose() * rv;
    const double trace = h.trace();
    for (int a = 0; a < 3 * m; ++a) h(a, a) += damping * h(a, a) + 1e-12 * (1.0 + trace);
    delta = h.ldlt().solve(-grad);
  }
  State next = st;
  for (int k = 0; k < m; ++k) {
    double a = delta[3 * k], c = delta[3 * k + 1], s = delta[3 * k + 2];
    if (!std::isfinite(a) || !std::isfinite(c) || !std::isfinite(s)) continue;
    const double turn = std::sqrt(a * a + c * c);
    if (turn > 0.5) {  // at most ~30° per step: the model is only locally linear
      a *= 0.5 / turn;
      c *= 0.5 / turn;
    }
    s = std::clamp(s, -1.0, 1.0);
    next.axis[k] = Normalized(st.axis[k] + t1[k] * a + t2[k] * c);
    next.lambda[k] = std::clamp(st.lambda[k] * std::exp(s), options.min_sharpness, options.max_sharpness);
  }
  return next;
}

// One greedy lobe: on the sample with the largest weighted deficit
// sqrt(w_i)(Y_i − M_i) (relative where bright), with the sharpness from a
// ladder (refined once around the best rung) and the non-negative amplitude
// that lower the loss most given the current model M.
struct Placement {
  Vec3 axis;
  double lambda = 1.0;
  Eigen::Vector3d mu = Eigen::Vector3d::Zero();
};

void RefineLobe(const Data& data, const MatrixXd& model, Placement& lobe, const SgFitOptions& options, int iterations);
constexpr int kRefineIterations = 8;  // a lobe placed on a sample is off by < 1 spacing; a few steps centre it

// `prior_sharpness` > 0 (warm fits: the dead lobe's own λ, most often right
// for a feature that moved) replaces the ladder by {½, 1, 2}× that λ, and the
// refinement takes kWarmRefineIterations: a quarter of the cost.
constexpr int kWarmRefineIterations = 3;
Placement PlaceLobe(const Data& data, const MatrixXd& model, std::vector<char>& used, const SgFitOptions& options,
                    double prior_sharpness = 0.0) {
  int best_i = -1;
  double best_deficit = -1e300;
  for (int i = 0; i < data.n; ++i) {
    if (used[i]) continue;
    const double y = LuminanceOf({data.y(i, 0), data.y(i, 1), data.y(i, 2)});
    const double md = LuminanceOf({model(i, 0), model(i, 1), model(i, 2)});
    const double deficit = (y - md) * data.sqrt_w[i];
    if (deficit > best_deficit) {
      best_deficit = deficit;
      best_i = i;
    }
  }
  if (best_i < 0) best_i = 0;
  used[best_i] = 1;
  Placement best;
  best.axis = data.d[best_i];
  double best_gain = -1.0;
  std::vector<double> column(data.n);
  const auto try_lambda = [&](double ladder) {
    const double l = std::clamp(ladder, options.min_sharpness, options.max_sharpness);
    double bb = 0.0;
    Eigen::Vector3d br = Eigen::Vector3d::Zero();
    LobeColumn(data, best.axis, l, column.data());
    for (int i = 0; i < data.n; ++i) {
      const double bi = column[i];
      const double wb = data.w[i] * bi;
      bb += wb * bi;
      for (int c = 0; c < 3; ++c) br[c] += wb * (data.y(i, c) - model(i, c));
    }
    if (!(bb > 0.0)) return;
    const Eigen::Vector3d mu = (br / bb).cwiseMax(0.0);
    const double gain = (mu.array() * br.array()).sum();  // loss decrease of the optimal positive step
    if (gain > best_gain) {
      best_gain = gain;
      best.lambda = l;
      best.mu = mu;
    }
  };
  if (prior_sharpness > 0.0) {
    for (double f : {0.5, 1.0, 2.0}) try_lambda(prior_sharpness * f);
    RefineLobe(data, model, best, options, kWarmRefineIterations);
    return best;
  }
  for (double ladder : {1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0, 3000.0}) try_lambda(ladder);
  const double rung = best.lambda;
  for (double f : {0.5, 0.7, 1.4, 2.0}) try_lambda(rung * f);
  RefineLobe(data, model, best, options, kRefineIterations);
  return best;
}

// Loss of one lobe against the residual target R = y − model, its amplitude
// solved in closed form (per channel, ≥ 0). Fills `basis` with the lobe's shape.
double SingleLobeFit(const Data& data, const MatrixXd& model, Placement& lobe, VectorXd& basis) {
  double bb = 0.0;
  Eigen::Vector3d br = Eigen::Vector3d::Zero();
  basis.resize(data.n);
  LobeColumn(data, lobe.axis, lobe.lambda, basis.data());
  for (int i = 0; i < data.n; ++i) {
    const double bi = basis[i];
    const double wb = data.w[i] * bi;
    bb += wb * bi;
    for (int c = 0; c < 3; ++c) br[c] += wb * (data.y(i, c) - model(i, c));
  }
  lobe.mu = Eigen::Vector3d::Zero();
  if (bb > 0.0) lobe.mu = (br / bb).cwiseMax(0.0);
  double loss = 0.0;
  for (int i = 0; i < data.n; ++i)
    for (int c = 0; c < 3; ++c) {
      const double r = lobe.mu[c] * basis[i] - (data.y(i, c) - model(i, c));
      loss += data.w[i] * r * r;
    }
  return loss;
}

// Refines a newly placed lobe alone against the residual of the others
// (damped Gauss-Newton on axis and log λ, amplitude in closed form): one lobe
// has no coupling to get stuck on, so this centres it on the feature that the
// sample grid only locates to within a sample spacing.
void RefineLobe(const Data& data, const MatrixXd& model, Placement& lobe, const SgFitOptions& options, int iterations) {
  VectorXd basis;
  double loss = SingleLobeFit(data, model, lobe, basis);
  double damping = 1e-3;
  for (int it = 0; it < iterations; ++it) {
    Vec3 t1, t2;
    Tangents(lobe.axis, t1, t2);
    Eigen::Matrix3d h = Eigen::Matrix3d::Zero();
    Eigen::Vector3d g = Eigen::Vector3d::Zero();
    const double mu2 = lobe.mu.squaredNorm();
    if (!(mu2 > 0.0)) return;
    for (int i = 0; i < data.n; ++i) {
      const double bi = basis[i];
      if (bi < 1e-12) continue;
      const Vec3& d = data.d[i];
      const double l = lobe.lambda;
      const Eigen::Vector3d j(bi * l * Dot(d, t1), bi * l * Dot(d, t2), bi * l * (Dot(d, lobe.axis) - 1.0));
      double s = 0.0;
      for (int c = 0; c < 3; ++c) s += lobe.mu[c] * (lobe.mu[c] * bi - (data.y(i, c) - model(i, c)));
      g += data.w[i] * s * j;
      h.noalias() += (data.w[i] * mu2) * j * j.transpose();
    }
    bool accepted = false;
    for (int attempt = 0; attempt < 4 && !accepted; ++attempt) {
      Eigen::Matrix3d a = h;
      for (int k = 0; k < 3; ++k) a(k, k) += damping * h(k, k) + 1e-12 * (1.0 + h.trace());
      Eigen::Vector3d step = a.ldlt().solve(-g);
      if (!step.allFinite()) return;
      const double turn = std::hypot(step[0], step[1]);
      if (turn > 0.5) step.head<2>() *= 0.5 / turn;
      Placement next = lobe;
      next.axis = Normalized(lobe.axis + t1 * step[0] + t2 * step[1]);
      next.lambda = std::clamp(lobe.lambda * std::exp(std::clamp(step[2], -1.0, 1.0)), options.min_sharpness,
                               options.max_sharpness);
      VectorXd next_basis;
      const double next_loss = SingleLobeFit(data, model, next, next_basis);
      if (next_loss < loss) {
        const double gain = (loss - next_loss) / std::max(loss, 1e-300);
        lobe = next;
        basis.swap(next_basis);
        loss = next_loss;
        damping = std::max(1e-6, damping * 0.3);
        accepted = true;
        if (gain < 1e-6) return;
      } else {
        damping *= 10.0;
      }
    }
    if (!accepted) return;
  }
}

void AddToModel(const Data& data, const Placement& lobe, MatrixXd& model) {
  std::vector<double> column(data.n);
  LobeColumn(data, lobe.axis, lobe.lambda, column.data());
  for (int i = 0; i < data.n; ++i) model.row(i) += column[i] * lobe.mu.transpose();
}

// Greedy placement (cold start): a deterministic matching pursuit.
State ColdStart(const Data& data, const SgFitOptions& options) {
  State st;
  const int m = options.lobes;
  MatrixXd model = MatrixXd::Zero(data.n, 3);
  std::vector<char> used(data.n, 0);
  st.mu.resize(m, 3);
  MatrixXd b;
  for (int k = 0; k < m; ++k) {
    const Placement lobe = PlaceLobe(data, model, used, options);
    st.axis.push_back(lobe.axis);
    st.lambda.push_back(lobe.lambda);
    st.mu.conservativeResize(k + 1, 3);
    st.mu.row(k) = lobe.mu.transpose();
    // Orthogonal matching pursuit: re-solve every amplitude so the next lobe
    // goes where the best k-lobe model (not the sum of greedy steps) falls short.
    b.conservativeResize(data.n, k + 1);
    LobeColumn(data, lobe.axis, lobe.lambda, b.col(k).data());
    SolveAmplitudes(data, b, st);
    model = b * st.mu;
  }
  return st;
}

// Lobes the amplitude solve switched off (μ = 0) get no gradient and would
// stay dead: move each to the largest remaining deficit. Returns how many.
int ReseedDeadLobes(const Data& data, const MatrixXd& b, State& st, const SgFitOptions& options, bool warm) {
  std::vector<int> dead;
  for (int k = 0; k < st.m(); ++k)
    if (st.mu.row(k).maxCoeff() <= 0.0) dead.push_back(k);
  if (dead.empty()) return 0;
  MatrixXd model = b * st.mu;
  std::vector<char> used(data.n, 0);
  for (int k : dead) {
    const Placement lobe = PlaceLobe(data, model, used, options, warm ? st.lambda[k] : 0.0);
    AddToModel(data, lobe, model);
    st.axis[k] = lobe.axis;
    st.lambda[k] = lobe.lambda;
    st.mu.row(k) = lobe.mu.transpose();
  }
  return static_cast<int>(dead.size());
}

// Adam on all parameters (axes as free 3-vectors, log λ, log μ).
void RunAdam(const Data& data, State& st, int iterations, const SgFitOptions& options) {
  const int m = st.m(), np = 7 * m;
  VectorXd theta(np), mom = VectorXd::Zero(np), vel = VectorXd::Zero(np);
  for (int k = 0; k < m; ++k) {
    theta.segment<3>(7 * k) << st.axis[k].x, st.axis[k].y, st.axis[k].z;
    theta[7 * k + 3] = std::log(st.lambda[k]);
    for (int c = 0; c < 3; ++c) theta[7 * k + 4 + c] = std::log(std::max(st.mu(k, c), 1e-8));
  }
  const double b1 = 0.9, b2 = 0.999, eps = 1e-12;
  MatrixXd b;
  for (int it = 1; it <= iterations; ++it) {
    for (int k = 0; k < m; ++k) {
      st.axis[k] = Normalized(Vec3(theta[7 * k], theta[7 * k + 1], theta[7 * k + 2]));
      st.lambda[k] = std::clamp(std::exp(theta[7 * k + 3]), options.min_sharpness, options.max_sharpness);
      for (int c = 0; c < 3; ++c) st.mu(k, c) = std::exp(std::min(theta[7 * k + 4 + c], 50.0));
    }
    Basis(data, st, b);
    const MatrixXd r = b * st.mu - data.y;
    VectorXd grad = VectorXd::Zero(np);
    for (int k = 0; k < m; ++k) {
      const double l = st.lambda[k];
      const Vec3 q(theta[7 * k], theta[7 * k + 1], theta[7 * k + 2]);
      const double qn = Length(q);
      Vec3 gp;
      double gl = 0.0;
      Eigen::Vector3d gm = Eigen::Vector3d::Zero();
      for (int i = 0; i < data.n; ++i) {
        const double bik = b(i, k);
        if (bik < 1e-12) continue;
        const double wi = 2.0 * data.w[i] / data.norm;
        const double s = wi * (r(i, 0) * st.mu(k, 0) + r(i, 1) * st.mu(k, 1) + r(i, 2) * st.mu(k, 2));
        gp += data.d[i] * (s * bik * l);
        gl += s * bik * l * (Dot(data.d[i], st.axis[k]) - 1.0);
        for (int c = 0; c < 3; ++c) gm[c] += wi * r(i, c) * bik * st.mu(k, c);
      }
      const Vec3 tangential = (gp - st.axis[k] * Dot(gp, st.axis[k])) / std::max(qn, 1e-12);
      grad.segment<3>(7 * k) << tangential.x, tangential.y, tangential.z;
      grad[7 * k + 3] = gl;
      grad.segment<3>(7 * k + 4) = gm;
    }
    mom = b1 * mom + (1 - b1) * grad;
    vel = b2 * vel + (1 - b2) * grad.cwiseProduct(grad);
    const double c1 = 1.0 - std::pow(b1, it), c2 = 1.0 - std::pow(b2, it);
    theta -= (options.adam_step * (mom / c1).array() / ((vel / c2).array().sqrt() + eps)).matrix();
  }
  for (int k = 0; k < m; ++k) {
    st.axis[k] = Normalized(Vec3(theta[7 * k], theta[7 * k + 1], theta[7 * k + 2]));
    st.lambda[k] = std::clamp(std::exp(theta[7 * k + 3]), options.min_sharpness, options.max_sharpness);
    for (int c = 0; c < 3; ++c) st.mu(k, c) = std::exp(std::min(theta[7 * k + 4 + c], 50.0));
  }
}

void ValidateSamples(const RadianceSamples& s) {
  Problems problems("radiance samples");
  if (s.directions.empty()) problems.Add("directions", "empty (expected at least one sample)");
  if (s.radiance.size() != s.directions.size() || s.solid_angles.size() != s.directions.size())
    problems.Add("size", std::to_string(s.directions.size()) + " directions, " + std::to_string(s.radiance.size()) +
                             " radiance values, " + std::to_string(s.solid_angles.size()) +
                             " solid angles (expected equal counts)");
  problems.ThrowIfAny();
  for (size_t i = 0; i < s.size(); ++i) {
    const Vec3& d = s.directions[i];
    const Vec3& y = s.radiance[i];
    const std::string where = "sample " + std::to_string(i);
    if (!(std::abs(Length(d) - 1.0) < 1e-3)) problems.Add(where, "direction not a unit vector");
    if (!(y.x >= 0.0 && y.y >= 0.0 && y.z >= 0.0 && std::isfinite(y.x) && std::isfinite(y.y) && std::isfinite(y.z)))
      problems.Add(where, "radiance negative or not finite (expected >= 0)");
    if (!(s.solid_angles[i] > 0.0 && std::isfinite(s.solid_angles[i])))
      problems.Add(where, "solid angle not positive and finite");
    if (problems.items().size() > 10) break;
  }
  problems.ThrowIfAny();
}

}  // namespace

const std::vector<const char*>& SgFitMethodNames() {
  static const std::vector<const char*> kNames = {"block", "dense", "adam"};
  return kNames;
}

std::vector<std::string> SgFitOptions::Validate() const {
  std::vector<std::string> p;
  if (lobes < 1 || lobes > kMaxSgLobes) p.push_back("lobes: " + std::to_string(lobes) + " (expected 1..64)");
  if (cold_iterations < 0) p.push_back("cold_iterations: negative (expected >= 0)");
  if (warm_iterations < 0) p.push_back("warm_iterations: negative (expected >= 0)");
  if (!(hdr_floor > 0.0 && std::isfinite(hdr_floor))) p.push_back("hdr_floor: expected a positive number");
  if (!(min_sharpness > 0.0 && min_sharpness <= max_sharpness && max_sharpness <= 1e6))
    p.push_back("min_sharpness, max_sharpness: expected 0 < min <= max <= 1e6");
  if (!(tolerance >= 0.0)) p.push_back("tolerance: expected >= 0");
  if (adam_iterations < 0) p.push_back("adam_iterations: negative (expected >= 0)");
  if (!(adam_step > 0.0)) p.push_back("adam_step: expected > 0");
  return p;
}

SgFitOptions SgFitOptions::Preset(const std::string& name) {
  SgFitOptions o;
  if (name == "fast") {
    o.lobes = 16;
    o.cold_iterations = 12;
    o.warm_iterations = 1;
  } else if (name == "balanced") {
  } else if (name == "accurate") {
    o.lobes = 48;
    o.cold_iterations = 60;
    o.warm_iterations = 4;
  } else {
    ThrowInputError("sg fit preset", "'" + name + "' (expected fast, balanced or accurate)");
  }
  return o;
}

double SgFitLoss(const RadianceSamples& samples, const SgMixture& mixture, double hdr_floor) {
  ValidateSamples(samples);
  const Data data = MakeData(samples, hdr_floor);
  State st;
  st.mu.resize(static_cast<int>(mixture.size()), 3);
  for (size_t k = 0; k < mixture.size(); ++k) {
    st.axis.push_back(mixture[k].axis);
    st.lambda.push_back(mixture[k].sharpness);
    st.mu.row(static_cast<int>(k)) << mixture[k].amplitude.x, mixture[k].amplitude.y, mixture[k].amplitude.z;
  }
  MatrixXd b;
  Basis(data, st, b);
  return Loss(data, b, st.mu);
}

namespace {
SgMixture FitPrepared(const Data& data, const SgFitOptions& options, const SgMixture* warm_start, SgFitReport* report);
}  // namespace

SgMixture FitSg(const RadianceSamples& samples, const SgFitOptions& options, const SgMixture* warm_start,
                SgFitReport* report) {
  {
    Problems problems("sg fit options");
    for (const std::string& p : options.Validate()) problems.Add("", p);
    problems.ThrowIfAny();
  }
  ValidateSamples(samples);
  const Data data = MakeData(samples, options.hdr_floor);
  // A lobe narrower than half the sample spacing would fit single samples,
  // not the light between them: cap λ at 4/Ω̄ (width 1/sqrt(λ) ≥ sqrt(Ω̄)/2,
  // Ω̄ the mean solid angle per sample; 652 for 2048 samples over the sphere).
  SgFitOptions capped = options;
  capped.max_sharpness = std::min(options.max_sharpness, 4.0 * data.n / data.norm);
  capped.min_sharpness = std::min(options.min_sharpness, capped.max_sharpness);
  return FitPrepared(data, capped, warm_start, report);
}

namespace {

SgMixture FitPrepared(const Data& data, const SgFitOptions& options, const SgMixture* warm_start, SgFitReport* report) {
  const bool warm = warm_start != nullptr && static_cast<int>(warm_start->size()) == options.lobes;
  SgFitReport local;
  local.warm = warm;

  SgMixture result;
  double total_w = data.w.sum();
  if (!(total_w > 0.0) || data.y.maxCoeff() <= 0.0) {
    // No light at all: zero lobes spread over the sphere.
    for (const Vec3& p : FibonacciSphere(options.lobes)) result.push_back({p, 1.0, Vec3()});
    if (report) *report = local;
    return result;
  }

  State st;
  if (warm) {
    st.mu.resize(options.lobes, 3);
    for (int k = 0; k < options.lobes; ++k) {
      const Sg& sg = (*warm_start)[k];
      st.axis.push_back(Length(sg.axis) > 0.0 ? Normalized(sg.axis) : Vec3(0, 0, 1));
      st.lambda.push_back(
          std::clamp(std::isfinite(sg.sharpness) ? sg.sharpness : 1.0, options.min_sharpness, options.max_sharpness));
      st.mu.row(k) << std::max(0.0, sg.amplitude.x), std::max(0.0, sg.amplitude.y), std::max(0.0, sg.amplitude.z);
    }
  } else {
    st = ColdStart(data, options);
  }
  MatrixXd b;
  Basis(data, st, b);
  const int iterations = warm ? options.warm_iterations : options.cold_iterations;
  if (options.method == SgFitMethod::kAdam) {
    local.initial_loss = Loss(data, b, st.mu);
    RunAdam(data, st, warm ? options.adam_iterations / 4 : options.adam_iterations, options);
    Basis(data, st, b);
    local.iterations = warm ? options.adam_iterations / 4 : options.adam_iterations;
  } else {
    SolveAmplitudes(data, b, st);
    double loss = Loss(data, b, st.mu);
    local.initial_loss = loss;
    double damping = 1e-2;
    const bool dense = options.method == SgFitMethod::kAlternatingDense;
    MatrixXd b_next;
    for (int it = 0; it < iterations; ++it) {
      ++local.iterations;
      if (State seeded = st; ReseedDeadLobes(data, b, seeded, options, warm) > 0) {
        // Dead lobes moved to the largest deficits; kept if the re-solved loss fell.
        Basis(data, seeded, b_next);
        SolveAmplitudes(data, b_next, seeded);
        const double seeded_loss = Loss(data, b_next, seeded.mu);
        if (seeded_loss < loss) {
          st = std::move(seeded);
          b.swap(b_next);
          loss = seeded_loss;
        }
      }
      bool accepted = false;
      for (int attempt = 0; attempt < 3 && !accepted; ++attempt) {
        State next = GeometryStep(data, b, st, damping, dense, options);
        Basis(data, next, b_next);
        SolveAmplitudes(data, b_next, next);
        const double next_loss = Loss(data, b_next, next.mu);
        if (next_loss < loss) {
          const double gain = (loss - next_loss) / loss;
          st = std::move(next);
          b.swap(b_next);
          loss = next_loss;
          damping = std::max(1e-6, damping * 0.3);
          accepted = true;
          if (gain < options.tolerance) it = iterations;  // converged
        } else {
          damping *= 10.0;
        }
      }
      if (!accepted) break;  // no damped step helps: at a minimum
    }
  }
  local.final_loss = Loss(data, b, st.mu);
  for (int k = 0; k < st.m(); ++k)
    result.push_back({st.axis[k], st.lambda[k], Vec3(st.mu(k, 0), st.mu(k, 1), st.mu(k, 2))});
  if (report) *report = local;
  return result;
}

}  // namespace

}  // namespace nerfar
