// Directions on the sphere: the equirectangular panorama convention of the
// shared scenes (scenes/README.md: column i, row j, u = (i + 0.5)/W,
// v = (j + 0.5)/H, θ = πv from +z, φ = π(1 − 2u) from +x towards +y; world
// frame, z up), radiance samples taken from such a panorama, and Fibonacci
// point sets for quadrature and evaluation normals.
#pragma once

#include <vector>

#include "calib/core/image.h"
#include "render/sg/sg.h"

namespace nerfar {

// Direction a panorama coordinate (u, v in [0, 1]) looks in, and back
// (u in [0, 1), v in [0, 1]).
Vec3 EquirectDirection(double u, double v);
void EquirectCoordinates(const Vec3& direction, double* u, double* v);
// Solid angle (sr) of one pixel of row `row` in a width × height panorama.
double EquirectPixelSolidAngle(int width, int height, int row);

// Radiance arriving from directions (linear RGB), each with the solid angle it
// stands for (sr; they sum to 4π for a whole panorama, any positive values
// otherwise, e.g. 4π/N for ray-traced directions).
struct RadianceSamples {
  std::vector<Vec3> directions;
  std::vector<Vec3> radiance;
  std::vector<double> solid_angles;
  size_t size() const { return directions.size(); }
};

// Area-averages a panorama down to out_width × out_height pixels (the input
// size must be a whole multiple; out 64 × 32 gives 2048 samples) and returns
// one sample per output pixel at its centre. InputError for bad sizes or
// non-finite / negative pixels.
RadianceSamples SamplesFromEquirect(const ImageF& panorama, int out_width, int out_height);

// The mixture rendered as a panorama (3 channels).
ImageF RenderEquirect(const SgMixture& mixture, int width, int height);

// Irradiance E(n) = Σ L max(d·n, 0) Δω of a panorama by direct summation over
// its pixels (the ground truth the lighting error uses).
Vec3 PanoramaIrradiance(const ImageF& panorama, const Vec3& normal);

// n points spread evenly over the sphere (golden-angle spiral), each standing
// for 4π/n sr: a quadrature rule whose error for smooth integrands falls like
// 1/n (the tests state tolerances from n).
std::vector<Vec3> FibonacciSphere(int n);

}  // namespace nerfar
