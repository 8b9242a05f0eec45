// Images: row-major, interleaved channels, origin at the top-left pixel.
// ImageF holds linear HDR radiance (or any float layer: depth, alpha, κ);
// Image8 holds 8-bit camera frames and display pixels. Sizes are validated by
// the readers before anything is allocated (see kMaxImageSide).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace nerfar {

// Largest width or height any reader accepts; larger headers are rejected as
// corrupt before allocation (16k covers every camera and panorama we meet).
inline constexpr int kMaxImageSide = 16384;
// Largest pixel count (2^26: 8192x8192, a 48-megapixel phone frame, a 16384x4096
// panorama): a decoded frame beyond it is refused before its float copy, which
// would take 12 bytes a pixel.
inline constexpr int64_t kMaxImagePixels = int64_t{1} << 26;
inline constexpr int kMaxImageChannels = 64;

template <typename T>
struct ImageT {
  int width = 0;
  int height = 0;
  int channels = 0;
  std::vector<T> pixels;

  ImageT() = default;
  ImageT(int w, int h, int c, T fill = T{})
      : width(w), height(h), channels(c), pixels(static_cast<size_t>(w) * h * c, fill) {}

  bool empty() const { return pixels.empty(); }
  size_t PixelCount() const { return static_cast<size_t>(width) * height; }
  size_t Index(int x, int y, int c = 0) const { return (static_cast<size_t>(y) * width + x) * channels + c; }
  T& at(int x, int y, int c = 0) { return pixels[Index(x, y, c)]; }
  const T& at(int x, int y, int c = 0) const { return pixels[Index(x, y, c)]; }
  T* Pixel(int x, int y) { return pixels.data() + Index(x, y); }
  const T* Pixel(int x, int y) const { return pixels.data() + Index(x, y); }
};

using ImageF = ImageT<float>;
using Image8 = ImageT<std::uint8_t>;

}  // namespace nerfar
