// Bench stage "ssdf": per preset, bake time and file size for a 10,000-triangle
// torus (concave), SSD error against the brute-force reference inside the grid
// and outside it (1.5 to 10 radii), the outside-grid re-mapping against plain
// snapping, and the per-frame query cost per point per lobe.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <random>
#include <string>

#include "app/bench.h"
#include "calib/core/parallel.h"
#include "render/mesh/mesh.h"
#include "render/ssdf/ssdf.h"

namespace nerfar {

namespace {

constexpr double kDegPerRad = 180.0 / kPi;

Vec3 RandomUnit(std::mt19937& rng) {
  std::normal_distribution<double> n;
  Vec3 v;
  do v = {n(rng), n(rng), n(rng)};
  while (Length(v) < 1e-6);
  return Normalized(v);
}

struct Query {
  Vec3 x, d;
  double reference;
};

// Random (x, d) with |x - c| in [lo, hi] radii, and the brute-force answer.
std::vector<Query> MakeQueries(const SsdReference& reference, const Vec3& c, double r, double lo, double hi, int count,
                               uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(lo, hi);
  std::vector<Query> queries(count);
  for (Query& q : queries) {
    q.x = c + RandomUnit(rng) * (u(rng) * r);
    q.d = RandomUnit(rng);
  }
  ParallelFor(
      queries.size(), [&](size_t i) { queries[i].reference = reference.Ssd(queries[i].x, queries[i].d); }, 4);
  return queries;
}

struct ErrorStats {
  double mean_deg = 0, p95_deg = 0;
};

template <typename Fn>
ErrorStats Measure(const std::vector<Query>& queries, Fn&& estimate) {
  std::vector<double> errors;
  for (const Query& q : queries) errors.push_back(std::abs(estimate(q) - q.reference) * kDegPerRad);
  ErrorStats s;
  for (double e : errors) s.mean_deg += e;
  s.mean_deg /= errors.size();
  std::sort(errors.begin(), errors.end());
  s.p95_deg = errors[std::min(errors.size() - 1, static_cast<size_t>(0.95 * errors.size()))];
  return s;
}

}  // namespace

std::vector<BenchFigure> BenchSsdf(const BenchOptions& options) {
  // 100 x 50 segments: 10,000 triangles, a concave shape with a hole.
  const TriangleMesh mesh = MakeTorus(0.05, 0.02, 100, 50);
  const BoundingSphere sphere = ComputeBoundingSphere(mesh);
  const SsdReference reference(mesh);
  const int count = options.quick ? 60 : 400;
  const std::vector<Query> inside = MakeQueries(reference, sphere.center, sphere.radius, 1.05, 1.5, count, 1);
  const std::vector<Query> outside = MakeQueries(reference, sphere.center, sphere.radius, 1.5, 10.0, count, 2);
  const std::string threads = std::to_string(ThreadCount()) + " threads";
  const std::string shape = "torus 10k tris, ";

  std::vector<BenchFigure> figures;
  const std::vector<std::string> presets =
      options.quick ? std::vector<std::string>{"fast"} : std::vector<std::string>{"fast", "balanced", "accurate"};
  for (const std::string& preset : presets) {
    SsdfBakeOptions o = SsdfBakeOptions::Preset(preset);
    if (options.quick) o.grid = 8;
    const std::string note = preset + ", " + shape + threads;
    SsdfBakeReport report;
    const double t0 = NowSeconds();
    const SsdfField field = BakeSsdf(mesh, o, std::nullopt, nullptr, &report);
    const double bake_s = NowSeconds() - t0;
    const std::string bytes = SerializeSsdf(field);
    figures.push_back({"bake_" + preset + "_s", bake_s, "s", note});
    figures.push_back({"bake_" + preset + "_rays_s", report.seconds_rays, "s", note + " (rays + distance transform)"});
    figures.push_back({"bake_" + preset + "_pca_s", report.seconds_pca, "s", note});
    figures.push_back({"file_" + preset + "_kb", bytes.size() / 1e3, "KB", note});
    figures.push_back({"file_" + preset + "_percent_raw", 100.0 * bytes.size() / report.raw_bytes, "%",
                       note + ", raw " + std::to_string(report.raw_bytes / 1000) + " KB"});
    figures.push_back({"pca_" + preset + "_rms_deg", report.pca_rms_rad * kDegPerRad, "deg", note});
    const auto query = [&field](const Query& q) { return field.Query(Vec3f(q.x), Vec3f(q.d)); };
    const ErrorStats in = Measure(inside, query), out = Measure(outside, query);
    figures.push_back({"ssd_" + preset + "_grid_mean_deg", in.mean_deg, "deg", note + ", 1.05-1.5 radii"});
    figures.push_back({"ssd_" + preset + "_grid_p95_deg", in.p95_deg, "deg", note + ", 1.05-1.5 radii"});
    figures.push_back({"ssd_" + preset + "_far_mean_deg", out.mean_deg, "deg", note + ", 1.5-10 radii"});
    figures.push_back({"ssd_" + preset + "_far_p95_deg", out.p95_deg, "deg", note + ", 1.5-10 radii"});

    if (preset == "balanced" || options.quick) {
      // The outside-grid design against plain snapping (the value at the
      // radially projected box point, direction unchanged), per distance.
      for (double radii : {1.5, 2.0, 3.0, 5.0, 10.0}) {
        const std::vector<Query> ring = MakeQueries(reference, sphere.center, sphere.radius, radii, radii, count / 2,
                                                    static_cast<uint32_t>(radii * 10));
        const ErrorStats mapped = Measure(ring, query);
        const ErrorStats snapped = Measure(ring, [&](const Query& q) {
          const Vec3 v = q.x - field.center();
          const double extent = std::max({std::abs(v.x), std::abs(v.y), std::abs(v.z)});
          const Vec3 x_b = field.center() + v * std::min(1.0, field.edge() / 2 / extent);
          return field.Query(Vec3f(x_b), Vec3f(q.d));
        });
        char name[64];
        std::snprintf(name, sizeof name, "far_%gr", radii);
        figures.push_back({std::string("ssd_") + name + "_mapped_mean_deg", mapped.mean_deg, "deg", note});
        figures.push_back({std::string("ssd_") + name + "_snapped_mean_deg", snapped.mean_deg, "deg", note});
      }
      // Per-frame path: 32 lobes, points inside and outside the grid.
      std::mt19937 rng(3);
      std::vector<Vec3f> lobes;
      for (int m = 0; m < 32; ++m) lobes.push_back(Vec3f(RandomUnit(rng)));
      SsdfBatch batch(field);
      const double prepare_ms = MedianMilliseconds([&] { batch.PrepareDirections(lobes); });
      figures.push_back({"batch_prepare_32_lobes_ms", prepare_ms, "ms", note});
      const size_t n = options.quick ? 2000 : 20000;
      std::vector<float> out_values(n * lobes.size());
      for (const auto& [label, lo, hi] : {std::tuple{"grid", 1.05, 1.45}, std::tuple{"far", 2.0, 10.0}}) {
        std::vector<Vec3f> points(n);
        std::uniform_real_distribution<double> u(lo, hi);
        for (Vec3f& p : points) p = Vec3f(sphere.center + RandomUnit(rng) * (u(rng) * sphere.radius));
        const double ms = MedianMilliseconds([&] { batch.QueryBatch(points.data(), n, out_values.data()); }, 3);
        figures.push_back({std::string("query_") + label + "_ns_per_point_lobe", ms * 1e6 / (n * lobes.size()), "ns",
                           note + ", K=" + std::to_string(field.components()) + ", 1 thread, 32 lobes"});
      }
    }
  }
  return figures;
}

}  // namespace nerfar
