// A fixed amount of SG shading for instruction counts (docs/BENCHMARKS.md
// "sg"): shades 256 random pixels R times under a synthetic light.
//   sg_shade_driver MODE MATERIAL LOBES R
// MODE: batch (one many-pixel call per pass) or single (one call per pixel);
// MATERIAL: 0 dielectric (roughness 0.7), 1 metal (roughness 0.25).
// Instructions per pixel = (Ir at R = 11 − Ir at R = 1) / (10 · 256), e.g.
//   valgrind --tool=callgrind --callgrind-out-file=/dev/null sg_shade_driver batch 0 32 11
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "render/sg/brdf.h"
#include "render/sg/sphere.h"
#include "tests/bench/shade_inputs.h"

int main(int argc, char** argv) {
  using namespace nerfar;
  if (argc != 5) {
    std::fprintf(stderr, "usage: sg_shade_driver batch|single MATERIAL(0|1) LOBES(1-64) REPEATS\n");
    return 2;
  }
  const bool batch = std::strcmp(argv[1], "batch") == 0;
  const int metal = std::atoi(argv[2]), lobes = std::atoi(argv[3]), repeats = std::atoi(argv[4]);
  if (lobes < 1 || lobes > kMaxSgLobes || repeats < 0) {
    std::fprintf(stderr, "LOBES must be 1-64 and REPEATS >= 0\n");
    return 2;
  }
  const SgShader shader(BenchLight(lobes));
  const SgMaterial material = BenchMaterial(metal != 0);
  const int pixels = 256;
  std::vector<float> gamma(static_cast<size_t>(lobes) * pixels, 0.8f);
  std::vector<Vec3f> out(pixels);
  const std::vector<SgMaterial> materials(pixels, material);
  const auto [normals, views] = RandomShadePixels(pixels);
  float sink = 0.0f;
  for (int r = 0; r < repeats; ++r) {
    if (batch) {
      shader.Shade(materials.data(), normals.data(), views.data(), gamma.data(), pixels, out.data());
      sink += out[r % pixels].x;
    } else {
      for (int p = 0; p < pixels; ++p)
        sink += shader.Shade(material, normals[p], views[p], &gamma[static_cast<size_t>(lobes) * p]).x;
    }
  }
  std::printf("%g\n", sink);
  return 0;
}
