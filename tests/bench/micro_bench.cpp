// Micro-kernels of the per-frame path, timed with Google Benchmark.
#include <benchmark/benchmark.h>

#include "calib/core/image_io.h"

namespace nerfar {
namespace {

void BM_ToneMapToDisplay720p(benchmark::State& state) {
  ImageF image(1280, 720, 3);
  for (size_t i = 0; i < image.pixels.size(); ++i) image.pixels[i] = static_cast<float>(i % 977) * 0.01f;
  for (auto _ : state) benchmark::DoNotOptimize(ToneMapToDisplay(image, 1.0f));
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(image.PixelCount()));
}
BENCHMARK(BM_ToneMapToDisplay720p)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace nerfar
