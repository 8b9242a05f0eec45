#include "render/sg/sg.h"

#include <algorithm>
#include <cmath>

namespace nerfar {

namespace {
constexpr double kTwoPi = 2.0 * kPi;
}  // namespace

double SgShape(const Vec3& axis, double sharpness, const Vec3& v) {
  const Vec3 d = v - axis;
  return std::exp(-0.5 * sharpness * Dot(d, d));
}

Vec3 Evaluate(const Sg& sg, const Vec3& v) { return sg.amplitude * SgShape(sg.axis, sg.sharpness, v); }

Vec3 Evaluate(const SgMixture& mixture, const Vec3& v) {
  Vec3 sum;
  for (const Sg& sg : mixture) sum += Evaluate(sg, v);
  return sum;
}

double OneMinusExpNeg2LOverL(double sharpness) {
  // Below 1e-8 the series 2 − 2λ + (4/3)λ² is exact to double precision;
  // above, expm1 keeps the relative accuracy that 1 − exp would lose.
  if (sharpness < 1e-8) return 2.0 - 2.0 * sharpness;
  return -std::expm1(-2.0 * sharpness) / sharpness;
}

double SgUnitIntegral(double sharpness) { return kTwoPi * OneMinusExpNeg2LOverL(sharpness); }

Vec3 Integral(const Sg& sg) { return sg.amplitude * SgUnitIntegral(sg.sharpness); }

Vec3 Integral(const SgMixture& mixture) {
  Vec3 sum;
  for (const Sg& sg : mixture) sum += Integral(sg);
  return sum;
}

namespace {

// Axis, sharpness and log-scale of the product of two unit-amplitude lobes.
struct UnitProduct {
  Vec3 axis;
  double sharpness;
  double log_scale;  // λ_m − λ_a − λ_b ≤ 0
};

UnitProduct MultiplyUnit(const Vec3& pa, double la, const Vec3& pb, double lb) {
  const Vec3 u = pa * la + pb * lb;
  const double lm = Length(u);
  const Vec3 d = pa - pb;
  const double denom = la + lb + lm;
  // λ_a + λ_b − λ_m = ((λ_a + λ_b)² − λ_m²)/(λ_a + λ_b + λ_m) = λ_a λ_b |p_a − p_b|² / (…).
  const double log_scale = denom > 0.0 ? -la * lb * Dot(d, d) / denom : 0.0;
  // Opposite lobes of equal sharpness cancel to a constant (λ_m = 0): keep
  // p_a as a valid axis; its direction no longer matters.
  const Vec3 axis = lm > 0.0 ? u / lm : pa;
  return {axis, lm, std::min(0.0, log_scale)};
}

}  // namespace

Sg Product(const Sg& a, const Sg& b) {
  const UnitProduct p = MultiplyUnit(a.axis, a.sharpness, b.axis, b.sharpness);
  return {p.axis, p.sharpness, (a.amplitude * b.amplitude) * std::exp(p.log_scale)};
}

double UnitInnerProduct(const Vec3& axis_a, double sharpness_a, const Vec3& axis_b, double sharpness_b) {
  const UnitProduct p = MultiplyUnit(axis_a, sharpness_a, axis_b, sharpness_b);
  return std::exp(p.log_scale) * SgUnitIntegral(p.sharpness);
}

Vec3 InnerProduct(const Sg& a, const Sg& b) {
  return (a.amplitude * b.amplitude) * UnitInnerProduct(a.axis, a.sharpness, b.axis, b.sharpness);
}

Sg Rotated(const Sg& sg, const Mat3& rotation) { return {Normalized(rotation * sg.axis), sg.sharpness, sg.amplitude}; }

SgMixture Rotated(const SgMixture& mixture, const Mat3& rotation) {
  SgMixture out;
  out.reserve(mixture.size());
  for (const Sg& sg : mixture) out.push_back(Rotated(sg, rotation));
  return out;
}

Sg CosineLobe(const Vec3& normal) {
  return {normal, kCosineLobeSharpness, Vec3(kCosineLobeAmplitude, kCosineLobeAmplitude, kCosineLobeAmplitude)};
}

std::vector<Vec3> SgQuadrature(const Vec3& axis, double sharpness, int count) {
  std::vector<Vec3> out;
  const Vec3 p = Normalized(axis);
  if (count < 1 || !(Length(p) > 0.5)) return out;
  const Vec3 a = std::abs(p.x) < 0.9 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
  const Vec3 t1 = Normalized(Cross(p, a)), t2 = Cross(p, t1);
  const double golden = kPi * (3.0 - std::sqrt(5.0));
  const double lambda = std::max(sharpness, 1e-12);
  out.reserve(count);
  for (int j = 0; j < count; ++j) {
    const double u = (j + 0.5) / count;
    // 1 − cos θ = −log1p(u·expm1(−2λ))/λ ∈ [0, 2]: no cancellation for sharp lobes.
    const double one_minus_c = std::clamp(-std::log1p(u * std::expm1(-2.0 * lambda)) / lambda, 0.0, 2.0);
    const double sin_t = std::sqrt(std::max(0.0, one_minus_c * (2.0 - one_minus_c)));
    const double phi = golden * j;
    out.push_back(Normalized(p * (1.0 - one_minus_c) + (t1 * std::cos(phi) + t2 * std::sin(phi)) * sin_t));
  }
  return out;
}

double LuminanceOf(const Vec3& rgb) { return 0.2126 * rgb.x + 0.7152 * rgb.y + 0.0722 * rgb.z; }

}  // namespace nerfar
