// render/ssdf: the baked SSDF against the analytic sphere and against a
// brute-force reference written here (Möller–Trumbore over every triangle,
// exact spherical distances for unblocked directions, great-circle search for
// blocked ones) for a box and a torus, inside and outside the grid; PCA error
// against the component count; the batched path against single queries; the
// file round trip and its rejection of corrupt files.
#include "render/ssdf/ssdf.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <random>

#include "calib/core/binary_file.h"
#include "calib/core/parallel.h"
#include "tests/ssdf/format_fixtures.h"
#include "tests/support/sectioned_file.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

using testing::TempDir;

constexpr double kDeg = kPi / 180;

// ---------------------------------------------------------------- brute force

struct BruteForce {
  const TriangleMesh& mesh;

  // Möller–Trumbore in double against every triangle; t > 1e-12.
  bool Blocked(const Vec3& x, const Vec3& d) const {
    for (const auto& t : mesh.triangles) {
      const Vec3 a(mesh.positions[t[0]]), b(mesh.positions[t[1]]), c(mesh.positions[t[2]]);
      const Vec3 e1 = b - a, e2 = c - a, p = Cross(d, e2);
      const double det = Dot(e1, p);
      if (std::abs(det) < 1e-300) continue;
      const Vec3 s = x - a;
      const double u = Dot(s, p) / det;
      if (u < 0 || u > 1) continue;
      const Vec3 q = Cross(s, e1);
      const double v = Dot(d, q) / det;
      if (v < 0 || u + v > 1) continue;
      if (Dot(e2, q) / det > 1e-12) return true;
    }
    return false;
  }

  static double Angle(const Vec3& a, const Vec3& b) { return std::atan2(Length(Cross(a, b)), Dot(a, b)); }

  // Distance from d to the arc a-b, by dense sampling of the arc refined by
  // golden-section search (independent of the library's closed form).
  static double ArcDistance(const Vec3& d, const Vec3& a, const Vec3& b) {
    const auto at = [&](double s) { return Normalized(a * (1 - s) + b * s); };
    double best = std::min(Angle(d, a), Angle(d, b));
    int best_i = 0;
    const int n = 16;
    for (int i = 0; i <= n; ++i) {
      const double v = Angle(d, at(double(i) / n));
      if (v < best) best = v, best_i = i;
    }
    double lo = std::max(0, best_i - 1) / double(n), hi = std::min(n, best_i + 1) / double(n);
    for (int it = 0; it < 60; ++it) {
      const double m1 = lo + (hi - lo) * 0.382, m2 = lo + (hi - lo) * 0.618;
      if (Angle(d, at(m1)) < Angle(d, at(m2)))
        hi = m2;
      else
        lo = m1;
    }
    return std::min(best, Angle(d, at(0.5 * (lo + hi))));
  }

  double Ssd(const Vec3& x, const Vec3& d_in) const {
    const Vec3 d = Normalized(d_in);
    if (!Blocked(x, d)) {
      double best = kPi;
      for (const auto& t : mesh.triangles) {
        const Vec3 a = Normalized(Vec3(mesh.positions[t[0]]) - x), b = Normalized(Vec3(mesh.positions[t[1]]) - x),
                   c = Normalized(Vec3(mesh.positions[t[2]]) - x);
        // Skip triangles whose nearest vertex is much farther than the best (an
        // arc is never nearer than its nearest vertex minus its own length).
        const double near = std::min({Angle(d, a), Angle(d, b), Angle(d, c)});
        const double span = std::max({Angle(a, b), Angle(b, c), Angle(c, a)});
        if (near - span > best) continue;
        best = std::min({best, ArcDistance(d, a, b), ArcDistance(d, b, c), ArcDistance(d, c, a)});
      }
      return best;
    }
    // Blocked: along 120 great circles from d, step 0.5° then bisect; the
    // azimuth gap overestimates by at most θ(1 - cos 1.5°) < 0.05°.
    const Vec3 helper = std::abs(d.x) < 0.9 ? Vec3(1, 0, 0) : Vec3(0, 1, 0);
    const Vec3 w1 = Normalized(Cross(d, helper)), w2 = Cross(d, w1);
    double best = kPi;
    for (int k = 0; k < 120; ++k) {
      const double phi = 2 * kPi * k / 120;
      const Vec3 w = w1 * std::cos(phi) + w2 * std::sin(phi);
      const auto at = [&](double th) { return d * std::cos(th) + w * std::sin(th); };
      double lo = 0;
      for (double th = 0.5 * kDeg; th < best; th += 0.5 * kDeg) {
        if (!Blocked(x, at(th))) {
          double hi = th;
          for (int it = 0; it < 20; ++it) {
            const double mid = 0.5 * (lo + hi);
            (Blocked(x, at(mid)) ? lo : hi) = mid;
          }
          best = std::min(best, hi);
          break;
        }
        lo = th;
      }
    }
    return -best;
  }
};

// Analytic SSD of a sphere (centre c, radius r) seen from x outside it.
double SphereSsd(const Vec3& c, double r, const Vec3& x, const Vec3& d) {
  const Vec3 to_c = c - x;
  return BruteForce::Angle(Normalized(d), Normalized(to_c)) - std::asin(r / Length(to_c));
}

Vec3 RandomDirection(std::mt19937& rng) {
  std::normal_distribution<double> n;
  Vec3 v;
  do v = {n(rng), n(rng), n(rng)};
  while (Length(v) < 1e-6);
  return Normalized(v);
}

// A point at distance in [d_min, d_max] radii from the centre along a random direction.
Vec3 RandomPointAtRadii(std::mt19937& rng, const Vec3& c, double r, double d_min, double d_max) {
  std::uniform_real_distribution<double> u(d_min, d_max);
  return c + RandomDirection(rng) * (u(rng) * r);
}

struct Errors {
  std::vector<double> abs_deg;
  void Add(double got, double want) { abs_deg.push_back(std::abs(got - want) / kDeg); }
  double Mean() const {
    double s = 0;
    for (double e : abs_deg) s += e;
    return s / abs_deg.size();
  }
  double Quantile(double q) const {
    std::vector<double> v = abs_deg;
    std::sort(v.begin(), v.end());
    return v[std::min(v.size() - 1, static_cast<size_t>(q * v.size()))];
  }
};

// Test bakes: grid 12, R 24 (texel spacing ≈ 8.5°), 24 components; a few
// seconds for all shapes together on 2 cores.
SsdfBakeOptions TestOptions() {
  SsdfBakeOptions o;
  o.grid = 12;
  o.dirs = 24;
  o.components = 24;
  o.bisection_steps = 6;
  return o;
}

const TriangleMesh& Sphere() {
  static const TriangleMesh mesh = MakeUvSphere(1.0, 64, 32);
  return mesh;
}
const TriangleMesh& Box() {
  static const TriangleMesh mesh = MakeBox({0.6, 0.4, 0.25});
  return mesh;
}
const TriangleMesh& Torus() {
  static const TriangleMesh mesh = MakeTorus(0.7, 0.25, 24, 12);
  return mesh;
}
const SsdfField& Baked(const TriangleMesh& mesh) {
  static std::map<const TriangleMesh*, SsdfField> fields;
  auto it = fields.find(&mesh);
  if (it == fields.end()) it = fields.emplace(&mesh, BakeSsdf(mesh, TestOptions(), std::nullopt)).first;
  return it->second;
}

// ---------------------------------------------------------------- directions

TEST(Octahedral, RoundTripAndWrap) {
  std::mt19937 rng(1);
  for (int i = 0; i < 2000; ++i) {
    const Vec3 d = RandomDirection(rng);
    const auto uv = OctahedralCoordinates(d);
    EXPECT_LT(BruteForce::Angle(OctahedralDirection(uv[0], uv[1]), d), 1e-12);  // double rounding only
  }
  // Neighbours across a folded edge are neighbours on the sphere: within two
  // texel spacings (the largest texel spans ≈ 203°/R / (sqrt 2) per side).
  const int r = 16;
  const double spacing = 203.0 / r * kDeg;
  for (int k = 0; k < r; ++k) {
    for (const auto& [i, j] : std::vector<std::array<int, 2>>{{-1, k}, {r, k}, {k, -1}, {k, r}}) {
      const auto w = OctahedralWrap(i, j, r);
      ASSERT_TRUE(w[0] >= 0 && w[0] < r && w[1] >= 0 && w[1] < r);
      const int ii = std::clamp(i, 0, r - 1), jj = std::clamp(j, 0, r - 1);
      EXPECT_LT(BruteForce::Angle(OctahedralTexelDirection(ii, jj, r), OctahedralTexelDirection(w[0], w[1], r)),
                2 * spacing)
          << i << "," << j;
    }
  }
}

TEST(Options, PresetsValidAndProblemsListed) {
  for (const char* name : {"fast", "balanced", "accurate"})
    EXPECT_TRUE(SsdfBakeOptions::Preset(name).Validate().empty());
  EXPECT_THROW(SsdfBakeOptions::Preset("fastest"), InputError);
  SsdfBakeOptions bad;
  bad.grid = 1;
  bad.dirs = 1000;
  bad.components = 0;
  bad.bisection_steps = -1;
  bad.grid_extent = 1.5;
  EXPECT_EQ(bad.Validate().size(), 5u);
  SsdfBakeOptions too_many;
  too_many.grid = 2;
  too_many.components = 9;  // 2³ = 8 points
  EXPECT_EQ(too_many.Validate().size(), 1u);
  EXPECT_THROW(ComputeSsdSamples(Sphere(), bad), InputError);
}

// ---------------------------------------------------------------- accuracy

TEST(Samples, SphereGridPointsMatchTheAnalyticSsd) {
  SsdfBakeOptions o = TestOptions();
  o.grid = 6;
  const SsdSamples samples = ComputeSsdSamples(Sphere(), o);
  EXPECT_NEAR(Length(samples.center), 0, 1e-6);
  EXPECT_NEAR(samples.radius, 1.0, 1e-6);
  Errors errors;
  for (int iz = 0; iz < o.grid; ++iz)
    for (int iy = 0; iy < o.grid; ++iy)
      for (int ix = 0; ix < o.grid; ++ix) {
        const Vec3 x = samples.GridPoint(ix, iy, iz);
        if (Length(x) < 1.05) continue;
        const size_t p = (static_cast<size_t>(iz) * o.grid + iy) * o.grid + ix;
        for (int t = 0; t < o.dirs * o.dirs; ++t) {
          const Vec3 d = OctahedralTexelDirection(t % o.dirs, t / o.dirs, o.dirs);
          errors.Add(samples.values[p * o.dirs * o.dirs + t], SphereSsd({0, 0, 0}, 1.0, x, d));
        }
      }
  // Silhouette crossings lie on the true silhouette (bisection to 8.5°/64 ≈
  // 0.13°); a texel's nearest crossing is at most half a crossing spacing
  // (~4°) off along the silhouette, which matters only near it: max ~1.5°.
  // The 64-segment sphere itself is within 0.07° of the exact one.
  EXPECT_LT(errors.Mean(), 0.3) << errors.Quantile(0.95) << " " << errors.Quantile(0.99);
  EXPECT_LT(errors.Quantile(1.0), 2.0) << errors.Mean() << " " << errors.Quantile(0.95) << " " << errors.Quantile(0.99);
}

TEST(Samples, TorusGridPointsMatchBruteForce) {
  // A concave shape with a hole, before compression: ray casting, silhouette
  // bisection and the distance transform alone.
  SsdfBakeOptions o = TestOptions();
  o.grid = 6;
  const SsdSamples samples = ComputeSsdSamples(Torus(), o);
  const BruteForce brute{Torus()};
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> point(0, o.grid * o.grid * o.grid - 1), texel(0, o.dirs * o.dirs - 1);
  Errors errors;
  for (int n = 0; n < 150; ++n) {
    const int p = point(rng), t = texel(rng);
    const Vec3 x = samples.GridPoint(p % o.grid, (p / o.grid) % o.grid, p / (o.grid * o.grid));
    const Vec3 d = OctahedralTexelDirection(t % o.dirs, t / o.dirs, o.dirs);
    if (brute.Blocked(x, d) && brute.Blocked(x, -d) && brute.Blocked(x, Vec3(0, 0, 1)) &&
        brute.Blocked(x, Vec3(0, 0, -1)))
      continue;  // inside the tube: filled from outside neighbours, no reference
    errors.Add(samples.values[static_cast<size_t>(p) * o.dirs * o.dirs + t], brute.Ssd(x, d));
  }
  ASSERT_GT(errors.abs_deg.size(), 100u);
  // As for the sphere (crossings exact to 0.13°, at most ~0.25 texel spacing
  // apart along the silhouette); the torus's inner rim is more curved: 2.5°.
  EXPECT_LT(errors.Mean(), 0.4);
  EXPECT_LT(errors.Quantile(1.0), 2.5) << errors.Quantile(0.95);
}

void ExpectFieldMatches(const SsdfField& field, const std::function<double(const Vec3&, const Vec3&)>& reference,
                        double d_min, double d_max, int count, double mean_deg, double p95_deg, uint32_t seed) {
  std::mt19937 rng(seed);
  Errors errors;
  for (int i = 0; i < count; ++i) {
    const Vec3 x = RandomPointAtRadii(rng, field.center(), field.radius(), d_min, d_max);
    const Vec3 d = RandomDirection(rng);
    const float s = field.Query(Vec3f(x), Vec3f(d));
    ASSERT_TRUE(std::isfinite(s));
    ASSERT_LE(std::abs(s), kPi + 1e-6);
    errors.Add(s, reference(x, d));
  }
  SCOPED_TRACE("radii " + std::to_string(d_min) + " to " + std::to_string(d_max));
  EXPECT_LT(errors.Mean(), mean_deg) << "p95 " << errors.Quantile(0.95);
  EXPECT_LT(errors.Quantile(0.95), p95_deg) << "mean " << errors.Mean();
}

TEST(Field, SphereInsideAndOutsideTheGridMatchesTheAnalyticSsd) {
  const SsdfField& field = Baked(Sphere());
  const auto analytic = [](const Vec3& x, const Vec3& d) { return SphereSsd({0, 0, 0}, 1.0, x, d); };
  // Inside the grid (1.1 to 1.5 radii: the box's inscribed sphere): the
  // trilinear blend of a function curving like asin(1/D) over a 0.27 r cell
  // adds ~1° near the object to the ~0.3° of the samples. Outside (1.5 to 10
  // radii) the re-mapping is exact for a sphere: only the boundary values'
  // error. Cells touching the surface also blend filled inside points: ~1°
  // mean, p95 ~3.5° measured (grid 12), budget 1.5° and 5°.
  ExpectFieldMatches(field, analytic, 1.1, 1.5, 400, 1.5, 5.0, 2);
  ExpectFieldMatches(field, analytic, 1.5, 3.0, 400, 0.6, 2.0, 3);
  ExpectFieldMatches(field, analytic, 3.0, 10.0, 400, 0.5, 1.5, 4);
}

TEST(Field, BoxAndTorusMatchBruteForceInsideAndOutsideTheGrid) {
  struct Case {
    const char* name;
    const TriangleMesh* mesh;
  };
  for (const Case& c : {Case{"box", &Box()}, Case{"torus", &Torus()}}) {
    SCOPED_TRACE(c.name);
    const SsdfField& field = Baked(*c.mesh);
    const BruteForce brute{*c.mesh};
    const auto reference = [&](const Vec3& x, const Vec3& d) { return brute.Ssd(x, d); };
    // Tolerances: inside the grid, trilinear + texel errors as for the sphere,
    // larger where a sharp edge or the torus hole moves fast with x; outside,
    // the re-mapping ignores parallax (the far view is not a scaled near view):
    // measured ≲ 1-2° mean, budget 2-3x that.
    ExpectFieldMatches(field, reference, 1.05, 1.5, 120, 2.5, 8.0, 5);
    ExpectFieldMatches(field, reference, 1.5, 4.0, 120, 2.5, 8.0, 6);
    ExpectFieldMatches(field, reference, 4.0, 10.0, 120, 1.5, 5.0, 7);
  }
}

TEST(Field, LibraryReferenceAgreesWithTheIndependentBruteForce) {
  const SsdReference library(Torus());
  const BruteForce brute{Torus()};
  std::mt19937 rng(8);
  for (int i = 0; i < 40; ++i) {
    const Vec3 x = RandomPointAtRadii(rng, {0, 0, 0}, 0.95, 1.05, 4.0);
    const Vec3 d = RandomDirection(rng);
    // Misses: both exact (to 1e-9). Blocked: both search along great circles
    // and miss unblocked slivers thinner than their steps (0.29° and 0.5°)
    // seen from the torus rim at a grazing angle: agree to 0.5°.
    EXPECT_NEAR(library.Ssd(x, d), brute.Ssd(x, d), 0.5 * kDeg);
  }
}

TEST(Field, TorusHoleSeenFromAboveIsOpen) {
  const SsdfField& field = Baked(Torus());
  // Straight down through the hole from the axis: open (the rim is at
  // atan(0.45 / 1.2) = 20.6°; the nearest grid points, 0.18 off the axis, see
  // the rim closer, so the blend reads less but stays positive).
  EXPECT_GT(field.Query(Vec3f(0, 0, 1.2), Vec3f(0, 0, -1)), 0);
}

TEST(Field, InsideAndOnTheObjectAreSane) {
  const SsdfField& field = Baked(Sphere());
  std::mt19937 rng(9);
  for (int i = 0; i < 200; ++i) {
    const Vec3 n = RandomDirection(rng);
    for (double radius : {0.0, 0.3, 0.6, 0.9, 1.0, 1.01, 1.05}) {
      const float out = field.Query(Vec3f(n * radius), Vec3f(n)), in = field.Query(Vec3f(n * radius), Vec3f(-n));
      ASSERT_TRUE(std::isfinite(out) && std::isfinite(in));
      ASSERT_LE(std::abs(out), kPi + 1e-6);
      ASSERT_LE(std::abs(in), kPi + 1e-6);
      if (radius < 0.9) continue;  // deep inside: bounded, no meaning
      // On and near the surface: outwards open (analytic 90° on it, 108° at
      // 1.05), inwards blocked (-90°, -72°); the blend with the filled points
      // inside keeps the signs.
      EXPECT_GT(out, 0) << radius;
      EXPECT_LT(in, 0) << radius;
    }
  }
}

TEST(Field, BatchEqualsSingleQueries) {
  const SsdfField& field = Baked(Torus());
  std::mt19937 rng(10);
  std::vector<Vec3f> lobes;
  for (int m = 0; m < 12; ++m) lobes.push_back(Vec3f(RandomDirection(rng)));
  std::vector<Vec3f> points;
  for (int p = 0; p < 300; ++p) points.push_back(Vec3f(RandomPointAtRadii(rng, {0, 0, 0}, 0.95, 0.0, 8.0)));
  SsdfBatch batch(field);
  batch.PrepareDirections(lobes);
  std::vector<float> out(points.size() * lobes.size());
  batch.QueryBatch(points.data(), points.size(), out.data());
  // The same arithmetic in the same order: bit-identical.
  for (size_t p = 0; p < points.size(); ++p)
    for (size_t m = 0; m < lobes.size(); ++m) ASSERT_EQ(out[p * lobes.size() + m], field.Query(points[p], lobes[m]));
}

TEST(Pca, ErrorFallsWithTheComponentCountAndVanishesAtFullRank) {
  SsdfBakeOptions o;
  o.grid = 8;
  o.dirs = 12;  // 512 points x 144 directions: full rank 144
  const SsdSamples samples = ComputeSsdSamples(Torus(), o);
  double previous = 1e9;
  for (int k : {1, 2, 4, 8, 16, 32, 64, 144}) {
    const SsdfField field = SsdfField::Compress(samples, k);
    double sum = 0;
    for (int p = 0; p < 512; ++p)
      for (int t = 0; t < 144; ++t) {
        const double e = field.SampleAt(p % 8, (p / 8) % 8, p / 64, t) - samples.values[p * 144 + t];
        sum += e * e;
      }
    const double rms = std::sqrt(sum / (512 * 144));
    SCOPED_TRACE(k);
    EXPECT_LT(rms, previous);
    previous = rms;
    // Full rank reproduces the samples to float rounding of values up to π.
    if (k == 144) {
      EXPECT_LT(rms, 1e-4);
    }
  }
}

TEST(Bake, IndependentOfTheThreadCount) {
  SsdfBakeOptions o = TestOptions();
  o.grid = 6;
  SetThreadCount(1);
  const std::string one = SerializeSsdf(BakeSsdf(Box(), o, std::nullopt));
  SetThreadCount(2);
  const std::string two = SerializeSsdf(BakeSsdf(Box(), o, std::nullopt));
  SetThreadCount(0);
  EXPECT_TRUE(one == two);
}

// ---------------------------------------------------------------- file

void ExpectRejected(const std::string& bytes, const std::string& fragment) {
  try {
    ParseSsdf(bytes, "field.ssdf");
    ADD_FAILURE() << "accepted; expected an error with '" << fragment << "'";
  } catch (const InputError& e) {
    const std::string message = e.what();
    EXPECT_EQ(message.rfind("field.ssdf", 0), 0u) << message;
    EXPECT_NE(message.find(fragment), std::string::npos) << message;
  }
}

TEST(File, RoundTripIsBitIdenticalAndCarriesTheObject) {
  SsdfBakeOptions o = TestOptions();
  o.grid = 5;
  Material material;
  material.albedo = {0.1, 0.2, 0.3};
  material.roughness = 0.4;
  material.albedo_texture = "tex/a.png";
  TriangleMesh box = Box();
  box.source = "objects/box.obj";
  const SsdfField field = BakeSsdf(box, o, material);
  TempDir dir;
  WriteSsdf(dir.File("box.ssdf"), field);
  const SsdfField back = ReadSsdf(dir.File("box.ssdf"));
  EXPECT_TRUE(SerializeSsdf(back) == testing::ReadText(dir.File("box.ssdf")));
  EXPECT_TRUE(back.mean() == field.mean());
  EXPECT_TRUE(back.basis() == field.basis());
  EXPECT_TRUE(back.coefficients() == field.coefficients());
  EXPECT_EQ(back.mesh_reference, "objects/box.obj");
  EXPECT_EQ(back.mesh_bounds.max, Vec3(0.6f, 0.4f, 0.25f));  // float vertices
  ASSERT_TRUE(back.material.has_value());
  EXPECT_EQ(back.material->albedo, material.albedo);
  EXPECT_EQ(back.material->albedo_texture, "tex/a.png");
  EXPECT_EQ(back.options_json, o.ToJson());
  EXPECT_EQ(back.center(), field.center());
  EXPECT_EQ(back.Query(Vec3f(2, 1, 0), Vec3f(-1, 0, 0)), field.Query(Vec3f(2, 1, 0), Vec3f(-1, 0, 0)));
}

TEST(File, CorruptAndTruncatedFilesAreRejected) {
  SsdfBakeOptions o = TestOptions();
  o.grid = 4;
  o.components = 8;
  const std::string good = SerializeSsdf(BakeSsdf(Box(), o, std::nullopt));
  EXPECT_NO_THROW(ParseSsdf(good, "field.ssdf"));
  ExpectRejected("", "magic");
  ExpectRejected("NERFSSDX" + good.substr(8), "magic");
  for (size_t cut : {size_t{8}, size_t{12}, size_t{40}, good.size() / 2, good.size() - 1})
    ExpectRejected(good.substr(0, cut), "file is truncated");
  std::string flipped = good;
  flipped[good.size() / 2] ^= 0x10;
  ExpectRejected(flipped, "crc32 mismatch (the file is corrupt");
  std::string version = good;
  version[8] = 7;
  ExpectRejected(version, "version 7 (expected 1 to 2; written by a newer nerfar?)");

  // Well-formed crc, bad contents: every check still runs.
  const size_t grid_at = testing::SectionOf(good, "GRID").offset();
  std::string grid = good;
  const uint32_t one = 1;
  std::memcpy(grid.data() + grid_at, &one, 4);
  ExpectRejected(testing::Resealed(grid), "grid");
  std::string huge = good;
  const uint32_t big = 512;
  std::memcpy(huge.data() + grid_at + 4, &big, 4);  // dirs 512: sizes no longer match the sections
  ExpectRejected(testing::Resealed(huge), "expected");
  std::string nan = good;
  const float not_a_number = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(nan.data() + nan.size() - 4 - 4, &not_a_number, 4);  // last coefficient
  ExpectRejected(testing::Resealed(nan), "finite");
  std::string radius = good;
  const double negative = -1;
  std::memcpy(radius.data() + grid_at + 12 + 24, &negative, 8);
  ExpectRejected(testing::Resealed(radius), "radius");

  TempDir dir;
  EXPECT_THROW(ReadSsdf(dir.File("missing.ssdf")), InputError);
}

TEST(File, UnknownSectionsAreSkippedAMissingOneIsNamed) {
  SsdfBakeOptions o = TestOptions();
  o.grid = 3;
  const SsdfField field = BakeSsdf(Box(), o, Material{});
  const std::string good = SerializeSsdf(field);
  // The file again through the container's writer, its sections copied, some left out, one added.
  const auto rewrite = [&](const std::vector<std::string>& tags, bool extra) {
    const BinaryFormat format{"SSDF file", "NERFSSDF", true, kSsdfFileVersion, kSsdfFileVersion, kSsdfFileVersion, ""};
    BinaryFileWriter w(format, kSsdfFileVersion);
    if (extra) w.Section("XTRA").PutBytes("a later version's section");
    for (const std::string& tag : tags) w.Section(tag).PutBytes(testing::SectionBytes(good, tag));
    return std::move(w).Seal();
  };
  const SsdfField back = ParseSsdf(rewrite({"GRID", "MATL", "MEAN", "BASI", "COEF"}, true), "field.ssdf");
  EXPECT_TRUE(back.coefficients() == field.coefficients());
  ASSERT_TRUE(back.material.has_value()) << "MATL read";
  EXPECT_FALSE(ParseSsdf(rewrite({"GRID", "MEAN", "BASI", "COEF"}, false), "field.ssdf").material.has_value())
      << "no MATL: no material";
  ExpectRejected(rewrite({"GRID", "MATL", "MEAN", "BASI"}, false), "field.ssdf: no 'COEF' section");
}

TEST(File, RandomlyDamagedHeadersNeverCrash) {
  // Mutations of the header, section table and strings, resealed so that the crc passes:
  // every one either parses into a valid field or is an InputError.
  SsdfBakeOptions o = TestOptions();
  o.grid = 3;
  o.dirs = 6;
  o.components = 4;
  const std::string good = SerializeSsdf(BakeSsdf(Box(), o, Material{}));
  std::mt19937 rng(12);
  std::uniform_int_distribution<size_t> where(0, std::min<size_t>(good.size() - 5, 400));
  std::uniform_int_distribution<int> byte(0, 255);
  int parsed = 0, rejected = 0;
  for (int i = 0; i < 500; ++i) {
    std::string bytes = good;
    for (int k = 0; k < 3; ++k) bytes[where(rng)] = static_cast<char>(byte(rng));
    try {
      const SsdfField field = ParseSsdf(testing::Resealed(bytes), "field.ssdf");
      EXPECT_TRUE(field.Validate().empty());
      ++parsed;
    } catch (const InputError&) {
      ++rejected;
    }
  }
  EXPECT_EQ(parsed + rejected, 500);
  EXPECT_GT(rejected, 0);
}

TEST(File, SharedObjectsBakeAndLoadBackBitIdentical) {
  NERFAR_REQUIRE_SHARED_SCENES(scenes);
  TempDir dir;
  for (const char* name : {"sphere_glossy", "monkey_diffuse"}) {
    SCOPED_TRACE(name);
    const TriangleMesh mesh = ReadMesh(scenes + "/objects/" + name + ".obj");
    const SsdfField field = BakeSsdf(mesh, SsdfBakeOptions::Preset("fast"), std::nullopt);
    const std::string path = dir.File(std::string(name) + ".ssdf");
    WriteSsdf(path, field);
    const SsdfField back = ReadSsdf(path);
    EXPECT_TRUE(back.mean() == field.mean() && back.basis() == field.basis() &&
                back.coefficients() == field.coefficients());
    EXPECT_TRUE(SerializeSsdf(back) == testing::ReadText(path));
    EXPECT_EQ(back.mesh_reference, mesh.source);
  }
}

// .ssdf files written by earlier builds (tests/data/formats, see tests/make_format_fixtures.cpp),
// flat version 1 and this one, read with what was written into them and save the same fields
// (version 1's in sections).
TEST(OldFiles, SsdfFilesOfEachVersionReadAndSaveTheSameFields) {
  for (const uint32_t version : {uint32_t{1}, kSsdfFileVersion}) {
    SCOPED_TRACE("version " + std::to_string(version));
    const std::string old =
        testing::ReadText(testing::TestDataPath("formats/tetra_v" + std::to_string(version) + ".ssdf"));
    const SsdfField field = ParseSsdf(old, "tetra.ssdf");
    const SsdfBakeOptions options = testing::FormatFixtureSsdfOptions();
    EXPECT_EQ(field.grid(), options.grid);
    EXPECT_EQ(field.dirs(), options.dirs);
    EXPECT_EQ(field.components(), options.components);
    EXPECT_EQ(field.mesh_reference, testing::FormatFixtureMesh().source);
    ASSERT_TRUE(field.material.has_value());
    const Material expected = testing::FormatFixtureMaterial();
    EXPECT_EQ(field.material->albedo.y, expected.albedo.y);
    EXPECT_EQ(field.material->roughness, expected.roughness);
    EXPECT_EQ(field.material->metallic, expected.metallic);
    EXPECT_EQ(field.material->f0, expected.f0);
    EXPECT_EQ(field.material->albedo_texture, expected.albedo_texture);
    EXPECT_NE(field.options_json.find("\"grid\":4"), std::string::npos) << field.options_json;
    const std::string again = SerializeSsdf(field);
    if (version == kSsdfFileVersion) {
      EXPECT_TRUE(again == old) << "the writer no longer writes the file it wrote";
      continue;
    }
    // Version 1's fields: GRID up to the mesh reference, the material flag and MATL, the options
    // (GRID's last string), the arrays.
    const std::string grid = testing::SectionBytes(again, "GRID");
    const size_t options_at = grid.size() - 4 - field.options_json.size();
    const std::string fields = grid.substr(0, options_at) + '\x01' + testing::SectionBytes(again, "MATL") +
                               grid.substr(options_at) + testing::SectionBytes(again, "MEAN") +
                               testing::SectionBytes(again, "BASI") + testing::SectionBytes(again, "COEF");
    EXPECT_TRUE(fields == old.substr(12, old.size() - 20)) << "the writer no longer writes the fields it wrote";
  }
}

}  // namespace
}  // namespace nerfar
