// The search for a sharp source (env_fit_internal.h): given the fit so far,
// the direction and size of the one light that lowers its weighted data term
// most, seen through shadow rays from the samples (env_shadow.h). A source's
// best amplitude and the term's drop are closed form for a fixed column
// (ResidualPull), so directions are scored without refitting: first a point
// source from an even set of directions on a subset of the samples, then the
// best few directions refined continuously (re-marching at every step), then
// the size from a ladder of sharpnesses, each seen through a bundle of rays
// spread over the lobe (its penumbra).
#include <algorithm>
#include <cmath>

#include "render/lighting/env_fit_internal.h"
#include "render/lighting/env_internal.h"
#include "render/sg/sphere.h"

namespace nerfar::env_internal {
namespace {

// Directions refined after the coarse search: the best few local maxima, so
// that a second, nearly as good direction (a shadow pattern's mirror image
// across a symmetric object) is not lost to the coarse grid's sampling.
constexpr int kRefinedDirections = 3;
// Coarse maxima closer than this many grid spacings are one maximum.
constexpr double kDistinctSpacings = 3;
// Candidates scored per batch of shadow rays.
constexpr size_t kCandidateBatch = 64;

// About m of the samples, spread evenly, leaving out emitter-like ones: a
// lamp's own surface glows with light no reflection explains, and would steer
// the search towards whatever lights it.
std::vector<uint32_t> EvenSubset(const FitState& st, size_t m) {
  std::vector<uint32_t> reflecting;
  for (size_t i = 0; i < st.emitter.size(); ++i)
    if (!st.emitter[i]) reflecting.push_back(static_cast<uint32_t>(i));
  const size_t n = reflecting.size();
  m = std::min(m, n);
  std::vector<uint32_t> subset;
  for (size_t k = 0; k < m; ++k) subset.push_back(reflecting[k * n / m]);
  return subset;
}

// How far from the origin a light in direction `axis` is at `reach` times
// the distance where the axis leaves the volume (0: distant, or no exit).
double SourceDistance(const FitState& st, const Vec3& axis, double reach) {
  float t_near = 0, t_far = 0;
  if (!(reach > 0) || !IntersectAabb(st.volume, Vec3f{}, Vec3f(axis), t_near, t_far) || !(t_far > 0)) return 0;
  return reach * t_far;
}

// The reaches a source is searched at (SourceDistance; 0 first: distant). A
// light f times as far as the volume's edge turns by about 1/f rad over the
// volume; beyond f = √λ_min that is within the broadest source's own width
// (1/√λ_min), and the light is as good as distant. Below, a ladder of
// halvings down to the volume's edge (f > 1) tells near from far.
std::vector<double> Reaches(const EnvEstimateOptions& o) {
  std::vector<double> reaches{0};
  for (double f = std::sqrt(o.source_sharpness_min); f > 1; f *= 0.5) reaches.push_back(f);
  return reaches;
}

// Scores of point sources (bundle of one ray) in the given directions.
std::vector<double> PointScores(const FitState& st, const ResidualPull& pull, const EnvShadowRays& shadow,
                                const std::vector<Vec3>& axes, double sharpness, double reach, uint64_t seed) {
  std::vector<double> scores;
  for (size_t begin = 0; begin < axes.size(); begin += kCandidateBatch) {
    const size_t end = std::min(axes.size(), begin + kCandidateBatch);
    const std::vector<Vec3> batch(axes.begin() + begin, axes.begin() + end);
    const std::vector<double> lambda(batch.size(), sharpness);
    std::vector<double> distance;
    for (const Vec3& axis : batch) distance.push_back(SourceDistance(st, axis, reach));
    for (const std::vector<double>& b :
         BundleIrradiance(*st.s, shadow, pull.subset(), batch, lambda, 1, seed, distance))
      scores.push_back(pull.Score(b));
  }
  return scores;
}

// The best directions of the coarse grid, at least kDistinctSpacings apart.
std::vector<Vec3> CoarseMaxima(const std::vector<Vec3>& grid, const std::vector<double>& scores, double spacing) {
  std::vector<size_t> order(grid.size());
  for (size_t k = 0; k < order.size(); ++k) order[k] = k;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return scores[a] > scores[b]; });
  std::vector<Vec3> maxima;
  const double min_cos = std::cos(kDistinctSpacings * spacing);
  for (size_t k : order) {
    if (!(scores[k] > 0) || static_cast<int>(maxima.size()) == kRefinedDirections) break;
    bool distinct = true;
    for (const Vec3& m : maxima) distinct = distinct && Dot(m, grid[k]) < min_cos;
    if (distinct) maxima.push_back(grid[k]);
  }
  return maxima;
}

// Where the search has a light: direction, reach (SourceDistance; 0:
// distant) and score.
struct Placement {
  Vec3 axis;
  double reach = 0, score = 0;
};

// Compass search on the sphere: the four neighbours at angle h along the
// tangent frame, and for a light at a distance its reach times 2^±s (s
// starting at half the ladder's step, halved with h: the distance is placed
// between the ladder's rungs too, within the ladder's range, Reaches); move
// to the best when it scores higher, else halve h; stop below h_min (a tenth
// of the sharpest lobe's width).
Placement RefinePlacement(const FitState& st, const ResidualPull& pull, const EnvShadowRays& shadow,
                          const Placement& start, double h, double sharpness, double reach_max, uint64_t seed) {
  Placement best = start;
  best.score = PointScores(st, pull, shadow, {start.axis}, sharpness, start.reach, seed)[0];
  const double h_min = 0.1 / std::sqrt(sharpness);
  double s = 0.5;
  for (int step = 0; step < 100 && h > h_min; ++step) {
    Vec3 u, v;
    OrthonormalBasis(best.axis, u, v);
    std::vector<Placement> around;
    std::vector<Vec3> turned;
    for (const Vec3& t : {u, u * -1.0, v, v * -1.0})
      turned.push_back(Normalized(best.axis * std::cos(h) + t * std::sin(h)));
    const std::vector<double> scores = PointScores(st, pull, shadow, turned, sharpness, best.reach, seed);
    for (size_t k = 0; k < turned.size(); ++k) around.push_back({turned[k], best.reach, scores[k]});
    if (best.reach > 0)
      for (const double reach : {best.reach * std::exp2(s), best.reach * std::exp2(-s)})
        if (reach > 1 && reach <= reach_max)
          around.push_back({best.axis, reach, PointScores(st, pull, shadow, {best.axis}, sharpness, reach, seed)[0]});
    const Placement& top = *std::max_element(around.begin(), around.end(),
                                             [](const Placement& a, const Placement& b) { return a.score < b.score; });
    if (top.score > best.score) {
      best = top;
    } else {
      h *= 0.5;
      s *= 0.5;
    }
  }
  return best;
}

// The size: a geometric ladder of sharpnesses from the options' range, each
// lobe's column from `bundle` rays spread over it; the best score wins.
SourceCandidate ChooseSize(const FitState& st, const ResidualPull& pull, const EnvShadowRays& shadow, const Vec3& axis,
                           double reach, const EnvEstimateOptions& o) {
  std::vector<double> ladder;
  const double ratio = std::sqrt(10.0);
  for (double lambda = o.source_sharpness_min; lambda <= o.source_sharpness_max * 1.0001; lambda *= ratio)
    ladder.push_back(lambda);
  const std::vector<Vec3> axes(ladder.size(), axis);
  const double distance = SourceDistance(st, axis, reach);
  const std::vector<std::vector<double>> columns =
      BundleIrradiance(*st.s, shadow, pull.subset(), axes, ladder, o.source_bundle_rays, o.seed,
                       std::vector<double>(ladder.size(), distance));
  SourceCandidate best{axis, ladder.back(), distance, 0};
  for (size_t k = 0; k < ladder.size(); ++k) {
    const double score = pull.Score(columns[k]);
    if (score > best.score) best = {axis, ladder[k], distance, score};
  }
  return best;
}

}  // namespace

ResidualPull::ResidualPull(const FitState& st, std::vector<uint32_t> subset) : subset_(std::move(subset)) {
  const Eigen::MatrixXd S = Shading(st);
  const Linearised lin = LineariseAtModel(st, S);
  const Eigen::Index m = static_cast<Eigen::Index>(subset_.size());
  std::vector<uint32_t> cell_slot(st.albedo.size(), UINT32_MAX);
  uint32_t cells = 0;
  slot_.resize(subset_.size());
  for (size_t a = 0; a < subset_.size(); ++a) {
    uint32_t& slot = cell_slot[st.cell[subset_[a]]];
    if (slot == UINT32_MAX) slot = cells++;
    slot_[a] = slot;
  }
  p_ = Eigen::VectorXd::Zero(m);
  q_ = Eigen::VectorXd::Zero(m);
  wfs_ = Eigen::MatrixXd::Zero(m, 3);
  Eigen::VectorXd d = Eigen::VectorXd::Zero(3 * cells);
  albedo_pull_ = Eigen::VectorXd::Zero(3 * cells);
  for (Eigen::Index a = 0; a < m; ++a) {
    const size_t i = subset_[a];
    for (int c = 0; c < 3; ++c) {
      const double w = lin.weight(i, c);
      const double f = st.albedo[st.cell[i]][c] / kPi, s = S(static_cast<Eigen::Index>(i), c);
      const double r = lin.target(i, c) - f * s;
      p_[a] += w * f * r;
      q_[a] += w * f * f;
      wfs_(a, c) = w * f * f * s;
      d[3 * slot_[a] + c] += w * f * f * s * s;
      albedo_pull_[3 * slot_[a] + c] += w * f * s * r;
    }
  }
  inv_d_ = Eigen::VectorXd::Zero(d.size());
  for (Eigen::Index j = 0; j < d.size(); ++j)
    if (d[j] > 0) inv_d_[j] = 1.0 / d[j];
  std::vector<Eigen::Index> lit;
  for (Eigen::Index k = 0; k < st.mu.rows(); ++k)
    if (st.mu.row(k).maxCoeff() > 0) lit.push_back(k);
  const Eigen::Index active = static_cast<Eigen::Index>(lit.size());
  active_.resize(m, active);
  active_sums_.resize(3 * cells, active);
  for (Eigen::Index k = 0; k < active; ++k) {
    for (Eigen::Index a = 0; a < m; ++a) active_(a, k) = st.A(subset_[a], lit[k]);
    active_sums_.col(k) = AlbedoSums(active_.col(k).data());
  }
  Eigen::MatrixXd gram =
      active_.transpose() * q_.asDiagonal() * active_ - active_sums_.transpose() * inv_d_.asDiagonal() * active_sums_;
  if (gram.rows() > 0) gram.diagonal().array() += 1e-9 * std::max(1e-300, gram.diagonal().maxCoeff());
  gram_.compute(gram);
  active_pull_ = active_.transpose() * p_ - active_sums_.transpose() * inv_d_.cwiseProduct(albedo_pull_);
}

Eigen::VectorXd ResidualPull::AlbedoSums(const double* x) const {
  Eigen::VectorXd sums = Eigen::VectorXd::Zero(inv_d_.size());
  for (Eigen::Index a = 0; a < wfs_.rows(); ++a)
    for (int c = 0; c < 3; ++c) sums[3 * slot_[a] + c] += wfs_(a, c) * x[a];
  return sums;
}

double ResidualPull::Score(const std::vector<double>& b) const {
  const Eigen::Map<const Eigen::VectorXd> column(b.data(), static_cast<Eigen::Index>(b.size()));
  const Eigen::VectorXd sums = AlbedoSums(b.data());
  const double open = column.dot(q_.cwiseProduct(column));
  double num = column.dot(p_) - sums.dot(inv_d_.cwiseProduct(albedo_pull_));
  double den = open - sums.dot(inv_d_.cwiseProduct(sums));
  if (active_.cols() > 0) {
    const Eigen::VectorXd c =
        active_.transpose() * q_.cwiseProduct(column) - active_sums_.transpose() * inv_d_.cwiseProduct(sums);
    const Eigen::VectorXd g_c = gram_.solve(c);
    num -= g_c.dot(active_pull_);
    den -= g_c.dot(c);
  }
  return num > 0 && den > 1e-12 * open ? num * num / den : 0.0;
}

std::vector<SourceCandidate> FindSources(const FitState& st, const EnvShadowRays& shadow, const EnvEstimateOptions& o) {
  const ResidualPull coarse(st, EvenSubset(st, static_cast<size_t>(o.source_search_samples)));
  const ResidualPull fine(st, EvenSubset(st, static_cast<size_t>(o.source_refine_samples)));
  const std::vector<Vec3> grid = FibonacciSphere(o.source_candidates);
  const double spacing = std::sqrt(4 * kPi / o.source_candidates);
  const double point = o.source_sharpness_max;  // the search's point source
  std::vector<SourceCandidate> found;
  const std::vector<double> reaches = Reaches(o);
  const double reach_max = *std::max_element(reaches.begin(), reaches.end());
  for (const double reach : reaches) {
    const std::vector<double> scores = PointScores(st, coarse, shadow, grid, point, reach, o.seed);
    for (const Vec3& start : CoarseMaxima(grid, scores, spacing)) {
      const Placement refined = RefinePlacement(st, fine, shadow, {start, reach}, spacing, point, reach_max, o.seed);
      if (!(refined.score > 0)) continue;
      const SourceCandidate sized = ChooseSize(st, fine, shadow, refined.axis, refined.reach, o);
      if (sized.score > 0) found.push_back(sized);
    }
  }
  std::stable_sort(found.begin(), found.end(),
                   [](const SourceCandidate& a, const SourceCandidate& b) { return a.score > b.score; });
  if (found.size() > kRefinedDirections) found.resize(kRefinedDirections);
  return found;
}

}  // namespace nerfar::env_internal
