// The evaluation metrics of DESIGN.md, shared by every stage that reports
// quality. psnr_tm compares tm(k·x) images, tm(x) = x/(1+x) per channel, with
// k = 1 / (99th percentile of the ground truth's luminance).
#pragma once

#include "calib/core/image.h"

namespace nerfar {

// Luminance (Rec. 709 weights) of an RGB pixel; the value itself for 1 channel.
float Luminance(const float* pixel, int channels);

// psnr_tm over all pixels, or over pixels where mask (same size, 1 channel) > 0.5.
// Peak is 1 (tone-mapped range). Infinite for identical images; NaN if the
// mask selects no pixel. Only the first 3 channels are compared.
double PsnrTm(const ImageF& estimate, const ImageF& truth, const ImageF* mask = nullptr);

}  // namespace nerfar
