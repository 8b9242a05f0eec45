// The insertion metrics of DESIGN.md, computed exactly as the evaluation
// does: object psnr_tm over the ground-truth mask, the normalised shadow
// error from luminance ratios of 5×5 box-blurred images, and the lighting
// error (relative RMS of irradiance over 64 Fibonacci normals).
#pragma once

#include <cstddef>

#include "calib/core/image.h"
#include "render/sg/sg.h"

namespace nerfar {

// psnr_tm of `ours` against `truth` over the mask (1 channel, > 0.5 counts;
// 8-bit masks converted with values / 255). NaN if the mask is empty.
double ObjectPsnrTm(const ImageF& ours, const ImageF& truth, const ImageF& mask);

struct ShadowError {
  double error = 0;   // mean |κ − κ_gt| / mean |1 − κ_gt| over the region (0 perfect, 1 no shadow)
  size_t region = 0;  // pixels in the region (κ_gt < 0.9, dilated 5 px, outside the mask)
  double mean_kappa_gt = 1, mean_kappa = 1;  // over the region
  // The pixel contributing most to the numerator (diagnosis of outliers).
  int worst_x = -1, worst_y = -1;
  double worst_kappa = 1, worst_kappa_gt = 1, worst_background = 0;  // κ, κ_gt and Y(blur(truth_without)) there
};
// κ = blur(Y(with)) / blur(Y(without)) for ours and for the truth (5×5 box,
// borders mirrored), the mask's pixels of `with` taken from `without` before
// the blur, clipped to [0, 2]; over the region κ_gt < 0.9 dilated 5 px,
// outside the mask, where the blurred background luminance exceeds 1e-4:
// eval/metrics.py's shadow_error step for step (ours_without is the
// truth's background there: the evaluation inserts over bg_XXX). NaN when
// the region holds kMinShadowRegion pixels or fewer (eval/e2e.sh leaves such
// views out). `ours_with` / `ours_without`: our composite and the same frame
// without the object; `truth_with` / `truth_without` likewise.
inline constexpr size_t kMinShadowRegion = 50;
ShadowError ComputeShadowError(const ImageF& ours_with, const ImageF& ours_without, const ImageF& truth_with,
                               const ImageF& truth_without, const ImageF& mask);

// The metric's κ map: blur(Y(with)) / blur(Y(without)) per pixel (1
// channel), 1 where the blurred background luminance is at most 1e-4.
ImageF ShadowRatioImage(const ImageF& with, const ImageF& without);

// Relative RMS over 64 Fibonacci normals of E(n) (RGB) from our panorama vs
// the true one: sqrt(Σ|E − E_gt|² / Σ|E_gt|²).
double LightingError(const ImageF& our_panorama, const ImageF& true_panorama);
// The same with our light given as SGs (exact irradiance of the lobes).
double LightingError(const SgMixture& our_light, const ImageF& true_panorama);

// Irradiance over 64 normals (what both lighting errors compare).
std::vector<Vec3> IrradianceAtNormals(const ImageF& panorama);

}  // namespace nerfar
