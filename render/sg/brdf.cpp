#include "render/sg/brdf.h"

#include <algorithm>
#include <cmath>

#include "calib/core/error.h"
#include "render/sg/fast_exp.h"

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

// The per-view part of SpecularLobes, in T = double (reference) or float
// (per pixel): the mirror direction, the sharpness per unit b_j (1/α²)/(4 n·v)
// and the amplitude per unit c_j F·G/(4 n·v πα²) (RGB). False from behind.
template <class T>
struct SpecularView {
  T rx = 0, ry = 0, rz = 1;           // mirror direction
  T sharpness_unit = 1;               // × b_j: lobe j's sharpness
  T amp_r = 0, amp_g = 0, amp_b = 0;  // × c_j: lobe j's amplitude
};
template <class T>
SpecularView<T> MakeSpecularView(T f0r, T f0g, T f0b, T roughness, T nx, T ny, T nz, T vx, T vy, T vz) {
  SpecularView<T> out;
  const T nv_raw = nx * vx + ny * vy + nz * vz;
  if (!(nv_raw > T(0))) {
    out.rx = nx, out.ry = ny, out.rz = nz;
    return out;
  }
  const T nv = std::max(nv_raw, T(1e-6));
  const T alpha = std::max(roughness * roughness, T(kMinAlpha)), a2 = alpha * alpha;
  const T rx = T(2) * nv_raw * nx - vx, ry = T(2) * nv_raw * ny - vy, rz = T(2) * nv_raw * nz - vz;
  const T inv_len = T(1) / std::sqrt(rx * rx + ry * ry + rz * rz);
  out.rx = rx * inv_len, out.ry = ry * inv_len, out.rz = rz * inv_len;
  // Smith G1 at n·l = n·v, squared; Schlick at v·h = n·v.
  const T g1 = T(2) * nv / (nv + std::sqrt(a2 + (T(1) - a2) * nv * nv));
  const T w = T(1) - std::min(nv, T(1)), w2 = w * w, w5 = w2 * w2 * w;
  const T common = g1 * g1 / (T(4) * nv * T(kPi) * a2);
  out.amp_r = (f0r + (T(1) - f0r) * w5) * common;
  out.amp_g = (f0g + (T(1) - f0g) * w5) * common;
  out.amp_b = (f0b + (T(1) - f0b) * w5) * common;
  out.sharpness_unit = T(1) / (a2 * T(4) * nv);
  return out;
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

std::array<Sg, kNdfLobes> SpecularLobes(const SgMaterial& m, const Vec3& n, const Vec3& v) {
  const Vec3 f0 = F0Of(m);
  const SpecularView<double> s = MakeSpecularView<double>(f0.x, f0.y, f0.z, m.roughness, n.x, n.y, n.z, v.x, v.y, v.z);
  std::array<Sg, kNdfLobes> lobes;
  for (int j = 0; j < kNdfLobes; ++j)
    lobes[j] = {Vec3(s.rx, s.ry, s.rz), kNdfSharpness[j] * s.sharpness_unit,
                Vec3(s.amp_r, s.amp_g, s.amp_b) * kNdfWeight[j]};
  return lobes;
}

Vec3 ShadeSg(const SgMixture& light, const SgMaterial& m, const Vec3& n, const Vec3& v,
             const std::vector<double>& gamma) {
  NERFAR_CHECK(gamma.empty() || gamma.size() == light.size());
  const std::array<Sg, kNdfLobes> spec = SpecularLobes(m, n, v);
  const Vec3 diffuse_albedo = m.base_color * ((1.0 - m.metallic) * kInvPi);
  Vec3 sum;
  for (size_t k = 0; k < light.size(); ++k) {
    const Sg& sg = light[k];
    const double g = gamma.empty() ? 1.0 : gamma[k];
    const double irradiance = UnitIrradiance(Dot(sg.axis, n), sg.sharpness);
    Vec3 term = diffuse_albedo * (BurleyFactor(m.roughness, n, v, sg.axis) * irradiance);
    for (const Sg& s : spec) term += s.amplitude * UnitInnerProduct(sg.axis, sg.sharpness, s.axis, s.sharpness);
    sum += sg.amplitude * term * g;
  }
  return sum;
}

SgShader::SgShader(const SgMixture& light) {
  NERFAR_CHECK_LE(light.size(), static_cast<size_t>(kMaxSgLobes));
  count_ = static_cast<int>(light.size());
  padded_ = (count_ + kSgLanes - 1) / kSgLanes * kSgLanes;
  rows_.assign(static_cast<size_t>(std::max(padded_, 1)) * kIrradianceTableColumns, 0.0f);
  for (int k = 0; k < padded_; ++k) {
    // Padded lobes: zero amplitude and finite everything else, so they add 0.
    const Sg sg = k < count_ ? light[k] : Sg{Vec3(0, 0, 1), 1.0, Vec3()};
    px_[k] = static_cast<float>(sg.axis.x);
    py_[k] = static_cast<float>(sg.axis.y);
    pz_[k] = static_cast<float>(sg.axis.z);
    lambda_[k] = static_cast<float>(sg.sharpness);
    mr_[k] = static_cast<float>(sg.amplitude.x);
    mg_[k] = static_cast<float>(sg.amplitude.y);
    mb_[k] = static_cast<float>(sg.amplitude.z);
    const SgTableRow row = PrepareIrradiance(sg.sharpness);
    inv_width_[k] = row.inv_width;
    scale_[k] = k < count_ ? row.scale : 0.0f;
    slope_[k] = k < count_ ? row.cosine_slope : 0.0f;
    BlendedIrradianceRow(row, &rows_[static_cast<size_t>(k) * kIrradianceTableColumns]);
  }
}

namespace {

// The per-lobe loops of SgShader::Shade. Each loop body is straight-line
// float arithmetic over structure-of-arrays inputs (FastExp, selects, one
// table read pair), which the compiler vectorises over lobes; the sums use
// `omp simd` reductions (-fopenmp-simd: the order of the float sum is the
// vector lanes', fixed for a given build and CPU). Compiled twice and picked
// once per process: AVX2 + FMA (8 lobes per instruction) where the CPU has
// them, the build's baseline (x86-64: SSE2, 4 lobes) otherwise.
struct LobeArrays {
  const float* px;
  const float* py;
  const float* pz;
  const float* lambda;
  const float* mr;
  const float* mg;
  const float* mb;
  const float* inv_width;
  const float* scale;
  const float* slope;
  const float* rows;
  int count;  // a multiple of kSgLanes
};
struct PixelTerms {
  float nx, ny, nz, vx, vy, vz;
  float rough, view_term;  // roughness; (1 − n·v)⁵ of Burley's factor
  bool diffuse;            // metallic < 1
  float sx, sy, sz;        // mirror direction
  float sl[kNdfLobes];     // specular lobes' sharpness
  const float* gamma;      // count factors
};
// out: diffuse RGB sums (Σ μ_k γ_k E_k Burley_k) then specular RGB sums per NDF lobe.
constexpr int kSums = 3 + 3 * kNdfLobes;

// ⟨G_k, S⟩ / 2π with unit amplitudes (sg.cpp's UnitInnerProduct, in float):
// exp(−λ_k λ_s |p_k − s|²/(λ_k + λ_s + λ_m)) (1 − e^{−2λ_m})/λ_m, one
// division for both quotients. (1 − e^{−2x})/x: FastExp above x = 1/64 (its
// absolute error ~3e-7 over x: ≤ 2e-5 relative), the series
// 2 − 2x + 4x²/3 − 2x³/3 below (truncation ≤ 1e-8). Terms below e^{−60}
// (9e-27 of the lobe's scale) are dropped: the products they enter would
// otherwise reach subnormal floats, ~100 cycles each.
constexpr float kCut = -60.0f;
// MinC/MaxC(c, x): min/max against a constant, by value, in the operand
// order of the x86 min/max instructions (x unordered → c), so they compile
// to one instruction instead of a NaN-preserving compare and blend.
[[gnu::always_inline]] inline float MinC(float c, float x) { return x < c ? x : c; }
[[gnu::always_inline]] inline float MaxC(float c, float x) { return c < x ? x : c; }
[[gnu::always_inline]] inline int MinC(int c, int x) { return x < c ? x : c; }
[[gnu::always_inline]] inline float UnitInnerProductF(float l, float sl, float d2, float ps) {
  const float lm = std::sqrt(MaxC(0.0f, l * l + sl * sl + 2.0f * l * sl * ps));
  const float lm_safe = MaxC(1.0f / 64.0f, lm);
  const float sum = l + sl + lm;
  const float inv = 1.0f / (sum * lm_safe);
  const float log_scale = MinC(0.0f, -l * sl * d2 * lm_safe * inv);
  const float big = (1.0f - FastExp(-2.0f * lm_safe)) * sum * inv;
  const float small = 2.0f + lm * (-2.0f + lm * (4.0f / 3.0f - lm * (2.0f / 3.0f)));
  return FastExpCut(log_scale, kCut) * (lm > 1.0f / 64.0f ? big : small);
}

// The lobe loops: the diffuse one (skipped for metals), then one per
// specular lobe. Separate loops keep each body's live values within the 16
// vector registers (one fused loop spilled a third of its instructions).
[[gnu::always_inline]] inline void ShadeLobesBody(const LobeArrays& a, const PixelTerms& t, float* out) {
  const int count = a.count;
  const float* __restrict px = a.px;
  const float* __restrict py = a.py;
  const float* __restrict pz = a.pz;
  const float* __restrict mr = a.mr;
  const float* __restrict mg = a.mg;
  const float* __restrict mb = a.mb;
  const float* __restrict g = t.gamma;
  for (int c = 0; c < kSums; ++c) out[c] = 0.0f;
  if (t.diffuse) {
    const float* __restrict inv_width = a.inv_width;
    const float* __restrict scale = a.scale;
    const float* __restrict slope = a.slope;
    const float* __restrict rows = a.rows;
    const float nx = t.nx, ny = t.ny, nz = t.nz, vx = t.vx, vy = t.vy, vz = t.vz;
    const float rough = t.rough, view_term = t.view_term;
    constexpr int kLast = kIrradianceTableColumns - 1;
    float dr = 0, dg = 0, db = 0;
#pragma omp simd reduction(+ : dr, dg, db)
    for (int k = 0; k < count; ++k) {
      // Exact clamped-cosine irradiance of the lobe (its table row, FastExp).
      const float c = px[k] * nx + py[k] * ny + pz[k] * nz;
      const float x = MinC(static_cast<float>(kLast), std::abs(c) * inv_width[k]);
      const int j = MinC(kLast - 1, static_cast<int>(x));
      const float f = x - static_cast<float>(j);
      const int at = k * kIrradianceTableColumns + j;
      const float lo = rows[at], hi = rows[at + 1];
      const float e = MaxC(0.0f, c) * slope[k] + scale[k] * FastExpCut(lo + f * (hi - lo), kCut);
      // Burley's factor with l = the lobe axis.
      const float pv = px[k] * vx + py[k] * vy + pz[k] * vz;
      const float f90m1 = rough * (1.0f + pv) - 0.5f;
      const float nl = MinC(1.0f, MaxC(0.0f, c)), w = 1.0f - nl, w2 = w * w, w5 = w2 * w2 * w;
      const float weight = g[k] * e * (1.0f + f90m1 * w5) * (1.0f + f90m1 * view_term);
      dr += mr[k] * weight;
      dg += mg[k] * weight;
      db += mb[k] * weight;
    }
    out[0] = dr, out[1] = dg, out[2] = db;
  }
  const float* __restrict lambda = a.lambda;
  const float sx = t.sx, sy = t.sy, sz = t.sz;
  constexpr float kTwoPiF = 6.28318530717958647692f;
  for (int s = 0; s < kNdfLobes; ++s) {
    const float sl = t.sl[s];
    float sr = 0, sg = 0, sb = 0;
#pragma omp simd reduction(+ : sr, sg, sb)
    for (int k = 0; k < count; ++k) {
      // |p − s|² from the difference (2 − 2p·s loses digits for close axes).
      const float dx = px[k] - sx, dy = py[k] - sy, dz = pz[k] - sz;
      const float d2 = dx * dx + dy * dy + dz * dz;
      const float weight = g[k] * kTwoPiF * UnitInnerProductF(lambda[k], sl, d2, 1.0f - 0.5f * d2);
      sr += mr[k] * weight;
      sg += mg[k] * weight;
      sb += mb[k] * weight;
    }
    out[3 + 3 * s] = sr, out[4 + 3 * s] = sg, out[5 + 3 * s] = sb;
  }
}

void ShadeLobesBaseline(const LobeArrays& a, const PixelTerms& t, float* out) { ShadeLobesBody(a, t, out); }

using ShadeLobesFn = void (*)(const LobeArrays&, const PixelTerms&, float*);
#if defined(__x86_64__) && defined(__GNUC__)
[[gnu::target("avx2,fma")]] void ShadeLobesAvx2(const LobeArrays& a, const PixelTerms& t, float* out) {
  ShadeLobesBody(a, t, out);
}
ShadeLobesFn PickShadeLobes() {
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") ? ShadeLobesAvx2 : ShadeLobesBaseline;
}
#else
ShadeLobesFn PickShadeLobes() { return ShadeLobesBaseline; }
#endif
const ShadeLobesFn kShadeLobes = PickShadeLobes();

}  // namespace

Vec3f SgShader::Shade(const SgMaterial& m, const Vec3f& n, const Vec3f& v, const float* gamma) const {
  const float metallic = static_cast<float>(m.metallic);
  const float f0r = kDielectricF0 + (static_cast<float>(m.base_color.x) - float(kDielectricF0)) * metallic;
  const float f0g = kDielectricF0 + (static_cast<float>(m.base_color.y) - float(kDielectricF0)) * metallic;
  const float f0b = kDielectricF0 + (static_cast<float>(m.base_color.z) - float(kDielectricF0)) * metallic;
  const float rough = static_cast<float>(m.roughness);
  const SpecularView<float> view = MakeSpecularView<float>(f0r, f0g, f0b, rough, n.x, n.y, n.z, v.x, v.y, v.z);

  alignas(64) float g[kMaxSgLobes];
  std::fill(g, g + padded_, 1.0f);
  if (gamma != nullptr) std::copy(gamma, gamma + count_, g);

  const float nv = std::clamp(Dot(n, v), 0.0f, 1.0f), wv = 1.0f - nv;
  PixelTerms terms{n.x,     n.y,     n.z,     v.x, v.y, v.z, rough, wv * wv * wv * wv * wv, m.metallic < 1.0,
                   view.rx, view.ry, view.rz, {},  g};
  for (int j = 0; j < kNdfLobes; ++j) terms.sl[j] = static_cast<float>(kNdfSharpness[j]) * view.sharpness_unit;
  const LobeArrays arrays{px_, py_, pz_, lambda_, mr_, mg_, mb_, inv_width_, scale_, slope_, rows_.data(), padded_};
  float sums[kSums];
  kShadeLobes(arrays, terms, sums);

  const float kd = static_cast<float>((1.0 - m.metallic) * kInvPi);
  Vec3f out(kd * static_cast<float>(m.base_color.x) * sums[0], kd * static_cast<float>(m.base_color.y) * sums[1],
            kd * static_cast<float>(m.base_color.z) * sums[2]);
  for (int j = 0; j < kNdfLobes; ++j) {
    const float c = static_cast<float>(kNdfWeight[j]);
    out.x += c * view.amp_r * sums[3 + 3 * j];
    out.y += c * view.amp_g * sums[4 + 3 * j];
    out.z += c * view.amp_b * sums[5 + 3 * j];
  }
  return out;
}

}  // namespace nerfar
