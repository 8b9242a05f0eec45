#include "render/insert/shadow_terms.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

namespace nerfar {

// κ (paper eqs. 8-9) with the half-space visibility of f_h bounded by the
// occluder's size. f_h treats everything beyond the silhouette's nearest
// point as blocked (a half-space), which for a broad lobe and a small, far
// occluder blocks far more than the object can: the object lies inside a cap
// of angular radius α (its bounding sphere seen from x) whose centre is α
// beyond the nearest silhouette point, so a broad lobe k loses about
// G(cap centre) × solid angle(cap). Broad lobes take the smaller estimate,
// sharp ones (√λ·α ≥ 1.5) the half-space one, which is then render/sg's
// ShadowRatio exactly; in between they blend.
double ShadowRatioCapped(const SgMixture& cosine_weighted, const std::vector<PreparedShadowLobe>& lobes,
                         const Vec3& normal, const std::vector<double>& ssd, const std::vector<double>& cap_radius) {
  double visible = 0.0, total = 0.0;
  for (size_t k = 0; k < cosine_weighted.size(); ++k) {
    const Sg& sg = cosine_weighted[k];
    const LobeShadow lobe = ShadowOfLobePrepared(lobes[k], normal, ssd[k]);
    if (!(lobe.total > 0.0)) continue;
    const double lobe_total = lobe.total;
    double blocked = lobe.total - lobe.visible;
    if (blocked > 0.0) {
      const double alpha = std::clamp(cap_radius[k], 0.0, 0.5 * kPi);
      const double centre = std::clamp(ssd[k] + alpha, 0.0, kPi);  // the cap centre's angle from the lobe axis
      const double solid = 2.0 * kPi * (1.0 - std::cos(alpha));
      const double cap = LuminanceOf(sg.amplitude) * std::exp(sg.sharpness * (std::cos(centre) - 1.0)) * solid;
      // The cap estimate (value at its centre × its solid angle) holds for
      // lobes broader than the cap; for sharper ones it misses the peak, and
      // the half-space estimate is the right one: blend on √λ·α.
      const double t = std::clamp(std::sqrt(sg.sharpness) * alpha - 0.5, 0.0, 1.0);
      blocked = (1.0 - t) * std::min(blocked, cap) + t * blocked;
    }
    total += lobe_total;
    visible += lobe_total - std::min(blocked, lobe_total);
  }
  if (!(total > 0.0)) return 1.0;
  return std::clamp(visible / total, 0.0, 1.0);
}

// γ_k of every lobe at a surface point with normal n from the union SSD
// there (paper eq. 10; with `horizon`, relative to the part of the lobe above
// the surface's horizon, see InsertOptions::self_shadow_horizon).
void GammaFromSsd(const std::vector<Vec3f>& axes, const std::vector<SgTableRow>& rows, const Vec3f& n,
                  const float* ssd_min, bool horizon, float* gamma) {
  for (size_t l = 0; l < axes.size(); ++l) {
    gamma[l] = 1.0f;
    if (!(ssd_min[l] < 0.5f * static_cast<float>(kPi))) continue;  // nothing in the way: γ = 1
    if (horizon) {
      const float e = std::asin(std::clamp(Dot(axes[l], n), -1.0f, 1.0f));
      const float full = GammaPrepared(rows[l], e);
      gamma[l] = full > 1e-6f ? GammaPrepared(rows[l], std::min(ssd_min[l], e)) / full : 1.0f;
    } else {
      gamma[l] = GammaPrepared(rows[l], ssd_min[l]);
    }
    gamma[l] = std::isfinite(gamma[l]) ? std::clamp(gamma[l], 0.0f, 1.0f) : 1.0f;
  }
}

double DiscVisibleFraction(double s, double r) {
  if (!(r > 0.0)) return s >= 0.0 ? 1.0 : 0.0;
  const double t = std::clamp(s / r, -1.0, 1.0);
  // Blocked: the circular segment beyond the chord at t, (acos t − t√(1−t²))/π of the disc.
  return std::clamp(1.0 - (std::acos(t) - t * std::sqrt(std::max(0.0, 1.0 - t * t))) / kPi, 0.0, 1.0);
}

ShadowSources BuildShadowSources(const RadianceSamples& samples, const SgMixture& light, const LightParallax& parallax,
                                 const std::vector<InsertObject>& objects, int bins, double min_radius,
                                 const SgMixture& compact, double energy_cut) {
  ShadowSources out;
  out.center = Vec3f(parallax.center);
  out.min_radius = static_cast<float>(std::max(0.0, min_radius));
  const std::vector<Vec3> bin_dirs = FibonacciSphere(std::max(bins, 4));
  const size_t nb = bin_dirs.size();
  const bool has_distances = parallax.distance.size() == light.size() && !light.empty();
  // Per bin and kind (0 distant, 1 near): energy, Σ e·direction, Σ e/d,
  // then Σ e·(angle² + pixel radius²/2) about the mean direction.
  struct Acc {
    double e = 0, inv = 0, m2 = 0;
    Vec3 d;
  };
  std::vector<Acc> acc(2 * nb);
  std::vector<uint32_t> slot(samples.size(), UINT32_MAX);
  std::vector<double> energy(samples.size(), 0.0);
  double total = 0.0;
  for (size_t i = 0; i < samples.size(); ++i) {
    const double y = LuminanceOf(samples.radiance[i]) * samples.solid_angles[i];
    const Vec3 d = Normalized(samples.directions[i]);
    if (!(y > 0.0) || !std::isfinite(y) || !(Length(d) > 0.5)) continue;
    size_t b = 0;
    double best = -2.0;
    for (size_t k = 0; k < nb; ++k) {
      const double c = Dot(d, bin_dirs[k]);
      if (c > best) best = c, b = k;
    }
    double distance = std::numeric_limits<double>::infinity();
    if (has_distances) {
      size_t lobe = 0;
      double brightest = -1.0;
      for (size_t k = 0; k < light.size(); ++k) {
        const double v =
            LuminanceOf(light[k].amplitude) * std::exp(light[k].sharpness * (Dot(Normalized(light[k].axis), d) - 1.0));
        if (v > brightest) brightest = v, lobe = k;
      }
      // Re-aimed as ReaimLight does: a finite distance on a lobe at least
      // half-way past the parallax's minimum sharpness.
      const double w = std::clamp((light[lobe].sharpness - parallax.min_sharpness) / parallax.min_sharpness, 0.0, 1.0);
      if (std::isfinite(parallax.distance[lobe]) && parallax.distance[lobe] > 0.0 && w >= 0.5)
        distance = parallax.distance[lobe];
    }
    const size_t s = 2 * b + (std::isfinite(distance) ? 1 : 0);
    acc[s].e += y;
    acc[s].d += d * y;
    if (std::isfinite(distance)) acc[s].inv += y / distance;
    slot[i] = static_cast<uint32_t>(s);
    energy[i] = y;
    total += y;
  }
  for (const Sg& lobe : compact) total += std::max(0.0, LuminanceOf(Integral(lobe)));
  if (!(total > 0.0)) return out;
  std::vector<Vec3f> distant_axes;
  for (const Sg& lobe : compact) {
    const double e = LuminanceOf(Integral(lobe));
    if (!(e > energy_cut * total) || !std::isfinite(e)) continue;
    ShadowSource src;
    src.direction = Vec3f(Normalized(lobe.axis));
    src.energy = static_cast<float>(e);
    src.radius = static_cast<float>(std::max(min_radius, 2.0 / std::sqrt(std::max(lobe.sharpness, 1e-12))));
    src.distance = std::numeric_limits<float>::infinity();
    out.distant.push_back(src);
    distant_axes.push_back(src.direction);
  }
  std::vector<Vec3> mean(acc.size());
  for (size_t s = 0; s < acc.size(); ++s) mean[s] = acc[s].e > 0.0 ? Normalized(acc[s].d) : Vec3{0, 0, 1};
  for (size_t i = 0; i < samples.size(); ++i) {
    if (slot[i] == UINT32_MAX) continue;
    const double angle = std::acos(std::clamp(Dot(Normalized(samples.directions[i]), mean[slot[i]]), -1.0, 1.0));
    acc[slot[i]].m2 += energy[i] * (angle * angle + 0.5 * samples.solid_angles[i] / kPi);
  }
  for (size_t s = 0; s < acc.size(); ++s) {
    const Acc& a = acc[s];
    if (!(a.e > energy_cut * total)) continue;
    ShadowSource src;
    src.direction = Vec3f(mean[s]);
    src.energy = static_cast<float>(a.e);
    // A uniform disc of radius R has an RMS angle of R/√2.
    src.radius = static_cast<float>(std::max(min_radius, std::sqrt(2.0 * a.m2 / a.e)));
    if (s % 2 == 1 && a.inv > 0.0) {
      src.distance = static_cast<float>(a.e / a.inv);
      out.near.push_back(src);
    } else {
      src.distance = std::numeric_limits<float>::infinity();
      out.distant.push_back(src);
      distant_axes.push_back(src.direction);
    }
  }
  out.distant_queries.resize(objects.size());
  out.visibilities.resize(objects.size(), nullptr);
  for (size_t j = 0; j < objects.size(); ++j) {
    out.visibilities[j] = objects[j].visibility;
    if (objects[j].visibility && !distant_axes.empty())
      out.distant_queries[j] = objects[j].visibility->Prepare(distant_axes);
  }
  return out;
}

namespace {

// κ at x (normal n) from the owner's sources (see ShadowSources).
float KappaFromSources(const KappaContext& context, const ShadowSources& src, const Vec3f& x, const Vec3f& n,
                       KappaScratch& sc, bool* queried) {
  const std::vector<size_t>& casters = *context.casters;
  const std::vector<WorldSphere>& spheres = *context.spheres;
  const size_t nd = src.distant.size(), nn = src.near.size(), m = nd + nn;
  sc.src_dir.resize(m);
  sc.src_radius.resize(m);
  sc.src_weight.resize(m);
  // Each source as seen from x: direction, angular radius, weight e'·cos.
  double total = 0.0;
  for (size_t i = 0; i < m; ++i) {
    const ShadowSource& s = i < nd ? src.distant[i] : src.near[i - nd];
    Vec3f u = s.direction;
    float radius = s.radius, energy = s.energy;
    if (i >= nd) {
      const Vec3f to = src.center + s.direction * s.distance - x;
      const float d = Length(to);
      if (d > 0.0f && std::isfinite(d)) {
        u = to / d;
        const float ratio = std::clamp(d / s.distance, 0.25f, 4.0f);
        radius = s.radius / ratio;
        energy = s.energy / (ratio * ratio);
      }
    }
    const float c = Dot(u, n);
    sc.src_dir[i] = u;
    sc.src_radius[i] = std::max(radius, src.min_radius);
    sc.src_weight[i] = c > 0.0f ? energy * c : 0.0f;
    total += sc.src_weight[i];
  }
  if (!(total > 0.0)) return 1.0f;
  // Lower bound of S from the bounding spheres: sources it clears are
  // wholly visible; if even blocking all the others leaves κ ≥ 1 − ε,
  // nothing needs the SSDF.
  double maybe_blocked = 0.0;
  sc.src_ssd.assign(m, std::numeric_limits<float>::infinity());
  sc.src_alpha.assign(m, 0.0f);
  for (size_t i = 0; i < m; ++i) {
    if (!(sc.src_weight[i] > 0.0f)) continue;
    float bound = std::numeric_limits<float>::infinity();
    for (size_t j : casters)
      bound = std::min(bound, BallSsdLowerBound(spheres[j].center, spheres[j].radius, x, sc.src_dir[i]));
    if (bound < sc.src_radius[i]) {
      maybe_blocked += sc.src_weight[i];
      sc.src_ssd[i] = -std::numeric_limits<float>::infinity();  // to be queried
    }
  }
  if (1.0 - maybe_blocked / total >= context.one_minus_eps) return 1.0f;
  if (queried) *queried = true;
  // The near sources to query, in one prepared set per caster.
  sc.near_dirs.clear();
  sc.near_index.clear();
  for (size_t i = nd; i < m; ++i)
    if (sc.src_ssd[i] == -std::numeric_limits<float>::infinity()) {
      sc.near_dirs.push_back(sc.src_dir[i]);
      sc.near_index.push_back(static_cast<uint32_t>(i));
    }
  bool any_distant = false;
  for (size_t i = 0; i < nd && !any_distant; ++i)
    any_distant = sc.src_ssd[i] == -std::numeric_limits<float>::infinity();
  std::vector<float>& best = sc.src_best;
  best.assign(m, std::numeric_limits<float>::infinity());
  for (size_t j : casters) {
    const float dist = Length(x - spheres[j].center);
    const float alpha =
        dist > spheres[j].radius ? std::asin(std::min(1.0f, spheres[j].radius / dist)) : 0.5f * float(kPi);
    if (any_distant && j < src.distant_queries.size() && src.distant_queries[j]) {
      sc.distant_ssd.resize(nd);
      src.distant_queries[j]->Ssd(&x, 1, sc.distant_ssd.data());
      for (size_t i = 0; i < nd; ++i)
        if (sc.distant_ssd[i] < best[i]) best[i] = sc.distant_ssd[i], sc.src_alpha[i] = alpha;
    }
    if (!sc.near_dirs.empty() && j < src.visibilities.size() && src.visibilities[j]) {
      sc.near_ssd.resize(sc.near_dirs.size());
      src.visibilities[j]->Prepare(sc.near_dirs)->Ssd(&x, 1, sc.near_ssd.data());
      for (size_t q = 0; q < sc.near_dirs.size(); ++q) {
        const size_t i = sc.near_index[q];
        if (sc.near_ssd[q] < best[i]) best[i] = sc.near_ssd[q], sc.src_alpha[i] = alpha;
      }
    }
  }
  double visible = 0.0;
  for (size_t i = 0; i < m; ++i) {
    if (!(sc.src_weight[i] > 0.0f)) continue;
    if (sc.src_ssd[i] != -std::numeric_limits<float>::infinity() || !std::isfinite(best[i])) {
      visible += sc.src_weight[i];
      continue;
    }
    const double r = sc.src_radius[i];
    double blocked = 1.0 - DiscVisibleFraction(best[i], r);
    // An occluder that looks smaller than the source blocks at most its own disc.
    const double a = sc.src_alpha[i];
    if (a < r) blocked = std::min(blocked, (a * a) / (r * r));
    visible += sc.src_weight[i] * (1.0 - blocked);
  }
  const double k = visible / total;
  return std::isfinite(k) ? static_cast<float>(std::clamp(k, 0.0, 1.0)) : 1.0f;
}

}  // namespace

float KappaAt(const KappaContext& context, const Vec3f& x, const Vec3f& n, KappaScratch& sc, bool* queried) {
  const std::vector<size_t>& casters = *context.casters;
  const std::vector<WorldSphere>& spheres = *context.spheres;
  // The owner of the light: the caster nearest in units of its radius.
  size_t owner = casters[0];
  float best = std::numeric_limits<float>::infinity();
  for (size_t j : casters) {
    const float rel = Length(x - spheres[j].center) / spheres[j].radius;
    if (rel < best) {
      best = rel;
      owner = j;
    }
  }
  if (!(best <= context.reach)) return 1.0f;
  if (context.sources && owner < context.sources->size() && !(*context.sources)[owner].empty())
    return KappaFromSources(context, (*context.sources)[owner], x, n, sc, queried);
  const LightPrep& p = (*context.preps)[owner];
  const size_t m = p.axes.size();
  if (m == 0) return 1.0f;
  // Near lobes re-aimed from x (LightParallax): their axes, and S along them,
  // are this receiver's own; a source at or below x's tangent plane gives it
  // no light (as a near source behind the receiver in KappaFromSources).
  const bool parallax = !p.parallax.distance.empty();
  SgMixture reaimed;
  std::vector<Vec3f> reaimed_axes;
  if (parallax) {
    const Vec3 receiver_normal(n);
    reaimed = ReaimLight((*context.lights)[owner], p.parallax, Vec3(x), &receiver_normal);
    reaimed_axes.reserve(m);
    for (const Sg& lobe : reaimed) reaimed_axes.push_back(Vec3f(lobe.axis));
  }
  const std::vector<Vec3f>& axes = parallax ? reaimed_axes : p.axes;
  // The cosine-weighted light and its prepared lobes (render/sg): kept
  // from the last call for the same light and normal (bit for bit).
  const SgMixture& light = parallax ? reaimed : (*context.lights)[owner];
  if (parallax || sc.cw_light != &light || std::memcmp(&sc.cw_normal, &n, sizeof n) != 0) {
    sc.cw = CosineWeightedLight(light, Vec3(n));
    PrepareShadowLobes(sc.cw, sc.lobes);
    sc.cw_light = parallax ? nullptr : &light;
    sc.cw_normal = n;
  }
  const SgMixture& cw = sc.cw;
  // Lower bound of S from the bounding spheres: if even that leaves
  // κ ≥ 1 − ε, nothing needs the SSDF.
  sc.s_bound.assign(m, kPi);
  for (size_t j : casters)
    for (size_t l = 0; l < m; ++l)
      sc.s_bound[l] =
          std::min<double>(sc.s_bound[l], BallSsdLowerBound(spheres[j].center, spheres[j].radius, x, axes[l]));
  if (ShadowRatioPrepared(sc.lobes, Vec3(n), sc.s_bound) >= context.one_minus_eps) return 1.0f;
  if (queried) *queried = true;
  sc.s_exact.assign(m, kPi);
  sc.cap.assign(m, 0.0);
  sc.ssd.resize(m);
  for (size_t j : casters) {
    if (!p.queries[j]) continue;
    if (parallax && j < p.visibilities.size() && p.visibilities[j])
      p.visibilities[j]->Prepare(axes)->Ssd(&x, 1, sc.ssd.data());
    else
      p.queries[j]->Ssd(&x, 1, sc.ssd.data());
    const float dist = Length(x - spheres[j].center);
    const double alpha = dist > spheres[j].radius ? std::asin(std::min(1.0f, spheres[j].radius / dist)) : 0.5 * kPi;
    for (size_t l = 0; l < m; ++l) {
      if (sc.ssd[l] < sc.s_exact[l]) {
        sc.s_exact[l] = sc.ssd[l];
        sc.cap[l] = alpha;
      }
    }
  }
  const double k = ShadowRatioCapped(cw, sc.lobes, Vec3(n), sc.s_exact, sc.cap);
  return std::isfinite(k) ? static_cast<float>(std::clamp(k, 0.0, 1.0)) : 1.0f;
}

}  // namespace nerfar
