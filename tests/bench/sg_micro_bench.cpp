// render/sg micro-kernels, timed with Google Benchmark (not run by ctest):
// per-pixel shading with 32 lobes, γ lookups, the product/inner-product closed
// forms, and a warm fit on 2048 directions (docs/BENCHMARKS.md "sg").
#include <benchmark/benchmark.h>

#include <cmath>

#include "render/sg/brdf.h"
#include "render/sg/fit.h"
#include "render/sg/sphere.h"
#include "render/sg/visibility.h"
#include "tests/bench/shade_inputs.h"

namespace nerfar {
namespace {

// Args: material (0 diffuse dielectric, 1 metal), lobe count. 256 pixels of
// varied normals and views per iteration (reported per pixel), so the
// per-pixel cost and the per-lobe slope can be read off 8/32/64 lobes.
void BM_ShadePixel(benchmark::State& state) {
  const int lobes = static_cast<int>(state.range(1));
  const SgShader shader(BenchLight(lobes));
  const SgMaterial material = BenchMaterial(state.range(0) != 0);
  std::vector<float> gamma(lobes, 0.8f);
  const auto [normals, views] = RandomShadePixels(256);
  for (auto _ : state) {
    float sum = 0.0f;
    for (int p = 0; p < 256; ++p) sum += shader.Shade(material, normals[p], views[p], gamma.data()).x;
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(state.iterations() * 256);
  state.counters["ns_per_pixel"] = benchmark::Counter(static_cast<double>(state.iterations()) * 256,
                                                      benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_ShadePixel)->ArgsProduct({{0, 1}, {8, 32, 64}});

// Times the many-pixel call on the given pixels (γ 0.8 for every lobe),
// reported per pixel.
void RunShadeBatch(benchmark::State& state, const SgShader& shader, const SgMaterial& material, int lobes,
                   const std::vector<Vec3f>& normals, const std::vector<Vec3f>& views) {
  const int pixels = static_cast<int>(normals.size());
  std::vector<float> gamma(static_cast<size_t>(lobes) * pixels, 0.8f);
  std::vector<Vec3f> out(pixels);
  const std::vector<SgMaterial> materials(pixels, material);
  for (auto _ : state) {
    shader.Shade(materials.data(), normals.data(), views.data(), gamma.data(), pixels, out.data());
    benchmark::DoNotOptimize(out.data());
  }
  state.SetItemsProcessed(state.iterations() * pixels);
  state.counters["ns_per_pixel"] = benchmark::Counter(static_cast<double>(state.iterations()) * pixels,
                                                      benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

// The batch path (SgShader::Shade over many pixels), same pixels and args.
void BM_ShadeBatch(benchmark::State& state) {
  const int lobes = static_cast<int>(state.range(1));
  const SgShader shader(BenchLight(lobes));
  const SgMaterial material = BenchMaterial(state.range(0) != 0);
  const auto [normals, views] = RandomShadePixels(256);
  RunShadeBatch(state, shader, material, lobes, normals, views);
}
BENCHMARK(BM_ShadeBatch)->ArgsProduct({{0, 1}, {8, 32, 64}});

// The batch path on an image-like pixel order: a sphere filling a 64 × 64
// image (3216 pixels) seen from 3 radii away, scan order, as the insertion
// shades an object's pixels. Neighbouring pixels share lobes that matter,
// so the per-block skips fire. Args: material, lobe count.
// A room-like light: 26 broad lobes (λ 2-6) and a window of 6 sharp ones (λ 300).
SgMixture RoomLight() {
  SgMixture light;
  const std::vector<Vec3> axes = FibonacciSphere(26);
  for (size_t k = 0; k < axes.size(); ++k)
    light.push_back({axes[k], 2.0 + static_cast<double>(k % 5), Vec3(0.2, 0.22, 0.3) * (1.0 + 0.1 * (k % 3))});
  const Vec3 window = Normalized(Vec3(0.6, 0.55, 0.45));
  for (int k = 0; k < 6; ++k)
    light.push_back(
        {Normalized(window + Vec3(0.05 * std::cos(k), 0.05 * std::sin(k), 0.03 * (k % 2))), 300.0, Vec3(35, 32, 27)});
  return light;
}

// Args: material, light (0: BenchLight(32), 1: RoomLight()).
void BM_ShadeBatchSphere(benchmark::State& state) {
  const int lobes = 32;
  const SgShader shader(state.range(1) ? RoomLight() : BenchLight(lobes));
  const SgMaterial material = BenchMaterial(state.range(0) != 0);
  std::vector<Vec3f> normals, views;
  const Vec3f eye(0.0f, 0.0f, 3.0f);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      const float u = (x + 0.5f) / 32.0f - 1.0f, w = (y + 0.5f) / 32.0f - 1.0f;
      if (u * u + w * w >= 1.0f) continue;
      const Vec3f n(u, w, std::sqrt(1.0f - u * u - w * w));
      normals.push_back(n);
      views.push_back(Normalized(eye - n));
    }
  RunShadeBatch(state, shader, material, lobes, normals, views);
}
BENCHMARK(BM_ShadeBatchSphere)->ArgsProduct({{0, 1}, {0, 1}});

void BM_Gamma32Lobes(benchmark::State& state) {
  std::vector<SgTableRow> rows;
  for (const Sg& sg : BenchLight(32)) rows.push_back(PrepareGamma(sg.sharpness));
  float s = -0.3f;
  for (auto _ : state) {
    float sum = 0.0f;
    for (const SgTableRow& row : rows) sum += GammaPrepared(row, s);
    s = s > 0.5f ? -0.3f : s + 1e-3f;
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_Gamma32Lobes);

void BM_InnerProduct(benchmark::State& state) {
  Sg a{Normalized(Vec3(0.1, 0.2, 1.0)), 30.0, Vec3(1, 2, 3)}, b{Normalized(Vec3(0.3, -0.1, 1.0)), 500.0, Vec3(1, 1, 1)};
  for (auto _ : state) {
    benchmark::DoNotOptimize(a);
    benchmark::DoNotOptimize(InnerProduct(a, b));
  }
}
BENCHMARK(BM_InnerProduct);

void BM_FitWarm2048(benchmark::State& state) {
  const SgMixture truth = BenchLight(40);
  RadianceSamples samples;
  for (const Vec3& d : FibonacciSphere(2048)) {
    samples.directions.push_back(d);
    samples.radiance.push_back(Evaluate(truth, d));
    samples.solid_angles.push_back(4.0 * kPi / 2048);
  }
  const SgFitOptions options;
  const SgMixture previous = FitSg(samples, options);
  for (auto _ : state) benchmark::DoNotOptimize(FitSg(samples, options, &previous));
}
BENCHMARK(BM_FitWarm2048)->Unit(benchmark::kMillisecond);

void BM_FitCold2048(benchmark::State& state) {
  const SgMixture truth = BenchLight(40);
  RadianceSamples samples;
  for (const Vec3& d : FibonacciSphere(2048)) {
    samples.directions.push_back(d);
    samples.radiance.push_back(Evaluate(truth, d));
    samples.solid_angles.push_back(4.0 * kPi / 2048);
  }
  const SgFitOptions options;
  for (auto _ : state) benchmark::DoNotOptimize(FitSg(samples, options));
}
BENCHMARK(BM_FitCold2048)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace nerfar
