// 8-bit images (PNG and JPEG) and display tone mapping.
// Channel order in memory is R,G,B (OpenCV's BGR is converted at this edge).
// Tone mapping (DESIGN.md): Reinhard x/(1+x) after an exposure scale, then the
// sRGB transfer curve; only for display and PNG, never for data.
#pragma once

#include <string>
#include <string_view>

#include "calib/core/image.h"

namespace nerfar {

// Reads an 8-bit image with 1 (grey) or 3 (RGB) channels as stored; alpha is
// dropped. InputError naming the file if it is missing or not a PNG or JPEG.
Image8 ReadImage8(const std::string& path);
// The same from a PNG or JPEG file's bytes held in memory (a texture embedded
// in a GLB); `source` names them in errors.
Image8 DecodeImage8(std::string_view bytes, const std::string& source);
// InputError naming the file unless it starts as a PNG or a JPEG does and its
// header states a size within kMaxImageSide and kMaxImagePixels. Files are
// checked before OpenCV decodes them: OpenCV picks a decoder by content among
// every format it was built with, and some of those libraries abort the
// process on a malformed file (a DICOM header in a corrupt frame); and a
// small file can state a size whose decoding takes gigabytes and seconds.
void CheckPngOrJpegHeader(const std::string& path);
// Writes PNG or JPEG by extension (atomic). 1, 3 or 4 channels.
void WriteImage8(const std::string& path, const Image8& image);

// sRGB transfer of a linear value in [0, 1] and back.
float LinearToSrgb(float linear);
float SrgbToLinear(float srgb);

// Display pixels from linear radiance: tm(exposure * x) per channel, then sRGB,
// quantised. Non-finite input shows as magenta so it is never hidden.
Image8 ToneMapToDisplay(const ImageF& linear, float exposure = 1.0f);
// Linear RGB in [0,1] from 8-bit sRGB (a camera frame taken as display-referred).
ImageF DisplayToLinear(const Image8& image);
// Grey 8-bit image for detectors: luminance of the tone-mapped display image.
Image8 ToGray(const Image8& rgb);

// Exposure that maps the 99th percentile luminance to 1 (the metrics' k).
float ExposureForPercentile(const ImageF& linear, double percentile = 0.99);

}  // namespace nerfar
