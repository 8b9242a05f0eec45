#include "render/sg/brdf.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <string>

#include "calib/core/error.h"
#include "render/sg/fast_exp.h"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

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
[[gnu::always_inline]] inline SpecularView<T> MakeSpecularView(T f0r, T f0g, T f0b, T roughness, T nx, T ny, T nz, T vx,
                                                               T vy, T vz) {
  // Branch-free (selects only), so that a loop over pixels vectorises.
  SpecularView<T> out;
  const T nv_raw = nx * vx + ny * vy + nz * vz;
  const bool front = nv_raw > T(0);
  const T nv = std::max(nv_raw, T(1e-6));
  const T alpha = std::max(roughness * roughness, T(kMinAlpha)), a2 = alpha * alpha;
  const T rx = T(2) * nv_raw * nx - vx, ry = T(2) * nv_raw * ny - vy, rz = T(2) * nv_raw * nz - vz;
  const T inv_len = T(1) / std::sqrt(rx * rx + ry * ry + rz * rz);
  out.rx = front ? rx * inv_len : nx, out.ry = front ? ry * inv_len : ny, out.rz = front ? rz * inv_len : nz;
  // Smith G1 at n·l = n·v, squared; Schlick at v·h = n·v.
  const T g1 = T(2) * nv / (nv + std::sqrt(a2 + (T(1) - a2) * nv * nv));
  const T w = T(1) - std::min(nv, T(1)), w2 = w * w, w5 = w2 * w2 * w;
  const T common = front ? g1 * g1 / (T(4) * nv * T(kPi) * a2) : T(0);
  out.amp_r = (f0r + (T(1) - f0r) * w5) * common;
  out.amp_g = (f0g + (T(1) - f0g) * w5) * common;
  out.amp_b = (f0b + (T(1) - f0b) * w5) * common;
  out.sharpness_unit = front ? T(1) / (a2 * T(4) * nv) : T(1);
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
  return diffuse + DisneySpecularBrdf(m, n, v, l);
}

Vec3 DisneySpecularBrdf(const SgMaterial& m, const Vec3& n, const Vec3& v, const Vec3& l) {
  const double nl = Dot(n, l), nv = Dot(n, v);
  if (nl <= 0.0 || nv <= 0.0) return {};
  const Vec3 h = Normalized(l + v);
  const double alpha = Alpha(m.roughness), a2 = alpha * alpha;
  const double nh = Dot(n, h);
  const double denom = nh * nh * (a2 - 1.0) + 1.0;
  const double d = a2 / (kPi * denom * denom);
  const double g = SmithG1(alpha, nl) * SmithG1(alpha, nv);
  const Vec3 f = Schlick(F0Of(m), Dot(v, h));
  return f * (d * g / (4.0 * nl * nv));
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
  const float big = (1.0f - FastExpNonPositive(-2.0f * lm_safe)) * sum * inv;
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

// ---- Many pixels per call: lanes are pixels, the loop runs over lobes.
// One block is kPixelLanes pixels; per-pixel inputs and the sums are lane
// arrays, per-lobe values scalars (broadcast). Each lobe's arithmetic is the
// same as above (UnitInnerProductF, the table read, Burley's factor); there
// are no horizontal sums, and the lobes' bodies are independent, so they
// overlap in the pipeline.

constexpr int kPixelLanes = 16;
struct PixelBlock {
  alignas(64) float nx[kPixelLanes], ny[kPixelLanes], nz[kPixelLanes];
  alignas(64) float vx[kPixelLanes], vy[kPixelLanes], vz[kPixelLanes];
  alignas(64) float rough[kPixelLanes], view_term[kPixelLanes];
  alignas(64) float sx[kPixelLanes], sy[kPixelLanes], sz[kPixelLanes];  // mirror direction
  alignas(64) float sl0[kPixelLanes], sl1[kPixelLanes];                 // specular lobes' sharpness
  alignas(64) float gamma[kMaxSgLobes * kPixelLanes];                   // lobe-major: [k][lane]
};
// Sums per lane: diffuse RGB (Σ μ γ E Burley), specular RGB (Σ μ γ Σ_j 2π c_j ⟨G, S_j⟩).
struct BlockSums {
  alignas(64) float dr[kPixelLanes], dg[kPixelLanes], db[kPixelLanes];
  alignas(64) float sr[kPixelLanes], sg[kPixelLanes], sb[kPixelLanes];
};
// The table reads of one block (lo = rows[at], hi = rows[at + 1] per lane):
// a hardware gather where the kernel's instruction set has one (the
// compiler's generic tuning emulates gathers with scalar inserts).
struct GatherScalar {
  [[gnu::always_inline]] static inline void Run(const float* rows, const int* at, float* lo, float* hi) {
    for (int i = 0; i < kPixelLanes; ++i) lo[i] = rows[at[i]], hi[i] = rows[at[i] + 1];
  }
};

// kVisibility (with kSpecular): sr sums Σ γ Y(μ) ⟨G, spec⟩ and sg the same
// with γ = 1 (Y: luminance), sb is 0.
template <bool kDiffuse, bool kSpecular, class Gather, bool kVisibility = false>
[[gnu::always_inline]] inline void ShadeBlockBody(const LobeArrays& a, const PixelBlock& b, BlockSums* out) {
  constexpr int kLast = kIrradianceTableColumns - 1;
  constexpr float kTwoPiF = 6.28318530717958647692f;
  const float c0 = kTwoPiF * static_cast<float>(kNdfWeight[0]), c1 = kTwoPiF * static_cast<float>(kNdfWeight[1]);
  float* __restrict dr = out->dr;
  float* __restrict dg = out->dg;
  float* __restrict db = out->db;
  float* __restrict sr = out->sr;
  float* __restrict sg = out->sg;
  float* __restrict sb = out->sb;
  for (int i = 0; i < kPixelLanes; ++i) dr[i] = dg[i] = db[i] = sr[i] = sg[i] = sb[i] = 0.0f;
  alignas(64) float cos_n[kPixelLanes], frac[kPixelLanes], lo[kPixelLanes], hi[kPixelLanes];
  alignas(64) int at[kPixelLanes];
  for (int k = 0; k < a.count; ++k) {
    const float px = a.px[k], py = a.py[k], pz = a.pz[k], lambda = a.lambda[k];
    const float mr = a.mr[k], mg = a.mg[k], mb = a.mb[k];
    const float* __restrict g = b.gamma + k * kPixelLanes;
    if constexpr (kDiffuse) {
      const float inv_width = a.inv_width[k], scale = a.scale[k], slope = a.slope[k];
      const int row = k * kIrradianceTableColumns;
#pragma omp simd
      for (int i = 0; i < kPixelLanes; ++i) {
        const float c = px * b.nx[i] + py * b.ny[i] + pz * b.nz[i];
        cos_n[i] = c;
        const float x = MinC(static_cast<float>(kLast), std::abs(c) * inv_width);
        const int j = MinC(kLast - 1, static_cast<int>(x));
        frac[i] = x - static_cast<float>(j);
        at[i] = row + j;
      }
      Gather::Run(a.rows, at, lo, hi);
#pragma omp simd
      for (int i = 0; i < kPixelLanes; ++i) {
        // Exact clamped-cosine irradiance of the lobe, then Burley's factor with l = its axis.
        const float c = cos_n[i];
        const float e = MaxC(0.0f, c) * slope + scale * FastExpCut(lo[i] + frac[i] * (hi[i] - lo[i]), kCut);
        const float pv = px * b.vx[i] + py * b.vy[i] + pz * b.vz[i];
        const float f90m1 = b.rough[i] * (1.0f + pv) - 0.5f;
        const float nl = MinC(1.0f, MaxC(0.0f, c)), w = 1.0f - nl, w2 = w * w, w5 = w2 * w2 * w;
        const float weight = g[i] * e * (1.0f + f90m1 * w5) * (1.0f + f90m1 * b.view_term[i]);
        dr[i] += mr * weight;
        dg[i] += mg * weight;
        db[i] += mb * weight;
      }
    }
    if constexpr (kSpecular && kVisibility) {
      const float y = 0.2126f * mr + 0.7152f * mg + 0.0722f * mb;
#pragma omp simd
      for (int i = 0; i < kPixelLanes; ++i) {
        const float dx = px - b.sx[i], dy = py - b.sy[i], dz = pz - b.sz[i];
        const float d2 = dx * dx + dy * dy + dz * dz, ps = 1.0f - 0.5f * d2;
        const float open =
            y * (c0 * UnitInnerProductF(lambda, b.sl0[i], d2, ps) + c1 * UnitInnerProductF(lambda, b.sl1[i], d2, ps));
        sr[i] += g[i] * open;
        sg[i] += open;
      }
    } else if constexpr (kSpecular) {
#pragma omp simd
      for (int i = 0; i < kPixelLanes; ++i) {
        const float dx = px - b.sx[i], dy = py - b.sy[i], dz = pz - b.sz[i];
        const float d2 = dx * dx + dy * dy + dz * dz, ps = 1.0f - 0.5f * d2;
        const float weight = g[i] * (c0 * UnitInnerProductF(lambda, b.sl0[i], d2, ps) +
                                     c1 * UnitInnerProductF(lambda, b.sl1[i], d2, ps));
        sr[i] += mr * weight;
        sg[i] += mg * weight;
        sb[i] += mb * weight;
      }
    }
  }
}

void ShadeLobesBaseline(const LobeArrays& a, const PixelTerms& t, float* out) { ShadeLobesBody(a, t, out); }
// parts: 1 diffuse, 2 specular, 3 both (SgShader::Shade's `terms` and the
// materials), 4 the specular's visibility sums, 5 diffuse and those sums.
template <class Gather>
[[gnu::always_inline]] inline void ShadeBlockParts(const LobeArrays& a, const PixelBlock& b, int parts,
                                                   BlockSums* out) {
  if (parts == 1) return ShadeBlockBody<true, false, Gather>(a, b, out);
  if (parts == 2) return ShadeBlockBody<false, true, Gather>(a, b, out);
  if (parts == 4) return ShadeBlockBody<false, true, Gather, true>(a, b, out);
  if (parts == 5) return ShadeBlockBody<true, true, Gather, true>(a, b, out);
  ShadeBlockBody<true, true, Gather>(a, b, out);
}
void ShadeBlockBaseline(const LobeArrays& a, const PixelBlock& b, int parts, BlockSums* out) {
  ShadeBlockParts<GatherScalar>(a, b, parts, out);
}

using ShadeLobesFn = void (*)(const LobeArrays&, const PixelTerms&, float*);
using ShadeBlockFn = void (*)(const LobeArrays&, const PixelBlock&, int, BlockSums*);
struct Kernels {
  ShadeLobesFn lobes;
  ShadeBlockFn block;
};
#if defined(__x86_64__) && defined(__GNUC__)
#define NERFAR_SG_AVX2 "avx2,fma"
#define NERFAR_SG_AVX512 "avx512f,avx512vl,avx512dq,avx512bw,avx2,fma,prefer-vector-width=512"
[[gnu::target(NERFAR_SG_AVX2)]] void ShadeLobesAvx2(const LobeArrays& a, const PixelTerms& t, float* out) {
  ShadeLobesBody(a, t, out);
}
struct GatherAvx2 {
  [[gnu::target(NERFAR_SG_AVX2)]] static void Run(const float* rows, const int* at, float* lo, float* hi) {
    for (int h = 0; h < kPixelLanes; h += 8) {
      const __m256i index = _mm256_load_si256(reinterpret_cast<const __m256i*>(at + h));
      _mm256_store_ps(lo + h, _mm256_i32gather_ps(rows, index, 4));
      _mm256_store_ps(hi + h, _mm256_i32gather_ps(rows + 1, index, 4));
    }
  }
};
[[gnu::target(NERFAR_SG_AVX2)]] void ShadeBlockAvx2(const LobeArrays& a, const PixelBlock& b, int parts,
                                                    BlockSums* out) {
  ShadeBlockParts<GatherAvx2>(a, b, parts, out);
}
[[gnu::target(NERFAR_SG_AVX512)]] void ShadeLobesAvx512(const LobeArrays& a, const PixelTerms& t, float* out) {
  ShadeLobesBody(a, t, out);
}
struct GatherAvx512 {
  [[gnu::target(NERFAR_SG_AVX512)]] static void Run(const float* rows, const int* at, float* lo, float* hi) {
    static_assert(kPixelLanes == 16);
    const __m512i index = _mm512_load_si512(at);
    const __m512 zero = _mm512_setzero_ps();  // the masked form: the plain one reads an undefined register
    _mm512_store_ps(lo, _mm512_mask_i32gather_ps(zero, 0xFFFF, index, rows, 4));
    _mm512_store_ps(hi, _mm512_mask_i32gather_ps(zero, 0xFFFF, index, rows + 1, 4));
  }
};
[[gnu::target(NERFAR_SG_AVX512)]] void ShadeBlockAvx512(const LobeArrays& a, const PixelBlock& b, int parts,
                                                        BlockSums* out) {
  ShadeBlockParts<GatherAvx512>(a, b, parts, out);
}
// The widest instruction set the CPU has, or a narrower one named by the
// environment variable NERFAR_SG_SIMD (avx2 or baseline; for testing every
// kernel on one machine, tests/sg/CMakeLists.txt).
Kernels PickKernels() {
  __builtin_cpu_init();
  const char* env = std::getenv("NERFAR_SG_SIMD");
  const std::string limit = env != nullptr ? env : "";
  if (limit.empty() && __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
      __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512bw"))
    return {ShadeLobesAvx512, ShadeBlockAvx512};
  if (limit != "baseline" && __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma"))
    return {ShadeLobesAvx2, ShadeBlockAvx2};
  return {ShadeLobesBaseline, ShadeBlockBaseline};
}
#else
Kernels PickKernels() { return {ShadeLobesBaseline, ShadeBlockBaseline}; }
#endif
const Kernels kKernels = PickKernels();

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
  kKernels.lobes(arrays, terms, sums);

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

void SgShader::Shade(const SgMaterial* materials, const Vec3f* normals, const Vec3f* views, const float* gamma,
                     int count, Vec3f* out, SgTerms terms, Vec3f* visibility) const {
  NERFAR_CHECK(terms != SgTerms::kDiffuseAndVisibility || visibility != nullptr);
  // Lobes are the loop here, not lanes: no padding needed.
  const LobeArrays arrays{px_, py_, pz_, lambda_, mr_, mg_, mb_, inv_width_, scale_, slope_, rows_.data(), count_};
  PixelBlock block;
  BlockSums sums;
  // Per lane: the material, and the factors that turn the sums into radiance.
  alignas(64) float base[3][kPixelLanes], metal[kPixelLanes], kd[3][kPixelLanes], ks[3][kPixelLanes];
  for (int begin = 0; begin < count; begin += kPixelLanes) {
    const int lanes = std::min(kPixelLanes, count - begin);
    bool diffuse = false;
    for (int i = 0; i < kPixelLanes; ++i) {
      // Lanes past the end repeat the last pixel (finite inputs; results unused).
      const int p = begin + std::min(i, lanes - 1);
      const SgMaterial& m = materials[p];
      base[0][i] = static_cast<float>(m.base_color.x);
      base[1][i] = static_cast<float>(m.base_color.y);
      base[2][i] = static_cast<float>(m.base_color.z);
      metal[i] = static_cast<float>(m.metallic);
      block.rough[i] = static_cast<float>(m.roughness);
      diffuse = diffuse || m.metallic < 1.0;
      block.nx[i] = normals[p].x, block.ny[i] = normals[p].y, block.nz[i] = normals[p].z;
      block.vx[i] = views[p].x, block.vy[i] = views[p].y, block.vz[i] = views[p].z;
      // γ to lobe-major.
      const float* gp = gamma != nullptr ? gamma + static_cast<size_t>(p) * count_ : nullptr;
      for (int k = 0; k < count_; ++k) block.gamma[k * kPixelLanes + i] = gp != nullptr ? gp[k] : 1.0f;
    }
#pragma omp simd
    for (int i = 0; i < kPixelLanes; ++i) {
      float f0[3];
      for (int c = 0; c < 3; ++c) f0[c] = float(kDielectricF0) + (base[c][i] - float(kDielectricF0)) * metal[i];
      const SpecularView<float> view =
          MakeSpecularView<float>(f0[0], f0[1], f0[2], block.rough[i], block.nx[i], block.ny[i], block.nz[i],
                                  block.vx[i], block.vy[i], block.vz[i]);
      const float nv =
          MinC(1.0f, MaxC(0.0f, block.nx[i] * block.vx[i] + block.ny[i] * block.vy[i] + block.nz[i] * block.vz[i]));
      const float wv = 1.0f - nv, wv2 = wv * wv;
      block.view_term[i] = wv2 * wv2 * wv;
      block.sx[i] = view.rx, block.sy[i] = view.ry, block.sz[i] = view.rz;
      block.sl0[i] = static_cast<float>(kNdfSharpness[0]) * view.sharpness_unit;
      block.sl1[i] = static_cast<float>(kNdfSharpness[1]) * view.sharpness_unit;
      const float kdm = (1.0f - metal[i]) * static_cast<float>(kInvPi);
      for (int c = 0; c < 3; ++c) kd[c][i] = kdm * base[c][i];
      ks[0][i] = view.amp_r, ks[1][i] = view.amp_g, ks[2][i] = view.amp_b;
    }
    // Metals have no diffuse term: a block of metals skips that loop.
    const int parts = terms == SgTerms::kSpecularVisibility ? 4
                      : terms == SgTerms::kDiffuseAndVisibility
                          ? (diffuse ? 5 : 4)
                          : (terms != SgTerms::kSpecular && diffuse ? 1 : 0) | (terms != SgTerms::kDiffuse ? 2 : 0);
    if (parts == 0) {
      std::fill(out + begin, out + begin + lanes, Vec3f());
      continue;
    }
    kKernels.block(arrays, block, parts, &sums);
    if (terms == SgTerms::kSpecularVisibility) {
      for (int i = 0; i < lanes; ++i) out[begin + i] = Vec3f(sums.sr[i], sums.sg[i], 0.0f);
      continue;
    }
    if (terms == SgTerms::kDiffuseAndVisibility) {
      for (int i = 0; i < lanes; ++i) {
        visibility[begin + i] = Vec3f(sums.sr[i], sums.sg[i], 0.0f);
        out[begin + i] = Vec3f(kd[0][i] * sums.dr[i], kd[1][i] * sums.dg[i], kd[2][i] * sums.db[i]);
      }
      continue;
    }
    for (int i = 0; i < lanes; ++i)
      out[begin + i] =
          Vec3f(kd[0][i] * sums.dr[i] + ks[0][i] * sums.sr[i], kd[1][i] * sums.dg[i] + ks[1][i] * sums.sg[i],
                kd[2][i] * sums.db[i] + ks[2][i] * sums.sb[i]);
  }
}

}  // namespace nerfar
