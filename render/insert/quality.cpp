#include "render/insert/quality.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "calib/core/error.h"
#include "calib/core/metrics.h"
#include "render/sg/sphere.h"
#include "render/sg/visibility.h"

namespace nerfar {

namespace {

constexpr int kLightingNormals = 64;

// Luminance per pixel; where `mask` (may be null) holds the object, the
// luminance of `instead` (the metric compares the scene around the object,
// not the object: eval/metrics.py replaces those pixels before blurring).
std::vector<double> LuminanceOutside(const ImageF& image, const ImageF* mask = nullptr,
                                     const ImageF* instead = nullptr) {
  std::vector<double> lum(static_cast<size_t>(image.width) * image.height);
  for (size_t p = 0; p < lum.size(); ++p) {
    const bool object = mask != nullptr && mask->pixels[p * mask->channels] > 0.5f;
    const ImageF& from = object ? *instead : image;
    lum[p] = Luminance(&from.pixels[p * from.channels], from.channels);
  }
  return lum;
}

// 5×5 box blur with the borders mirrored about the edge pixel (OpenCV's
// default, BORDER_REFLECT_101, as eval/metrics.py's cv2.blur).
std::vector<double> Blur5(const std::vector<double>& v, int w, int h) {
  const auto mirror = [](int i, int n) { return n == 1 ? 0 : i < 0 ? -i : i >= n ? 2 * n - 2 - i : i; };
  std::vector<double> tmp(v.size()), out(v.size());
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double s = 0;
      for (int dx = -2; dx <= 2; ++dx) s += v[static_cast<size_t>(y) * w + mirror(x + dx, w)];
      tmp[static_cast<size_t>(y) * w + x] = s / 5.0;
    }
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double s = 0;
      for (int dy = -2; dy <= 2; ++dy) s += tmp[static_cast<size_t>(mirror(y + dy, h)) * w + x];
      out[static_cast<size_t>(y) * w + x] = s / 5.0;
    }
  return out;
}

// The metric's blurred background luminance below which a pixel shows
// nothing (κ = 1, outside the region): eval/metrics.py's eps.
constexpr double kDarkBackground = 1e-4;

// κ = blur(Y(with)) / blur(Y(without)), the object's pixels (mask, may be
// null) taken from `without`; 1 where the blurred background is dark.
std::vector<double> KappaOf(const ImageF& with, const ImageF& without, const ImageF* mask = nullptr) {
  const int w = with.width, h = with.height;
  const std::vector<double> a = Blur5(LuminanceOutside(with, mask, &without), w, h);
  const std::vector<double> b = Blur5(LuminanceOutside(without), w, h);
  std::vector<double> k(a.size(), 1.0);
  for (size_t i = 0; i < k.size(); ++i) k[i] = b[i] > kDarkBackground ? a[i] / b[i] : 1.0;
  return k;
}

void CheckSameSize(const ImageF& a, const ImageF& b, const char* what) {
  if (a.width != b.width || a.height != b.height)
    ThrowInputError(what, "sizes differ (" + std::to_string(a.width) + "x" + std::to_string(a.height) + " vs " +
                              std::to_string(b.width) + "x" + std::to_string(b.height) + ")");
}

double RelativeRms(const std::vector<Vec3>& ours, const std::vector<Vec3>& truth) {
  double num = 0, den = 0;
  for (size_t i = 0; i < truth.size(); ++i) {
    const Vec3 d = ours[i] - truth[i];
    num += Dot(d, d);
    den += Dot(truth[i], truth[i]);
  }
  return den > 0 ? std::sqrt(num / den) : (num > 0 ? std::numeric_limits<double>::infinity() : 0.0);
}

}  // namespace

double ObjectPsnrTm(const ImageF& ours, const ImageF& truth, const ImageF& mask) {
  CheckSameSize(ours, truth, "object psnr");
  CheckSameSize(mask, truth, "object mask");
  ImageF m(mask.width, mask.height, 1);
  float scale = 1.0f;
  for (float v : mask.pixels) scale = std::max(scale, v > 1.0f ? 1.0f / 255.0f : 1.0f);
  for (size_t p = 0; p < m.pixels.size(); ++p) m.pixels[p] = mask.pixels[p * mask.channels] * scale;
  return PsnrTm(ours, truth, &m);
}

ShadowError ComputeShadowError(const ImageF& ours_with, const ImageF& ours_without, const ImageF& truth_with,
                               const ImageF& truth_without, const ImageF& mask) {
  CheckSameSize(ours_with, truth_with, "shadow error");
  CheckSameSize(ours_without, truth_with, "shadow error");
  CheckSameSize(truth_without, truth_with, "shadow error");
  CheckSameSize(mask, truth_with, "shadow mask");
  const int w = truth_with.width, h = truth_with.height;
  const std::vector<double> k_ours = KappaOf(ours_with, ours_without, &mask);
  const std::vector<double> background = Blur5(LuminanceOutside(truth_without), w, h);
  const std::vector<double> k_gt = KappaOf(truth_with, truth_without, &mask);
  std::vector<uint8_t> counts(k_gt.size()), seed(k_gt.size()), region(k_gt.size(), 0);
  for (size_t p = 0; p < k_gt.size(); ++p) {
    counts[p] = mask.pixels[p * mask.channels] <= 0.5f && background[p] > kDarkBackground;
    seed[p] = counts[p] && k_gt[p] < 0.9;
  }
  // Dilate by 5 px (a square window); then only pixels outside the mask
  // with a background.
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (!seed[static_cast<size_t>(y) * w + x]) continue;
      for (int dy = -5; dy <= 5; ++dy)
        for (int dx = -5; dx <= 5; ++dx) {
          const int xx = x + dx, yy = y + dy;
          if (xx >= 0 && xx < w && yy >= 0 && yy < h) region[static_cast<size_t>(yy) * w + xx] = 1;
        }
    }
  ShadowError e;
  double num = 0, den = 0, sum_k = 0, sum_gt = 0, worst = -1;
  for (size_t p = 0; p < region.size(); ++p) {
    if (!region[p] || !counts[p]) continue;
    const double k = std::clamp(k_ours[p], 0.0, 2.0), k_true = std::clamp(k_gt[p], 0.0, 2.0);
    const double d = std::abs(k - k_true);
    if (d > worst) {
      worst = d;
      e.worst_x = static_cast<int>(p % w);
      e.worst_y = static_cast<int>(p / w);
      e.worst_kappa = k_ours[p];
      e.worst_kappa_gt = k_gt[p];
      e.worst_background = background[p];
    }
    num += d;
    den += std::abs(1.0 - k_true);
    sum_k += k;
    sum_gt += k_true;
    ++e.region;
  }
  if (e.region <= kMinShadowRegion || !(den > 0)) {
    e.error = std::numeric_limits<double>::quiet_NaN();
    return e;
  }
  e.error = num / den;
  e.mean_kappa = sum_k / e.region;
  e.mean_kappa_gt = sum_gt / e.region;
  return e;
}

ImageF ShadowRatioImage(const ImageF& with, const ImageF& without) {
  CheckSameSize(with, without, "shadow ratio");
  const std::vector<double> k = KappaOf(with, without);
  ImageF out(with.width, with.height, 1);
  for (size_t p = 0; p < k.size(); ++p) out.pixels[p] = static_cast<float>(k[p]);
  return out;
}

std::vector<Vec3> IrradianceAtNormals(const ImageF& panorama) {
  std::vector<Vec3> e;
  for (const Vec3& n : FibonacciSphere(kLightingNormals)) e.push_back(PanoramaIrradiance(panorama, n));
  return e;
}

double LightingError(const ImageF& our_panorama, const ImageF& true_panorama) {
  return RelativeRms(IrradianceAtNormals(our_panorama), IrradianceAtNormals(true_panorama));
}

double LightingError(const SgMixture& our_light, const ImageF& true_panorama) {
  std::vector<Vec3> ours;
  for (const Vec3& n : FibonacciSphere(kLightingNormals)) ours.push_back(Irradiance(our_light, n));
  return RelativeRms(ours, IrradianceAtNormals(true_panorama));
}

}  // namespace nerfar
