// Queries of a baked field: bilinear over the octahedral map, trilinear over
// the grid, the geometric re-mapping outside the grid, and the batched path.
#include <algorithm>
#include <cmath>

#include "render/ssdf/ssdf.h"

namespace nerfar {

namespace {

constexpr float kPiF = static_cast<float>(kPi);
constexpr size_t kMaxComponents = 1024;

float ClampSsd(float s) { return std::clamp(s, -kPiF, kPiF); }

}  // namespace

float SsdfField::SampleAt(int ix, int iy, int iz, int texel) const {
  const size_t k = static_cast<size_t>(components_);
  const size_t p = (static_cast<size_t>(iz) * grid_ + iy) * grid_ + ix;
  float s = mean_[texel];
  for (size_t c = 0; c < k; ++c) s += coefficients_[p * k + c] * basis_[texel * k + c];
  return s;
}

void SsdfField::EvaluateBasis(const Vec3f& d, float* out) const {
  const auto uv = OctahedralCoordinates(Vec3(d));
  const double x = uv[0] * dirs_ - 0.5, y = uv[1] * dirs_ - 0.5;
  const int i0 = static_cast<int>(std::floor(x)), j0 = static_cast<int>(std::floor(y));
  const float fx = static_cast<float>(x - i0), fy = static_cast<float>(y - j0);
  const float weights[4] = {(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy};
  const int offsets[4][2] = {{0, 0}, {1, 0}, {0, 1}, {1, 1}};
  const size_t k = static_cast<size_t>(components_);
  std::fill(out, out + k + 1, 0.0f);
  for (int n = 0; n < 4; ++n) {
    const auto ij = OctahedralWrap(i0 + offsets[n][0], j0 + offsets[n][1], dirs_);
    const size_t t = static_cast<size_t>(ij[1]) * dirs_ + ij[0];
    const float w = weights[n];
    out[0] += w * mean_[t];
    const float* b = basis_.data() + t * k;
    for (size_t c = 0; c < k; ++c) out[1 + c] += w * b[c];
  }
}

void SsdfField::InterpolateCoefficients(const Vec3f& x, float* out) const {
  const double step = edge_ / (grid_ - 1);
  const Vec3 origin = center_ - Vec3(1, 1, 1) * (edge_ / 2);
  int i0[3];
  float f[3];
  for (int a = 0; a < 3; ++a) {
    const double g = std::clamp((static_cast<double>(x[a]) - origin[a]) / step, 0.0, static_cast<double>(grid_ - 1));
    i0[a] = std::min(static_cast<int>(g), grid_ - 2);
    f[a] = static_cast<float>(g - i0[a]);
  }
  const size_t k = static_cast<size_t>(components_);
  std::fill(out, out + k, 0.0f);
  for (int corner = 0; corner < 8; ++corner) {
    const int dx = corner & 1, dy = (corner >> 1) & 1, dz = corner >> 2;
    const float w = (dx ? f[0] : 1 - f[0]) * (dy ? f[1] : 1 - f[1]) * (dz ? f[2] : 1 - f[2]);
    const size_t p = (static_cast<size_t>(i0[2] + dz) * grid_ + (i0[1] + dy)) * grid_ + (i0[0] + dx);
    const float* c = coefficients_.data() + p * k;
    for (size_t n = 0; n < k; ++n) out[n] += w * c[n];
  }
}

// Outside the grid (design; measured in docs/BENCHMARKS.md "ssdf"):
//
// x_f is projected radially onto the grid box, x_b = c + (x_f - c)·t, so both
// points see the object from the same side and differ only in distance
// (D_b < D_f). Seen from farther away the object shrinks about the centre
// direction u = (c - x)/|c - x|: a silhouette point at polar angle ρ_b from u
// in the x_b view lies at ρ_f = asin(sin ρ_b · D_b/D_f) in the x_f view (exact
// for a sphere, whose silhouette has sin α = r/D).
//
// A query direction d at polar angle β_f from u (azimuth kept) is looked up in
// the x_b view at h(β_f): the inverse shrink asin(sin β · D_f/D_b) on the
// object's cone [0, α_f], continued linearly from (α_f, α_b) to (π, π), so h
// is continuous, monotone and h(π) = π. The answer S_b gives a silhouette
// estimate ρ_b = h(β_f) - S_b at that azimuth, which is shrunk back to
// ρ_f = asin(sin ρ_b · D_b/D_f) (odd in ρ_b), and S_f = β_f - ρ_f.
// For a sphere every step is exact; for other shapes the error comes from
// parallax (the x_b view is not a scaled x_f view) and from treating the
// nearest-silhouette distance as radial. It is bounded because |ρ_f| ≤ α_f.
bool SsdfField::MapPoint(const Vec3f& x, OutsidePoint* point) const {
  const Vec3 v = Vec3(x) - center_;
  const double half = edge_ / 2;
  const double extent = std::max({std::abs(v.x), std::abs(v.y), std::abs(v.z)});
  if (extent <= half) return false;
  const double t = half / extent;
  const double d_f = Length(v), d_b = d_f * t;
  point->x_b = Vec3f(center_ + v * t);
  point->u = -v / d_f;
  point->far_over_near = d_f / d_b;
  point->alpha_f = std::asin(std::min(1.0, radius_ / d_f));
  point->alpha_b = std::asin(std::min(1.0, radius_ / d_b));
  return true;
}

SsdfField::OutsideMap SsdfField::MapDirection(const OutsidePoint& point, const Vec3f& d) {
  const Vec3 dn = Normalized(Vec3(d));
  const double cos_beta = std::clamp(Dot(dn, point.u), -1.0, 1.0);
  const Vec3 side = dn - point.u * cos_beta;
  const double sin_beta = Length(side);  // |d - (d·u)u| = sin β
  const double beta_f = std::atan2(sin_beta, cos_beta);
  double h, sin_h, cos_h;
  if (beta_f <= point.alpha_f) {
    // Inverse shrink on the object's cone: sin h = sin β · D_f/D_b, h ≤ α_b < π/2.
    sin_h = std::min(1.0, sin_beta * point.far_over_near);
    cos_h = std::sqrt(1.0 - sin_h * sin_h);
    h = std::asin(sin_h);
  } else {
    h = point.alpha_b + (beta_f - point.alpha_f) * (kPi - point.alpha_b) / (kPi - point.alpha_f);
    sin_h = std::sin(h);
    cos_h = std::cos(h);
  }
  OutsideMap map;
  map.d_b = sin_beta > 1e-9 ? Vec3f(point.u * cos_h + side * (sin_h / sin_beta)) : Vec3f(dn);
  map.beta_f = static_cast<float>(beta_f);
  map.h_beta = static_cast<float>(h);
  map.ratio = static_cast<float>(1.0 / point.far_over_near);
  return map;
}

float SsdfField::MapBack(const OutsideMap& map, float s_b) {
  const float rho_b = std::clamp(map.h_beta - s_b, -kPiF / 2, kPiF / 2);
  const float rho_f = std::copysign(std::asin(std::min(1.0f, std::sin(std::abs(rho_b)) * map.ratio)), rho_b);
  return ClampSsd(map.beta_f - rho_f);
}

float SsdfField::Query(const Vec3f& x, const Vec3f& d) const {
  const size_t k = static_cast<size_t>(components_);
  float basis[kMaxComponents + 1], coefficients[kMaxComponents];  // K ≤ 1024 (Validate)
  OutsidePoint point;
  const bool outside = MapPoint(x, &point);
  OutsideMap map;
  if (outside) map = MapDirection(point, d);
  InterpolateCoefficients(outside ? point.x_b : x, coefficients);
  EvaluateBasis(outside ? map.d_b : d, basis);
  float s = basis[0];
  for (size_t c = 0; c < k; ++c) s += coefficients[c] * basis[1 + c];
  return outside ? MapBack(map, s) : ClampSsd(s);
}

std::vector<std::string> SsdfField::Validate() const {
  std::vector<std::string> problems;
  if (grid_ < 2 || grid_ > 128) problems.push_back("grid " + std::to_string(grid_) + " (expected 2 to 128)");
  if (dirs_ < 4 || dirs_ > 512) problems.push_back("dirs " + std::to_string(dirs_) + " (expected 4 to 512)");
  if (components_ < 1 || components_ > 1024)
    problems.push_back("components " + std::to_string(components_) + " (expected 1 to 1024)");
  if (!problems.empty()) return problems;
  const size_t d = static_cast<size_t>(dirs_) * dirs_, p = static_cast<size_t>(grid_) * grid_ * grid_;
  const size_t k = static_cast<size_t>(components_);
  if (mean_.size() != d)
    problems.push_back("mean has " + std::to_string(mean_.size()) + " values (expected " + std::to_string(d) + ")");
  if (basis_.size() != d * k)
    problems.push_back("basis has " + std::to_string(basis_.size()) + " values (expected " + std::to_string(d * k) +
                       ")");
  if (coefficients_.size() != p * k)
    problems.push_back("coefficients have " + std::to_string(coefficients_.size()) + " values (expected " +
                       std::to_string(p * k) + ")");
  const auto finite = [](const std::vector<float>& values) {
    return std::all_of(values.begin(), values.end(), [](float v) { return std::isfinite(v); });
  };
  if (!finite(mean_) || !finite(basis_) || !finite(coefficients_))
    problems.push_back("arrays hold NaN or infinite values (expected finite)");
  if (!(std::isfinite(center_.x) && std::isfinite(center_.y) && std::isfinite(center_.z)))
    problems.push_back("centre is not finite (expected finite)");
  if (!(radius_ > 0 && std::isfinite(radius_)))
    problems.push_back("radius " + std::to_string(radius_) + " (expected > 0)");
  if (!(edge_ > 2 * radius_ && std::isfinite(edge_)))
    problems.push_back("grid edge " + std::to_string(edge_) + " (expected finite and above twice the radius)");
  return problems;
}

// ---------------------------------------------------------------- batch

void SsdfBatch::PrepareDirections(const std::vector<Vec3f>& directions) {
  const size_t k1 = static_cast<size_t>(field_.components_) + 1;
  directions_ = directions;
  evaluated_.resize(directions.size() * k1);
  for (size_t m = 0; m < directions.size(); ++m) field_.EvaluateBasis(directions[m], evaluated_.data() + m * k1);
}

void SsdfBatch::QueryBatch(const Vec3f* points, size_t count, float* out) const {
  const size_t k = static_cast<size_t>(field_.components_), lobes = directions_.size();
  std::vector<float> coefficients(k), basis(k + 1);
  for (size_t p = 0; p < count; ++p) {
    float* result = out + p * lobes;
    const Vec3f& x = points[p];
    SsdfField::OutsidePoint point;
    if (!field_.MapPoint(x, &point)) {
      field_.InterpolateCoefficients(x, coefficients.data());
      for (size_t m = 0; m < lobes; ++m) {
        const float* e = evaluated_.data() + m * (k + 1);
        float s = e[0];
        for (size_t c = 0; c < k; ++c) s += coefficients[c] * e[1 + c];
        result[m] = ClampSsd(s);
      }
      continue;
    }
    field_.InterpolateCoefficients(point.x_b, coefficients.data());  // x_b is the same for every lobe
    for (size_t m = 0; m < lobes; ++m) {
      const SsdfField::OutsideMap map = SsdfField::MapDirection(point, directions_[m]);
      field_.EvaluateBasis(map.d_b, basis.data());
      float s = basis[0];
      for (size_t c = 0; c < k; ++c) s += coefficients[c] * basis[1 + c];
      result[m] = SsdfField::MapBack(map, s);
    }
  }
}

}  // namespace nerfar
