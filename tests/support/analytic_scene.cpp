#include "tests/support/analytic_scene.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "calib/core/error.h"

namespace nerfar::testing {

namespace {

// Nearest t in [lo, hi] where the ray enters the sphere (or where it already is
// inside at lo). Returns false if the ray does not touch it in that range.
bool SphereSpan(const Vec3& c, double r, const Vec3& o, const Vec3& d, double lo, double hi, double& a, double& b) {
  const Vec3 oc = o - c;
  const double dd = Dot(d, d);
  const double half_b = Dot(oc, d);
  const double cc = Dot(oc, oc) - r * r;
  const double disc = half_b * half_b - dd * cc;
  if (disc < 0.0 || dd == 0.0) return false;
  const double s = std::sqrt(disc);
  a = std::max(lo, (-half_b - s) / dd);
  b = std::min(hi, (-half_b + s) / dd);
  return a < b;
}

}  // namespace

Vec3f AnalyticScene::PlaneRadiance(const Vec3& p) const {
  if (params_.checker_size_m <= 0.0f) return params_.plane_radiance;
  const long ix = static_cast<long>(std::floor(p.x / params_.checker_size_m));
  const long iy = static_cast<long>(std::floor(p.y / params_.checker_size_m));
  const float f = ((ix + iy) & 1) != 0 ? 1.2f : 0.8f;
  return params_.plane_radiance * f;
}

double AnalyticScene::FirstHit(const Vec3& o, const Vec3& d, double t0, double t1, Vec3f* radiance) const {
  double t_hit = std::numeric_limits<double>::infinity();
  if (d.z != 0.0) {
    const double t = -o.z / d.z;
    const Vec3 p = o + d * t;
    if (t >= t0 && t <= t1 && p.x >= params_.box.min.x && p.x <= params_.box.max.x && p.y >= params_.box.min.y &&
        p.y <= params_.box.max.y) {
      t_hit = t;
      *radiance = PlaneRadiance(p);
    }
  }
  double a = 0, b = 0;
  if (params_.has_sphere && SphereSpan(params_.sphere_center, params_.sphere_radius, o, d, t0, t1, a, b) && a < t_hit) {
    t_hit = a;
    *radiance = params_.sphere_radiance;
  }
  return t_hit;
}

void AnalyticScene::TransmittanceDepths(const SceneRays& rays, const std::vector<float>& transmittance,
                                        std::vector<float>& depth) const {
  NERFAR_CHECK_EQ(transmittance.size(), rays.size());
  depth.resize(rays.size());
  for (size_t i = 0; i < rays.size(); ++i) {
    const Vec3 o(rays.origins[i]), d(rays.directions[i]);
    const double t0 = rays.t_near[i], t1 = rays.t_far[i];
    Vec3f unused;
    const double t_hit = FirstHit(o, d, t0, t1, &unused);
    // The medium before the hit: T(t) = exp(−σ(t − a)) on [a, b], reaching
    // the level at a + ln(1/level)/σ; else the opaque hit takes T to 0.
    double t_level = t_hit;
    double a = 0, b = 0;
    if (params_.has_medium &&
        SphereSpan(params_.medium_center, params_.medium_radius, o, d, t0, std::min(t1, t_hit), a, b)) {
      const double t = a - std::log(double(transmittance[i])) / (params_.medium_density * Length(d));
      if (t <= b) t_level = t;
    }
    depth[i] = static_cast<float>(std::isfinite(t_level) && t_level <= t1 ? t_level : t1);
  }
}

void AnalyticScene::RenderOne(const Vec3& o, const Vec3& d, double t0, double t1, Vec3& colour, double& opacity,
                              double& depth) const {
  // Accumulates the paper's unnormalised D̂ = Σ T α t; RenderRays normalises.
  colour = {};
  opacity = 0.0;
  depth = 0.0;
  if (!(t1 > t0)) return;
  Vec3f hit_radiance{};
  const double t_hit = FirstHit(o, d, t0, t1, &hit_radiance);
  double a = 0, b = 0;
  const double end = std::min(t1, t_hit);
  double transmittance = 1.0;
  if (params_.has_medium && SphereSpan(params_.medium_center, params_.medium_radius, o, d, t0, end, a, b)) {
    // Homogeneous medium on [a, b]: T(t) = exp(-σ(t - a)); closed-form integrals of σT and σT·t.
    const double sigma = params_.medium_density * Length(d);  // density per unit of t
    const double len = b - a;
    const double absorbed = -std::expm1(-sigma * len);  // 1 - e^{-σL}
    const double mean_offset = sigma > 0.0 ? (absorbed / sigma - len * std::exp(-sigma * len)) : 0.0;
    colour = Vec3(params_.medium_radiance) * absorbed;
    opacity = absorbed;
    depth = a * absorbed + mean_offset;
    transmittance = 1.0 - absorbed;
  }
  if (t_hit <= t1) {
    colour += Vec3(hit_radiance) * transmittance;
    opacity += transmittance;
    depth += transmittance * t_hit;
  }
}

void AnalyticScene::RenderRays(const SceneRays& rays, SceneSamples& out) const {
  NERFAR_CHECK_EQ(rays.directions.size(), rays.size());
  NERFAR_CHECK_EQ(rays.t_near.size(), rays.size());
  NERFAR_CHECK_EQ(rays.t_far.size(), rays.size());
  out.Resize(rays.size());
  for (size_t i = 0; i < rays.size(); ++i) {
    Vec3 colour;
    double opacity = 0, depth = 0;
    RenderOne(Vec3(rays.origins[i]), Vec3(rays.directions[i]), rays.t_near[i], rays.t_far[i], colour, opacity, depth);
    out.colour[i] = Vec3f(colour);
    out.opacity[i] = static_cast<float>(opacity);
    out.depth[i] = opacity > 0.0 ? static_cast<float>(depth / opacity) : 0.0f;
  }
}

void AnalyticScene::Normals(const std::vector<Vec3f>& points, std::vector<Vec3f>& normals) const {
  normals.assign(points.size(), Vec3f{});
  // The nearest of the three surfaces within 5 cm gives the normal (a NeRF's
  // density gradient is likewise only meaningful near a surface).
  constexpr double kReach = 0.05;
  for (size_t i = 0; i < points.size(); ++i) {
    const Vec3 p(points[i]);
    double best = kReach;
    Vec3 n{};
    if (p.x >= params_.box.min.x && p.x <= params_.box.max.x && p.y >= params_.box.min.y && p.y <= params_.box.max.y &&
        std::abs(p.z) < best) {
      best = std::abs(p.z);
      n = {0, 0, p.z >= -1e-4 ? 1.0 : -1.0};  // points marched onto the top may round to just below it
    }
    if (params_.has_sphere) {
      const double dist = std::abs(Length(p - params_.sphere_center) - params_.sphere_radius);
      if (dist < best) {
        best = dist;
        n = Normalized(p - params_.sphere_center);
      }
    }
    if (params_.has_medium) {
      const double dist = std::abs(Length(p - params_.medium_center) - params_.medium_radius);
      if (dist < best) {
        best = dist;
        n = Normalized(p - params_.medium_center);
      }
    }
    normals[i] = Vec3f(n);
  }
}

}  // namespace nerfar::testing
