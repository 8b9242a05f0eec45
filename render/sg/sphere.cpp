#include "render/sg/sphere.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "calib/core/error.h"

namespace nerfar {

Vec3 EquirectDirection(double u, double v) {
  const double theta = kPi * v, phi = kPi * (1.0 - 2.0 * u);
  const double s = std::sin(theta);
  return {s * std::cos(phi), s * std::sin(phi), std::cos(theta)};
}

void EquirectCoordinates(const Vec3& d, double* u, double* v) {
  double uu = 0.5 - std::atan2(d.y, d.x) / (2.0 * kPi);
  uu -= std::floor(uu);
  if (uu >= 1.0) uu = 0.0;
  *u = uu;
  *v = std::acos(std::clamp(d.z, -1.0, 1.0)) / kPi;
}

double EquirectPixelSolidAngle(int width, int height, int row) {
  const double t0 = kPi * row / height, t1 = kPi * (row + 1) / height;
  return (2.0 * kPi / width) * (std::cos(t0) - std::cos(t1));
}

RadianceSamples SamplesFromEquirect(const ImageF& panorama, int out_width, int out_height) {
  Problems problems("panorama");
  if (panorama.channels < 3) problems.Add("channels", std::to_string(panorama.channels) + " (expected RGB)");
  if (out_width < 1 || out_height < 1 || panorama.width % std::max(out_width, 1) != 0 ||
      panorama.height % std::max(out_height, 1) != 0)
    problems.Add("size", std::to_string(panorama.width) + "x" + std::to_string(panorama.height) +
                             " (expected a whole multiple of " + std::to_string(out_width) + "x" +
                             std::to_string(out_height) + ")");
  problems.ThrowIfAny();
  const int fx = panorama.width / out_width, fy = panorama.height / out_height;
  RadianceSamples samples;
  samples.directions.reserve(static_cast<size_t>(out_width) * out_height);
  for (int j = 0; j < out_height; ++j) {
    for (int i = 0; i < out_width; ++i) {
      Vec3 sum;
      double area = 0.0;
      for (int y = j * fy; y < (j + 1) * fy; ++y) {
        const double w = EquirectPixelSolidAngle(panorama.width, panorama.height, y);
        for (int x = i * fx; x < (i + 1) * fx; ++x) {
          const float* p = panorama.Pixel(x, y);
          for (int c = 0; c < 3; ++c)
            if (!std::isfinite(p[c]) || p[c] < 0.0f)
              ThrowInputError("panorama", "pixel (" + std::to_string(x) + ", " + std::to_string(y) +
                                              ") is negative or not finite (expected radiance >= 0)");
          sum += Vec3(p[0], p[1], p[2]) * w;
          area += w;
        }
      }
      samples.directions.push_back(EquirectDirection((i + 0.5) / out_width, (j + 0.5) / out_height));
      samples.radiance.push_back(sum / area);
      samples.solid_angles.push_back(area);
    }
  }
  return samples;
}

ImageF RenderEquirect(const SgMixture& mixture, int width, int height) {
  ImageF image(width, height, 3);
  for (int j = 0; j < height; ++j)
    for (int i = 0; i < width; ++i) {
      const Vec3 value = Evaluate(mixture, EquirectDirection((i + 0.5) / width, (j + 0.5) / height));
      float* p = image.Pixel(i, j);
      p[0] = static_cast<float>(value.x);
      p[1] = static_cast<float>(value.y);
      p[2] = static_cast<float>(value.z);
    }
  return image;
}

Vec3 PanoramaIrradiance(const ImageF& panorama, const Vec3& normal) {
  Vec3 sum;
  for (int j = 0; j < panorama.height; ++j) {
    const double w = EquirectPixelSolidAngle(panorama.width, panorama.height, j);
    for (int i = 0; i < panorama.width; ++i) {
      const double c = Dot(EquirectDirection((i + 0.5) / panorama.width, (j + 0.5) / panorama.height), normal);
      if (c <= 0.0) continue;
      const float* p = panorama.Pixel(i, j);
      sum += Vec3(p[0], p[1], p[2]) * (w * c);
    }
  }
  return sum;
}

std::vector<Vec3> FibonacciSphere(int n) {
  std::vector<Vec3> points;
  points.reserve(static_cast<size_t>(std::max(n, 0)));
  const double golden = kPi * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - (2.0 * i + 1.0) / n;
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    const double phi = golden * i;
    points.push_back({r * std::cos(phi), r * std::sin(phi), z});
  }
  return points;
}

}  // namespace nerfar
