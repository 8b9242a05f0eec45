// The evaluation metrics of DESIGN.md, shared by every stage that reports
// quality. psnr_tm compares tm(k·x) images, tm(x) = x/(1+x) per channel, with
// k = 1 / (99th percentile of the ground truth's luminance).
#pragma once

#include <cstddef>
#include <vector>

#include "calib/core/image.h"

namespace nerfar {

// Luminance (Rec. 709 weights) of an RGB pixel; the value itself for 1 channel.
float Luminance(const float* pixel, int channels);

// psnr_tm over all pixels, or over pixels where mask (same size, 1 channel) > 0.5.
// Peak is 1 (tone-mapped range). Infinite for identical images; NaN if the
// mask selects no pixel. Only the first 3 channels are compared.
double PsnrTm(const ImageF& estimate, const ImageF& truth, const ImageF* mask = nullptr);

// One psnr over several images' pixels together, from each image's psnr
// (peak 1) and pixel count: -10·log10(Σ n_i·10^(−psnr_i/10) / Σ n_i).
// An exact image (psnr +∞) adds its pixels with no error; images whose psnr
// is NaN or that have no pixels are left out; NaN if none is left.
double PooledPsnr(const std::vector<double>& psnr_db, const std::vector<size_t>& pixels);

}  // namespace nerfar
