// The analytic acceptance tests of the environment estimate: a table
// with a box standing on it, Lambertian, lit by distant discs of known
// direction, size and radiance over a dim uniform sky (or by a lamp inside
// the volume). The scene's radiance is computed here, independently of the
// estimator: each surface point's direct light by quadrature over each
// disc's solid angle with exact ray-box visibility (so the box's shadow has
// its true penumbra), the sky and the interreflections by cosine-weighted
// quadrature over the hemisphere (two bounces, from a 1 cm patch grid). The
// estimate is judged against the known light: the light within a cone
// around each source (direction, energy, colour), the colour of every lobe,
// and the negligible flag.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include "calib/core/log.h"
#include "calib/core/parallel.h"
#include "render/lighting/env_estimate.h"
#include "render/lighting/incident_light.h"
#include "render/sg/sg.h"
#include "render/sg/sphere.h"
#include "tests/support/analytic_field.h"

namespace nerfar {
namespace {

using testing::BoxShape;
using testing::MakeField;
using testing::Shape;
using testing::SphereShape;

constexpr double kDeg = kPi / 180;
constexpr double kGoldenAngle = 2.39996322972865332;  // π(3 − √5): turns successive rings and points apart

Vec3 FromElevationAzimuth(double elevation_deg, double azimuth_deg) {
  const double el = elevation_deg * kDeg, az = azimuth_deg * kDeg;
  return {std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)};
}

// A unit vector's two perpendicular unit vectors (a right-handed frame).
void Perpendiculars(const Vec3& n, Vec3* t1, Vec3* t2) {
  *t1 = Normalized(Cross(std::fabs(n.z) < 0.9 ? Vec3{0, 0, 1} : Vec3{1, 0, 0}, n));
  *t2 = Cross(n, *t1);
}

double ConeSolidAngle(double half_angle_rad) { return 2 * kPi * (1 - std::cos(half_angle_rad)); }

// Directions filling a cone of half-angle `radius` about `axis`, each
// standing for the same solid angle (rings equal in solid angle, each turned
// by the golden angle): the quadrature of a uniform disc source.
std::vector<Vec3> ConeDirections(const Vec3& axis, double radius, int rings = 12, int around = 24) {
  Vec3 t1, t2;
  Perpendiculars(axis, &t1, &t2);
  std::vector<Vec3> dirs;
  for (int i = 0; i < rings; ++i) {
    const double c = 1 - (i + 0.5) / rings * (1 - std::cos(radius)), s = std::sqrt(std::max(0.0, 1 - c * c));
    for (int j = 0; j < around; ++j) {
      const double phi = 2 * kPi * (j + 0.5) / around + kGoldenAngle * i;
      dirs.push_back(axis * c + (t1 * std::cos(phi) + t2 * std::sin(phi)) * s);
    }
  }
  return dirs;
}

// A distant disc of uniform radiance: a sun, or a lamp far from the table.
struct DistantDisc {
  Vec3 direction;          // unit, towards the source
  double radius_deg;       // angular radius
  Vec3 normal_irradiance;  // E⊥ = radiance × solid angle (RGB)
};

// The scene: a table slab (top at z = 0) with a box standing on it, both
// Lambertian; distant light from discs added to a uniform sky over the upper
// hemisphere (nothing below the horizon); optionally a uniformly emitting
// sphere (a lamp) inside the volume, which reflects nothing.
struct Tabletop {
  Aabb table{{-0.35, -0.35, -0.03}, {0.35, 0.35, 0}};
  Aabb box{{0.05, 0.03, 0}, {0.15, 0.13, 0.2}};
  Vec3 table_albedo{0.5, 0.5, 0.5}, box_albedo{0.5, 0.5, 0.5};
  std::vector<DistantDisc> discs;
  Vec3 sky;  // radiance from every direction above the horizon
  Vec3 lamp_centre;
  double lamp_radius = 0;  // 0: no lamp
  Vec3 lamp_radiance;
};

// The NeRF volume round the table (1 cm voxels: the 20 cm box is 20 voxels tall).
const Aabb kVolume{{-0.4, -0.4, -0.06}, {0.4, 0.4, 0.3}};
constexpr double kVoxel = 0.01;

enum class Surface { kNone, kTable, kBox, kLamp, kInside };

// Surface points closer than this to a face count as on it (the grid's
// vertices lie on the faces up to float rounding).
constexpr double kSkin = 1e-6;

// Ray x + t·d against an axis-aligned box: the entry distance and the entry
// face's axis; a start inside (deeper than kSkin) gives a negative distance,
// a start on a face 0 unless the ray leaves through it.
bool RayBox(const Aabb& b, const Vec3& x, const Vec3& d, double* t, int* axis) {
  double t_near = -1e300, t_far = 1e300;
  int near_axis = 0;
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0) {
      if (x[a] < b.min[a] || x[a] > b.max[a]) return false;
      continue;
    }
    double t0 = (b.min[a] - x[a]) / d[a], t1 = (b.max[a] - x[a]) / d[a];
    if (t0 > t1) std::swap(t0, t1);
    if (t0 > t_near) t_near = t0, near_axis = a;
    t_far = std::min(t_far, t1);
  }
  if (t_near > t_far || t_far <= kSkin) return false;
  double depth = 1e300;  // how far inside x lies (when it does)
  for (int a = 0; a < 3; ++a) depth = std::min({depth, x[a] - b.min[a], b.max[a] - x[a]});
  *t = t_near >= 0 ? t_near : (depth > kSkin ? -depth : 0.0);
  *axis = near_axis;
  return true;
}

struct Hit {
  Surface surface = Surface::kNone;
  double t = 1e300;
  Vec3 point, normal;
};

// The first surface along x + t·d (t ≥ 0); kInside when x lies inside a solid.
Hit FirstHit(const Tabletop& s, const Vec3& x, const Vec3& d) {
  Hit hit;
  const std::pair<const Aabb*, Surface> solids[2] = {{&s.table, Surface::kTable}, {&s.box, Surface::kBox}};
  for (const auto& [box, surface] : solids) {
    double t;
    int axis;
    if (!RayBox(*box, x, d, &t, &axis) || std::max(t, 0.0) >= hit.t) continue;
    hit.surface = t < 0 ? Surface::kInside : surface;
    hit.t = std::max(t, 0.0);
    hit.normal = Vec3{};
    hit.normal[axis] = d[axis] > 0 ? -1 : 1;
  }
  if (s.lamp_radius > 0) {
    const Vec3 oc = x - s.lamp_centre;
    const double b = Dot(oc, d), c = Dot(oc, oc) - s.lamp_radius * s.lamp_radius, disc = b * b - c;
    if (disc > 0 && -b - std::sqrt(disc) > 1e-9 && -b - std::sqrt(disc) < hit.t) {
      hit.surface = Surface::kLamp;
      hit.t = -b - std::sqrt(disc);
    }
  }
  hit.point = x + d * hit.t;
  return hit;
}

// Does a solid cover the surface point x (normal n)? (The box's foot and
// the table top under it.)
bool Covered(const Tabletop& s, const Vec3& x, const Vec3& n) {
  const Vec3 out = x + n * (10 * kSkin);
  for (const Aabb* b : {&s.table, &s.box})
    if (out.x > b->min.x + kSkin && out.x < b->max.x - kSkin && out.y > b->min.y + kSkin && out.y < b->max.y - kSkin &&
        out.z > b->min.z + kSkin && out.z < b->max.z - kSkin)
      return true;
  return false;
}

// The scene's visible surface as a Shape: the signed distance to the union
// of the solids, and each point's nearest surface point that no solid
// covers. (Projecting onto the nearest solid instead gives the grid vertices
// round the box's foot the colour of covered, unlit points, which the
// grid's log-colour interpolation spreads as a dark rim.)
Shape VisibleSurface(const Tabletop& s) {
  std::vector<Shape> solids = {BoxShape(s.table), BoxShape(s.box)};
  if (s.lamp_radius > 0) solids.push_back(SphereShape(s.lamp_centre, s.lamp_radius));
  Shape visible;
  visible.sd = [solids](const Vec3& p) {
    double sd = 1e300;
    for (const Shape& solid : solids) sd = std::min(sd, solid.sd(p));
    return sd;
  };
  visible.project = [s, solids](const Vec3& p, Vec3* x, Vec3* n) {
    double best = 1e300;
    auto consider = [&](const Vec3& q, const Vec3& normal) {
      if (Length(q - p) < best && !Covered(s, q, normal)) best = Length(q - p), *x = q, *n = normal;
    };
    for (const Aabb* b : {&s.table, &s.box})
      for (int face = 0; face < 6; ++face) {
        const int axis = face / 2;
        Vec3 q{std::clamp(p.x, b->min.x, b->max.x), std::clamp(p.y, b->min.y, b->max.y),
               std::clamp(p.z, b->min.z, b->max.z)};
        Vec3 normal;
        q[axis] = face % 2 ? b->max[axis] : b->min[axis];
        normal[axis] = face % 2 ? 1 : -1;
        consider(q, normal);
      }
    if (s.lamp_radius > 0) {
      Vec3 q, normal;
      solids[2].project(p, &q, &normal);
      consider(q, normal);
    }
  };
  return visible;
}

// Radiance leaving the table and the box, piecewise constant over ~1 cm
// patches on each face of each: the light of the previous bounce.
class Patches {
 public:
  explicit Patches(const Tabletop& s) {
    for (int solid = 0; solid < 2; ++solid)
      for (int face = 0; face < 6; ++face) {
        Face f{solid == 0 ? s.table : s.box, solid, face / 2, face % 2 ? 1 : -1, 0, 0, values_.size()};
        f.nu = Cells(f.box, (f.axis + 1) % 3);
        f.nv = Cells(f.box, (f.axis + 2) % 3);
        values_.resize(values_.size() + f.nu * f.nv);
        faces_.push_back(f);
      }
  }
  size_t size() const { return values_.size(); }
  // Centre and outward normal of patch i.
  void Patch(size_t i, Vec3* centre, Vec3* normal) const {
    const Face& f = FaceOf(i);
    const int cell = static_cast<int>(i - f.first), u = (f.axis + 1) % 3, v = (f.axis + 2) % 3;
    *centre = f.box.min;
    (*centre)[f.axis] = f.sign > 0 ? f.box.max[f.axis] : f.box.min[f.axis];
    (*centre)[u] += (cell % f.nu + 0.5) * (f.box.max[u] - f.box.min[u]) / f.nu;
    (*centre)[v] += (cell / f.nu + 0.5) * (f.box.max[v] - f.box.min[v]) / f.nv;
    *normal = Vec3{};
    (*normal)[f.axis] = f.sign;
  }
  Vec3& operator[](size_t i) { return values_[i]; }
  // The radiance at a hit on the table or the box.
  Vec3 At(const Hit& hit) const {
    const int solid = hit.surface == Surface::kTable ? 0 : 1;
    for (const Face& f : faces_) {
      if (f.solid != solid || hit.normal[f.axis] != f.sign) continue;
      const int u = (f.axis + 1) % 3, v = (f.axis + 2) % 3;
      const Aabb& b = f.box;
      const int iu =
          std::clamp(static_cast<int>((hit.point[u] - b.min[u]) / (b.max[u] - b.min[u]) * f.nu), 0, f.nu - 1);
      const int iv =
          std::clamp(static_cast<int>((hit.point[v] - b.min[v]) / (b.max[v] - b.min[v]) * f.nv), 0, f.nv - 1);
      return values_[f.first + iv * f.nu + iu];
    }
    return {};
  }

 private:
  struct Face {
    Aabb box;
    int solid, axis, sign, nu, nv;
    size_t first;
  };
  static int Cells(const Aabb& b, int axis) {
    return std::max(1, static_cast<int>(std::ceil((b.max[axis] - b.min[axis]) / kVoxel - 1e-9)));
  }
  const Face& FaceOf(size_t i) const {
    for (const Face& f : faces_)
      if (i < f.first + f.nu * f.nv) return f;
    return faces_.back();
  }
  std::vector<Face> faces_;
  std::vector<Vec3> values_;
};

// Direct irradiance at x (normal n) from the discs and the lamp: quadrature
// over each source's solid angle (288 directions of equal solid angle) with
// exact visibility.
Vec3 DirectIrradiance(const Tabletop& s, const Vec3& x, const Vec3& n) {
  const Vec3 origin = x + n * 1e-7;
  Vec3 e;
  for (const DistantDisc& disc : s.discs) {
    const std::vector<Vec3> dirs = ConeDirections(disc.direction, disc.radius_deg * kDeg);
    for (const Vec3& d : dirs)
      if (Dot(n, d) > 0 && FirstHit(s, origin, d).surface == Surface::kNone)
        e += disc.normal_irradiance * (Dot(n, d) / dirs.size());
  }
  if (s.lamp_radius > 0) {
    const Vec3 to = s.lamp_centre - x;
    const double half_angle = std::asin(std::min(1.0, s.lamp_radius / Length(to)));
    const std::vector<Vec3> dirs = ConeDirections(Normalized(to), half_angle);
    for (const Vec3& d : dirs)
      if (Dot(n, d) > 0 && FirstHit(s, origin, d).surface == Surface::kLamp)
        e += s.lamp_radiance * (Dot(n, d) * ConeSolidAngle(half_angle) / dirs.size());
  }
  return e;
}

// Cosine-distributed directions about +z (a Fibonacci disk lifted to the
// hemisphere): E = π/N Σ L(d_j).
std::vector<Vec3> CosineHemisphere(int count) {
  std::vector<Vec3> dirs;
  for (int i = 0; i < count; ++i) {
    const double r = std::sqrt((i + 0.5) / count), phi = kGoldenAngle * i;
    dirs.push_back({r * std::cos(phi), r * std::sin(phi), std::sqrt(1 - r * r)});
  }
  return dirs;
}

// Irradiance at x (normal n) from the sky and from the table's and box's
// radiance `bounce` (none on the first pass), by cosine-weighted quadrature.
// The lamp and the discs are left to DirectIrradiance.
Vec3 GatheredIrradiance(const Tabletop& s, const Patches* bounce, const Vec3& x, const Vec3& n, int rays) {
  static const std::map<int, std::vector<Vec3>> sets = {{256, CosineHemisphere(256)}, {1024, CosineHemisphere(1024)}};
  Vec3 t1, t2;
  Perpendiculars(n, &t1, &t2);
  const Vec3 origin = x + n * 1e-7;
  Vec3 sum;
  for (const Vec3& l : sets.at(rays)) {
    const Vec3 d = t1 * l.x + t2 * l.y + n * l.z;
    const Hit hit = FirstHit(s, origin, d);
    if (hit.surface == Surface::kNone && d.z > 0) sum += s.sky;
    if (bounce && (hit.surface == Surface::kTable || hit.surface == Surface::kBox)) sum += bounce->At(hit);
  }
  return sum * (kPi / rays);
}

// The albedo at surface point x with normal n (axis-aligned): the box's on
// its faces (its foot included), the table's elsewhere.
Vec3 AlbedoAt(const Tabletop& s, const Vec3& x, const Vec3& n) {
  const Aabb& b = s.box;
  for (int a = 0; a < 3; ++a) {
    if (n[a] == 0) {
      if (x[a] < b.min[a] - kSkin || x[a] > b.max[a] + kSkin) return s.table_albedo;
    } else if (std::fabs(x[a] - (n[a] > 0 ? b.max[a] : b.min[a])) > kSkin) {
      return s.table_albedo;
    }
  }
  return s.box_albedo;
}

// Radiance leaving each patch after `passes` bounces of light (pass 0: direct and sky only).
Patches BounceLight(const Tabletop& s, int passes) {
  Patches light(s), previous(s);
  for (int pass = 0; pass <= passes; ++pass) {
    ParallelFor(light.size(), [&](size_t i) {
      Vec3 x, n;
      light.Patch(i, &x, &n);
      const Vec3 e = DirectIrradiance(s, x, n) + GatheredIrradiance(s, pass ? &previous : nullptr, x, n, 256);
      light[i] = AlbedoAt(s, x, n) * e * (1 / kPi);
    });
    previous = light;
  }
  return light;
}

// The scene as a NeRF grid: each vertex near a surface shows the radiance of
// its nearest visible surface point, computed there (direct light exactly,
// sky and two bounces by 1024-ray quadrature). The third and later bounces
// are left out: with albedo 0.5 and view factors under one half each adds
// under (1/4)³ ≈ 1.6 % of the direct light, and far less on most points.
NerfField TabletopField(const Tabletop& s) {
  const Patches bounce = BounceLight(s, 1);
  std::map<std::array<double, 6>, Vec3> known;  // vertices that share their surface point
  return MakeField(kVolume, kVoxel, VisibleSurface(s), [&](const Vec3& x, const Vec3& n) {
    if (s.lamp_radius > 0 && Length(x - s.lamp_centre) < s.lamp_radius + 1e-9) return s.lamp_radiance;
    const std::array<double, 6> key = {x.x, x.y, x.z, n.x, n.y, n.z};
    const auto it = known.find(key);
    if (it != known.end()) return it->second;
    const Vec3 e = DirectIrradiance(s, x, n) + GatheredIrradiance(s, &bounce, x, n, 1024);
    return known[key] = AlbedoAt(s, x, n) * e * (1 / kPi);
  });
}

// The estimator's options for these tests: the balanced preset with 40
// views instead of 100 (measured on the 2.5° sun: 2560 surface samples
// instead of 6400, 213 of them on the box, whose lit and shaded faces fix
// the light's direction by their shading alone, and 54 in its shadow),
// BRISQUE off (flat synthetic renders are not natural images) and the
// near-field rays leaving one voxel above the surface rather than four (the
// grid's surfaces are sharp; four voxels would lift the visibility origins
// 4 cm, a fifth of the way up the box).
EnvEstimateOptions SourcesOptions() {
  EnvEstimateOptions o = EnvEstimateOptions::Preset("balanced");
  o.views = 40;
  o.brisque_max = 100;
  o.ray_offset_voxels = 1;
  return o;
}

// The estimate's light within a cone: ∫_cone L dω (RGB) and the luminance-
// weighted first moment ∫_cone Y(L) d dω. Each lobe is integrated in its own
// frame by 128 x 128 points of equal weight (inverse CDF of its falloff in
// 1 − cos ψ), exact for any sharpness up to the cone edge's quadrature.
struct ConeLight {
  Vec3 energy, moment;
};
ConeLight LightInCone(const SgMixture& lobes, const Vec3& centre, double radius_rad) {
  constexpr int kRadial = 128, kAround = 128;
  const double cos_r = std::cos(radius_rad);
  ConeLight out;
  for (const Sg& g : lobes) {
    Vec3 t1, t2;
    Perpendiculars(g.axis, &t1, &t2);
    const double weight = SgUnitIntegral(g.sharpness) / (kRadial * kAround);
    const double spread = -std::expm1(-2 * g.sharpness);  // 1 − e^{−2λ}
    for (int i = 0; i < kRadial; ++i) {
      const double q = (i + 0.5) / kRadial;
      const double u = g.sharpness > 0 ? -std::log1p(-q * spread) / g.sharpness : 2 * q;  // 1 − cos ψ
      const double c = 1 - u, s = std::sqrt(std::max(0.0, 1 - c * c));
      for (int j = 0; j < kAround; ++j) {
        const double phi = 2 * kPi * (j + 0.5) / kAround;
        const Vec3 d = g.axis * c + (t1 * std::cos(phi) + t2 * std::sin(phi)) * s;
        if (Dot(d, centre) < cos_r) continue;
        out.energy += g.amplitude * weight;
        out.moment += d * (LuminanceOf(g.amplitude) * weight);
      }
    }
  }
  return out;
}

// A source as the estimate has it: its light within `radius` of its centre,
// the centre found by moving the cone to the light's centroid (starting at
// the true direction; 8 steps move it onto a lobe up to ~a radius away).
struct FoundSource {
  Vec3 direction, energy;
};
FoundSource FindSource(const SgMixture& lobes, const Vec3& start, double radius_rad) {
  Vec3 centre = start;
  for (int step = 0; step < 8; ++step) {
    const ConeLight in = LightInCone(lobes, centre, radius_rad);
    if (LuminanceOf(in.energy) <= 0) break;
    centre = Normalized(in.moment);
  }
  return {centre, LightInCone(lobes, centre, radius_rad).energy};
}

double AngleDeg(const Vec3& a, const Vec3& b) { return std::acos(std::clamp(Dot(a, b), -1.0, 1.0)) / kDeg; }

// Each channel over the channels' mean.
Vec3 Chroma(const Vec3& rgb) {
  const double mean = (rgb.x + rgb.y + rgb.z) / 3;
  return mean > 0 ? rgb / mean : Vec3{1, 1, 1};
}
double ChromaDeviation(const Vec3& rgb) {
  const Vec3 c = Chroma(rgb);
  return std::max({std::fabs(c.x - 1), std::fabs(c.y - 1), std::fabs(c.z - 1)});
}
// Each lobe's chroma deviation, weighted by its energy (luminance of ∫ G).
double LobeChromaDeviation(const SgMixture& lobes) {
  double sum = 0, weight = 0;
  for (const Sg& g : lobes) {
    const double e = LuminanceOf(Integral(g));
    sum += e * ChromaDeviation(g.amplitude);
    weight += e;
  }
  return weight > 0 ? sum / weight : 0;
}

// The cone a source is judged in: 10° beyond its rim. It holds the whole
// source (an SG as wide as the disc keeps > 99 % of its energy in it) and
// little sky (the sky's share is added to the truth); light spread wider
// than this would cast a shadow several times softer than the true one.
double JudgingRadius(const DistantDisc& disc) { return (disc.radius_deg + 10) * kDeg; }

// The true light in that cone: the disc plus the sky it covers.
Vec3 TrueLightInCone(const Tabletop& s, const DistantDisc& disc) {
  return disc.normal_irradiance + s.sky * ConeSolidAngle(JudgingRadius(disc));
}

struct SourceResult {
  double error_deg, energy_ratio;
  Vec3 chroma;
  // For the log: the estimate's light within 30° of the source over the
  // truth's there (how much of the source a broad estimate holds nearby).
  double energy_ratio_30deg;
};
SourceResult JudgeSource(const Tabletop& s, const DistantDisc& disc, const EnvLight& est) {
  const FoundSource found = FindSource(est.lobes, disc.direction, JudgingRadius(disc));
  const double wide = 30 * kDeg;
  const double wide_truth = LuminanceOf(disc.normal_irradiance + s.sky * ConeSolidAngle(wide));
  return {AngleDeg(found.direction, disc.direction), LuminanceOf(found.energy) / LuminanceOf(TrueLightInCone(s, disc)),
          Chroma(found.energy), LuminanceOf(LightInCone(est.lobes, disc.direction, wide).energy) / wide_truth};
}

// The estimate's five most energetic lobes (sharpness, elevation and
// azimuth in degrees, luminance of ∫ G), for the log.
std::string Describe(const EnvLight& est) {
  SgMixture lobes = est.lobes;
  std::sort(lobes.begin(), lobes.end(),
            [](const Sg& a, const Sg& b) { return LuminanceOf(Integral(a)) > LuminanceOf(Integral(b)); });
  std::string text = std::to_string(est.lobes.size()) + " lobes, brightest:";
  for (size_t k = 0; k < std::min<size_t>(5, lobes.size()); ++k) {
    const Sg& g = lobes[k];
    char line[160];
    std::snprintf(line, sizeof line, " [λ %.0f, el %.1f, az %.1f, %.3f]", g.sharpness,
                  std::asin(std::clamp(g.axis.z, -1.0, 1.0)) / kDeg, std::atan2(g.axis.y, g.axis.x) / kDeg,
                  LuminanceOf(Integral(g)));
    text += line;
  }
  return text;
}

// A sun at elevation 40°, azimuth 30° (the box's shadow, 24 cm long, falls
// on the table) over a sky of radiance 0.15: the sun gives the table 6.8x
// the sky's irradiance, as a sunny day through a window.
Tabletop SunnyTable(double sun_radius_deg) {
  Tabletop s;
  s.discs = {DistantDisc{FromElevationAzimuth(40, 30), sun_radius_deg, Vec3{5, 5, 5}}};
  s.sky = {0.15, 0.15, 0.15};
  return s;
}

// Direction within 2° and energy within 15 % (the figures): a 2°
// error moves the 24 cm shadow's tip by ~1.3 cm (its edge by a voxel), and
// 15 % is what a shadow's depth may be off before it looks wrong. The light
// is neutral, so every lobe must be neutral too (chroma within 5 %: the
// scene's albedos are grey and nothing in it is coloured).
void ExpectSunFound(const Tabletop& s, const std::string& name) {
  EnvEstimateReport report;
  const EnvLight est = EstimateEnvironment(TabletopField(s), SourcesOptions(), &report);
  const SourceResult sun = JudgeSource(s, s.discs[0], est);
  const double lobe_chroma = LobeChromaDeviation(est.lobes);
  LogInfo(name + ": direction error " + std::to_string(sun.error_deg) + "°, energy ratio " +
          std::to_string(sun.energy_ratio) + " (within 30°: " + std::to_string(sun.energy_ratio_30deg) +
          "), lobe chroma deviation " + std::to_string(lobe_chroma) + "; " + Describe(est));
  EXPECT_FALSE(est.negligible);
  EXPECT_LT(sun.error_deg, 2.0) << name;
  EXPECT_NEAR(sun.energy_ratio, 1.0, 0.15) << name;
  EXPECT_LT(ChromaDeviation(Integral(est.lobes)), 0.05) << name;
  EXPECT_LT(lobe_chroma, 0.05) << name;
  // Where the sun's evidence lies (SourceSupport): it lights the whole 70 cm
  // table but for the box's shadow (a twentieth of it), and every sunlit
  // sample gains alike from it, so about half of them hold half its gain.
  // A fifth (half that, for gains uneven over the albedo cells and the box's
  // faces) is far above a patch's share; and half the samples cannot lie
  // within 0.2 m of one point, a disc that covers a quarter of the table.
  int sources = 0;
  for (const SourceSupport& support : report.fit.lobe_support) {
    if (!(support.half_share > 0)) continue;
    ++sources;
    EXPECT_GT(support.half_share, 0.2) << name;
    EXPECT_GT(support.radius_m, 0.2) << name;
  }
  EXPECT_GE(sources, 1) << name;
}

// The scene's light itself against closed forms, so that the tests below
// judge the estimator against the right truth. A uniform disc of angular
// radius r wholly above the horizon, θ from the normal, gives
// E = L π sin²r cos θ = E⊥ cos θ (1 + cos r)/2; a uniform sphere seen whole
// the same with sin r = ρ/D; an open sky of radiance L gives π L.
TEST(EnvSources, TheScenesLightMatchesClosedForms) {
  const Tabletop s = SunnyTable(2.5);
  const Vec3 up{0, 0, 1}, box_top{0.1, 0.08, 0.2};
  const double sun_on_table = 5 * std::sin(40 * kDeg) * (1 + std::cos(2.5 * kDeg)) / 2;
  // 1e-4: the ring quadrature of a linear function over the disc is exact up to rounding.
  EXPECT_NEAR(DirectIrradiance(s, box_top, up).y, sun_on_table, 1e-4 * sun_on_table);
  EXPECT_NEAR(GatheredIrradiance(s, nullptr, box_top, up, 1024).y, kPi * 0.15, 1e-9);
  // 15 cm down-sun of the box's centre the sun ray passes the box 12.6 cm up: umbra.
  const Vec3 umbra = Vec3{0.1, 0.08, 0} - FromElevationAzimuth(0, 30) * 0.15;
  EXPECT_EQ(DirectIrradiance(s, umbra, up).y, 0.0);
  // Its sky is cut by the box: less than the open sky's, more than half of it.
  const double umbra_sky = GatheredIrradiance(s, nullptr, umbra, up, 1024).y;
  EXPECT_LT(umbra_sky, kPi * 0.15);
  EXPECT_GT(umbra_sky, 0.5 * kPi * 0.15);
  Tabletop lamp;
  lamp.lamp_centre = {-0.15, -0.12, 0.2};
  lamp.lamp_radius = 0.04;
  lamp.lamp_radiance = {40, 40, 40};
  const double under_lamp = kPi * 40 * std::pow(0.04 / 0.2, 2);
  EXPECT_NEAR(DirectIrradiance(lamp, {-0.15, -0.12, 0}, up).y, under_lamp, 1e-4 * under_lamp);
}

// A lamp of 2.5° radius (radiance ~840 against the sky's 0.15).
TEST(EnvSources, FindsAWideSunOverATableWithABox) { ExpectSunFound(SunnyTable(2.5), "2.5° sun"); }

// A sun of 0.75° radius (radiance ~9300): sharper than the shadow's voxel
// can tell apart from a point, so only its direction and energy are judged.
TEST(EnvSources, FindsASmallSunOverATableWithABox) { ExpectSunFound(SunnyTable(0.75), "0.75° sun"); }

// Neutral light over coloured surfaces: an orange box on a grey table. The
// estimate must put the colour in the albedo, not in the light: the sum of
// the lobes and every lobe within 5 % of neutral. (A global light colour
// and the inverse albedo colour look the same; the grey table, most of the
// samples, and the grey-world prior fix it. The box's colour reaches the
// table only through its bounce light, which the near field carries.)
TEST(EnvSources, NeutralLightOverColouredSurfacesGivesANeutralEstimate) {
  Tabletop s = SunnyTable(2.5);
  s.box_albedo = {0.7, 0.4, 0.2};
  const EnvLight est = EstimateEnvironment(TabletopField(s), SourcesOptions());
  const Vec3 total = Chroma(Integral(est.lobes));
  const double lobe_chroma = LobeChromaDeviation(est.lobes);
  const SourceResult sun = JudgeSource(s, s.discs[0], est);
  LogInfo("coloured box: total chroma " + std::to_string(total.x) + " " + std::to_string(total.y) + " " +
          std::to_string(total.z) + ", lobe chroma deviation " + std::to_string(lobe_chroma) + ", sun chroma " +
          std::to_string(sun.chroma.x) + " " + std::to_string(sun.chroma.y) + " " + std::to_string(sun.chroma.z) +
          "; " + Describe(est));
  EXPECT_LT(ChromaDeviation(Integral(est.lobes)), 0.05);
  EXPECT_LT(lobe_chroma, 0.05);
  EXPECT_LT(ChromaDeviation(sun.chroma), 0.05);
}

// A small warm key (2° radius, elevation 45°, azimuth 30°) and a large cool
// fill (8° radius, elevation 60°, azimuth 200°, half the key's energy); the
// box shadows both onto the table. Both must be found: the key within 2°
// and 15 % as above; the fill within 4° (its soft shadow places it less
// sharply: half its radius) and 25 % (its cone overlaps more of the sky's
// light, which the estimate may place in either). The fill bluer than red
// (the key's warmth is not yet recovered: the colour step gives the common
// tint to the albedo and the difference to the fill, leaving the key grey).
TEST(EnvSources, FindsTwoLightsOfDifferentSizeAndColour) {
  Tabletop s;
  const DistantDisc key{FromElevationAzimuth(45, 30), 2.0, Vec3{5.0, 4.2, 2.9}};
  const DistantDisc fill{FromElevationAzimuth(60, 200), 8.0, Vec3{1.6, 2.2, 2.9}};
  s.discs = {key, fill};
  s.sky = {0.1, 0.1, 0.1};
  const EnvLight est = EstimateEnvironment(TabletopField(s), SourcesOptions());
  const SourceResult k = JudgeSource(s, key, est), f = JudgeSource(s, fill, est);
  LogInfo("two lights: key error " + std::to_string(k.error_deg) + "°, energy " + std::to_string(k.energy_ratio) +
          " (within 30°: " + std::to_string(k.energy_ratio_30deg) + "), r/b " +
          std::to_string(k.chroma.x / k.chroma.z) + "; fill error " + std::to_string(f.error_deg) + "°, energy " +
          std::to_string(f.energy_ratio) + " (within 30°: " + std::to_string(f.energy_ratio_30deg) + "), r/b " +
          std::to_string(f.chroma.x / f.chroma.z) + " (true r/b " +
          std::to_string(key.normal_irradiance.x / key.normal_irradiance.z) + ", " +
          std::to_string(fill.normal_irradiance.x / fill.normal_irradiance.z) + "); " + Describe(est));
  EXPECT_LT(k.error_deg, 2.0);
  EXPECT_NEAR(k.energy_ratio, 1.0, 0.15);
  EXPECT_LT(f.error_deg, 4.0);
  EXPECT_NEAR(f.energy_ratio, 1.0, 0.25);
  EXPECT_GT(f.chroma.z, f.chroma.x) << "the fill is cool";
}

// A broad distant light (a disc of 15° radius, elevation 40°, azimuth 30°,
// as a window beside the table; it gives the table 4x the sky's irradiance)
// casts soft shadows, as wide as the disc: the estimate must not call it a
// sharp source. No lobe may be sharper than the disc warrants: an SG of the
// disc's solid angle Ω has sharpness 2π/Ω (about 29); the source's size is
// chosen on a ladder of steps of √10 from options.source_sharpness_min, so
// the rung nearest 2π/Ω and the one above it are the sizes the disc can
// honestly be given. The light itself is still found: within a third of the
// disc's radius of its centre (the penumbra's middle then moves by under a
// sixth of its width) and 25 % of its energy (its cone shares the sky's
// light).
TEST(EnvSources, ABroadLightIsNoSharpSource) {
  Tabletop s;
  const DistantDisc window{FromElevationAzimuth(40, 30), 15.0, Vec3{2, 2, 2}};
  s.discs = {window};
  s.sky = {0.1, 0.1, 0.1};
  const EnvEstimateOptions options = SourcesOptions();
  const EnvLight est = EstimateEnvironment(TabletopField(s), options);
  const SourceResult w = JudgeSource(s, window, est);
  double sharpest = 0;
  for (const Sg& g : est.lobes) sharpest = std::max(sharpest, g.sharpness);
  LogInfo("broad light: error " + std::to_string(w.error_deg) + "°, energy " + std::to_string(w.energy_ratio) +
          ", sharpest lobe " + std::to_string(sharpest) + "; " + Describe(est));
  const double disc_solid_angle = 2 * kPi * (1 - std::cos(window.radius_deg * kPi / 180));
  const double rung = std::sqrt(10.0);
  const double nearest_rung =
      options.source_sharpness_min *
      std::pow(rung, std::round(std::log(2 * kPi / disc_solid_angle / options.source_sharpness_min) / std::log(rung)));
  EXPECT_LE(sharpest, nearest_rung * rung * 1.0001);
  EXPECT_LT(w.error_deg, window.radius_deg / 3);
  EXPECT_NEAR(w.energy_ratio, 1.0, 0.25);
}

// All light inside the volume: a lamp (a sphere of 4 cm radius, 20 cm above
// the table, radiance 40: 5 on the table below it) and no distant light at
// all. The estimate written to env.json must say negligible.
TEST(EnvSources, AllLightInsideTheVolumeIsNegligible) {
  Tabletop s;
  s.lamp_centre = {-0.15, -0.12, 0.2};
  s.lamp_radius = 0.04;
  s.lamp_radiance = {40, 40, 40};
  const EnvLight est = EstimateEnvironment(TabletopField(s), SourcesOptions());
  const EnvLight written = ParseEnvLight(SerializeEnvLight(est), "env.json");
  LogInfo("lamp inside: env/near surface " + std::to_string(est.env_to_near_surface) + ", centre " +
          std::to_string(est.env_to_near_center) + ", evidence " + std::to_string(est.evidence) + " of " +
          std::to_string(est.evidence_needed) + "; " + Describe(est));
  EXPECT_TRUE(written.negligible);
}

// A lamp above the table, outside the volume (a sphere of 4 cm radius 70 cm
// up, 40 cm above the volume's top): from one side of the table to the other
// its direction turns by ~50° and its irradiance changes by ~25 %, which no
// distant light has. The search must place it at its distance, within a
// factor √2 of the true 0.71 m (half a step of the ladder of halvings it
// starts from), and its energy seen from the origin, as the lobes hold it,
// within the 15 %. Its direction seen from the origin within 6°: the
// issue's 2° for a distant light plus what the distance's band allows, since
// the box's shadow fixes the line from the box through the lamp, 14.5° off
// the origin's line of sight, and moving the lamp along it by the band's
// 0.29 of its distance turns it by up to 4° seen from the origin.
TEST(EnvSources, FindsALampAboveTheTableAtItsDistance) {
  Tabletop s;
  s.lamp_centre = {0.08, -0.06, 0.7};
  s.lamp_radius = 0.04;
  s.lamp_radiance = {500, 500, 500};
  s.sky = {0.15, 0.15, 0.15};
  const EnvLight est = EstimateEnvironment(TabletopField(s), SourcesOptions());
  const double distance = Length(s.lamp_centre);
  const double angular_radius = std::asin(s.lamp_radius / distance);
  const DistantDisc seen{Normalized(s.lamp_centre), angular_radius / kDeg,
                         s.lamp_radiance * ConeSolidAngle(angular_radius)};
  const SourceResult lamp = JudgeSource(s, seen, est);
  // The distance as env.json carries it: the placed lobe nearest the lamp.
  const EnvLight written = ParseEnvLight(SerializeEnvLight(est), "env.json");
  ASSERT_EQ(written.distance_m.size(), written.lobes.size());
  double placed = 0, nearest = 180;
  for (size_t k = 0; k < written.lobes.size(); ++k)
    if (written.distance_m[k] > 0 && AngleDeg(written.lobes[k].axis, seen.direction) < nearest) {
      nearest = AngleDeg(written.lobes[k].axis, seen.direction);
      placed = written.distance_m[k];
    }
  // Seen from the table's far side (36 cm from the origin) the stored lobe
  // is 27° off the lamp; seen from there as insertion sees it, within the
  // same 6° (the distance's band turns it by no more there).
  const Vec3 beside{0.3, 0.2, 0.0};
  const SgMixture from_beside = EnvironmentSeenFrom(written.lobes, written.distance_m, beside);
  double turned_error = 180, stored_error = 180;
  for (size_t k = 0; k < from_beside.size(); ++k)
    if (written.distance_m[k] > 0) {
      turned_error = std::min(turned_error, AngleDeg(from_beside[k].axis, Normalized(s.lamp_centre - beside)));
      stored_error = std::min(stored_error, AngleDeg(written.lobes[k].axis, Normalized(s.lamp_centre - beside)));
    }
  LogInfo("lamp above: placed at " + std::to_string(placed) + " m (true " + std::to_string(distance) +
          "), direction error " + std::to_string(lamp.error_deg) + "°, seen from the far side " +
          std::to_string(turned_error) + "°, energy ratio " + std::to_string(lamp.energy_ratio) + "; " + Describe(est));
  EXPECT_FALSE(est.negligible);
  EXPECT_GT(placed, distance / std::sqrt(2.0));
  EXPECT_LT(placed, distance * std::sqrt(2.0));
  EXPECT_LT(lamp.error_deg, 6.0);
  EXPECT_LT(turned_error, 6.0);
  EXPECT_GT(stored_error, 20.0);  // the test can fail: the light as stored is far off there
  EXPECT_NEAR(lamp.energy_ratio, 1.0, 0.15);
}

// What a glossy object reflects away from the source: over the upper
// hemisphere outside the sun's judging cone (and above 3° of elevation,
// where the sky meets the table's rim), the estimate's radiance against the
// true sky of 0.15. Shading tells the sky only through the cosine, so the
// estimate cannot match it in detail; it must not invent detail either: its
// RMS error must stay below the sky's own radiance, the error of reflecting
// no sky at all. (Dictionary lobes finer than shading resolves fail this:
// they gather the sky into bright blobs near the horizon.)
TEST(EnvSources, TheSkyBesideASunIsCloserThanNoSky) {
  const Tabletop s = SunnyTable(2.5);
  const EnvLight est = EstimateEnvironment(TabletopField(s), SourcesOptions());
  const double cos_cone = std::cos(JudgingRadius(s.discs[0]));
  const double sky = LuminanceOf(s.sky);
  double sum_squared = 0, peak = 0;
  int count = 0;
  for (const Vec3& d : FibonacciSphere(4000)) {
    if (d.z < std::sin(3 * kDeg) || Dot(d, s.discs[0].direction) > cos_cone) continue;
    const double y = LuminanceOf(Evaluate(est.lobes, d));
    sum_squared += (y - sky) * (y - sky);
    peak = std::max(peak, y);
    ++count;
  }
  const double rms = std::sqrt(sum_squared / count);
  LogInfo("sky beside the sun: RMS error " + std::to_string(rms) + " (sky " + std::to_string(sky) + "), peak " +
          std::to_string(peak) + "; " + Describe(est));
  EXPECT_LT(rms, sky);
}

}  // namespace
}  // namespace nerfar
