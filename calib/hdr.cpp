#include "calib/hdr.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <random>

#include "calib/core/error.h"
#include "calib/core/image_io.h"

namespace nerfar {
namespace {

// Sorted by exposure time (shortest first), with the input checked.
std::vector<const ExposureFrame*> CheckFrames(const std::vector<ExposureFrame>& frames, const std::string& source) {
  Problems problems(source);
  if (frames.size() < 2)
    problems.Add("frames", std::to_string(frames.size()) + " given (expected at least 2 exposures)");
  std::vector<const ExposureFrame*> sorted;
  for (size_t i = 0; i < frames.size(); ++i) {
    const ExposureFrame& f = frames[i];
    const std::string where = "frame " + std::to_string(i);
    if (f.image.empty() || (f.image.channels != 1 && f.image.channels != 3) ||
        f.image.pixels.size() != static_cast<size_t>(f.image.width) * f.image.height * f.image.channels) {
      problems.Add(where, "is not a 1- or 3-channel 8-bit image");
      continue;
    }
    if (!(f.exposure_s > 0) || !std::isfinite(f.exposure_s))
      problems.Add(where, "exposure is " + std::to_string(f.exposure_s) + " (expected a positive time)");
    if (!sorted.empty() && (f.image.width != sorted[0]->image.width || f.image.height != sorted[0]->image.height ||
                            f.image.channels != sorted[0]->image.channels))
      problems.Add(where, "size or channels differ from frame 0 (expected one static view)");
    sorted.push_back(&f);
  }
  problems.ThrowIfAny();
  std::sort(sorted.begin(), sorted.end(),
            [](const ExposureFrame* a, const ExposureFrame* b) { return a->exposure_s < b->exposure_s; });
  for (size_t i = 1; i < sorted.size(); ++i)
    if (!(sorted[i]->exposure_s > sorted[i - 1]->exposure_s * (1 + 1e-6)))
      problems.Add("frames", "two frames share the exposure " + std::to_string(sorted[i]->exposure_s) +
                                 " (expected distinct exposures)");
  problems.ThrowIfAny();
  return sorted;
}

// Makes g non-decreasing outward from the anchor z = 128 (noise at the ends,
// where few samples constrain the curve, must not fold it back).
void MakeMonotone(std::array<float, kResponseLevels>& g) {
  for (int z = 129; z < kResponseLevels; ++z) g[z] = std::max(g[z], g[z - 1]);
  for (int z = 127; z >= 0; --z) g[z] = std::min(g[z], g[z + 1]);
}

}  // namespace

double HatWeight(int z) { return (z <= 127 ? z : 255 - z) / 127.0; }

float CameraResponse::Linear(int channel, int z) const { return std::exp(log_exposure[channel][z]); }

std::vector<std::string> CameraResponse::Validate() const {
  std::vector<std::string> problems;
  if (log_exposure.size() != 1 && log_exposure.size() != 3)
    problems.push_back("has " + std::to_string(log_exposure.size()) + " channels (expected 1 or 3)");
  for (size_t c = 0; c < log_exposure.size(); ++c) {
    for (int z = 0; z < kResponseLevels; ++z) {
      if (!std::isfinite(log_exposure[c][z])) {
        problems.push_back("channel " + std::to_string(c) + " value " + std::to_string(z) + " is not finite");
        break;
      }
      if (z > 0 && log_exposure[c][z] < log_exposure[c][z - 1]) {
        problems.push_back("channel " + std::to_string(c) + " decreases at value " + std::to_string(z) +
                           " (expected a non-decreasing curve)");
        break;
      }
    }
  }
  return problems;
}

CameraResponse CameraResponse::Linear8(int channels) {
  CameraResponse r;
  r.log_exposure.resize(channels);
  for (auto& g : r.log_exposure)
    for (int z = 0; z < kResponseLevels; ++z) g[z] = static_cast<float>(std::log(std::max(z, 1) / 128.0));
  // Value 0 shares value 1's exposure: below that a linear camera says nothing.
  return r;
}

CameraResponse CameraResponse::Display8(int channels) {
  CameraResponse r;
  r.log_exposure.resize(channels);
  for (auto& g : r.log_exposure)
    for (int z = 0; z < kResponseLevels; ++z) {
      const double s = SrgbToLinear(static_cast<float>(std::clamp(z, 0, 255) == 0 ? 0.5 / 255
                                                       : z == kResponseLevels - 1 ? 254.5 / 255
                                                                                  : z / 255.0));
      g[z] = static_cast<float>(std::log(s / (1 - s)));
    }
  return r;
}

std::vector<std::string> ResponseOptions::Validate() const {
  std::vector<std::string> problems;
  if (samples < 16 || samples > 4096)
    problems.push_back("samples: is " + std::to_string(samples) + " (expected 16 to 4096)");
  if (!(smoothness > 0) || !std::isfinite(smoothness) || smoothness > 1e6)
    problems.push_back("smoothness: is " + std::to_string(smoothness) + " (expected > 0 and at most 1e6)");
  return problems;
}

CameraResponse RecoverResponse(const std::vector<ExposureFrame>& frames, const ResponseOptions& options) {
  {
    Problems problems("response options");
    for (const std::string& p : options.Validate()) problems.Add("", p);
    problems.ThrowIfAny();
  }
  const std::vector<const ExposureFrame*> sorted = CheckFrames(frames, "exposure bracket");
  const int p = static_cast<int>(sorted.size());
  const int channels = sorted[0]->image.channels;
  const size_t pixels = sorted[0]->image.PixelCount();
  const ExposureFrame& middle = *sorted[p / 2];
  std::mt19937 rng(options.seed);

  CameraResponse response;
  response.log_exposure.resize(channels);
  for (int c = 0; c < channels; ++c) {
    // Samples spread over the value range of the middle exposure (Debevec:
    // the sampled pixels should cover the whole curve), picked at random
    // within each value's pixels.
    // Only pixels with at least two unclipped values say anything about the
    // curve (a pixel clipped everywhere would leave its ln E unconstrained).
    std::vector<std::vector<size_t>> by_value(kResponseLevels);
    for (size_t i = 0; i < pixels; ++i) {
      int useful = 0;
      for (int j = 0; j < p; ++j) {
        const int z = sorted[j]->image.pixels[i * channels + c];
        useful += z > 0 && z < 255;
      }
      if (useful >= 2) by_value[middle.image.pixels[i * channels + c]].push_back(i);
    }
    std::vector<int> present;
    for (int z = 0; z < kResponseLevels; ++z)
      if (!by_value[z].empty()) present.push_back(z);
    if (present.empty())
      ThrowInputError("exposure bracket", "no pixel is unclipped in two frames (expected overlapping exposures)");
    std::vector<size_t> samples;
    for (int k = 0; k < options.samples; ++k) {
      const int z = present[static_cast<size_t>(k) * present.size() / options.samples];
      std::uniform_int_distribution<size_t> pick(0, by_value[z].size() - 1);
      samples.push_back(by_value[z][pick(rng)]);
    }
    // Least squares of Debevec & Malik: unknowns g(0..255) and ln E_i per
    // sample; rows w(z) (g(z) - ln E_i) = w(z) ln t_j, the anchor g(128) = 0
    // and lambda w(z) g''(z) = 0. Each row has at most 3 non-zeros, so the
    // normal equations are accumulated directly (no dense design matrix).
    const int n = static_cast<int>(samples.size());
    const int cols = kResponseLevels + n;
    Eigen::MatrixXd normal = Eigen::MatrixXd::Zero(cols, cols);
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(cols);
    const auto add_row = [&](std::initializer_list<std::pair<int, double>> row, double b) {
      for (const auto& [i, a] : row) {
        for (const auto& [j, a2] : row) normal(i, j) += a * a2;
        rhs(i) += a * b;
      }
    };
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < p; ++j) {
        const int z = sorted[j]->image.pixels[samples[i] * channels + c];
        const double w = HatWeight(z);
        if (w > 0) add_row({{z, w}, {kResponseLevels + i, -w}}, w * std::log(sorted[j]->exposure_s));
      }
    }
    add_row({{128, 1.0}}, 0.0);  // fixes the arbitrary scale: g(128) = 0
    for (int z = 1; z < kResponseLevels - 1; ++z) {
      const double w = options.smoothness * HatWeight(z);
      add_row({{z - 1, w}, {z, -2 * w}, {z + 1, w}}, 0.0);
    }
    const Eigen::VectorXd x = normal.ldlt().solve(rhs);
    for (int z = 0; z < kResponseLevels; ++z) response.log_exposure[c][z] = static_cast<float>(x(z));
    MakeMonotone(response.log_exposure[c]);
  }
  const std::vector<std::string> problems = response.Validate();
  if (!problems.empty())
    ThrowInputError("exposure bracket", "the frames do not determine a response (" + problems[0] +
                                            "; expected a static view with distinct exposures)");
  return response;
}

ImageF MergeExposures(const std::vector<ExposureFrame>& frames, const CameraResponse& response, MergeStats* stats) {
  const std::vector<const ExposureFrame*> sorted = CheckFrames(frames, "exposure bracket");
  const int channels = sorted[0]->image.channels;
  {
    Problems problems("camera response");
    for (const std::string& p : response.Validate()) problems.Add("", p);
    if (response.channels() != channels && response.channels() != 1)
      problems.Add("", "has " + std::to_string(response.channels()) + " channels for " + std::to_string(channels) +
                           "-channel frames (expected the same, or 1)");
    problems.ThrowIfAny();
  }
  const int p = static_cast<int>(sorted.size());
  std::vector<double> log_t(p);
  for (int j = 0; j < p; ++j) log_t[j] = std::log(sorted[j]->exposure_s);
  const int width = sorted[0]->image.width, height = sorted[0]->image.height;
  ImageF out(width, height, channels);
  MergeStats local;
  for (size_t i = 0; i < out.PixelCount(); ++i) {
    bool saturated_all = false, black_all = false;
    for (int c = 0; c < channels; ++c) {
      const auto& g = response.log_exposure[response.channels() == 1 ? 0 : c];
      double num = 0, den = 0;
      int saturated = 0;
      for (int j = 0; j < p; ++j) {
        const int z = sorted[j]->image.pixels[i * channels + c];
        const double w = HatWeight(z);
        num += w * (g[z] - log_t[j]);
        den += w;
        saturated += z == 255;
      }
      float value;
      if (den > 0) {
        value = static_cast<float>(std::exp(num / den));
      } else if (saturated > 0) {
        // Clipped even in the shortest exposure: at least this bright.
        value = static_cast<float>(std::exp(g[255] - log_t[0]));
        saturated_all = true;
      } else {
        // Black even in the longest exposure: no signal, radiance 0.
        value = 0.0f;
        black_all = true;
      }
      out.pixels[i * channels + c] = value;
    }
    local.saturated_everywhere += saturated_all;
    local.black_everywhere += black_all;
  }
  if (stats != nullptr) *stats = local;
  return out;
}

}  // namespace nerfar
