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
  const LightPrep& p = (*context.preps)[owner];
  const size_t m = p.axes.size();
  if (m == 0) return 1.0f;
  // Near lobes re-aimed from x (LightParallax): their axes, and S along them,
  // are this receiver's own.
  const bool parallax = !p.parallax.distance.empty();
  SgMixture reaimed;
  std::vector<Vec3f> reaimed_axes;
  if (parallax) {
    reaimed = ReaimLight((*context.lights)[owner], p.parallax, Vec3(x));
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
