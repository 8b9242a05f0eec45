#include "calib/core/math.h"

#include <algorithm>

namespace nerfar {

Mat3 RotationFromAxisAngle(const Vec3& axis, double angle_rad) {
  const Vec3 k = Normalized(axis);
  const double c = std::cos(angle_rad), s = std::sin(angle_rad), t = 1.0 - c;
  return Mat3{{t * k.x * k.x + c, t * k.x * k.y - s * k.z, t * k.x * k.z + s * k.y, t * k.x * k.y + s * k.z,
               t * k.y * k.y + c, t * k.y * k.z - s * k.x, t * k.x * k.z - s * k.y, t * k.y * k.z + s * k.x,
               t * k.z * k.z + c}};
}

Vec3 AxisAngleFromRotation(const Mat3& r) {
  const double cos_angle = std::clamp((r(0, 0) + r(1, 1) + r(2, 2) - 1.0) * 0.5, -1.0, 1.0);
  const double angle = std::acos(cos_angle);
  const Vec3 w{r(2, 1) - r(1, 2), r(0, 2) - r(2, 0), r(1, 0) - r(0, 1)};
  if (angle < 1e-12) return w * 0.5;
  if (kPi - angle > 1e-6) return w * (angle / (2.0 * std::sin(angle)));
  // Near pi the antisymmetric part vanishes: take the axis from the diagonal.
  Vec3 axis{std::sqrt(std::max(0.0, (r(0, 0) + 1) * 0.5)), std::sqrt(std::max(0.0, (r(1, 1) + 1) * 0.5)),
            std::sqrt(std::max(0.0, (r(2, 2) + 1) * 0.5))};
  if (r(0, 1) + r(1, 0) < 0 && axis.x > 0) axis.y = -axis.y;
  if (r(0, 2) + r(2, 0) < 0 && axis.x > 0) axis.z = -axis.z;
  if (axis.x == 0 && r(1, 2) + r(2, 1) < 0) axis.z = -axis.z;
  return Normalized(axis) * angle;
}

double RotationAngleBetween(const Mat3& a, const Mat3& b) { return Length(AxisAngleFromRotation(a.Transposed() * b)); }

Pose LookAt(const Vec3& eye, const Vec3& target) {
  const Vec3 z = Normalized(target - eye);
  Vec3 x = Cross(z, Vec3{0, 0, 1});
  x = Length(x) < 1e-9 ? Vec3{1, 0, 0} : Normalized(x);
  return {Mat3::FromColumns(x, Cross(z, x), z), eye};
}

std::array<double, 16> Pose::ToMatrix4() const {
  return {rotation(0, 0),
          rotation(0, 1),
          rotation(0, 2),
          translation.x,
          rotation(1, 0),
          rotation(1, 1),
          rotation(1, 2),
          translation.y,
          rotation(2, 0),
          rotation(2, 1),
          rotation(2, 2),
          translation.z,
          0,
          0,
          0,
          1};
}

Pose Pose::FromMatrix4(const std::array<double, 16>& m) {
  Vec3 c0{m[0], m[4], m[8]}, c1{m[1], m[5], m[9]};
  c0 = Normalized(c0);
  c1 = Normalized(c1 - c0 * Dot(c0, c1));
  const Vec3 c2 = Cross(c0, c1);
  return {Mat3::FromColumns(c0, c1, c2), {m[3], m[7], m[11]}};
}

}  // namespace nerfar
