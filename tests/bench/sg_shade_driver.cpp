// A fixed amount of SG shading for instruction counts (docs/BENCHMARKS.md
// "sg"): shades 256 random pixels R times under a synthetic light.
//   sg_shade_driver MODE MATERIAL LOBES R
// MODE: batch (one many-pixel call per pass) or single (one call per pixel);
// MATERIAL: 0 dielectric (roughness 0.7), 1 metal (roughness 0.25).
// Instructions per pixel = (Ir at R = 11 − Ir at R = 1) / (10 · 256), e.g.
//   valgrind --tool=callgrind --callgrind-out-file=/dev/null sg_shade_driver batch 0 32 11
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <vector>

#include "render/sg/brdf.h"
#include "render/sg/sphere.h"

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
  SgMixture light;
  const std::vector<Vec3> axes = FibonacciSphere(lobes);
  for (int k = 0; k < lobes; ++k)
    light.push_back({axes[k], std::pow(10.0, 0.1 * (k % 25)), Vec3(1.0 + k % 3, 1.0, 0.5 + 0.1 * k)});
  const SgShader shader(light);
  const SgMaterial material{Vec3(0.8, 0.35, 0.2), metal ? 0.25 : 0.7, metal ? 1.0 : 0.0};
  const int pixels = 256;
  std::vector<float> gamma(static_cast<size_t>(lobes) * pixels, 0.8f);
  std::vector<Vec3f> normals, views, out(pixels);
  const std::vector<SgMaterial> materials(pixels, material);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (int p = 0; p < pixels; ++p) {
    normals.push_back(Normalized(Vec3f(u(rng), u(rng), u(rng) + 0.01f)));
    views.push_back(Normalized(normals.back() + Vec3f(u(rng), u(rng), u(rng)) * 0.5f));
  }
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
