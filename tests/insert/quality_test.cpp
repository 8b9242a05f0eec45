// render/insert/quality: the metrics of DESIGN.md on images whose answer is
// known in closed form, independently of the code that renders insertions:
// a perfect shadow scores 0, no shadow 1, a shadow of half the strength
// exactly 0.5 on a uniform background (the blur and the ratio are linear
// there), pixels under the object mask do not count, a black background
// counts as κ = 1; irradiance of a uniform panorama is π·L and a light twice
// too bright has lighting error 1.
#include "render/insert/quality.h"

#include <gtest/gtest.h>

#include <cmath>

namespace nerfar {
namespace {

constexpr int kW = 96, kH = 64;

// A uniform background `level` with a disc of ratio `kappa` (radius 12 px).
ImageF WithDisc(float level, float kappa) {
  ImageF image(kW, kH, 3, level);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      if (std::hypot(x - 40.0, y - 30.0) < 12.0)
        for (int c = 0; c < 3; ++c) image.at(x, y, c) = level * kappa;
  return image;
}

ImageF EmptyMask() { return ImageF(kW, kH, 1, 0.0f); }

TEST(ShadowError, PerfectNoneAndHalfStrength) {
  const ImageF bg(kW, kH, 3, 0.5f);
  const ImageF truth = WithDisc(0.5f, 0.2f);
  const ShadowError perfect = ComputeShadowError(truth, bg, truth, bg, EmptyMask());
  EXPECT_NEAR(perfect.error, 0.0, 1e-12);
  EXPECT_GT(perfect.region, 400u);  // the disc (~450 px) and its 5-px dilation
  const ShadowError none = ComputeShadowError(bg, bg, truth, bg, EmptyMask());
  EXPECT_NEAR(none.error, 1.0, 1e-9);  // κ = 1 everywhere: numerator = denominator
  // 1 − κ halved everywhere (κ = 0.6 where the truth has 0.2): with a
  // uniform background blur and ratio commute, so the error is exactly 0.5.
  const ShadowError half = ComputeShadowError(WithDisc(0.5f, 0.6f), bg, truth, bg, EmptyMask());
  EXPECT_NEAR(half.error, 0.5, 1e-6);
  // The error does not depend on the background level (κ is a ratio).
  const ImageF bg2(kW, kH, 3, 3.0f);
  EXPECT_NEAR(ComputeShadowError(WithDisc(3.0f, 0.6f), bg2, WithDisc(3.0f, 0.2f), bg2, EmptyMask()).error, 0.5, 1e-6);
}

TEST(ShadowError, MaskedPixelsDoNotCountAndBlackBackgroundIsUnshadowed) {
  const ImageF bg(kW, kH, 3, 0.5f);
  const ImageF truth = WithDisc(0.5f, 0.2f);
  // Our image is wrong all over a masked square (an object drawn there):
  // the masked pixels are replaced by the background before the blur, as
  // eval/metrics.py does, so nothing of it leaks into κ around it: 0.
  ImageF ours = truth;
  ImageF mask = EmptyMask();
  for (int y = 20; y < 40; ++y)
    for (int x = 30; x < 50; ++x) {
      mask.at(x, y) = 1.0f;
      for (int c = 0; c < 3; ++c) ours.at(x, y, c) = 100.0f;
    }
  const ShadowError e = ComputeShadowError(ours, bg, truth, bg, mask);
  EXPECT_NEAR(e.error, 0.0, 1e-12);
  // A view whose region holds 50 pixels or fewer is left out (NaN), as
  // eval/e2e.sh leaves it out of the median: the object's mask covers all
  // of the shadow but a 6x6 window (36 px); with a 10x10 window (100 px) it
  // counts.
  for (const int side : {6, 10}) {
    ImageF cover(kW, kH, 1, 1.0f);
    for (int y = 30; y < 30 + side; ++y)
      for (int x = 40; x < 40 + side; ++x) cover.at(x, y) = 0.0f;
    const double error = ComputeShadowError(bg, bg, truth, bg, cover).error;
    EXPECT_EQ(std::isnan(error), side == 6) << side;
  }
  // κ is clipped to [0, 2]: a spot 10x too bright counts as κ = 2.
  ImageF bright = truth;
  for (int y = 26; y < 35; ++y)
    for (int x = 36; x < 45; ++x)
      for (int c = 0; c < 3; ++c) bright.at(x, y, c) = 5.0f;
  const ShadowError clipped = ComputeShadowError(bright, bg, truth, bg, EmptyMask());
  EXPECT_GT(clipped.error, 0.1);
  EXPECT_LE(clipped.mean_kappa, 2.0);
  // A black background (nothing seen) is κ = 1 for both: no region at all.
  const ImageF black(kW, kH, 3, 0.0f);
  const ShadowError b = ComputeShadowError(black, black, black, black, EmptyMask());
  EXPECT_EQ(b.region, 0u);
  EXPECT_TRUE(std::isnan(b.error));
  // The κ map is the blurred luminance ratio: 0.2 at the disc's centre.
  const ImageF k = ShadowRatioImage(truth, bg);
  EXPECT_NEAR(k.at(40, 30), 0.2f, 1e-6f);
  EXPECT_NEAR(k.at(5, 5), 1.0f, 1e-6f);
}

TEST(LightingError, UniformPanoramaAndScale) {
  ImageF pano(64, 32, 3, 2.0f);
  for (const Vec3& e : IrradianceAtNormals(pano)) {
    // E = ∫ L cos = π L over the hemisphere; equirect quadrature at 64x32
    // is within 1%.
    EXPECT_NEAR(e.x, kPi * 2.0, 0.01 * kPi * 2.0);
    EXPECT_NEAR(e.y, kPi * 2.0, 0.01 * kPi * 2.0);
  }
  EXPECT_NEAR(LightingError(pano, pano), 0.0, 1e-12);
  ImageF twice = pano;
  for (float& v : twice.pixels) v *= 2.0f;
  EXPECT_NEAR(LightingError(twice, pano), 1.0, 1e-9);
}

}  // namespace
}  // namespace nerfar
