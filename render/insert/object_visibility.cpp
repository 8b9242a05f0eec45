#include "render/insert/object_visibility.h"

#include <algorithm>
#include <cmath>

namespace nerfar {

namespace {
constexpr double kHalfPi = 0.5 * kPi;
}

float SphereVisibility::SsdAt(const Vec3& center, double radius, const Vec3& x, const Vec3& d) {
  const Vec3 to_center = center - x;
  const double dist = Length(to_center);
  if (!(dist > radius)) return static_cast<float>(-kHalfPi);
  const double half_angle = std::asin(std::min(1.0, radius / dist));
  // atan2 keeps the angle accurate near 0 and π (acos loses digits there).
  const double angle = std::atan2(Length(Cross(d, to_center)), Dot(d, to_center));
  return static_cast<float>(angle - half_angle);
}

namespace {
class SphereQuery final : public VisibilityQuery {
 public:
  SphereQuery(const Vec3& c, double r, const std::vector<Vec3f>& dirs) : c_(c), r_(r) {
    for (const Vec3f& d : dirs) dirs_.push_back(Normalized(Vec3(d)));
  }
  int direction_count() const override { return static_cast<int>(dirs_.size()); }
  void Ssd(const Vec3f* points, size_t count, float* ssd) const override {
    const size_t m = dirs_.size();
    for (size_t i = 0; i < count; ++i)
      for (size_t k = 0; k < m; ++k) ssd[i * m + k] = SphereVisibility::SsdAt(c_, r_, Vec3(points[i]), dirs_[k]);
  }

 private:
  Vec3 c_;
  double r_;
  std::vector<Vec3> dirs_;
};
}  // namespace

std::unique_ptr<VisibilityQuery> SphereVisibility::Prepare(const std::vector<Vec3f>& directions) const {
  return std::make_unique<SphereQuery>(center_, radius_, directions);
}

float BallSsdLowerBound(const Vec3f& center, float radius, const Vec3f& x, const Vec3f& d) {
  const Vec3f to_center = center - x;
  const float dist2 = Dot(to_center, to_center);
  if (!(dist2 > radius * radius)) return static_cast<float>(-kHalfPi);
  const float dist = std::sqrt(dist2);
  const float half_angle = std::asin(std::min(1.0f, radius / dist));
  const float angle = std::atan2(Length(Cross(d, to_center)), Dot(d, to_center));
  return angle - half_angle;
}

}  // namespace nerfar
