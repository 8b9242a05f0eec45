// Shading inputs shared by the SG micro benchmarks and the callgrind driver,
// so both measure exactly the same work (docs/BENCHMARKS.md "sg").
#pragma once

#include <cmath>
#include <random>
#include <vector>

#include "render/sg/brdf.h"
#include "render/sg/sphere.h"

namespace nerfar {

// A synthetic light of `lobes` SGs on a Fibonacci sphere, sharpness 1 to ~250
// and varied colours, so no lobe is a special case.
inline SgMixture BenchLight(int lobes) {
  SgMixture light;
  const std::vector<Vec3> axes = FibonacciSphere(lobes);
  for (int k = 0; k < lobes; ++k)
    light.push_back({axes[k], std::pow(10.0, 0.1 * (k % 25)), Vec3(1.0 + k % 3, 1.0, 0.5 + 0.1 * k)});
  return light;
}

// 0: a diffuse dielectric (roughness 0.7); otherwise a metal (roughness 0.25).
inline SgMaterial BenchMaterial(bool metal) {
  return SgMaterial{Vec3(0.8, 0.35, 0.2), metal ? 0.25 : 0.7, metal ? 1.0 : 0.0};
}

// `count` pixels with normals spread over the sphere and views within about
// 30° of them (fixed seed).
struct ShadePixels {
  std::vector<Vec3f> normals, views;
};
inline ShadePixels RandomShadePixels(int count) {
  ShadePixels pixels;
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (int p = 0; p < count; ++p) {
    pixels.normals.push_back(Normalized(Vec3f(u(rng), u(rng), u(rng) + 0.01f)));
    pixels.views.push_back(Normalized(pixels.normals.back() + Vec3f(u(rng), u(rng), u(rng)) * 0.5f));
  }
  return pixels;
}

}  // namespace nerfar
