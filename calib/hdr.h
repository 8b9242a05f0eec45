// HDR from exposure brackets: camera response recovery (Debevec & Malik 1997)
// and the merge of 8-bit brackets into linear HDR radiance. The response maps
// a pixel value z in 0..255 of channel c to g_c(z) = ln(E * t): log of
// relative irradiance E times exposure time t (seconds). Its scale is
// arbitrary (g(128) = 0 per channel): merged images are linear radiance up to
// one global factor per camera, which calibration against a known white or
// the scene's own exposure fixes later. Saturated (255) and black (0) pixels
// get zero weight; a pixel clipped in every bracket takes the bound its
// clipping implies and is counted.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "calib/core/image.h"

namespace nerfar {

inline constexpr int kResponseLevels = 256;

struct CameraResponse {
  // log_exposure[c][z] = g_c(z); 1 or 3 channels of 256 entries each.
  std::vector<std::array<float, kResponseLevels>> log_exposure;

  bool empty() const { return log_exposure.empty(); }
  int channels() const { return static_cast<int>(log_exposure.size()); }
  // Linear relative exposure E*t of value z in channel c: exp(g_c(z)).
  float Linear(int channel, int z) const;
  // Every problem: channel count, non-finite entries, a curve that decreases.
  std::vector<std::string> Validate() const;
  // The response of a linear camera (g(z) = ln(z / 128), black clamped to 0.5).
  static CameraResponse Linear8(int channels);
  // The response of frames made by ToneMapToDisplay (Reinhard x/(1+x), then
  // sRGB, 8 bits): g(z) = ln(s/(1-s)), s the linear value of z; the ends
  // (0 and 255, which stand for a range) use 0.5 and 254.5.
  static CameraResponse Display8(int channels);
};

// One exposure of a bracket: an 8-bit frame (1 or 3 channels, as the camera
// delivered it, after white balance is locked) and its exposure time.
struct ExposureFrame {
  Image8 image;
  double exposure_s = 0;  // seconds (or any unit, the same for every frame)
};

struct ResponseOptions {
  // Pixel locations sampled for the fit. Debevec needs samples x (frames - 1)
  // > 255; more gives a smoother curve at a quadratic solve cost.
  int samples = 200;
  // Weight of the second-derivative smoothness term (lambda in the paper).
  // Raise it for noisy frames, lower it for a sharp knee in the curve.
  double smoothness = 20.0;
  // Seed for the sample selection (results are deterministic).
  std::uint32_t seed = 1;
  std::vector<std::string> Validate() const;
};

struct MergeStats {
  size_t saturated_everywhere = 0;  // pixels at 255 (some channel) in every frame
  size_t black_everywhere = 0;      // pixels at 0 (some channel) in every frame
};

// Recovers the response from a bracket of the same static view. InputError
// for fewer than 2 frames, mismatched sizes or channels, non-positive or
// repeated exposure times.
CameraResponse RecoverResponse(const std::vector<ExposureFrame>& frames, const ResponseOptions& options = {});

// Merges a bracket to linear HDR (float, the frames' channel count), weighting
// each frame's value by the hat function of Debevec (zero at 0 and 255).
ImageF MergeExposures(const std::vector<ExposureFrame>& frames, const CameraResponse& response,
                      MergeStats* stats = nullptr);

// The hat weight of value z (0 at 0 and 255, 1 in the middle).
double HatWeight(int z);

}  // namespace nerfar
