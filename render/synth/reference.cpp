#include "render/synth/reference.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "calib/core/error.h"
#include "calib/core/parallel.h"

namespace nerfar::synth {

namespace {

constexpr int kGaussNodes = 128;

// Gauss-Legendre nodes and weights on [0, 1] (Newton on P_n, tolerance 1e-15).
struct GaussLegendre {
  std::array<double, kGaussNodes> x{}, w{};
  GaussLegendre() {
    const int n = kGaussNodes;
    for (int i = 0; i < n; ++i) {
      double z = std::cos(kPi * (i + 0.75) / (n + 0.5)), dp = 1;
      for (int iter = 0; iter < 100; ++iter) {
        double p0 = 1, p1 = 0;
        for (int k = 1; k <= n; ++k) {
          const double p2 = p1;
          p1 = p0;
          p0 = ((2.0 * k - 1) * z * p1 - (k - 1.0) * p2) / k;
        }
        dp = n * (z * p0 - p1) / (z * z - 1);
        const double dz = p0 / dp;
        z -= dz;
        if (std::fabs(dz) < 1e-15) break;
      }
      x[i] = 0.5 * (1 - z);
      w[i] = 1.0 / ((1 - z * z) * dp * dp);  // = 2/((1-z^2)P'^2) on [-1,1], halved for [0,1]
    }
  }
};

const GaussLegendre& Nodes() {
  static const GaussLegendre nodes;
  return nodes;
}

// Integral over azimuth of max(0, a + b cos(phi)), b >= 0.
double ClampedAzimuth(double a, double b) {
  if (b <= std::fabs(a)) return a > 0 ? 2 * kPi * a : 0.0;
  return 2 * (a * std::acos(std::clamp(-a / b, -1.0, 1.0)) + std::sqrt(std::max(0.0, b * b - a * a)));
}

Vec3 ToVec3(const Vec3f& v) { return Vec3(v); }

}  // namespace

double SgLobeIrradiance(double sharpness, double cos_angle) {
  NERFAR_CHECK_GT(sharpness, 0.0);
  const double lambda = sharpness;
  const double t = std::clamp(cos_angle, -1.0, 1.0), s = std::sqrt(std::max(0.0, 1 - t * t));
  const double alpha = std::acos(t);
  // Polar angle theta around the lobe axis; with u = 1 - cos(theta) in [0, 2]
  // the measure sin(theta) d(theta) is du and the lobe is exp(-lambda u).
  std::vector<double> cuts = {0.0, 2.0};
  for (double theta : {kPi / 2 - alpha, kPi / 2 + alpha, alpha - kPi / 2, 3 * kPi / 2 - alpha}) {
    if (theta > 0 && theta < kPi) cuts.push_back(1 - std::cos(theta));
  }
  std::sort(cuts.begin(), cuts.end());
  const GaussLegendre& gl = Nodes();
  double total = 0;
  for (size_t k = 0; k + 1 < cuts.size(); ++k) {
    const double ua = cuts[k], ub = cuts[k + 1];
    if (!(ub > ua)) continue;
    // u(r) = ua - log1p(-r (1 - e^{-lambda (ub - ua)})) / lambda maps r in [0,1]
    // so that exp(-lambda u) du = e^{-lambda ua} (1 - e^{-lambda du}) / lambda dr.
    const double one_minus = -std::expm1(-lambda * (ub - ua));
    const double scale = std::exp(-lambda * ua) * one_minus / lambda;
    double piece = 0;
    for (int i = 0; i < kGaussNodes; ++i) {
      const double u = std::min(ub, ua - std::log1p(-gl.x[i] * one_minus) / lambda);
      const double cos_theta = 1 - u, sin_theta = std::sqrt(std::max(0.0, u * (2 - u)));
      piece += gl.w[i] * ClampedAzimuth(t * cos_theta, s * sin_theta);
    }
    total += scale * piece;
  }
  return total;
}

Vec3 SgIrradiance(const std::vector<EnvLobe>& lobes, const Vec3& normal) {
  const Vec3 n = Normalized(normal);
  Vec3 e{0, 0, 0};
  for (const EnvLobe& lobe : lobes) {
    const double c = Dot(n, Normalized(ToVec3(lobe.axis)));
    e += ToVec3(lobe.amplitude) * SgLobeIrradiance(lobe.sharpness, c);
  }
  return e;
}

Vec3 SphereLightIrradiance(const SphereLight& light, const Vec3& point, const Vec3& normal) {
  const Vec3 n = Normalized(normal);
  const Vec3 to_c = ToVec3(light.center) - point;
  const double d = Length(to_c), r = light.radius;
  const double cos_theta = Dot(n, to_c) / d;
  // Entirely above the tangent plane: the centre's height exceeds the radius.
  NERFAR_CHECK_GT(Dot(n, to_c), r);
  return ToVec3(light.radiance) * (kPi * (r / d) * (r / d) * cos_theta);
}

Vec3 RectangleLightIrradiance(const RectangleLight& light, const Vec3& point, const Vec3& normal) {
  const Vec3 n = Normalized(normal);
  const Vec3 c = ToVec3(light.center), u = ToVec3(light.u_axis) * light.half_u, v = ToVec3(light.v_axis) * light.half_v;
  const Vec3 light_n = Normalized(Cross(ToVec3(light.u_axis), ToVec3(light.v_axis)));
  if (!light.two_sided && Dot(point - c, light_n) <= 0) return {0, 0, 0};
  const std::array<Vec3, 4> corners = {c - u - v, c + u - v, c + u + v, c - u + v};
  std::array<Vec3, 4> dirs;
  for (int i = 0; i < 4; ++i) {
    const Vec3 rel = corners[i] - point;
    NERFAR_CHECK_GT(Dot(rel, n), 0.0);  // the whole polygon above the tangent plane
    dirs[i] = Normalized(rel);
  }
  double sum = 0;
  for (int i = 0; i < 4; ++i) {
    const Vec3& a = dirs[i];
    const Vec3& b = dirs[(i + 1) % 4];
    const Vec3 cr = Cross(a, b);
    const double len = Length(cr);
    if (len <= 0) continue;
    const double angle = std::atan2(len, Dot(a, b));
    sum += angle * Dot(n, cr / len);
  }
  return ToVec3(light.radiance) * (0.5 * std::fabs(sum));
}

ImageF ReferenceProbe(const Scene& lights, const Vec3& point, int width, int height, int supersample) {
  NERFAR_CHECK(width > 0 && height > 0 && supersample > 0);
  ImageF image(width, height, 3, 0.0f);
  ParallelFor(image.PixelCount(), [&](size_t index) {
    const int i = static_cast<int>(index % width), j = static_cast<int>(index / width);
    Vec3 sum{0, 0, 0};
    for (int a = 0; a < supersample; ++a)
      for (int b = 0; b < supersample; ++b) {
        const Vec3 d = EquirectDirection((i + (b + 0.5) / supersample) / width, (j + (a + 0.5) / supersample) / height);
        double best = std::numeric_limits<double>::infinity();
        Vec3 radiance = ToVec3(lights.EnvironmentRadiance(Vec3f(d)));
        for (const SphereLight& l : lights.sphere_lights) {
          const Vec3 oc = point - ToVec3(l.center);
          const double bb = Dot(oc, d), cc = Dot(oc, oc) - double(l.radius) * l.radius;
          const double disc = bb * bb - cc;
          if (disc < 0) continue;
          const double t = -bb - std::sqrt(disc);
          if (t > 0 && t < best) best = t, radiance = ToVec3(l.radiance);
        }
        for (const RectangleLight& l : lights.rectangle_lights) {
          const Vec3 ln = Cross(ToVec3(l.u_axis), ToVec3(l.v_axis));
          const double denom = Dot(d, ln);
          if (denom == 0) continue;
          const double t = Dot(ToVec3(l.center) - point, ln) / denom;
          if (!(t > 0 && t < best)) continue;
          const Vec3 q = point + d * t - ToVec3(l.center);
          if (std::fabs(Dot(q, ToVec3(l.u_axis))) > l.half_u || std::fabs(Dot(q, ToVec3(l.v_axis))) > l.half_v)
            continue;
          best = t;
          radiance = (denom < 0 || l.two_sided) ? ToVec3(l.radiance) : Vec3{0, 0, 0};
        }
        for (const BoxLight& l : lights.box_lights) {
          const double c = std::cos(l.yaw_rad), s = std::sin(l.yaw_rad);
          const Vec3 o = point - ToVec3(l.center);
          const Vec3 ol{c * o.x + s * o.y, -s * o.x + c * o.y, o.z}, dl{c * d.x + s * d.y, -s * d.x + c * d.y, d.z};
          double t0 = -std::numeric_limits<double>::infinity(), t1 = std::numeric_limits<double>::infinity();
          for (int k = 0; k < 3; ++k) {
            const double h = l.half_size[k];
            if (dl[k] == 0) {
              if (std::fabs(ol[k]) > h) t0 = std::numeric_limits<double>::infinity();
              continue;
            }
            double ta = (-h - ol[k]) / dl[k], tb = (h - ol[k]) / dl[k];
            if (ta > tb) std::swap(ta, tb);
            t0 = std::max(t0, ta);
            t1 = std::min(t1, tb);
          }
          if (t0 <= t1 && t0 > 0 && t0 < best) best = t0, radiance = ToVec3(l.radiance);
        }
        sum += radiance;
      }
    const double count = static_cast<double>(supersample) * supersample;
    float* p = image.Pixel(i, j);
    p[0] = static_cast<float>(sum.x / count);
    p[1] = static_cast<float>(sum.y / count);
    p[2] = static_cast<float>(sum.z / count);
  });
  return image;
}

}  // namespace nerfar::synth
