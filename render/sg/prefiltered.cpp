#include "render/sg/prefiltered.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>

#include "calib/core/parallel.h"

namespace nerfar {

namespace {

// Environment-BRDF table: nodes n·v = i/(kTableNv − 1) (0 taken as 1e-4),
// r = j/(kTableR − 1); each node integrated with kTableSamples GGX
// importance samples (Hammersley points).
constexpr int kTableNv = 32, kTableR = 32, kTableSamples = 1024;

double RadicalInverse(uint32_t bits) {
  bits = (bits << 16u) | (bits >> 16u);
  bits = ((bits & 0x55555555u) << 1u) | ((bits & 0xAAAAAAAAu) >> 1u);
  bits = ((bits & 0x33333333u) << 2u) | ((bits & 0xCCCCCCCCu) >> 2u);
  bits = ((bits & 0x0F0F0F0Fu) << 4u) | ((bits & 0xF0F0F0F0u) >> 4u);
  bits = ((bits & 0x00FF00FFu) << 8u) | ((bits & 0xFF00FF00u) >> 8u);
  return static_cast<double>(bits) * 2.3283064365386963e-10;
}

// A and B at one node: f from DisneySpecularBrdf with F0 = 1 (red) and
// F0 = 0 (green), so red = A + B, green = B; h drawn from D(h)(n·h), whose
// density in l is D(h)(n·h)/(4 v·h).
EnvironmentBrdfTerms IntegrateEnvironmentBrdf(double nv, double roughness) {
  SgMaterial m;
  m.base_color = Vec3(1, 0, 0);
  m.metallic = 1.0;  // F0 = base colour
  m.roughness = roughness;
  const double alpha = std::max(roughness * roughness, kMinAlpha), a2 = alpha * alpha;
  const Vec3 n(0, 0, 1), v(std::sqrt(std::max(0.0, 1.0 - nv * nv)), 0, nv);
  double red = 0, green = 0;
  for (int s = 0; s < kTableSamples; ++s) {
    const double u1 = (s + 0.5) / kTableSamples, u2 = RadicalInverse(static_cast<uint32_t>(s));
    const double cos_h = std::sqrt((1.0 - u1) / (1.0 + (a2 - 1.0) * u1));
    const double sin_h = std::sqrt(std::max(0.0, 1.0 - cos_h * cos_h)), phi = 2.0 * kPi * u2;
    const Vec3 h(sin_h * std::cos(phi), sin_h * std::sin(phi), cos_h);
    const double vh = Dot(v, h);
    if (vh <= 0.0) continue;
    const Vec3 l = h * (2.0 * vh) - v;
    const double nl = Dot(n, l);
    if (nl <= 0.0) continue;
    const double denom = cos_h * cos_h * (a2 - 1.0) + 1.0;
    const double pdf = a2 / (kPi * denom * denom) * cos_h / (4.0 * vh);
    const Vec3 f = DisneySpecularBrdf(m, n, v, l);
    red += f.x * nl / pdf;
    green += f.y * nl / pdf;
  }
  red /= kTableSamples, green /= kTableSamples;
  return {static_cast<float>(red - green), static_cast<float>(green)};
}

const std::vector<EnvironmentBrdfTerms>& EnvironmentBrdfTable() {
  static const std::vector<EnvironmentBrdfTerms> table = [] {
    std::vector<EnvironmentBrdfTerms> t(size_t(kTableNv) * kTableR);
    ParallelFor(
        t.size(),
        [&](size_t k) {
          const int i = static_cast<int>(k % kTableNv), j = static_cast<int>(k / kTableNv);
          t[k] = IntegrateEnvironmentBrdf(std::max(1e-4, double(i) / (kTableNv - 1)), double(j) / (kTableR - 1));
        },
        16);
    return t;
  }();
  return table;
}

// Bucket coordinates of a direction (sphere.h's panorama convention); a
// non-finite one lands at (0, 0) (its sample counts as black anyway). Only
// the maps' build uses them, to find the samples near a texel.
void Coordinates(const Vec3f& d, float* u, float* v) {
  double du = 0, dv = 0;
  if (std::isfinite(d.x) && std::isfinite(d.y) && std::isfinite(d.z)) EquirectCoordinates(Vec3(d), &du, &dv);
  *u = static_cast<float>(du), *v = static_cast<float>(dv);
}

// Octahedral layout of the level maps: a direction d projected onto the
// octahedron |x| + |y| + |z| = 1, the lower half folded out over the
// square's corners: (x, y) in [−1, 1]². Needs no unit d (the projection is
// scale-free) and no trigonometry. A texel's solid angle is its area over
// |p|³ (p its point on the octahedron): within 3^1.5 = 5.2 of each other,
// no pole singularity. sign(0) counts as +.
void OctahedralEncode(float x, float y, float z, float* px, float* py) {
  const float inv = 1.0f / (std::abs(x) + std::abs(y) + std::abs(z));
  float a = x * inv, b = y * inv;
  if (z < 0.0f) {
    const float fa = (1.0f - std::abs(b)) * (a >= 0.0f ? 1.0f : -1.0f);
    b = (1.0f - std::abs(a)) * (b >= 0.0f ? 1.0f : -1.0f);
    a = fa;
  }
  *px = a, *py = b;
}
Vec3f OctahedralDecode(float a, float b) {
  const float z = 1.0f - std::abs(a) - std::abs(b);
  if (z < 0.0f) {
    const float fa = (1.0f - std::abs(b)) * (a >= 0.0f ? 1.0f : -1.0f);
    b = (1.0f - std::abs(a)) * (b >= 0.0f ? 1.0f : -1.0f);
    a = fa;
  }
  return Normalized(Vec3f(a, b, z));
}

// Fills the one-texel border of an n × n octahedral map stored (n + 2)²
// texels of `channels` floats: each padded texel copies the interior texel
// it neighbours across the square's edge (the edge x = ±1 folds onto itself
// mirrored in y, likewise y = ±1; a corner onto the opposite corner), so a
// bilinear read never wraps.
void FillFoldedBorder(float* texels, int n, int channels) {
  const int padded = n + 2;
  for (int row = 0; row < padded; ++row)
    for (int col = 0; col < padded; ++col) {
      if (row > 0 && row <= n && col > 0 && col <= n) continue;
      float a = 2.0f * (col - 0.5f) / n - 1.0f, b = 2.0f * (row - 0.5f) / n - 1.0f;
      if (std::abs(a) > 1.0f) a = (a > 0 ? 2.0f : -2.0f) - a, b = -b;
      if (std::abs(b) > 1.0f) b = (b > 0 ? 2.0f : -2.0f) - b, a = -a;
      const int ic = std::clamp(static_cast<int>((a + 1.0f) * 0.5f * n), 0, n - 1);
      const int ir = std::clamp(static_cast<int>((b + 1.0f) * 0.5f * n), 0, n - 1);
      const float* from = &texels[(size_t(ir + 1) * padded + ic + 1) * channels];
      std::copy(from, from + channels, &texels[(size_t(row) * padded + col) * channels]);
    }
}

// Bilinear read position of octahedral (a, b) in [−1, 1]² on an n × n map
// with its border: the top-left texel (x0, y0) of the four and the weights
// (ax, ay) of the right and lower ones; NaN reads texel 0.
inline void BilinearAt(float a, float b, int size, float fsize, int* x0, int* y0, float* ax, float* ay) {
  const float top = fsize + 0.99999f;  // the padded texel n + 1 starts at n + 1
  const float fx = std::min(std::max(0.0f, (a + 1.0f) * 0.5f * fsize + 0.5f), top);
  const float fy = std::min(std::max(0.0f, (b + 1.0f) * 0.5f * fsize + 0.5f), top);
  *x0 = std::min(static_cast<int>(fx), size), *y0 = std::min(static_cast<int>(fy), size);
  *ax = fx - static_cast<float>(*x0), *ay = fy - static_cast<float>(*y0);
}

// Adds w times the bilinear value of one level at octahedral (a, b) in
// [−1, 1]² to acc: the level blend folded into the four texel weights; the
// padded border makes every read in range (NaN reads texel 0). Inlined into
// the look-up (a call per level was a fifth of a pixel's instructions).
inline void AddLevel(const float* rgb, int size, float fsize, float a, float b, float w, float* acc) {
  int x0, y0;
  float ax, ay;
  BilinearAt(a, b, size, fsize, &x0, &y0, &ax, &ay);
  const float* p00 = rgb + (size_t(y0) * (size + 2) + x0) * 3;
  const float* p10 = p00 + size_t(size + 2) * 3;
  const float t = w * (1 - ay), u = w * ay;
  const float w00 = t * (1 - ax), w01 = t * ax, w10 = u * (1 - ax), w11 = u * ax;
  for (int c = 0; c < 3; ++c) acc[c] += w00 * p00[c] + w01 * p00[3 + c] + w10 * p10[c] + w11 * p10[3 + c];
}

// The finest map a level gets for compact lobes: n × n texels (~0.01 rad).
constexpr int kMaxCompactSize = 384;

}  // namespace

DistanceMap::DistanceMap(const std::vector<Vec3>& directions, const std::vector<float>& distance) {
  const size_t count = std::min(directions.size(), distance.size());
  if (count == 0) return;
  std::vector<Vec3f> dirs;
  std::vector<float> inverse;
  dirs.reserve(count);
  inverse.reserve(count);
  for (size_t i = 0; i < count; ++i) {
    const Vec3f d = Normalized(Vec3f(directions[i]));
    if (!(std::isfinite(d.x) && std::isfinite(d.y) && std::isfinite(d.z))) continue;
    dirs.push_back(d);
    inverse.push_back(std::isfinite(distance[i]) && distance[i] > 0.0f ? 1.0f / distance[i] : 0.0f);
  }
  if (dirs.empty()) return;
  const int n = std::clamp(static_cast<int>(std::ceil(std::sqrt(static_cast<double>(dirs.size())))), 8, 128);
  size_ = n, fsize_ = static_cast<float>(n);
  const int padded = n + 2;
  inverse_.assign(size_t(padded) * padded, 0.0f);
  // The nearest given direction per texel (brute force: n² ≈ count texels
  // × count directions, once per light).
  ParallelFor(
      static_cast<size_t>(n),
      [&](size_t row) {
        for (int col = 0; col < n; ++col) {
          const Vec3f t = OctahedralDecode(2.0f * (col + 0.5f) / n - 1.0f, 2.0f * (row + 0.5f) / n - 1.0f);
          float best = -2.0f;
          size_t nearest = 0;
          for (size_t i = 0; i < dirs.size(); ++i) {
            const float c = Dot(t, dirs[i]);
            if (c > best) best = c, nearest = i;
          }
          inverse_[(row + 1) * padded + col + 1] = inverse[nearest];
        }
      },
      1);
  FillFoldedBorder(inverse_.data(), n, 1);
}

float DistanceMap::InverseAt(const Vec3f& d) const {
  if (size_ == 0) return 0.0f;
  float a, b, ax, ay;
  int x0, y0;
  OctahedralEncode(d.x, d.y, d.z, &a, &b);
  BilinearAt(a, b, size_, fsize_, &x0, &y0, &ax, &ay);
  const float* p0 = &inverse_[size_t(y0) * (size_ + 2) + x0];
  const float* p1 = p0 + (size_ + 2);
  return (1 - ay) * ((1 - ax) * p0[0] + ax * p0[1]) + ay * ((1 - ax) * p1[0] + ax * p1[1]);
}

EnvironmentBrdfTerms EnvironmentBrdf(float n_dot_v, float roughness) {
  const std::vector<EnvironmentBrdfTerms>& t = EnvironmentBrdfTable();
  const float x = std::clamp(n_dot_v, 0.0f, 1.0f) * (kTableNv - 1),
              y = std::clamp(roughness, 0.0f, 1.0f) * (kTableR - 1);
  const int i = std::min(kTableNv - 2, static_cast<int>(x)), j = std::min(kTableR - 2, static_cast<int>(y));
  const float fx = x - i, fy = y - j;
  const auto at = [&](int a, int b) { return t[size_t(b) * kTableNv + a]; };
  const EnvironmentBrdfTerms p = at(i, j), q = at(i + 1, j), r = at(i, j + 1), s = at(i + 1, j + 1);
  const auto mix = [&](float a, float b, float c, float d) {
    return (1 - fy) * ((1 - fx) * a + fx * b) + fy * ((1 - fx) * c + fx * d);
  };
  return {mix(p.scale, q.scale, r.scale, s.scale), mix(p.bias, q.bias, r.bias, s.bias)};
}

Vec3 ShadeSamplesBruteForce(const RadianceSamples& samples, const SgMaterial& material, const Vec3& n, const Vec3& v,
                            bool specular_only) {
  Vec3 sum;
  for (size_t i = 0; i < samples.size(); ++i) {
    const Vec3& l = samples.directions[i];
    const double nl = Dot(n, l);
    if (nl <= 0.0) continue;
    const Vec3 f = specular_only ? DisneySpecularBrdf(material, n, v, l) : DisneyBrdf(material, n, v, l);
    sum += f * samples.radiance[i] * (nl * samples.solid_angles[i]);
  }
  return sum;
}

namespace {

// The samples bucketed over a (θ, φ) grid (counting sort), structure of arrays.
struct BucketedSamples {
  static constexpr int kRows = 32, kCols = 64;
  std::vector<int> start;  // kRows × kCols + 1 offsets
  std::vector<float> x, y, z, lr, lg, lb, omega;
  double spacing = 0;  // mean spacing: √ of the mean solid angle
};

BucketedSamples BucketSamples(const RadianceSamples& samples) {
  constexpr int kRows = BucketedSamples::kRows, kCols = BucketedSamples::kCols;
  const size_t count = samples.size();
  BucketedSamples out;
  std::vector<int> bucket(count);
  out.start.assign(kRows * kCols + 1, 0);
  double total_solid_angle = 0;
  for (size_t i = 0; i < count; ++i) {
    float u, v;
    Coordinates(Vec3f(samples.directions[i]), &u, &v);
    const int r = std::min(kRows - 1, static_cast<int>(v * kRows)),
              c = std::min(kCols - 1, static_cast<int>(u * kCols));
    bucket[i] = r * kCols + c;
    ++out.start[bucket[i] + 1];
    const double w = samples.solid_angles[i];
    if (std::isfinite(w) && w > 0) total_solid_angle += w;
  }
  for (int b = 0; b < kRows * kCols; ++b) out.start[b + 1] += out.start[b];
  for (std::vector<float>* a : {&out.x, &out.y, &out.z, &out.lr, &out.lg, &out.lb, &out.omega}) a->resize(count);
  std::vector<int> fill(out.start.begin(), out.start.end() - 1);
  for (size_t i = 0; i < count; ++i) {
    const int k = fill[bucket[i]]++;
    const Vec3f d = Normalized(Vec3f(samples.directions[i]));
    const Vec3& L = samples.radiance[i];
    const double w = samples.solid_angles[i];
    const bool ok = std::isfinite(L.x) && std::isfinite(L.y) && std::isfinite(L.z) && L.x >= 0 && L.y >= 0 &&
                    L.z >= 0 && std::isfinite(w) && w > 0 && std::isfinite(d.x);
    out.x[k] = ok ? d.x : 0.0f, out.y[k] = ok ? d.y : 0.0f, out.z[k] = ok ? d.z : 1.0f;
    out.lr[k] = ok ? static_cast<float>(L.x) : 0.0f;
    out.lg[k] = ok ? static_cast<float>(L.y) : 0.0f;
    out.lb[k] = ok ? static_cast<float>(L.z) : 0.0f;
    out.omega[k] = ok ? static_cast<float>(w) : 0.0f;
  }
  out.spacing = std::sqrt(std::max(total_solid_angle, 1e-12) / static_cast<double>(count));
  return out;
}

// The direction of texel (col, row) of an n × n octahedral map.
Vec3f TexelDirection(int col, int row, int n) {
  return OctahedralDecode(2.0f * (col + 0.5f) / n - 1.0f, 2.0f * (row + 0.5f) / n - 1.0f);
}

// One n × n level of the samples filtered by the GGX lobe of width α (the
// class comment's sums), border included.
std::vector<float> FilterSamples(const BucketedSamples& s, double alpha, int n) {
  constexpr int kRows = BucketedSamples::kRows, kCols = BucketedSamples::kCols;
  const int padded = n + 2;
  std::vector<float> rgb(size_t(padded) * padded * 3, 0.0f);
  const float a2 = static_cast<float>(alpha * alpha);
  // Support: angle between R and l up to 2 atan(6α) (θ_h up to atan(6α)).
  const double reach = std::min(kPi, 2.0 * std::atan(6.0 * alpha));
  const float cos_reach = static_cast<float>(std::cos(reach));
  ParallelFor(
      static_cast<size_t>(n),
      [&](size_t row) {
        for (int col = 0; col < n; ++col) {
          const Vec3f R = TexelDirection(col, static_cast<int>(row), n);
          float u, v;
          Coordinates(R, &u, &v);
          const double theta = kPi * v;
          const double lo = theta - reach, hi = theta + reach;
          const int r0 = std::max(0, static_cast<int>(std::floor(lo / kPi * kRows)));
          const int r1 = std::min(kRows - 1, static_cast<int>(std::floor(hi / kPi * kRows)));
          // Columns within reach: all near a pole, else |Δφ| ≤ asin(sin reach / sin θ) plus a bucket.
          int half_cols = kCols;
          if (lo > 0 && hi < kPi && reach < 0.5 * kPi) {
            const double dphi = std::asin(std::min(1.0, std::sin(reach) / std::sin(theta)));
            half_cols = static_cast<int>(std::ceil(dphi / (2.0 * kPi) * kCols)) + 1;
          }
          const int c_mid = std::min(kCols - 1, static_cast<int>(u * kCols));
          const int c0 = half_cols >= kCols / 2 ? 0 : c_mid - half_cols;
          const int c1 = half_cols >= kCols / 2 ? kCols - 1 : c_mid + half_cols;
          float sw = 0, sr = 0, sg = 0, sb = 0;
          for (int br = r0; br <= r1; ++br)
            for (int bc = c0; bc <= c1; ++bc) {
              const int b = br * kCols + ((bc % kCols) + kCols) % kCols;
              for (int i = s.start[b]; i < s.start[b + 1]; ++i) {
                const float c = R.x * s.x[i] + R.y * s.y[i] + R.z * s.z[i];
                if (c < cos_reach || c <= 0.0f) continue;
                // D(h) up to constants: 1/((n·h)²(α² − 1) + 1)², (n·h)² = (1 + c)/2.
                const float denom = 0.5f * (1.0f + c) * (a2 - 1.0f) + 1.0f;
                const float w = s.omega[i] * c / (denom * denom);
                sw += w, sr += w * s.lr[i], sg += w * s.lg[i], sb += w * s.lb[i];
              }
            }
          float* out = &rgb[((row + 1) * padded + col + 1) * 3];
          if (sw > 0) out[0] = sr / sw, out[1] = sg / sw, out[2] = sb / sw;
        }
      },
      1);
  FillFoldedBorder(rgb.data(), n, 3);
  return rgb;
}

// ∫ c / ((1 + c)/2 · (α² − 1) + 1)² dω over the directions at c = R·l in
// [c0, 1] (the filter's weight without its Δω, integrated: the normaliser
// that the samples' Σ w approximates). With u = 1 + k(1 + c), k = (α² − 1)/2:
// ∫ c/u² dc = [(ln u + 1/u)/k² + 1/(k u)]; near α = 1 (k → 0) the weight
// is c itself.
double FilterWeightIntegral(double alpha, double c0) {
  const double a2 = alpha * alpha, k = 0.5 * (a2 - 1.0);
  if (std::abs(k) < 1e-3) {  // the closed form cancels; the integrand is smooth: Simpson
    constexpr int kSteps = 64;
    const auto f = [&](double c) {
      const double u = 1.0 + k * (1.0 + c);
      return c / (u * u);
    };
    const double h = (1.0 - c0) / kSteps;
    double sum = f(c0) + f(1.0);
    for (int i = 1; i < kSteps; ++i) sum += (i % 2 ? 4.0 : 2.0) * f(c0 + i * h);
    return 2.0 * kPi * sum * h / 3.0;
  }
  const auto F = [&](double u) { return (std::log(u) + 1.0 / u) / (k * k) + 1.0 / (k * u); };
  return 2.0 * kPi * (F(a2) - F(1.0 + k * (1.0 + c0)));
}

// Lobes too sharp for the samples, each as SgQuadrature directions with an
// equal share of its integral (RGB), structure of arrays; and the sharpest
// lobe's angular width.
struct CompactPoints {
  std::vector<Vec3f> axis;        // per lobe
  std::vector<float> cos_extent;  // per lobe: its points lie within this of its axis
  std::vector<int> first;         // per lobe + 1: offsets into the points
  std::vector<Vec3f> d, energy;   // per point
  double min_width = kPi;         // min over lobes of 1/√λ, radians
};

// Points per compact lobe: 64 equal shares lie ~0.4 lobe widths apart, so
// a filter no narrower than that (a texel of the finest map) sees them as one.
constexpr int kCompactPoints = 64;

CompactPoints MakeCompactPoints(const SgMixture& lobes) {
  CompactPoints out;
  out.first.push_back(0);
  for (const Sg& lobe : lobes) {
    const Vec3 e = Integral(lobe) / static_cast<double>(kCompactPoints);
    if (!(LuminanceOf(e) > 0.0) || !std::isfinite(LuminanceOf(e))) continue;
    const std::vector<Vec3> q = SgQuadrature(lobe.axis, lobe.sharpness, kCompactPoints);
    float cos_extent = 1.0f;
    for (const Vec3& d : q) {
      out.d.push_back(Vec3f(d));
      out.energy.push_back(Vec3f(e));
      cos_extent = std::min(cos_extent, static_cast<float>(Dot(d, Normalized(lobe.axis))));
    }
    out.axis.push_back(Vec3f(Normalized(lobe.axis)));
    out.cos_extent.push_back(cos_extent);
    out.first.push_back(static_cast<int>(out.d.size()));
    out.min_width = std::min(out.min_width, 1.0 / std::sqrt(std::max(lobe.sharpness, 1e-12)));
  }
  return out;
}

// Adds the compact lobes filtered by the GGX lobe of width α to an n × n
// level (border refilled): Σ_j w(R·l_j) E_j / ∫ w dω, the exact normaliser
// (FilterWeightIntegral) in place of the samples' Σ w.
void AddCompactLobes(const CompactPoints& points, double alpha, int n, std::vector<float>& rgb) {
  if (points.axis.empty()) return;
  const int padded = n + 2;
  const float a2 = static_cast<float>(alpha * alpha);
  const double reach = std::min(kPi, 2.0 * std::atan(6.0 * alpha));
  const float cos_reach = static_cast<float>(std::cos(reach));
  const float inv_norm = static_cast<float>(1.0 / FilterWeightIntegral(alpha, std::max(0.0, std::cos(reach))));
  // A lobe whose points all lie beyond the reach of R adds nothing there.
  std::vector<float> cos_skip(points.axis.size());
  for (size_t k = 0; k < points.axis.size(); ++k)
    cos_skip[k] = static_cast<float>(std::cos(std::min(kPi, reach + std::acos(double(points.cos_extent[k])))));
  ParallelFor(
      static_cast<size_t>(n),
      [&](size_t row) {
        for (int col = 0; col < n; ++col) {
          const Vec3f R = TexelDirection(col, static_cast<int>(row), n);
          Vec3f sum;
          for (size_t k = 0; k < points.axis.size(); ++k) {
            if (Dot(R, points.axis[k]) < cos_skip[k]) continue;
            for (int j = points.first[k]; j < points.first[k + 1]; ++j) {
              const float c = Dot(R, points.d[j]);
              if (c < cos_reach || c <= 0.0f) continue;
              const float denom = 0.5f * (1.0f + c) * (a2 - 1.0f) + 1.0f;
              sum += points.energy[j] * (c / (denom * denom));
            }
          }
          float* out = &rgb[((row + 1) * padded + col + 1) * 3];
          out[0] += sum.x * inv_norm, out[1] += sum.y * inv_norm, out[2] += sum.z * inv_norm;
        }
      },
      16);
  FillFoldedBorder(rgb.data(), n, 3);
}

// An n × n map read bilinearly from a coarser one (coarse_n × coarse_n),
// border included: the samples' smooth part of a level made finer for its
// compact lobes.
std::vector<float> Upsample(const std::vector<float>& coarse, int coarse_n, int n) {
  const int padded = n + 2;
  std::vector<float> rgb(size_t(padded) * padded * 3, 0.0f);
  ParallelFor(
      static_cast<size_t>(n),
      [&](size_t row) {
        for (int col = 0; col < n; ++col) {
          const Vec3f R = TexelDirection(col, static_cast<int>(row), n);
          float a, b;
          OctahedralEncode(R.x, R.y, R.z, &a, &b);
          float* out = &rgb[((row + 1) * padded + col + 1) * 3];
          AddLevel(coarse.data(), coarse_n, static_cast<float>(coarse_n), a, b, 1.0f, out);
        }
      },
      16);
  FillFoldedBorder(rgb.data(), n, 3);
  return rgb;
}

}  // namespace

PrefilteredRadiance::PrefilteredRadiance(const RadianceSamples& samples, int levels, const SgMixture& compact) {
  const size_t count = samples.size();
  if (count == 0 || levels < 2 || samples.radiance.size() != count || samples.solid_angles.size() != count) return;
  const BucketedSamples bucketed = BucketSamples(samples);
  const CompactPoints points = MakeCompactPoints(compact);
  // The finest map the samples can fill.
  const double spacing = bucketed.spacing;
  const int finest = std::max(8, static_cast<int>(std::ceil(kPi / spacing)));
  levels_.resize(levels);
  for (int k = 0; k < levels; ++k) {
    const double r = double(k) / (levels - 1);
    const double alpha_brdf = std::max(r * r, kMinAlpha);
    const double alpha = std::sqrt(alpha_brdf * alpha_brdf + 0.25 * spacing * spacing);
    // n = 1.5 × the rows of an equirect map of α-wide texels: the largest
    // texel (at the octahedron's vertices) is 2/n = 1.33/rows rad wide, finer
    // than that map's equator (π/rows).
    const int equirect_rows = std::clamp(static_cast<int>(std::ceil(kPi / alpha)), 8, finest);
    const int n_samples = (3 * equirect_rows + 1) / 2;
    std::vector<float> rgb = FilterSamples(bucketed, alpha, n_samples);
    int n = n_samples;
    if (!points.axis.empty()) {
      // Compact lobes: a map fine enough for the sharpest one's reflection,
      // whose width is about the filter's and half the lobe's: its texels,
      // 2√3/n rad at the octahedron's face centres (where they are widest),
      // a third of that (bilinear reads then keep a peak within ~2 %), at
      // most kMaxCompactSize a side; the samples' part read from their own
      // map; each lobe filtered with the BRDF's α widened only by a texel.
      const double width = std::sqrt(alpha_brdf * alpha_brdf + 0.25 * points.min_width * points.min_width);
      n = std::max(n_samples, std::min(static_cast<int>(std::ceil(6.0 * std::sqrt(3.0) / width)), kMaxCompactSize));
      if (n != n_samples) rgb = Upsample(rgb, n_samples, n);
      AddCompactLobes(points, std::sqrt(alpha_brdf * alpha_brdf + 1.0 / (double(n) * n)), n, rgb);
    }
    levels_[k].size = n;
    levels_[k].fsize = static_cast<float>(n);
    levels_[k].rgb = std::move(rgb);
  }
}

// The constants of a look-up that depend on roughness alone.
struct PrefilteredRadiance::Prepared {
  float roughness = 0;  // as given (NaN never equals itself: never reused)
  int k = 0;            // the lower of the two levels
  float t = 0;          // the upper level's weight (0: level k alone)
  float s = 0;          // the lobe's dominant direction: mix(n, R, s)
  // The environment BRDF's A and B at n·v = i/(kTableNv − 1), already linear
  // between the table's two roughness rows (bilinear as EnvironmentBrdf, the
  // two lerps in the other order: a float rounding apart).
  float scale[kTableNv], bias[kTableNv];
};

PrefilteredRadiance::Prepared PrefilteredRadiance::Prepare(float rough) const {
  Prepared p;
  p.roughness = rough;
  const float x = std::clamp(std::isfinite(rough) ? rough : 1.0f, 0.0f, 1.0f) * (levels_.size() - 1);
  p.k = std::min(static_cast<int>(levels_.size()) - 2, static_cast<int>(x));
  p.t = x - p.k;
  // The lobe's dominant direction: from R towards n as α grows (at α = 1
  // it is n: the rough lobe is weighted by n·l more than it is centred on
  // R); s(α) = (1 − α)(√(1 − α) + α), a published fit to the GGX lobe's
  // peak. Against brute force over a lamp-lit panorama (shading_test) it
  // halves the error at r = 1 and changes it by ±0.04 below r = 0.5.
  const float alpha = std::max(rough * rough, static_cast<float>(kMinAlpha));
  const float smooth = 1.0f - std::min(alpha, 1.0f);
  p.s = smooth * (std::sqrt(smooth) + alpha);
  const std::vector<EnvironmentBrdfTerms>& t = EnvironmentBrdfTable();
  const float y = std::clamp(rough, 0.0f, 1.0f) * (kTableR - 1);
  const int j = std::min(kTableR - 2, static_cast<int>(y));
  const float fy = y - j;
  for (int i = 0; i < kTableNv; ++i) {
    const EnvironmentBrdfTerms& lo = t[size_t(j) * kTableNv + i];
    const EnvironmentBrdfTerms& hi = t[size_t(j + 1) * kTableNv + i];
    p.scale[i] = (1 - fy) * lo.scale + fy * hi.scale;
    p.bias[i] = (1 - fy) * lo.bias + fy * hi.bias;
  }
  return p;
}

Vec3f PrefilteredRadiance::Lookup(const Vec3f& d, const Prepared& p) const {
  float a, b;
  OctahedralEncode(d.x, d.y, d.z, &a, &b);
  float acc[3] = {0, 0, 0};
  const Level& lo = levels_[p.k];
  if (p.t <= 0.0f) {
    AddLevel(lo.rgb.data(), lo.size, lo.fsize, a, b, 1.0f, acc);
  } else {
    const Level& hi = levels_[p.k + 1];
    AddLevel(lo.rgb.data(), lo.size, lo.fsize, a, b, 1.0f - p.t, acc);
    AddLevel(hi.rgb.data(), hi.size, hi.fsize, a, b, p.t, acc);
  }
  return {acc[0], acc[1], acc[2]};
}

Vec3f PrefilteredRadiance::Lookup(const Vec3f& d, float roughness) const {
  if (levels_.empty()) return {};
  return Lookup(d, Prepare(roughness));
}

void PrefilteredRadiance::SetParallax(const Vec3& center, DistanceMap distances, int iterations) {
  center_ = Vec3f(center);
  distances_ = std::move(distances);
  iterations_ = std::max(1, iterations);
}

Vec3f PrefilteredRadiance::ParallaxDirection(const Vec3f& point, const Vec3f& r) const {
  if (distances_.empty()) return r;
  const Vec3f x = point - center_, u = Normalized(r);
  const float xx = Dot(x, x), b = Dot(x, u);
  Vec3f d = r;
  for (int k = 0; k < iterations_; ++k) {
    const float inverse = distances_.InverseAt(d);
    // Distant (or a non-finite point): the hit is at infinity along r.
    if (!(inverse > 0.0f) || !std::isfinite(xx)) return r;
    // |x + t·u| = D with D² at least |x|²: t = −b + √(b² − |x|² + D²) ≥ 0.
    const float d2 = std::max(1.0f / (inverse * inverse), xx);
    const float t = std::sqrt(std::max(0.0f, b * b - xx + d2)) - b;
    d = x + u * t;
  }
  return d;
}

void PrefilteredRadiance::ShadeParts(const Prepared& p, const Vec3f& n, const Vec3f& v, const Vec3f* point,
                                     Vec3f* scaled, Vec3f* biased) const {
  const float nv = Dot(n, v);
  if (!(nv > 0.0f)) {
    *scaled = *biased = Vec3f{};
    return;
  }
  const Vec3f r = n * (2.0f * nv) - v;
  Vec3f dominant = n * (1.0f - p.s) + r * p.s;  // any length: octahedral
  if (point != nullptr && !distances_.empty()) dominant = ParallaxDirection(*point, dominant);
  const Vec3f L = Lookup(dominant, p);
  const float x = std::min(nv, 1.0f) * (kTableNv - 1);
  const int i = std::min(kTableNv - 2, static_cast<int>(x));
  const float fx = x - i;
  const float scale = (1 - fx) * p.scale[i] + fx * p.scale[i + 1], bias = (1 - fx) * p.bias[i] + fx * p.bias[i + 1];
  *scaled = L * scale;
  *biased = L * bias;
}

Vec3f PrefilteredRadiance::SpecularFromParts(const SgMaterial& m, const Vec3f& scaled, const Vec3f& biased) {
  const float metal = static_cast<float>(m.metallic), d0 = static_cast<float>(kDielectricF0);
  const Vec3f f0(d0 + (static_cast<float>(m.base_color.x) - d0) * metal,
                 d0 + (static_cast<float>(m.base_color.y) - d0) * metal,
                 d0 + (static_cast<float>(m.base_color.z) - d0) * metal);
  return {f0.x * scaled.x + biased.x, f0.y * scaled.y + biased.y, f0.z * scaled.z + biased.z};
}

template <class PerPixel>
void PrefilteredRadiance::EachPrepared(const SgMaterial* materials, size_t count, PerPixel&& per_pixel) const {
  Prepared p;
  bool prepared = false;
  for (size_t i = 0; i < count; ++i) {
    const float rough = static_cast<float>(materials[i].roughness);
    if (!prepared || !(rough == p.roughness)) p = Prepare(rough), prepared = true;
    per_pixel(p, i);
  }
}

Vec3f PrefilteredRadiance::Shade(const Prepared& p, const SgMaterial& m, const Vec3f& n, const Vec3f& v,
                                 const Vec3f* point) const {
  Vec3f scaled, biased;
  ShadeParts(p, n, v, point, &scaled, &biased);
  return SpecularFromParts(m, scaled, biased);
}

Vec3f PrefilteredRadiance::ShadeSpecular(const SgMaterial& m, const Vec3f& n, const Vec3f& v) const {
  if (levels_.empty()) return {};
  return Shade(Prepare(static_cast<float>(m.roughness)), m, n, v);
}

void PrefilteredRadiance::ShadeSpecular(const SgMaterial* materials, const Vec3f* n, const Vec3f* v, size_t count,
                                        Vec3f* out) const {
  ShadeSpecular(materials, n, v, nullptr, count, out);
}

void PrefilteredRadiance::ShadeSpecular(const SgMaterial* materials, const Vec3f* n, const Vec3f* v,
                                        const Vec3f* points, size_t count, Vec3f* out) const {
  if (levels_.empty()) {
    std::fill(out, out + count, Vec3f{});
    return;
  }
  EachPrepared(materials, count, [&](const Prepared& p, size_t i) {
    out[i] = Shade(p, materials[i], n[i], v[i], points ? &points[i] : nullptr);
  });
}

void PrefilteredRadiance::ShadeSpecularParts(const SgMaterial* materials, const Vec3f* n, const Vec3f* v,
                                             const Vec3f* points, size_t count, Vec3f* scaled, Vec3f* biased) const {
  if (levels_.empty()) {
    std::fill(scaled, scaled + count, Vec3f{});
    std::fill(biased, biased + count, Vec3f{});
    return;
  }
  EachPrepared(materials, count, [&](const Prepared& p, size_t i) {
    ShadeParts(p, n[i], v[i], points ? &points[i] : nullptr, &scaled[i], &biased[i]);
  });
}

}  // namespace nerfar
