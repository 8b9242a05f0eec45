#include "render/sg/brdf.h"

#include <algorithm>
#include <cmath>

#include "calib/core/error.h"

namespace nerfar {

namespace {

constexpr double kInvPi = 1.0 / kPi;

double Pow5(double x) {
  const double x2 = x * x;
  return x2 * x2 * x;
}

double Alpha(double roughness) { return std::max(roughness * roughness, kMinAlpha); }

// Smith G1 for GGX: 2x / (x + sqrt(α² + (1 − α²) x²)), x = cosine to n.
double SmithG1(double alpha, double x) {
  if (x <= 0.0) return 0.0;
  const double a2 = alpha * alpha;
  return 2.0 * x / (x + std::sqrt(a2 + (1.0 - a2) * x * x));
}

Vec3 F0Of(const SgMaterial& m) {
  const double k = 1.0 - m.metallic;
  return Vec3(kDielectricF0, kDielectricF0, kDielectricF0) * k + m.base_color * m.metallic;
}

Vec3 Schlick(const Vec3& f0, double cos_theta) {
  const double w = Pow5(1.0 - std::clamp(cos_theta, 0.0, 1.0));
  return f0 + (Vec3(1, 1, 1) - f0) * w;
}

}  // namespace

std::vector<std::string> SgMaterial::Validate() const {
  std::vector<std::string> problems;
  const auto unit = [](double x) { return std::isfinite(x) && x >= 0.0 && x <= 1.0; };
  if (!unit(base_color.x) || !unit(base_color.y) || !unit(base_color.z))
    problems.push_back("base_color: outside [0, 1] or not finite (linear RGB albedo)");
  if (!unit(roughness)) problems.push_back("roughness: " + std::to_string(roughness) + " (expected in [0, 1])");
  if (!unit(metallic)) problems.push_back("metallic: " + std::to_string(metallic) + " (expected in [0, 1])");
  return problems;
}

double BurleyFactor(double roughness, const Vec3& n, const Vec3& v, const Vec3& l) {
  const double nl = std::clamp(Dot(n, l), 0.0, 1.0), nv = std::clamp(Dot(n, v), 0.0, 1.0);
  const double cos2_d = 0.5 * (1.0 + Dot(l, v));  // (l·h)², h = (l + v)/|l + v|
  const double f90 = 0.5 + 2.0 * roughness * cos2_d;
  return (1.0 + (f90 - 1.0) * Pow5(1.0 - nl)) * (1.0 + (f90 - 1.0) * Pow5(1.0 - nv));
}

Vec3 DisneyBrdf(const SgMaterial& m, const Vec3& n, const Vec3& v, const Vec3& l) {
  const double nl = Dot(n, l), nv = Dot(n, v);
  if (nl <= 0.0 || nv <= 0.0) return {};
  const Vec3 diffuse = m.base_color * ((1.0 - m.metallic) * kInvPi * BurleyFactor(m.roughness, n, v, l));
  const Vec3 h = Normalized(l + v);
  const double alpha = Alpha(m.roughness), a2 = alpha * alpha;
  const double nh = Dot(n, h);
  const double denom = nh * nh * (a2 - 1.0) + 1.0;
  const double d = a2 / (kPi * denom * denom);
  const double g = SmithG1(alpha, nl) * SmithG1(alpha, nv);
  const Vec3 f = Schlick(F0Of(m), Dot(v, h));
  return diffuse + f * (d * g / (4.0 * nl * nv));
}

Sg SpecularLobe(const SgMaterial& m, const Vec3& n, const Vec3& v) {
  const double nv_raw = Dot(n, v);
  if (nv_raw <= 0.0) return {n, 1.0, Vec3()};  // viewed from behind: no specular
  const double nv = std::max(nv_raw, 1e-6);
  const double alpha = Alpha(m.roughness), a2 = alpha * alpha;
  const double lambda_h = 2.0 / a2, mu_h = 1.0 / (kPi * a2);
  const Vec3 r = Normalized(n * (2.0 * nv_raw) - v);
  // At the mirror direction h = n, so n·l = n·v and v·h = n·v.
  const double g = SmithG1(alpha, nv) * SmithG1(alpha, nv);
  const Vec3 f = Schlick(F0Of(m), nv);
  return {r, lambda_h / (4.0 * nv), f * (mu_h * g / (4.0 * nv))};
}

Vec3 ShadeSg(const SgMixture& light, const SgMaterial& m, const Vec3& n, const Vec3& v,
             const std::vector<double>& gamma) {
  NERFAR_CHECK(gamma.empty() || gamma.size() == light.size());
  const Sg spec = SpecularLobe(m, n, v);
  const Vec3 diffuse_albedo = m.base_color * ((1.0 - m.metallic) * kInvPi);
  Vec3 sum;
  for (size_t k = 0; k < light.size(); ++k) {
    const Sg& sg = light[k];
    const double g = gamma.empty() ? 1.0 : gamma[k];
    const double irradiance = UnitIrradiance(Dot(sg.axis, n), sg.sharpness);
    const Vec3 diffuse = diffuse_albedo * (BurleyFactor(m.roughness, n, v, sg.axis) * irradiance);
    const Vec3 specular = spec.amplitude * UnitInnerProduct(sg.axis, sg.sharpness, spec.axis, spec.sharpness);
    sum += sg.amplitude * (diffuse + specular) * g;
  }
  return sum;
}

SgShader::SgShader(const SgMixture& light) {
  NERFAR_CHECK_LE(light.size(), static_cast<size_t>(kMaxSgLobes));
  count_ = static_cast<int>(light.size());
  for (int k = 0; k < count_; ++k) {
    const Sg& sg = light[k];
    px_[k] = static_cast<float>(sg.axis.x);
    py_[k] = static_cast<float>(sg.axis.y);
    pz_[k] = static_cast<float>(sg.axis.z);
    lambda_[k] = static_cast<float>(sg.sharpness);
    mr_[k] = static_cast<float>(sg.amplitude.x);
    mg_[k] = static_cast<float>(sg.amplitude.y);
    mb_[k] = static_cast<float>(sg.amplitude.z);
    irradiance_[k] = PrepareIrradiance(sg.sharpness);
  }
}

Vec3f SgShader::Shade(const SgMaterial& m, const Vec3f& n, const Vec3f& v, const float* gamma) const {
  // Per pixel: the specular lobe (as SpecularLobe, in float).
  const Sg spec = SpecularLobe(m, Vec3(n), Vec3(v));
  const float sx = static_cast<float>(spec.axis.x), sy = static_cast<float>(spec.axis.y),
              sz = static_cast<float>(spec.axis.z), sl = static_cast<float>(spec.sharpness);
  const float nv = std::clamp(Dot(n, v), 0.0f, 1.0f);
  const float rough = static_cast<float>(m.roughness);
  const float view_term = [&] {
    const float w = 1.0f - nv, w5 = w * w * w * w * w;
    return w5;
  }();
  const bool has_diffuse = m.metallic < 1.0;
  float dr = 0, dg = 0, db = 0, sr = 0, sg = 0, sb = 0;
  constexpr float kTwoPiF = 6.28318530717958647692f;
  for (int k = 0; k < count_; ++k) {
    const float g = gamma != nullptr ? gamma[k] : 1.0f;
    if (g <= 0.0f) continue;
    const float wr = mr_[k] * g, wg = mg_[k] * g, wb = mb_[k] * g;
    if (has_diffuse) {
      const float c = px_[k] * n.x + py_[k] * n.y + pz_[k] * n.z;
      const float e = UnitIrradiancePrepared(irradiance_[k], c);
      const float pv = px_[k] * v.x + py_[k] * v.y + pz_[k] * v.z;
      const float f90m1 = 0.5f + rough * (1.0f + pv) - 1.0f;
      const float nl = std::clamp(c, 0.0f, 1.0f), w = 1.0f - nl, w5 = w * w * w * w * w;
      const float burley = (1.0f + f90m1 * w5) * (1.0f + f90m1 * view_term);
      const float s = e * burley;
      dr += wr * s;
      dg += wg * s;
      db += wb * s;
    }
    // ⟨G_k, spec⟩ with unit amplitudes (sg.cpp's MultiplyUnit, in float).
    const float l = lambda_[k];
    const float dx = px_[k] - sx, dy = py_[k] - sy, dz = pz_[k] - sz;
    const float d2 = dx * dx + dy * dy + dz * dz;
    // λ_m ≤ λ_k + λ_s bounds the product's scale by exp(−λ_k λ_s d²/(2(λ_k + λ_s))):
    // below e^{−30} the lobes do not overlap (most lobes for a glossy
    // surface); skip the sqrt and two exps.
    if (l * sl * d2 > 60.0f * (l + sl)) continue;
    const float ux = l * px_[k] + sl * sx, uy = l * py_[k] + sl * sy, uz = l * pz_[k] + sl * sz;
    const float lm = std::sqrt(ux * ux + uy * uy + uz * uz);
    const float log_scale = std::min(0.0f, -l * sl * d2 / (l + sl + lm));
    const float integral = lm > 1e-6f ? -std::expm1(-2.0f * lm) / lm : 2.0f - 2.0f * lm;
    const float s = kTwoPiF * std::exp(log_scale) * integral;
    sr += wr * s;
    sg += wg * s;
    sb += wb * s;
  }
  const float kd = static_cast<float>((1.0 - m.metallic) * kInvPi);
  return {kd * static_cast<float>(m.base_color.x) * dr + static_cast<float>(spec.amplitude.x) * sr,
          kd * static_cast<float>(m.base_color.y) * dg + static_cast<float>(spec.amplitude.y) * sg,
          kd * static_cast<float>(m.base_color.z) * db + static_cast<float>(spec.amplitude.z) * sb};
}

}  // namespace nerfar
