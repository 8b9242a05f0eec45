// calib/hdr and calib/camera_file: response recovery and merge on brackets
// simulated from a known HDR image through a known response curve (gamma
// 2.2 followed by an S-curve), the exact linear-camera case, clipped pixels,
// and camera.json round trips.
#include "calib/hdr.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>

#include "calib/camera_file.h"
#include "calib/core/error.h"
#include "calib/dataset.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

using testing::TempDir;
using testing::WriteText;

// The simulated camera: x = exposure E*t (1 saturates), u = x^(1/2.2), then an
// S-curve blend s(u) = 0.6 u + 0.4 smoothstep(u), strictly increasing.
double TrueCurve(double x) {
  const double u = std::pow(std::clamp(x, 0.0, 1.0), 1.0 / 2.2);
  return 0.6 * u + 0.4 * u * u * (3 - 2 * u);
}
std::uint8_t TrueResponse(double x) { return static_cast<std::uint8_t>(std::lround(255.0 * TrueCurve(x))); }
// x at which the curve reaches value z / 255 (bisection; the curve is monotone).
double TrueInverse(double z) {
  double lo = 0, hi = 1;
  for (int i = 0; i < 100; ++i) {
    const double mid = 0.5 * (lo + hi);
    (255.0 * TrueCurve(mid) < z ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

// A linear HDR image spanning about four decades (0.005 to 110) with texture and a
// colour tint; a 10x10 block far too bright (saturates every frame) and one
// at zero (black in every frame).
ImageF SceneRadiance() {
  const int w = 160, h = 120;
  ImageF image(w, h, 3);
  std::mt19937 rng(4);
  std::normal_distribution<double> texture(0.0, 0.08);
  const double tint[3] = {1.0, 0.8, 0.6};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const double log10_l = -1.5 + 3.0 * x / (w - 1) + 0.3 * std::sin(0.2 * y) + texture(rng);
      for (int c = 0; c < 3; ++c) image.at(x, y, c) = static_cast<float>(std::pow(10.0, log10_l) * tint[c]);
    }
  for (int y = 100; y < 110; ++y)
    for (int x = 10; x < 20; ++x)
      for (int c = 0; c < 3; ++c) {
        image.at(x, y, c) = 1e5f;
        image.at(x + 100, y, c) = 0.0f;
      }
  return image;
}

// Exposures 2 EV apart: the brightest texture (~110) is unclipped at the
// shortest (t0 = 0.008), the darkest (~0.005) reaches value ~25 at the longest.
std::vector<ExposureFrame> Bracket(const ImageF& radiance, int count, double t0, double step) {
  std::vector<ExposureFrame> frames;
  for (int j = 0; j < count; ++j) {
    ExposureFrame f;
    f.exposure_s = t0 * std::pow(step, j);
    f.image = Image8(radiance.width, radiance.height, radiance.channels);
    for (size_t i = 0; i < radiance.pixels.size(); ++i)
      f.image.pixels[i] = TrueResponse(radiance.pixels[i] * f.exposure_s);
    frames.push_back(std::move(f));
  }
  return frames;
}

bool InBlock(int x, int y) { return y >= 100 && y < 110 && ((x >= 10 && x < 20) || (x >= 110 && x < 120)); }

TEST(Hdr, RecoveredResponseMatchesTheTrueCurve) {
  const ImageF radiance = SceneRadiance();
  const CameraResponse response = RecoverResponse(Bracket(radiance, 5, 0.008, 4.0));
  ASSERT_EQ(response.channels(), 3);
  EXPECT_TRUE(response.Validate().empty());
  for (int c = 0; c < 3; ++c) {
    // g is known up to a constant: align at the anchor z = 128.
    const double offset = std::log(TrueInverse(128));
    double worst = 0;
    for (int z = 8; z <= 247; ++z)
      worst = std::max(worst, std::abs(response.log_exposure[c][z] - (std::log(TrueInverse(z)) - offset)));
    // 8-bit quantisation alone puts ln x of one level anywhere in a step of up
    // to 1/(255 x slope) ~ 0.06 in ln at z = 8 (x^(1/2.2) is steep there):
    // 0.08 allows that plus the smoothness prior's bias.
    EXPECT_LT(worst, 0.08) << "channel " << c;
  }
}

struct MergeErrors {
  double median = 0, p99 = 0, max = 0;
};

// Relative error of a merge against the radiance after one global scale (the
// response's arbitrary unit: the median ratio); clipped blocks excluded.
MergeErrors RelativeErrors(const ImageF& merged, const ImageF& radiance) {
  std::vector<double> ratios, errors;
  for (int y = 0; y < merged.height; ++y)
    for (int x = 0; x < merged.width; ++x)
      if (!InBlock(x, y))
        for (int c = 0; c < 3; ++c) ratios.push_back(merged.at(x, y, c) / radiance.at(x, y, c));
  std::nth_element(ratios.begin(), ratios.begin() + ratios.size() / 2, ratios.end());
  const double scale = ratios[ratios.size() / 2];
  for (int y = 0; y < merged.height; ++y)
    for (int x = 0; x < merged.width; ++x)
      if (!InBlock(x, y))
        for (int c = 0; c < 3; ++c) errors.push_back(std::abs(merged.at(x, y, c) / scale / radiance.at(x, y, c) - 1.0));
  std::sort(errors.begin(), errors.end());
  return {errors[errors.size() / 2], errors[errors.size() * 99 / 100], errors.back()};
}

TEST(Hdr, MergeRecoversRadianceUpToScale) {
  const ImageF radiance = SceneRadiance();
  const std::vector<ExposureFrame> frames = Bracket(radiance, 5, 0.008, 4.0);
  const CameraResponse response = RecoverResponse(frames);
  MergeStats stats;
  const ImageF merged = MergeExposures(frames, response, &stats);
  ASSERT_EQ(merged.width, radiance.width);
  ASSERT_EQ(merged.channels, 3);
  EXPECT_EQ(stats.saturated_everywhere, 100u);
  EXPECT_EQ(stats.black_everywhere, 100u);
  for (float v : merged.pixels) ASSERT_TRUE(std::isfinite(v) && v >= 0.0f);
  // The same merge with the true curve (g = ln of the inverse response at
  // each level's centre) separates quantisation from response error.
  CameraResponse truth;
  truth.log_exposure.resize(3);
  for (auto& g : truth.log_exposure)
    for (int z = 0; z < kResponseLevels; ++z) g[z] = static_cast<float>(std::log(TrueInverse(std::max(z, 1))));
  const MergeErrors ours = RelativeErrors(merged, radiance);
  const MergeErrors ideal = RelativeErrors(MergeExposures(frames, truth), radiance);
  std::printf("HDR merge relative error, recovered response: median %.4f, p99 %.4f, max %.4f\n", ours.median, ours.p99,
              ours.max);
  std::printf("HDR merge relative error, true response:      median %.4f, p99 %.4f, max %.4f\n", ideal.median,
              ideal.p99, ideal.max);
  // Quantisation bounds the error: a value seen only at level z in its one
  // usable frame is known to about 2.2 x 0.5 / z (gamma 2.2), 4.4 % at z = 25
  // (the scene's darkest texture in the longest frame), far less for the
  // mid-tones. Measured (docs/BENCHMARKS.md): median 0.4 %, p99 4 %.
  EXPECT_LT(ours.median, 0.01);
  EXPECT_LT(ours.p99, 0.06);
  // The recovered curve costs little beyond quantisation.
  EXPECT_LT(ours.median, 2.0 * ideal.median + 0.002);
  // Clipped blocks: saturated takes the bound of the shortest frame (and is
  // brighter than anything unclipped); black is 0.
  float brightest = 0;
  for (int y = 0; y < 100; ++y)
    for (int x = 0; x < merged.width; ++x) brightest = std::max(brightest, merged.at(x, y, 0));
  EXPECT_GE(merged.at(15, 105, 0), 0.9f * brightest);
  EXPECT_EQ(merged.at(115, 105, 1), 0.0f);
}

TEST(Hdr, LinearCameraMergesExactly) {
  // A linear camera (z = round(128 E t)) with the linear response: the merge
  // is a weighted mean of values each within half a level: error <= 0.5/z.
  const CameraResponse linear = CameraResponse::Linear8(1);
  std::vector<ExposureFrame> frames;
  const float radiance[4] = {0.3f, 1.0f, 1.5f, 1.9f};  // unclipped at t = 1
  for (double t : {1.0, 4.0, 16.0}) {
    ExposureFrame f;
    f.exposure_s = t;
    f.image = Image8(4, 1, 1);
    for (int i = 0; i < 4; ++i)
      f.image.pixels[i] = static_cast<std::uint8_t>(std::min(255.0, std::round(128 * radiance[i] * t)));
    frames.push_back(f);
  }
  const ImageF merged = MergeExposures(frames, linear);
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(merged.pixels[i], radiance[i], radiance[i] * 0.5 / 38) << i;
}

TEST(Hdr, BadBrackets) {
  const ImageF radiance = SceneRadiance();
  std::vector<ExposureFrame> frames = Bracket(radiance, 3, 0.008, 4.0);
  EXPECT_THROW(RecoverResponse({frames[0]}), InputError);
  std::vector<ExposureFrame> same = {frames[0], frames[0]};
  EXPECT_THROW(RecoverResponse(same), InputError);
  frames[1].exposure_s = -1;
  frames[2].image = Image8(10, 10, 3);
  try {
    MergeExposures(frames, CameraResponse::Linear8(3));
    ADD_FAILURE() << "bad bracket accepted";
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("frame 1: exposure"), std::string::npos) << m;
    EXPECT_NE(m.find("frame 2: size or channels differ"), std::string::npos) << m;
  }
  ResponseOptions options;
  options.samples = 3;
  options.smoothness = -1;
  EXPECT_EQ(options.Validate().size(), 2u);
}

// ------------------------------------------------------------ camera.json

TEST(CameraFile, RoundTripWithResponseAndRecord) {
  TempDir tmp;
  CameraFile file;
  file.camera.width = 1280;
  file.camera.height = 720;
  file.camera.fx = 910.5;
  file.camera.fy = 909.25;
  file.camera.cx = 641.2;
  file.camera.cy = 359.9;
  file.camera.k1 = -0.1;
  file.camera.k3 = 0.02;
  file.response = CameraResponse::Linear8(3);
  for (float& g : file.response->log_exposure[1]) g += 0.125f;  // a shifted (still monotone) curve
  file.calibration = CalibrationRecord{0.31, 14, 2, 0.8, 0.4, 0.41, 0.3, 0.29};
  WriteCameraFile(tmp.File("camera.json"), file);
  const CameraFile r = ReadCameraFile(tmp.File("camera.json"));
  EXPECT_EQ(r.camera.fx, 910.5);
  EXPECT_EQ(r.camera.cy, 359.9);
  EXPECT_EQ(r.camera.k3, 0.02);
  ASSERT_TRUE(r.response.has_value());
  EXPECT_EQ(r.response->log_exposure[1][200],
            file.response->log_exposure[1][200]);  // float -> double -> float is exact
  ASSERT_TRUE(r.calibration.has_value());
  EXPECT_EQ(r.calibration->views_rejected, 2);
  // The intrinsics keys are those of transforms.json.
  const nlohmann::json doc = nlohmann::json::parse(testing::ReadText(tmp.File("camera.json")));
  for (const char* key : {"fl_x", "fl_y", "cx", "cy", "w", "h", "k1", "k2", "p1", "p2", "k3"})
    EXPECT_TRUE(doc.contains(key)) << key;
}

TEST(CameraFile, TransformsJsonIsACameraSource) {
  TempDir tmp;
  Dataset d;
  d.camera.width = 400;
  d.camera.height = 300;
  d.camera.fx = d.camera.fy = 346.41;
  d.camera.cx = 200;
  d.camera.cy = 150;
  DatasetFrame frame;
  frame.file_path = "a.exr";
  d.frames.push_back(frame);
  WriteDataset(tmp.File("transforms.json"), d);
  const CameraFile r = ReadCameraFile(tmp.File("transforms.json"));
  EXPECT_EQ(r.camera.fx, 346.41);
  EXPECT_FALSE(r.response.has_value());
}

TEST(CameraFile, BadFiles) {
  TempDir tmp;
  const std::string path = tmp.File("camera.json");
  WriteText(path, R"({"fl_x": 500, "cx": 320, "cy": 240, "w": 640, "h": 480, "gain": 2,
                      "response": {"model": "debevec_log_exposure", "log_exposure": [[0, 1, 2]]},
                      "calibration": {"rms_px": "small"}})");
  std::string m;
  try {
    ReadCameraFile(path);
  } catch (const InputError& e) {
    m = e.what();
  }
  EXPECT_NE(m.find(path + ": /gain: unknown key"), std::string::npos) << m;
  EXPECT_NE(m.find(path + ": /response/log_exposure/0: is not an array of 256"), std::string::npos) << m;
  EXPECT_NE(m.find(path + ": /calibration/rms_px"), std::string::npos) << m;
  EXPECT_NE(m.find(path + ": /calibration/views_used: missing"), std::string::npos) << m;
}

}  // namespace
}  // namespace nerfar
