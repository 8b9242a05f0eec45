// OpenEXR images: half or float, any channel names. Pixel values are linear.
// Readers validate the header (size, channels, sampling) before allocating and
// reject non-finite pixels, naming the file and the first bad pixel.
#pragma once

#include <string>
#include <vector>

#include "calib/core/image.h"

namespace nerfar {

enum class ExrPixelType { kHalf, kFloat };

// Channel names in the file (OpenEXR keeps them sorted by name).
std::vector<std::string> ReadExrChannelNames(const std::string& path);

// Reads the named channels, in the order given, into one interleaved image.
// InputError if a channel is missing or the file is bad.
ImageF ReadExr(const std::string& path, const std::vector<std::string>& channels);

// Reads colour as 3 channels: R,G,B (an A channel is ignored); a file with a
// single Y channel is read as grey (Y in all three).
ImageF ReadExrRgb(const std::string& path);

// Reads a single channel (e.g. "Y" for depth); the only channel if the file
// has exactly one and `channel` is empty.
ImageF ReadExrChannel(const std::string& path, const std::string& channel = "");

// Writes image.channels channels named by `names` (atomic). Half stores about
// 3 significant digits up to 65504; use float for depth. An image holding a
// value beyond ±65504 (a lamp filament, the sun) is written as float whatever
// `type` says, so that every finite image round-trips.
void WriteExr(const std::string& path, const ImageF& image, const std::vector<std::string>& names,
              ExrPixelType type = ExrPixelType::kHalf);

// RGB (3 channels) or RGBA (4) shorthand for WriteExr.
void WriteExrRgb(const std::string& path, const ImageF& image, ExrPixelType type = ExrPixelType::kHalf);

}  // namespace nerfar
