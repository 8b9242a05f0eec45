// Integrals of SGs over half-spaces: f_h (paper eq. 9, after all_freq), the
// self-shadow ratio γ_k (paper eq. 10), the exact clamped-cosine irradiance of
// a lobe, and the shadow ratio κ (paper eqs. 8-9). Angles in radians. The
// boundary of a half-space is a great circle; a signed angular distance θ is
// positive when the lobe axis lies on the visible side. SSDF values S come
// from render/ssdf and are passed in as numbers (positive: ray misses the object).
#pragma once

#include <string>
#include <vector>

#include "render/sg/sg.h"

namespace nerfar {

// f_h(θ, λ) = ∫_{visible side} exp(λ(v·p − 1)) dv, the boundary a great circle
// at signed angular distance θ from p. θ is clamped to [−π/2, π/2]; f_h(π/2, λ)
// is the hemisphere around p, 2π(1 − e^{−λ})/λ, and f_h(θ) + f_h(−θ) is the
// whole-sphere integral. From a table (interpolated in θ and log λ, accurate to
// ~2e-4 of f_h(π/2)); λ outside [1e-4, 1e4] uses the end rows (exact shape in
// the sharp limit, O(λ) error in the flat one).
double HalfSpaceIntegral(double theta_rad, double sharpness);
// The same by adaptive 1-D quadrature (the table's source; ~1e-10 relative).
double HalfSpaceIntegralQuadrature(double theta_rad, double sharpness);
// f_h(π/2, λ) in closed form.
double HemisphereIntegral(double sharpness);

// Self-shadow ratio γ = f_h(S, λ)/f_h(π/2, λ) (paper eq. 10): in [0, 1],
// non-decreasing in S, exactly 1 for S ≥ π/2 (nothing in the way).
double SelfShadowGamma(double ssd_rad, double sharpness);

// Irradiance of a unit lobe on a surface with normal n: ∫ exp(λ(v·p − 1))
// max(v·n, 0) dv as a function of cos_axis_normal = p·n. Exact up to table
// interpolation (~2e-4 of the lobe's integral), no SG cosine approximation.
double UnitIrradiance(double cos_axis_normal, double sharpness);
double UnitIrradianceQuadrature(double cos_axis_normal, double sharpness);
// E(n) = ∫ L(v) max(v·n, 0) dv for an SG light (RGB).
Vec3 Irradiance(const SgMixture& light, const Vec3& normal);

// Per-lobe lookups prepared once per sharpness (one log per lobe per frame),
// so per-pixel γ and irradiance cost a few multiplies and two table reads.
struct SgTableRow {
  int row = 0;             // lower table row (log λ)
  float frac = 0;          // weight of row + 1
  float inv_width = 1;     // table coordinate per unit of angle / cosine
  float scale = 1;         // normaliser of the stored values
  float cosine_slope = 0;  // irradiance: the part linear in p·n (0 for γ)
};
SgTableRow PrepareGamma(double sharpness);
float GammaPrepared(const SgTableRow& row, float ssd_rad);
SgTableRow PrepareIrradiance(double sharpness);
float UnitIrradiancePrepared(const SgTableRow& row, float cos_axis_normal);
// The irradiance row of a prepared lobe with its two table rows already
// blended (kIrradianceTableColumns log values over |c|·inv_width = 0..256):
// UnitIrradiancePrepared is scale·exp(linear interpolation of these) plus
// max(c, 0)·cosine_slope. For kernels that keep one row per lobe and frame.
inline constexpr int kIrradianceTableColumns = 257;
void BlendedIrradianceRow(const SgTableRow& row, float* out);

// Shadow ratio κ (paper eqs. 8-9). First the light times the cosine about the
// receiver normal as SGs, one lobe per light lobe (query the SSDF at their axes):
SgMixture CosineWeightedLight(const SgMixture& light, const Vec3& normal);
// then κ = Σ_k Y(μ'_k) f_h(min(S_k, e_k), λ'_k) / Σ_k Y(μ'_k) f_h(e_k, λ'_k), with
// e_k = asin(p'_k·n) the lobe's signed distance to the receiver's horizon and
// Y the luminance. κ is in [0, 1], 1 when every S_k ≥ e_k (the object is not
// in the way of any lobe) or when no light reaches the receiver.
double ShadowRatio(const SgMixture& cosine_weighted, const Vec3& normal, const std::vector<double>& ssd_rad);

// One lobe's share of ShadowRatio, in luminance: its energy above the
// receiver's horizon (`total`) and the part of that not blocked by an
// occluder at signed distance ssd_rad from its axis (`visible` <= total).
struct LobeShadow {
  double total = 0, visible = 0;
};
LobeShadow ShadowOfLobe(const Sg& cosine_weighted_lobe, const Vec3& normal, double ssd_rad);

// What ShadowOfLobe needs of a lobe that does not depend on the receiver's
// SSD: its luminance, luminance × hemisphere integral and γ table row
// (one log per lobe). For callers that take κ of one cosine-weighted light
// more than once (several SSDs, or receivers sharing a normal):
// ShadowOfLobePrepared / ShadowRatioPrepared give bit for bit what
// ShadowOfLobe / ShadowRatio give for the same lobe.
struct PreparedShadowLobe {
  Vec3 axis;
  double luminance = 0;  // Y(μ'_k); <= 0: the lobe adds nothing
  double weight = 0;     // Y(μ'_k) · f_h(π/2, λ'_k)
  SgTableRow row;        // PrepareGamma(λ'_k)
};
PreparedShadowLobe PrepareShadowLobe(const Sg& cosine_weighted_lobe);
// Replaces `out` with the prepared lobes of `cosine_weighted` (keeps its storage).
void PrepareShadowLobes(const SgMixture& cosine_weighted, std::vector<PreparedShadowLobe>& out);
LobeShadow ShadowOfLobePrepared(const PreparedShadowLobe& lobe, const Vec3& normal, double ssd_rad);
double ShadowRatioPrepared(const std::vector<PreparedShadowLobe>& lobes, const Vec3& normal,
                           const std::vector<double>& ssd_rad);

}  // namespace nerfar
