#include "calib/core/metrics.h"

#include <cmath>
#include <limits>

#include "calib/core/error.h"
#include "calib/core/image_io.h"

namespace nerfar {

float Luminance(const float* pixel, int channels) {
  return channels >= 3 ? 0.2126f * pixel[0] + 0.7152f * pixel[1] + 0.0722f * pixel[2] : pixel[0];
}

double PsnrTm(const ImageF& estimate, const ImageF& truth, const ImageF* mask) {
  NERFAR_CHECK_EQ(estimate.width, truth.width);
  NERFAR_CHECK_EQ(estimate.height, truth.height);
  NERFAR_CHECK_EQ(estimate.channels, truth.channels);
  if (mask != nullptr) {
    NERFAR_CHECK_EQ(mask->width, truth.width);
    NERFAR_CHECK_EQ(mask->height, truth.height);
  }
  const double k = ExposureForPercentile(truth, 0.99);
  const int channels = truth.channels < 3 ? truth.channels : 3;
  double sum = 0.0;
  size_t count = 0;
  for (size_t p = 0; p < truth.PixelCount(); ++p) {
    if (mask != nullptr && mask->pixels[p * mask->channels] <= 0.5f) continue;
    for (int c = 0; c < channels; ++c) {
      const double a = std::max(0.0, k * estimate.pixels[p * truth.channels + c]);
      const double b = std::max(0.0, k * truth.pixels[p * truth.channels + c]);
      const double d = a / (1.0 + a) - b / (1.0 + b);
      sum += d * d;
      ++count;
    }
  }
  if (count == 0) return std::numeric_limits<double>::quiet_NaN();
  const double mse = sum / static_cast<double>(count);
  if (mse == 0.0) return std::numeric_limits<double>::infinity();
  return -10.0 * std::log10(mse);
}

double PooledPsnr(const std::vector<double>& psnr_db, const std::vector<size_t>& pixels) {
  NERFAR_CHECK_EQ(psnr_db.size(), pixels.size());
  double squared_error = 0.0, count = 0.0;
  for (size_t i = 0; i < psnr_db.size(); ++i) {
    if (std::isnan(psnr_db[i]) || pixels[i] == 0) continue;
    squared_error += std::pow(10.0, -psnr_db[i] / 10.0) * static_cast<double>(pixels[i]);
    count += static_cast<double>(pixels[i]);
  }
  if (count == 0.0) return std::numeric_limits<double>::quiet_NaN();
  return -10.0 * std::log10(squared_error / count);
}

}  // namespace nerfar
