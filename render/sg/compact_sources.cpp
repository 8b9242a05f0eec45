#include "render/sg/compact_sources.h"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace nerfar {

namespace {

// Samples sorted by z, for the neighbours of a direction within an angle.
struct ZIndex {
  std::vector<uint32_t> order;
  std::vector<double> z;
  explicit ZIndex(const std::vector<Vec3>& d) : order(d.size()), z(d.size()) {
    std::iota(order.begin(), order.end(), 0u);
    std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return d[a].z < d[b].z; });
    for (size_t k = 0; k < d.size(); ++k) z[k] = d[order[k]].z;
  }
  // Calls f(j) for every sample within `angle` of direction v.
  template <class F>
  void Near(const std::vector<Vec3>& d, const Vec3& v, double angle, F&& f) const {
    const double c = std::cos(angle), reach = 2.0 * std::sin(0.5 * angle) + 1e-12;
    const size_t first = std::lower_bound(z.begin(), z.end(), v.z - reach) - z.begin();
    const size_t last = std::upper_bound(z.begin(), z.end(), v.z + reach) - z.begin();
    for (size_t k = first; k < last; ++k)
      if (Dot(d[order[k]], v) >= c) f(order[k]);
  }
};

}  // namespace

double CompactSharpness(int samples) { return std::max(samples, 1) / (4.0 * kPi); }

CompactSplit SplitCompactSources(const RadianceSamples& samples, int max_sources, double hdr_floor) {
  CompactSplit out;
  out.rest = samples;
  const size_t n = samples.size();
  if (n < 16 || max_sources < 1) return out;
  std::vector<Vec3> d(n);
  std::vector<double> y(n);
  double flux = 0.0, area = 0.0;
  for (size_t i = 0; i < n; ++i) {
    d[i] = Normalized(samples.directions[i]);
    y[i] = LuminanceOf(samples.radiance[i]);
    if (!std::isfinite(y[i]) || !(samples.solid_angles[i] > 0.0)) y[i] = 0.0;
    flux += y[i] * samples.solid_angles[i];
    area += samples.solid_angles[i] > 0.0 ? samples.solid_angles[i] : 0.0;
  }
  if (!(flux > 0.0) || !(area > 0.0)) return out;
  const double bright = hdr_floor * flux / area;
  const double reach = 2.0 * std::sqrt(4.0 * kPi / static_cast<double>(n));
  const double sharp = CompactSharpness(static_cast<int>(n));
  const ZIndex index(d);
  std::vector<char> taken(n, 0);
  std::vector<uint32_t> seeds;
  for (size_t i = 0; i < n; ++i)
    if (y[i] > bright) seeds.push_back(static_cast<uint32_t>(i));
  std::sort(seeds.begin(), seeds.end(), [&](uint32_t a, uint32_t b) { return y[a] > y[b]; });
  struct Found {
    Sg lobe;
    std::vector<uint32_t> members;
    Vec3 around;
    double energy = 0.0;
  };
  std::vector<Found> found;
  for (uint32_t seed : seeds) {
    if (taken[seed]) continue;
    // The cluster: bright samples reachable from the seed; the samples next
    // to it that are not bright give the radiance around it.
    Found f;
    std::vector<uint32_t> dim;
    f.members.push_back(seed);
    taken[seed] = 1;
    for (size_t k = 0; k < f.members.size(); ++k)
      index.Near(d, d[f.members[k]], reach, [&](uint32_t j) {
        if (taken[j] == 1) return;
        if (y[j] > bright) {
          taken[j] = 1;
          f.members.push_back(j);
        } else if (taken[j] == 0) {
          taken[j] = 2;  // counted as around once
          dim.push_back(j);
        }
      });
    for (uint32_t j : dim) taken[j] = 0;
    Vec3 around;
    double around_area = 0.0;
    for (uint32_t j : dim)
      around += samples.radiance[j] * samples.solid_angles[j], around_area += samples.solid_angles[j];
    f.around = around_area > 0.0 ? around / around_area : Vec3{};
    // Energy, centroid and second moment of the excess over the surroundings.
    Vec3 energy, centre;
    double weight = 0.0;
    for (uint32_t i : f.members) {
      const Vec3 excess = (samples.radiance[i] - f.around) * samples.solid_angles[i];
      const double e = std::max(0.0, LuminanceOf(excess));
      for (int c = 0; c < 3; ++c) energy[c] += std::max(0.0, excess[c]);
      centre += d[i] * e;
      weight += e;
    }
    if (!(weight > 0.0) || !(Length(centre) > 0.0)) continue;
    centre = Normalized(centre);
    double moment = 0.0;
    for (uint32_t i : f.members) {
      const double e = std::max(0.0, LuminanceOf((samples.radiance[i] - f.around) * samples.solid_angles[i]));
      const double angle = std::acos(std::clamp(Dot(d[i], centre), -1.0, 1.0));
      moment += e * (angle * angle + samples.solid_angles[i] / 6.0);
    }
    const double lambda = 2.0 / (moment / weight);
    if (!(lambda > sharp)) continue;  // the samples resolve it: left to the fit
    f.lobe.axis = centre;
    f.lobe.sharpness = std::min(lambda, 1e4);
    f.lobe.amplitude = energy / SgUnitIntegral(f.lobe.sharpness);
    f.energy = weight;
    found.push_back(std::move(f));
  }
  std::stable_sort(found.begin(), found.end(), [](const Found& a, const Found& b) { return a.energy > b.energy; });
  if (found.size() > static_cast<size_t>(max_sources)) found.resize(static_cast<size_t>(max_sources));
  for (const Found& f : found) {
    out.lobes.push_back(f.lobe);
    for (uint32_t i : f.members) out.rest.radiance[i] = f.around;
  }
  return out;
}

}  // namespace nerfar
