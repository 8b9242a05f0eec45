// Derivation (used for both tables). Put the boundary great circle on the
// equator of a frame whose pole m points into the visible side; a direction v
// has latitude β (visible: β ≥ 0) and longitude ψ, and the lobe axis p has
// latitude θ, its signed distance to the boundary. Then
//   v·p = cos β cos θ cos ψ + sin β sin θ,   dω = cos β dβ dψ,
// and the ψ integral is 2π I0(λ cos β cos θ) (modified Bessel function), so
//   f_h(θ, λ) = 2π ∫_0^{π/2} exp(λ(cos(β − θ) − 1)) I0e(λ cos β cos θ) cos β dβ
// with I0e(x) = e^{−x} I0(x): every exponent ≤ 0. The clamped-cosine
// irradiance is the same integral with m = n and one more factor sin β = v·n.
// For θ ≤ 0 the integrand's mass sits at β = 0, within ~14/sqrt(λ) of it, and
// is smooth there; the θ > 0 side follows from f_h(θ) = ∫_S² − f_h(−θ) (the two
// sides partition the sphere), and the irradiance for p·n = c > 0 from
// E(c) = c·K(λ) + E(−c), K(λ) = ∫ exp(λ(v·p − 1)) (v·p) dv (the lobe's mean
// cosine: ∫ G max(x, 0) = ∫ G x + ∫ G max(−x, 0)).
//
// Tables: rows over log10 λ in [−4, 4] (32 per decade); columns over a
// coordinate scaled by the lobe width w(λ) (all of [−π/2, π/2] for broad lobes,
// ~16/sqrt(λ) in angle for f_h and ~10/sqrt(λ) in cosine for the irradiance
// when sharp), so sharp lobes, whose profiles become one Gaussian shape in these
// units, keep their resolution.
// γ is stored as log γ: across rows (log λ) the occluded side falls like
// e^{−cλ}, which a linear interpolation of γ itself follows only to ~1e-3;
// its logarithm is nearly linear. Linear interpolation in both directions
// keeps γ monotone in S (each row is monotone and the row weights do not
// depend on S).
#include "render/sg/visibility.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <mutex>

#include "calib/core/error.h"

namespace nerfar {

namespace {

constexpr double kHalfPi = 0.5 * kPi;
constexpr double kTwoPi = 2.0 * kPi;
constexpr int kRowsPerDecade = 32;
constexpr double kLogMin = -4.0, kLogMax = 4.0;
constexpr int kRows = static_cast<int>((kLogMax - kLogMin) * kRowsPerDecade) + 1;
constexpr int kGammaHalfColumns = 256;  // columns for t in [0, 1]; the table spans [−1, 1]
constexpr int kGammaColumns = 2 * kGammaHalfColumns + 1;
constexpr int kIrradianceColumns = kIrradianceTableColumns;  // s in [0, 1]
constexpr double kQuadratureSigmas = 14.0;

// e^{−x} I0(x) for x ≥ 0: Abramowitz & Stegun 9.8.1 / 9.8.2 polynomial
// approximations, relative error < 2e-7 (enough for tables read to 1e-4).
double BesselI0Scaled(double x) {
  if (x < 3.75) {
    const double t = (x / 3.75) * (x / 3.75);
    const double i0 =
        1.0 + t * (3.5156229 + t * (3.0899424 + t * (1.2067492 + t * (0.2659732 + t * (0.0360768 + t * 0.0045813)))));
    return i0 * std::exp(-x);
  }
  const double u = 3.75 / x;
  const double poly =
      0.39894228 +
      u * (0.01328592 +
           u * (0.00225319 +
                u * (-0.00157565 +
                     u * (0.00916281 + u * (-0.02057706 + u * (0.02635537 + u * (-0.01647633 + u * 0.00392377)))))));
  return poly / std::sqrt(x);
}

// 16-point Gauss-Legendre nodes and weights on [−1, 1] (Newton on P_16).
struct GaussLegendre16 {
  std::array<double, 16> x{}, w{};
  GaussLegendre16() {
    const int n = 16;
    for (int i = 0; i < n; ++i) {
      double z = std::cos(kPi * (i + 0.75) / (n + 0.5));
      double dp = 1.0;
      for (int iter = 0; iter < 100; ++iter) {
        double p0 = 1.0, p1 = 0.0;
        for (int j = 1; j <= n; ++j) {
          const double p2 = p1;
          p1 = p0;
          p0 = ((2.0 * j - 1.0) * z * p1 - (j - 1.0) * p2) / j;
        }
        dp = n * (z * p0 - p1) / (z * z - 1.0);
        const double dz = p0 / dp;
        z -= dz;
        if (std::abs(dz) < 1e-15) break;
      }
      x[i] = z;
      w[i] = 2.0 / ((1.0 - z * z) * dp * dp);
    }
  }
};

const GaussLegendre16& Gl16() {
  static const GaussLegendre16 gl;
  return gl;
}

// Integrates the occluded side for every θ ≤ 0 of one row at once:
// 2π ∫_0^{π/2} exp(λ(cos(β−θ)−1)) I0e(λ cos β cos θ) cos β (sin β)^k dβ, k = 0
// (f_h) or 1 (irradiance). For θ ≤ 0 the integrand's mass lies in
// [0, 14/sqrt(λ)] whatever θ is (exp(−98) beyond), so one set of nodes serves
// the row: composite 16-point Gauss-Legendre on 6 panels. The exponent is
// formed as λ(cos β cos θ + sin β sin θ − 1): its rounding error is ~1e-16·λ
// absolute, i.e. ≤ 1e-12 relative for λ ≤ 1e4.
class OccludedSideRule {
 public:
  explicit OccludedSideRule(double sharpness) : lambda_(sharpness) {
    const double hi = sharpness > 1.0 ? std::min(kHalfPi, kQuadratureSigmas / std::sqrt(sharpness)) : kHalfPi;
    const GaussLegendre16& gl = Gl16();
    const int panels = 6;
    const double h = hi / panels;
    for (int panel = 0; panel < panels; ++panel)
      for (int i = 0; i < 16; ++i) {
        const double beta = panel * h + 0.5 * h * (gl.x[i] + 1.0);
        cos_.push_back(std::cos(beta));
        sin_.push_back(std::sin(beta));
        weight_.push_back(0.5 * h * gl.w[i] * std::cos(beta));
      }
  }
  double operator()(double theta, bool cosine_weighted) const {
    theta = std::clamp(theta, -kHalfPi, 0.0);
    const double ct = std::cos(theta), st = std::sin(theta);
    double sum = 0.0;
    for (size_t q = 0; q < cos_.size(); ++q) {
      const double exponent = std::min(0.0, lambda_ * (cos_[q] * ct + sin_[q] * st - 1.0));
      double f = weight_[q] * std::exp(exponent) * BesselI0Scaled(lambda_ * cos_[q] * ct);
      if (cosine_weighted) f *= sin_[q];
      sum += f;
    }
    return kTwoPi * sum;
  }

 private:
  double lambda_;
  std::vector<double> cos_, sin_, weight_;
};

double OccludedSideIntegral(double theta, double sharpness, bool cosine_weighted) {
  return OccludedSideRule(sharpness)(theta, cosine_weighted);
}

double RowSharpness(int row) { return std::pow(10.0, kLogMin + static_cast<double>(row) / kRowsPerDecade); }
// The covered range: all of it for broad lobes, ~10-16σ (σ = 1/sqrt(λ)) for
// sharp ones, where the rest is within 1e-20 of saturation. Written as
// w_0/(1 + (λ/100)^4)^{1/8}: smooth in λ (a kink would break the interpolation
// between rows), flat to fourth order for broad lobes (clamping |θ| > w costs
// O((w_0 − w)²) there), and w_0·10/sqrt(λ) for sharp ones.
double WidthFactor(double sharpness) {
  const double x = sharpness / 100.0;
  return 1.0 / std::pow(1.0 + x * x * x * x, 0.125);
}
double GammaWidth(double sharpness) { return kHalfPi * WidthFactor(sharpness); }
double IrradianceWidth(double sharpness) { return WidthFactor(sharpness); }

// Scale of the irradiance correction term: it shrinks like the lobe width.
double IrradianceScale(double sharpness) { return SgUnitIntegral(sharpness) / std::sqrt(1.0 + sharpness); }

// K(λ) = ∫ exp(λ(v·p − 1)) (v·p) dv = 2π e^{−λ}·2(λ cosh λ − sinh λ)/λ².
double MeanCosineIntegral(double sharpness) {
  const double l = sharpness;
  if (l < 0.1) {
    // λ cosh λ − sinh λ = λ³/3 + λ⁵/30 + λ⁷/840 + …; truncation < 1e-12 relative.
    return kTwoPi * std::exp(-l) * 2.0 * (l / 3.0 + l * l * l / 30.0 + l * l * l * l * l / 840.0);
  }
  const double e = std::exp(-2.0 * l);
  return kTwoPi * ((1.0 + e) / l - (1.0 - e) / (l * l));
}

struct Tables {
  std::vector<float> log_gamma;       // kRows × kGammaColumns: log(f_h(θ)/f_h(π/2)), t = θ/w ∈ [−1, 1]
  std::vector<float> log_irradiance;  // kRows × kIrradianceColumns: log(E(−a)/scale), s = a/w ∈ [0, 1]

  Tables()
      : log_gamma(static_cast<size_t>(kRows) * kGammaColumns),
        log_irradiance(static_cast<size_t>(kRows) * kIrradianceColumns),
        built(kRows) {}

  // Rows are built on first use (a frame's lobes touch a few dozen of the 257
  // rows; 2 ms each), once, by the same arithmetic whichever thread asks, so
  // results do not depend on threads or call order.
  void Ensure(int r) {
    std::call_once(built[r].flag, [this, r] { BuildRow(r); });
  }

  struct OnceFlag {
    std::once_flag flag;
  };
  std::vector<OnceFlag> built;

  void BuildRow(int r) {
    const double l = RowSharpness(r);
    const OccludedSideRule rule(l);
    const double hemisphere = HemisphereIntegral(l), whole = SgUnitIntegral(l);
    const double width = GammaWidth(l);
    float* g = &log_gamma[static_cast<size_t>(r) * kGammaColumns];
    std::vector<double> ratio(kGammaColumns);
    for (int j = 0; j <= kGammaHalfColumns; ++j) {
      const double theta = -width * (1.0 - static_cast<double>(j) / kGammaHalfColumns);
      const double occluded = rule(theta, false);
      ratio[j] = occluded / hemisphere;
      ratio[kGammaColumns - 1 - j] = (whole - occluded) / hemisphere;
    }
    ratio[kGammaColumns - 1] = 1.0;  // θ = w: the hemisphere (exactly) or within 1e-15 of it
    double running = 0.0;
    for (int j = 0; j < kGammaColumns; ++j) {
      running = std::max(running, std::clamp(ratio[j], 1e-30, 1.0));  // monotone despite rounding
      g[j] = static_cast<float>(std::log(running));
    }
    g[kGammaColumns - 1] = 0.0f;
    const double iwidth = IrradianceWidth(l), scale = IrradianceScale(l);
    float* e = &log_irradiance[static_cast<size_t>(r) * kIrradianceColumns];
    for (int j = 0; j < kIrradianceColumns; ++j) {
      const double a = iwidth * static_cast<double>(j) / (kIrradianceColumns - 1);
      e[j] = static_cast<float>(std::log(std::max(1e-30, rule(-std::asin(std::min(1.0, a)), true) / scale)));
    }
  }
};

Tables& GetTables() {
  static Tables tables;
  return tables;
}

// Rows are log-spaced, but the weight between two rows is linear in λ: at a
// fixed table coordinate the stored logarithms are close to linear in λ
// (e^{−cλ} tails, and first order in λ for broad lobes), far less so in log λ.
void RowOf(double sharpness, SgTableRow& row) {
  const double x = (std::log10(std::max(sharpness, 1e-300)) - kLogMin) * kRowsPerDecade;
  const double clamped = std::clamp(x, 0.0, static_cast<double>(kRows - 1));
  row.row = std::min(static_cast<int>(clamped), kRows - 2);
  const double l0 = RowSharpness(row.row), l1 = RowSharpness(row.row + 1);
  row.frac = static_cast<float>(std::clamp((sharpness - l0) / (l1 - l0), 0.0, 1.0));
  GetTables().Ensure(row.row);
  GetTables().Ensure(row.row + 1);
}

float Interpolate(const float* table, int columns, const SgTableRow& row, float coordinate) {
  // coordinate in [0, columns − 1]
  const float c = std::clamp(coordinate, 0.0f, static_cast<float>(columns - 1));
  const int j = std::min(static_cast<int>(c), columns - 2);
  const float fj = c - static_cast<float>(j);
  const float* a = table + static_cast<size_t>(row.row) * columns + j;
  const float* b = a + columns;
  const float va = a[0] + fj * (a[1] - a[0]);
  const float vb = b[0] + fj * (b[1] - b[0]);
  return va + row.frac * (vb - va);
}

}  // namespace

double HemisphereIntegral(double sharpness) {
  if (sharpness < 1e-8) return kTwoPi * (1.0 - 0.5 * sharpness);
  return kTwoPi * -std::expm1(-sharpness) / sharpness;
}

double HalfSpaceIntegralQuadrature(double theta_rad, double sharpness) {
  const double theta = std::clamp(theta_rad, -kHalfPi, kHalfPi);
  if (theta <= 0.0) return OccludedSideIntegral(theta, sharpness, false);
  return SgUnitIntegral(sharpness) - OccludedSideIntegral(-theta, sharpness, false);
}

double UnitIrradianceQuadrature(double cos_axis_normal, double sharpness) {
  const double c = std::clamp(cos_axis_normal, -1.0, 1.0);
  const double below = OccludedSideIntegral(-std::asin(std::abs(c)), sharpness, true);
  return c > 0.0 ? c * MeanCosineIntegral(sharpness) + below : below;
}

SgTableRow PrepareGamma(double sharpness) {
  SgTableRow row;
  RowOf(sharpness, row);
  row.inv_width = static_cast<float>(kGammaHalfColumns / GammaWidth(std::max(sharpness, 1e-300)));
  row.scale = 1.0f;
  return row;
}

float GammaPrepared(const SgTableRow& row, float ssd_rad) {
  if (!(ssd_rad < 1.5707963f)) return 1.0f;  // nothing in the way (also NaN-safe: treated as visible)
  const float log_g =
      Interpolate(GetTables().log_gamma.data(), kGammaColumns, row, kGammaHalfColumns + ssd_rad * row.inv_width);
  return std::clamp(std::exp(log_g), 0.0f, 1.0f);
}

SgTableRow PrepareIrradiance(double sharpness) {
  SgTableRow row;
  RowOf(sharpness, row);
  const double l = std::max(sharpness, 0.0);
  row.inv_width = static_cast<float>((kIrradianceColumns - 1) / IrradianceWidth(std::max(l, 1e-300)));
  row.scale = static_cast<float>(IrradianceScale(l));
  row.cosine_slope = static_cast<float>(MeanCosineIntegral(l));
  return row;
}

float UnitIrradiancePrepared(const SgTableRow& row, float cos_axis_normal) {
  const float below = row.scale * std::exp(Interpolate(GetTables().log_irradiance.data(), kIrradianceColumns, row,
                                                       std::abs(cos_axis_normal) * row.inv_width));
  return cos_axis_normal > 0.0f ? cos_axis_normal * row.cosine_slope + below : below;
}

void BlendedIrradianceRow(const SgTableRow& row, float* out) {
  const float* a = GetTables().log_irradiance.data() + static_cast<size_t>(row.row) * kIrradianceColumns;
  const float* b = a + kIrradianceColumns;
  for (int j = 0; j < kIrradianceColumns; ++j) out[j] = a[j] + row.frac * (b[j] - a[j]);
}

double HalfSpaceIntegral(double theta_rad, double sharpness) {
  return SelfShadowGamma(theta_rad, sharpness) * HemisphereIntegral(sharpness);
}

double SelfShadowGamma(double ssd_rad, double sharpness) {
  return GammaPrepared(PrepareGamma(sharpness), static_cast<float>(ssd_rad));
}

double UnitIrradiance(double cos_axis_normal, double sharpness) {
  return UnitIrradiancePrepared(PrepareIrradiance(sharpness), static_cast<float>(cos_axis_normal));
}

Vec3 Irradiance(const SgMixture& light, const Vec3& normal) {
  Vec3 sum;
  for (const Sg& sg : light) sum += sg.amplitude * UnitIrradiance(Dot(sg.axis, normal), sg.sharpness);
  return sum;
}

SgMixture CosineWeightedLight(const SgMixture& light, const Vec3& normal) {
  const Sg cosine = CosineLobe(normal);
  SgMixture out;
  out.reserve(light.size());
  for (const Sg& sg : light) out.push_back(Product(sg, cosine));
  return out;
}

PreparedShadowLobe PrepareShadowLobe(const Sg& sg) {
  PreparedShadowLobe p;
  p.axis = sg.axis;
  p.luminance = LuminanceOf(sg.amplitude);
  if (!(p.luminance > 0.0)) return p;
  p.weight = p.luminance * HemisphereIntegral(sg.sharpness);
  p.row = PrepareGamma(sg.sharpness);
  return p;
}

void PrepareShadowLobes(const SgMixture& cosine_weighted, std::vector<PreparedShadowLobe>& out) {
  out.resize(cosine_weighted.size());
  for (size_t k = 0; k < cosine_weighted.size(); ++k) out[k] = PrepareShadowLobe(cosine_weighted[k]);
}

LobeShadow ShadowOfLobePrepared(const PreparedShadowLobe& lobe, const Vec3& normal, double ssd_rad) {
  if (!(lobe.luminance > 0.0)) return {};
  const double horizon = std::asin(std::clamp(Dot(lobe.axis, normal), -1.0, 1.0));
  const double up = GammaPrepared(lobe.row, static_cast<float>(horizon));
  const double seen = ssd_rad < horizon ? GammaPrepared(lobe.row, static_cast<float>(ssd_rad)) : up;
  return {lobe.weight * up, lobe.weight * seen};
}

LobeShadow ShadowOfLobe(const Sg& sg, const Vec3& normal, double ssd_rad) {
  return ShadowOfLobePrepared(PrepareShadowLobe(sg), normal, ssd_rad);
}

double ShadowRatioPrepared(const std::vector<PreparedShadowLobe>& lobes, const Vec3& normal,
                           const std::vector<double>& ssd_rad) {
  NERFAR_CHECK_EQ(lobes.size(), ssd_rad.size());
  double visible = 0.0, total = 0.0;
  for (size_t k = 0; k < lobes.size(); ++k) {
    const LobeShadow lobe = ShadowOfLobePrepared(lobes[k], normal, ssd_rad[k]);
    total += lobe.total;
    visible += lobe.visible;
  }
  if (!(total > 0.0)) return 1.0;
  return std::clamp(visible / total, 0.0, 1.0);
}

double ShadowRatio(const SgMixture& cosine_weighted, const Vec3& normal, const std::vector<double>& ssd_rad) {
  std::vector<PreparedShadowLobe> lobes;
  PrepareShadowLobes(cosine_weighted, lobes);
  return ShadowRatioPrepared(lobes, normal, ssd_rad);
}

}  // namespace nerfar
