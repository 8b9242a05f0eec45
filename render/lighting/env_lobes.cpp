// The SG dictionary and each lobe's irradiance at the samples through the
// NeRF's visibility cache (env_fit_internal.h).
#include <algorithm>
#include <cmath>

#include "calib/core/parallel.h"
#include "render/lighting/env_fit.h"
#include "render/lighting/env_fit_internal.h"
#include "render/lighting/env_internal.h"
#include "render/sg/sphere.h"
#include "render/sg/visibility.h"

namespace nerfar {
namespace env_internal {
namespace {

constexpr float kOccludedMin = 1e-3f;  // directions with less opacity are treated as open

}  // namespace

Dictionary MakeDictionary(const EnvEstimateOptions& o) {
  Dictionary d;
  int count = o.dictionary_base;
  double lambda = o.dictionary_sharpness;
  for (int l = 0; l < o.dictionary_levels; ++l, count *= 4, lambda *= 4) {
    for (const Vec3& p : FibonacciSphere(count)) d.Add(p, lambda, false);
  }
  return d;
}

// A(i, k): irradiance at sample i from unit-amplitude lobe k through the
// NeRF's visibility: the exact unoccluded irradiance U(p·n, λ) times the
// lobe's open fraction over the cached directions,
//   V_k = Σ_j (1 − Ô_j) G_k(d_j) / Σ_j G_k(d_j)
// (the directions are cosine distributed, so this is the cosine-weighted
// visibility of the lobe). A ratio rather than U − Σ Ô G: exactly 0 for a
// lobe hidden behind the NeRF and exactly U for an open one, even when the
// lobe is sharper than the spacing of the cached directions (weights are
// normalised by their largest term, so nothing underflows).
Eigen::MatrixXd LobeIrradianceMatrix(const EnvSurfaceSamples& s, const std::vector<Vec3>& axes,
                                     const std::vector<double>& sharpness, const EnvShadowRays& shadow, int bundle,
                                     uint64_t seed, const std::vector<double>& distance) {
  const size_t n = s.size(), d = axes.size();
  const int R = s.rays_per_point;
  // Lobes sharper than the cache resolves, and lights at a distance (the
  // cache's rays leave each sample, not aimed at a point): through shadow-ray
  // bundles.
  std::vector<bool> by_rays(d, false);
  std::vector<Vec3> sharp_axes;
  std::vector<double> sharp_lambda, sharp_distance;
  for (size_t k = 0; k < d; ++k) {
    const double at = distance.empty() ? 0 : distance[k];
    by_rays[k] = shadow != nullptr && (sharpness[k] > CacheSharpnessLimit(R) || at > 0);
    if (!by_rays[k]) continue;
    sharp_axes.push_back(axes[k]);
    sharp_lambda.push_back(sharpness[k]);
    sharp_distance.push_back(at);
  }
  Eigen::MatrixXd A(n, d);
  if (!sharp_axes.empty()) {
    const std::vector<std::vector<double>> columns =
        BundleIrradiance(s, shadow, AllSamples(s), sharp_axes, sharp_lambda, bundle, seed, sharp_distance);
    for (size_t k = 0, next = 0; k < d; ++k)
      if (by_rays[k])
        A.col(static_cast<Eigen::Index>(k)) = Eigen::Map<const Eigen::VectorXd>(columns[next++].data(), n);
  }
  std::vector<SgTableRow> rows(d);
  for (size_t k = 0; k < d; ++k) rows[k] = PrepareIrradiance(sharpness[k]);
  ParallelFor(
      n,
      [&](size_t i) {
        const Vec3 normal = ToD(s.normals[i]);
        bool any_occluded = false;
        for (int j = 0; j < R && !any_occluded; ++j) any_occluded = s.opacity[i * R + j] > kOccludedMin;
        std::vector<double> exponent(R);
        for (size_t k = 0; k < d; ++k) {
          if (by_rays[k]) continue;
          const double open = UnitIrradiancePrepared(rows[k], static_cast<float>(Dot(axes[k], normal)));
          double visible = 1;
          if (any_occluded) {
            double top = -1e300;
            for (int j = 0; j < R; ++j) {
              const Vec3 dir = ToD(s.ray_dirs[i * R + j]);
              exponent[j] = -0.5 * sharpness[k] * Dot(dir - axes[k], dir - axes[k]);  // λ(d·p − 1)
              top = std::max(top, exponent[j]);
            }
            double num = 0, den = 0;
            for (int j = 0; j < R; ++j) {
              const double g = std::exp(exponent[j] - top);
              den += g;
              num += g * (1.0 - s.opacity[i * R + j]);
            }
            visible = den > 0 ? num / den : 1.0;
          }
          A(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(k)) = std::max(0.0, open * visible);
        }
      },
      16);
  return A;
}

}  // namespace env_internal

using env_internal::LobeIrradianceMatrix;

std::vector<Vec3> EnvironmentIrradiance(const EnvSurfaceSamples& samples, const SgMixture& light,
                                        const EnvShadowRays& shadow, int bundle, uint64_t seed,
                                        const std::vector<double>& distance) {
  std::vector<Vec3> axes;
  std::vector<double> sharpness;
  for (const Sg& g : light) {
    axes.push_back(g.axis);
    sharpness.push_back(g.sharpness);
  }
  const Eigen::MatrixXd A = LobeIrradianceMatrix(samples, axes, sharpness, shadow, bundle, seed, distance);
  std::vector<Vec3> e(samples.size());
  for (size_t i = 0; i < samples.size(); ++i)
    for (size_t k = 0; k < light.size(); ++k) e[i] += light[k].amplitude * A(i, k);
  return e;
}

}  // namespace nerfar
