// The live display path: 8-bit camera codes <-> linear light under the
// camera's response ("display": the synthetic camera's sRGB of Reinhard
// x/(1+x), inverted; "srgb": a plain sRGB camera), and the AR view made by
// re-encoding only the pixels the insertion changed. Linear values are in
// the scene field's radiance units (camera linear / exposure gain).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "calib/core/image.h"
#include "render/insert/rasterizer.h"

namespace nerfar {

class DisplayCodec {
 public:
  explicit DisplayCodec(bool display_response);

  // Linear camera value of an 8-bit code (before the exposure gain).
  float Linear(std::uint8_t code) const { return linear_[code]; }
  // The code of a linear camera value: exactly EncodeReference(x) for every
  // float (a table lookup and a step or two instead of a pow per value).
  std::uint8_t Encode(float x) const;
  // Encode(x) when x is likely to keep the code `hint` (a shadowed pixel
  // of that code): two comparisons instead of the table, same result.
  std::uint8_t EncodeNear(float x, std::uint8_t hint) const {
    return x >= lower_[hint] && x < upper_open_[hint] ? hint : Encode(x);
  }
  // The defining formula (lround of the sRGB of the response's display
  // value); 0 for NaN and infinities.
  static std::uint8_t EncodeReference(float x, bool display_response);
  bool display_response() const { return display_response_; }

  // out = Linear(frame) / gain, RGB (grey frames repeated); out is resized
  // only when its size differs (the live loop reuses one buffer).
  void Linearise(const Image8& frame, double gain, ImageF& out) const;
  // Linear (scene units, 1 or 3 channels) × gain -> RGB codes.
  Image8 ToDisplay(const ImageF& linear, double gain) const;

 private:
  bool display_response_;
  std::array<float, 256> linear_{};
  // upper_[k]: the smallest float whose code is k + 1 (codes grow with x).
  std::array<float, 255> upper_{};
  // Code of the first float of each bucket of positive floats with the same
  // top 16 bits (exponent and 7 mantissa bits: 0.8 % wide, narrower than
  // the relative step between any two codes, 0.94 % at the top): a lookup
  // and at most two steps up upper_, since a shadow's box can hold half the
  // frame (470 000 pixels re-encoded a frame in bench live, fast preset).
  std::vector<std::uint8_t> bucket_code_;
  // [lower_[k], upper_open_[k]): the floats of code k (−FLT_MAX and +∞ at
  // the ends, so NaN and ±∞ fall through to Encode).
  std::array<float, 256> lower_{}, upper_open_{};
};

// The AR view from the composite: `ar` holds the camera frame (RGB, the size
// of `composite`) and keeps it wherever the composite still holds that
// frame's own linear value (Linearise with this gain); within `touched` (the
// insertion's boxes) every other pixel is re-encoded from composite × gain.
// Returns the number of pixels rewritten. Pixel for pixel the same as
// re-encoding the whole frame under that rule. Rows run in parallel.
size_t CompositeToDisplay(const DisplayCodec& codec, const ImageF& composite, double gain, const PixelRect& touched,
                          Image8& ar);

// Lines of text over frames (the HUD), rendered once per change and blended
// from then on: DrawText's anti-aliased outline and text are blends, so per
// channel the result is A + B·frame, and drawing the lines once over black
// (A) and once over white (A + 255·B) gives both. Blending the ~5 000
// touched pixels costs a few µs where drawing costs 0.6 ms a frame.
class TextOverlay {
 public:
  // Line i at (4, 4 + 13·i) as DrawText draws it, over frames `width` wide;
  // rendered again only when the lines or the width differ from the last.
  void Set(const std::vector<std::string>& lines, int width);
  void Draw(Image8& image) const;  // RGB; rows beyond the image are skipped

 private:
  std::vector<std::string> lines_;
  int width_ = 0;
  std::vector<std::uint32_t> offsets_;             // byte offsets (y·width + x)·3 + c that the text touches
  std::vector<std::uint8_t> over_black_, spread_;  // A and 255·B per offset
};

}  // namespace nerfar
