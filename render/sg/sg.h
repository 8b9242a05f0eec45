// Spherical Gaussians (SGs) and their closed forms (DESIGN.md "The numerics").
// G(v; p, λ, μ) = μ · exp(λ(v·p − 1)): p unit axis in the world frame, λ ≥ 0
// sharpness (tested from 1e-4 to 1e4; 0 is the constant μ), μ ≥ 0 linear RGB
// amplitude (tested up to 1e6). Every exp here has an exponent ≤ 0 and every
// (1 − e^{−x}) is an expm1, so grazing, identical and opposite lobes stay finite.
#pragma once

#include <vector>

#include "calib/core/math.h"

namespace nerfar {

struct Sg {
  Vec3 axis{0, 0, 1};                          // p: unit direction the lobe peaks at (world frame)
  double sharpness = 1.0;                      // λ ≥ 0: angular width ~ 1/sqrt(λ) rad
  Vec3 amplitude{0, 0, 0};                     // μ ≥ 0: value at the axis, linear RGB
  bool operator==(const Sg&) const = default;  // every field exactly (a cache's key)
};

// A light or a BRDF as a sum of lobes (paper eq. 2); at most kMaxSgLobes for
// lighting.
using SgMixture = std::vector<Sg>;
inline constexpr int kMaxSgLobes = 64;

// exp(λ(v·p − 1)) for unit v, p: computed as exp(−λ|v − p|²/2), which is the
// same for unit vectors, never has a positive exponent and keeps its relative
// accuracy for sharp lobes near the axis.
double SgShape(const Vec3& axis, double sharpness, const Vec3& v);
Vec3 Evaluate(const Sg& sg, const Vec3& v);
Vec3 Evaluate(const SgMixture& mixture, const Vec3& v);

// (1 − e^{−2λ})/λ, with its limit 2 at λ = 0 (accurate for every λ ≥ 0).
double OneMinusExpNeg2LOverL(double sharpness);
// ∫_S² exp(λ(v·p − 1)) dv = 2π(1 − e^{−2λ})/λ.
double SgUnitIntegral(double sharpness);
// ∫_S² G dv = μ · SgUnitIntegral(λ).
Vec3 Integral(const Sg& sg);
Vec3 Integral(const SgMixture& mixture);

// G_a · G_b as one SG: axis (λ_a p_a + λ_b p_b)/λ_m, λ_m = |λ_a p_a + λ_b p_b|,
// amplitude μ_a μ_b exp(λ_m − λ_a − λ_b) with the exponent written as
// −λ_a λ_b |p_a − p_b|² / (λ_a + λ_b + λ_m) (no cancellation, always ≤ 0).
// Exactly opposite lobes of equal sharpness give λ_m = 0: the constant
// μ_a μ_b e^{−2λ}, returned with axis p_a.
Sg Product(const Sg& a, const Sg& b);
// ∫_S² G_a G_b dv (per channel).
Vec3 InnerProduct(const Sg& a, const Sg& b);
// Inner product of unit-amplitude lobes (the scalar kernel of InnerProduct).
double UnitInnerProduct(const Vec3& axis_a, double sharpness_a, const Vec3& axis_b, double sharpness_b);

// The lobe seen in another frame: axis R·p (R a rotation, e.g. T_world_object).
Sg Rotated(const Sg& sg, const Mat3& rotation);
SgMixture Rotated(const SgMixture& mixture, const Mat3& rotation);

// Cosine lobe: max(v·n, 0) ≈ kCosineLobeAmplitude · exp(kCosineLobeSharpness (v·n − 1)),
// the least-squares fit over the sphere (weight 1 everywhere). Used where a
// product with the cosine must stay an SG (the κ numerator, paper eq. 9);
// irradiance itself uses the exact tables of visibility.h.
inline constexpr double kCosineLobeSharpness = 2.133;
inline constexpr double kCosineLobeAmplitude = 1.170;
Sg CosineLobe(const Vec3& normal);

// `count` directions distributed as the lobe itself (its shape
// exp(λ(v·p − 1)) as a density on the sphere), each standing for an equal
// share of its integral: cos θ_j by the exact inverse of the distribution,
// c = 1 + log1p(u_j·expm1(−2λ))/λ at u_j = (j + ½)/count, azimuths by the
// golden angle. A quadrature for what a lobe sharper than a sampling's
// spacing reaches (its transmittance, its reflection). count ≥ 1.
std::vector<Vec3> SgQuadrature(const Vec3& axis, double sharpness, int count);

// Luminance weights (Rec. 709) used to reduce RGB amplitudes to one number.
double LuminanceOf(const Vec3& rgb);

}  // namespace nerfar
