#include "tracking/simulated_exposure.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "calib/core/error.h"

namespace nerfar {
namespace {

class SimulatedExposureSource : public FrameSource {
 public:
  SimulatedExposureSource(std::unique_ptr<FrameSource> source, CameraResponse response, double base_exposure_us)
      : source_(std::move(source)), response_(std::move(response)), base_us_(base_exposure_us) {}

  std::string Describe() const override { return source_->Describe() + " (simulated exposure control)"; }
  std::string LastError() const override { return source_->LastError(); }

  bool SetExposure(double exposure_us) override {
    if (!(exposure_us > 0)) return false;
    scale_ = exposure_us / base_us_;
    BuildTables();
    return true;
  }

  FrameStatus Next(Frame& frame, int timeout_ms) override {
    const FrameStatus status = source_->Next(frame, timeout_ms);
    if (status != FrameStatus::kOk || scale_ == 1.0) return status;
    const int channels = frame.image.channels;
    for (size_t i = 0; i < frame.image.pixels.size(); ++i) {
      const int c = std::min(static_cast<int>(i % channels), response_.channels() - 1);
      frame.image.pixels[i] = tables_[c][frame.image.pixels[i]];
    }
    return status;
  }

 private:
  // Value z -> the value of exposure(z) * scale: the level whose exposure is
  // nearest in log (the response increases).
  void BuildTables() {
    tables_.assign(response_.channels(), {});
    const double log_scale = std::log(scale_);
    for (int c = 0; c < response_.channels(); ++c) {
      const auto& g = response_.log_exposure[c];
      for (int z = 0; z < kResponseLevels; ++z) {
        const double target = g[z] + log_scale;
        int best = 0;
        for (int k = 1; k < kResponseLevels; ++k)
          if (std::abs(g[k] - target) < std::abs(g[best] - target)) best = k;
        tables_[c][z] = static_cast<std::uint8_t>(z == kResponseLevels - 1 && scale_ > 1 ? z : best);
      }
    }
  }

  std::unique_ptr<FrameSource> source_;
  CameraResponse response_;
  double base_us_;
  double scale_ = 1.0;
  std::vector<std::array<std::uint8_t, kResponseLevels>> tables_;
};

}  // namespace

std::unique_ptr<FrameSource> SimulateExposureControl(std::unique_ptr<FrameSource> source, CameraResponse response,
                                                     double base_exposure_us) {
  Problems problems("simulated exposure");
  for (const std::string& p : response.Validate()) problems.Add("response", p);
  if (response.empty()) problems.Add("response", "is empty (expected 1 or 3 channels)");
  if (!(base_exposure_us > 0)) problems.Add("base exposure", "must be > 0 microseconds");
  problems.ThrowIfAny();
  return std::make_unique<SimulatedExposureSource>(std::move(source), std::move(response), base_exposure_us);
}

}  // namespace nerfar
