#include "tests/support/analytic_field.h"

#include <algorithm>
#include <cmath>

namespace nerfar::testing {

NerfField MakeField(const Aabb& aabb, double voxel, const Shape& shape,
                    const std::function<Vec3(const Vec3&, const Vec3&)>& radiance,
                    const std::function<Vec3(const Vec3&, const Vec3&)>& log_slope) {
  NerfField field = NerfField::Dense(aabb, voxel, kNerfEmptyDensityRaw, Vec3f{-20, -20, -20});
  for (int k = 0; k < field.res[2]; ++k)
    for (int j = 0; j < field.res[1]; ++j)
      for (int i = 0; i < field.res[0]; ++i) {
        const int32_t slot = field.Slot(i, j, k);
        const Vec3 p = Vec3(field.origin) + Vec3{double(i), double(j), double(k)} * double(field.voxel_m);
        const double sd = shape.sd(p);
        field.density[slot] = static_cast<float>(std::clamp(3.0 - 10.0 * sd / voxel, -30.0, 8.0));
        if (std::fabs(sd) > 3 * voxel) continue;
        Vec3 x, n;
        shape.project(p, &x, &n);
        const Vec3 l = radiance(x, n);
        const Vec3 slope = log_slope ? log_slope(x, n) : Vec3{};
        for (int c = 0; c < 3; ++c) {
          field.color[slot * kNerfColorCoeffs + c * 4] = static_cast<float>(std::log(std::max(l[c], 1e-9)));
          for (int b = 1; b < 4; ++b)
            field.color[slot * kNerfColorCoeffs + c * 4 + b] = static_cast<float>(slope[b - 1]);
        }
      }
  field.UpdateOccupancy(1.0f);
  return field;
}

Shape OrientedBox(const Vec3& c, const std::array<Vec3, 3>& axes, const Vec3& half) {
  auto local = [=](const Vec3& p) {
    const Vec3 d = p - c;
    return Vec3{Dot(d, axes[0]), Dot(d, axes[1]), Dot(d, axes[2])};
  };
  auto world = [=](const Vec3& q) { return c + axes[0] * q.x + axes[1] * q.y + axes[2] * q.z; };
  Shape s;
  s.sd = [=](const Vec3& p) {
    const Vec3 q = local(p);
    const Vec3 d{std::fabs(q.x) - half.x, std::fabs(q.y) - half.y, std::fabs(q.z) - half.z};
    const Vec3 out{std::max(d.x, 0.0), std::max(d.y, 0.0), std::max(d.z, 0.0)};
    return Length(out) + std::min(std::max({d.x, d.y, d.z}), 0.0);
  };
  s.project = [=](const Vec3& p, Vec3* x, Vec3* n) {
    Vec3 q = local(p);
    const Vec3 clamped{std::clamp(q.x, -half.x, half.x), std::clamp(q.y, -half.y, half.y),
                       std::clamp(q.z, -half.z, half.z)};
    Vec3 ln = q - clamped;
    if (Length(ln) > 0) {
      ln = Normalized(ln);
      q = clamped;
    } else {  // inside: out through the nearest face
      int k = 0;
      double best = 1e30;
      for (int a = 0; a < 3; ++a)
        if (half[a] - std::fabs(q[a]) < best) best = half[a] - std::fabs(q[a]), k = a;
      ln = Vec3{};
      ln[k] = q[k] >= 0 ? 1 : -1;
      q[k] = half[k] * ln[k];
    }
    *x = world(q);
    *n = Normalized(axes[0] * ln.x + axes[1] * ln.y + axes[2] * ln.z);
  };
  return s;
}

Shape BoxShape(const Aabb& box) {
  return OrientedBox((box.min + box.max) * 0.5, {Vec3{1, 0, 0}, Vec3{0, 1, 0}, Vec3{0, 0, 1}},
                     (box.max - box.min) * 0.5);
}

Shape SphereShape(const Vec3& centre, double radius) {
  Shape s;
  s.sd = [=](const Vec3& p) { return Length(p - centre) - radius; };
  s.project = [=](const Vec3& p, Vec3* x, Vec3* n) {
    *n = Normalized(p - centre);
    *x = centre + *n * radius;
  };
  return s;
}

}  // namespace nerfar::testing
