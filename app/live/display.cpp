#include "app/live/display.h"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstring>
#include <limits>

#include "calib/core/error.h"
#include "calib/core/image_io.h"
#include "calib/core/media.h"
#include "calib/core/parallel.h"

namespace nerfar {

namespace {

// The display value a linear value stands for under the "display" response
// is capped here: y/(1 − y) diverges at white, and a clipped pixel says only
// "at least this bright".
constexpr float kDisplayCap = 0.995f;

float FromBits(std::uint32_t bits) {
  float x;
  std::memcpy(&x, &bits, sizeof x);
  return x;
}

}  // namespace

std::uint8_t DisplayCodec::EncodeReference(float x, bool display_response) {
  if (!std::isfinite(x)) return 0;
  x = std::max(0.0f, x);
  if (display_response) x = x / (1.0f + x);
  return static_cast<std::uint8_t>(std::lround(LinearToSrgb(std::min(1.0f, x)) * 255.0f));
}

DisplayCodec::DisplayCodec(bool display_response) : display_response_(display_response) {
  for (int i = 0; i < 256; ++i) {
    float v = SrgbToLinear(static_cast<float>(i) / 255.0f);
    if (display_response) {
      v = std::min(v, kDisplayCap);
      v = v / (1.0f - v);
    }
    linear_[i] = v;
  }
  // Non-negative floats order like their bit patterns: bisect those for the
  // first float of each code (FLT_MAX encodes to 255 under both responses).
  const std::uint32_t top = 0x7f7fffffu;
  NERFAR_CHECK_EQ(static_cast<int>(EncodeReference(FromBits(top), display_response)), 255);
  for (int k = 0; k < 255; ++k) {
    std::uint32_t lo = 0, hi = top;  // code(lo) <= k unless lo == 0 decides it; code(hi) > k
    if (EncodeReference(0.0f, display_response) > k) {
      upper_[k] = 0.0f;
      continue;
    }
    while (hi - lo > 1) {
      const std::uint32_t mid = lo + (hi - lo) / 2;
      (EncodeReference(FromBits(mid), display_response) > k ? hi : lo) = mid;
    }
    upper_[k] = FromBits(hi);
  }
  for (int k = 0; k < 256; ++k) {
    lower_[k] = k == 0 ? -FLT_MAX : upper_[k - 1];
    upper_open_[k] = k == 255 ? std::numeric_limits<float>::infinity() : upper_[k];
  }
  bucket_code_.resize((top >> 16) + 1);
  for (std::uint32_t b = 0; b < bucket_code_.size(); ++b)
    bucket_code_[b] =
        static_cast<std::uint8_t>(std::upper_bound(upper_.begin(), upper_.end(), FromBits(b << 16)) - upper_.begin());
}

std::uint8_t DisplayCodec::Encode(float x) const {
  if (!std::isfinite(x)) return 0;
  if (!(x > 0.0f)) return bucket_code_[0];  // ±0 and negatives encode as 0 does
  std::uint32_t bits;
  std::memcpy(&bits, &x, sizeof bits);
  int code = bucket_code_[bits >> 16];
  while (code < 255 && x >= upper_[code]) ++code;
  return static_cast<std::uint8_t>(code);
}

void DisplayCodec::Linearise(const Image8& frame, double gain, ImageF& out) const {
  NERFAR_CHECK(frame.channels == 1 || frame.channels >= 3);
  // The same float operations as linearising and then dividing by the gain,
  // so that CompositeToDisplay recognises the frame's own values bit for bit.
  const float inv_gain = static_cast<float>(1.0 / gain);
  float table[256];
  for (int i = 0; i < 256; ++i) table[i] = linear_[i] * inv_gain;
  if (out.width != frame.width || out.height != frame.height || out.channels != 3)
    out = ImageF(frame.width, frame.height, 3);
  const int channels = frame.channels;
  const std::uint8_t* in = frame.pixels.data();
  float* dst = out.pixels.data();
  const size_t n = frame.PixelCount();
  if (channels == 3) {
    for (size_t i = 0; i < n * 3; ++i) dst[i] = table[in[i]];
  } else {
    for (size_t p = 0; p < n; ++p)
      for (int c = 0; c < 3; ++c) dst[p * 3 + c] = table[in[p * channels + (channels >= 3 ? c : 0)]];
  }
}

Image8 DisplayCodec::ToDisplay(const ImageF& linear, double gain) const {
  Image8 out(linear.width, linear.height, 3);
  for (size_t p = 0; p < linear.PixelCount(); ++p)
    for (int c = 0; c < 3; ++c)
      out.pixels[p * 3 + c] =
          Encode(static_cast<float>(linear.pixels[p * linear.channels + std::min(c, linear.channels - 1)] * gain));
  return out;
}

size_t CompositeToDisplay(const DisplayCodec& codec, const ImageF& composite, double gain, const PixelRect& touched,
                          Image8& ar) {
  NERFAR_CHECK_EQ(ar.width, composite.width);
  NERFAR_CHECK_EQ(ar.height, composite.height);
  NERFAR_CHECK_EQ(ar.channels, 3);
  NERFAR_CHECK_EQ(composite.channels, 3);
  const float inv_gain = static_cast<float>(1.0 / gain);
  float background[256];
  for (int i = 0; i < 256; ++i) background[i] = codec.Linear(static_cast<std::uint8_t>(i)) * inv_gain;
  const PixelRect r = ClipToImage(touched, ar.width, ar.height);
  std::vector<size_t> rewritten(static_cast<size_t>(r.height()), 0);
  ParallelFor(
      rewritten.size(),
      [&](size_t row) {
        const int y = r.y0 + static_cast<int>(row);
        std::uint8_t* out = ar.Pixel(r.x0, y);
        const float* in = composite.Pixel(r.x0, y);
        for (int x = r.x0; x < r.x1; ++x, out += 3, in += 3) {
          if (in[0] == background[out[0]] && in[1] == background[out[1]] && in[2] == background[out[2]]) continue;
          // Mostly κ slightly below 1 over the camera's value: the code often stays.
          for (int c = 0; c < 3; ++c) out[c] = codec.EncodeNear(static_cast<float>(in[c] * gain), out[c]);
          ++rewritten[row];
        }
      },
      16);
  size_t total = 0;
  for (const size_t n : rewritten) total += n;
  return total;
}

void TextOverlay::Set(const std::vector<std::string>& lines, int width) {
  if (lines == lines_ && width == width_) return;
  lines_ = lines;
  width_ = width;
  const int height = 4 + 13 * static_cast<int>(lines.size()) + 6;
  Image8 black(width, height, 3, 0), white(width, height, 3, 255);
  for (size_t i = 0; i < lines.size(); ++i) {
    DrawText(black, lines[i], 4, 4 + 13 * static_cast<int>(i));
    DrawText(white, lines[i], 4, 4 + 13 * static_cast<int>(i));
  }
  offsets_.clear();
  over_black_.clear();
  spread_.clear();
  for (size_t i = 0; i < black.pixels.size(); ++i) {
    if (black.pixels[i] == 0 && white.pixels[i] == 255) continue;  // untouched: the frame shows through
    offsets_.push_back(static_cast<std::uint32_t>(i));
    over_black_.push_back(black.pixels[i]);
    spread_.push_back(static_cast<std::uint8_t>(std::max(0, white.pixels[i] - black.pixels[i])));
  }
}

void TextOverlay::Draw(Image8& image) const {
  NERFAR_CHECK_EQ(image.channels, 3);
  if (image.width != width_) return;
  const size_t size = image.pixels.size();
  for (size_t k = 0; k < offsets_.size(); ++k) {
    if (offsets_[k] >= size) break;  // offsets grow: the rest lies below the image
    std::uint8_t& v = image.pixels[offsets_[k]];
    v = static_cast<std::uint8_t>(std::min(255, over_black_[k] + (spread_[k] * v + 127) / 255));
  }
}

}  // namespace nerfar
