// Drawing pieces of the environment report (env_report.cpp); not part of the
// module's interface. Pictures are 8-bit sRGB, 3 channels; panoramas follow
// the scenes' equirect convention (render/sg/sphere.h).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "calib/camera.h"
#include "calib/core/image.h"
#include "render/sg/sg.h"

namespace nerfar::env_report_internal {

using Colour = std::array<std::uint8_t, 3>;

// Angle (radians) from a lobe's axis at which it falls to half its maximum:
// acos(1 − ln2/λ); π when it never does (λ < ln2/2).
double LobeHalfMaxAngle(double sharpness);

// Elevation lines every 30 degrees (the horizon solid), the ±x and ±y
// azimuth lines, and their labels, drawn over a panorama picture.
void DrawPanoramaGuides(Image8& panorama);
// A lobe's energy: the luminance of its integral over the sphere.
double LobeEnergy(const Sg& lobe);
// Lobe indices from the most to the least energy, ties in the mixture's order.
std::vector<size_t> LobesByEnergy(const SgMixture& lobes);
// The lobes' axes (crosses) and half-maximum circles: of every lobe, or of the
// `labelled` brightest only; those numbered 1, 2, ... by energy.
void DrawLobes(Image8& panorama, const SgMixture& lobes, int labelled, bool labelled_only);

// A filled dot with a dark rim at continuous pixel coordinates.
void DrawDot(Image8& image, const Vec2& pixel, double radius, const Colour& colour);

// The colour scale of t in [−1, 1] with ticks at the factors 1/2, 1/√2, 1,
// √2, 2 of a log2 scale of ±scale_log2 and words at both ends.
Image8 ResidualLegend(int width, double scale_log2, const std::string& low_words, const std::string& high_words);

// The upper hemisphere seen from above (+x right, +y up, orthographic), one
// dot per normal coloured by values[i] / scale on the diverging scale.
Image8 HemisphereDots(int size, const std::vector<Vec3>& normals, const std::vector<double>& values, double scale);

// An image resized (bilinear, or nearest to keep pixels visible) to width × height.
Image8 Resized(const Image8& image, int width, int height, bool nearest);
// 1-channel → 3 channels, each value scaled by `gain` (a dimmed grey backdrop).
Image8 GreyBackdrop(const Image8& grey, double gain);
// Copies `tile` into `page` with its top-left corner at (x, y), clipped.
void Paste(Image8& page, const Image8& tile, int x, int y);

}  // namespace nerfar::env_report_internal
