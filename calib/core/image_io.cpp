#include "calib/core/image_io.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <stdexcept>
#include <tuple>
#include <utility>

#include "calib/core/atomic_file.h"
#include "calib/core/error.h"

namespace nerfar {

namespace {

int64_t BigEndian(const unsigned char* bytes, int count) {
  int64_t value = 0;
  for (int i = 0; i < count; ++i) value = value << 8 | bytes[i];
  return value;
}

// A JPEG's frame size from its SOF segment, walking the segments from after
// the SOI marker (a valid file states it before its first scan).
std::pair<int64_t, int64_t> JpegFrameSize(std::istream& file, const std::string& path) {
  file.clear();
  file.seekg(2);
  for (int segment = 0; segment < 4096; ++segment) {
    int byte = file.get();
    if (byte != 0xff) break;
    while (byte == 0xff) byte = file.get();  // fill bytes
    const int marker = byte;
    if (marker == 0x01 || (marker >= 0xd0 && marker <= 0xd8)) continue;  // no length
    if (marker < 0 || marker == 0xd9 || marker == 0xda) break;           // end or a scan before any frame
    unsigned char length_bytes[2];
    if (!file.read(reinterpret_cast<char*>(length_bytes), 2)) break;
    const int64_t length = BigEndian(length_bytes, 2);
    if (length < 2) break;
    const bool frame = marker >= 0xc0 && marker <= 0xcf && marker != 0xc4 && marker != 0xc8 && marker != 0xcc;
    if (frame) {
      unsigned char sof[5];
      if (!file.read(reinterpret_cast<char*>(sof), 5)) break;
      return {BigEndian(sof + 3, 2), BigEndian(sof + 1, 2)};  // width, height
    }
    file.seekg(length - 2, std::ios::cur);
  }
  ThrowInputError(path, "JPEG without a readable frame header (the file is corrupt)");
}

// CheckPngOrJpegHeader on any stream; `source` names it in errors.
void CheckImageHeader(std::istream& file, const std::string& source) {
  static constexpr unsigned char kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  static constexpr unsigned char kJpeg[3] = {0xff, 0xd8, 0xff};
  unsigned char head[24] = {};
  file.read(reinterpret_cast<char*>(head), sizeof head);
  const std::streamsize got = file.gcount();
  int64_t width = 0, height = 0;
  if (got >= 8 && std::equal(kPng, kPng + 8, head)) {
    // The first chunk is IHDR: length, type, then width and height.
    if (got < 24 || !std::equal(head + 12, head + 16, "IHDR"))
      ThrowInputError(source, "PNG without its IHDR header (the file is corrupt)");
    width = BigEndian(head + 16, 4);
    height = BigEndian(head + 20, 4);
  } else if (got >= 3 && std::equal(kJpeg, kJpeg + 3, head)) {
    std::tie(width, height) = JpegFrameSize(file, source);
  } else {
    ThrowInputError(source, "not a PNG or JPEG file (its first bytes are neither signature)");
  }
  if (width < 1 || height < 1 || width > kMaxImageSide || height > kMaxImageSide || width * height > kMaxImagePixels)
    ThrowInputError(source, "header states " + std::to_string(width) + "x" + std::to_string(height) +
                                " pixels (expected 1.." + std::to_string(kMaxImageSide) + " a side, at most " +
                                std::to_string(kMaxImagePixels) + " pixels)");
}

}  // namespace

void CheckPngOrJpegHeader(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  CheckImageHeader(file, path);
}

Image8 DecodeImage8(std::string_view bytes, const std::string& source) {
  std::istringstream stream{std::string(bytes)};
  CheckImageHeader(stream, source);
  cv::Mat mat;
  try {
    const cv::Mat encoded(1, static_cast<int>(bytes.size()), CV_8U, const_cast<char*>(bytes.data()));
    mat = cv::imdecode(encoded, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    ThrowInputError(source, std::string("cannot decode image (") + e.what() + ")");
  }
  if (mat.empty()) ThrowInputError(source, "cannot decode image (expected PNG or JPEG)");
  if (mat.depth() != CV_8U) {
    if (mat.depth() != CV_16U) ThrowInputError(source, "pixel type is not 8 or 16 bit (expected an 8-bit image)");
    mat.convertTo(mat, CV_8U, 1.0 / 257.0);
  }
  if (mat.cols > kMaxImageSide || mat.rows > kMaxImageSide || int64_t(mat.total()) > kMaxImagePixels)
    ThrowInputError(source, "image of " + std::to_string(mat.cols) + "x" + std::to_string(mat.rows) +
                                " pixels is too large (at most " + std::to_string(kMaxImageSide) + " a side and " +
                                std::to_string(kMaxImagePixels) + " pixels)");
  cv::Mat converted;
  switch (mat.channels()) {
    case 1:
      converted = mat;
      break;
    case 3:
      cv::cvtColor(mat, converted, cv::COLOR_BGR2RGB);
      break;
    case 4:
      cv::cvtColor(mat, converted, cv::COLOR_BGRA2RGB);
      break;
    default:
      ThrowInputError(source, std::to_string(mat.channels()) + " channels (expected 1, 3 or 4)");
  }
  Image8 image(converted.cols, converted.rows, converted.channels());
  for (int y = 0; y < converted.rows; ++y)
    std::copy_n(converted.ptr<std::uint8_t>(y), static_cast<size_t>(converted.cols) * converted.channels(),
                image.Pixel(0, y));
  return image;
}

Image8 ReadImage8(const std::string& path) {
  std::error_code error;
  if (!std::filesystem::is_regular_file(path, error)) ThrowInputError(path, "no such file (expected an image)");
  return DecodeImage8(ReadFileBytes(path), path);
}

void WriteImage8(const std::string& path, const Image8& image) {
  NERFAR_CHECK(image.channels == 1 || image.channels == 3 || image.channels == 4);
  NERFAR_CHECK_EQ(image.pixels.size(), image.PixelCount() * image.channels);
  cv::Mat view(image.height, image.width, CV_8UC(image.channels), const_cast<std::uint8_t*>(image.pixels.data()));
  cv::Mat bgr;
  if (image.channels == 3) {
    cv::cvtColor(view, bgr, cv::COLOR_RGB2BGR);
  } else if (image.channels == 4) {
    cv::cvtColor(view, bgr, cv::COLOR_RGBA2BGRA);
  } else {
    bgr = view;
  }
  const std::string extension = std::filesystem::path(path).extension().string();
  std::vector<uchar> bytes;
  if (!cv::imencode(extension.empty() ? ".png" : extension, bgr, bytes))
    throw std::runtime_error(path + ": cannot encode image (unknown extension?)");
  WriteFileAtomic(path, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
}

float LinearToSrgb(float linear) {
  const float x = std::clamp(linear, 0.0f, 1.0f);
  return x <= 0.0031308f ? 12.92f * x : 1.055f * std::pow(x, 1.0f / 2.4f) - 0.055f;
}

float SrgbToLinear(float srgb) {
  const float x = std::clamp(srgb, 0.0f, 1.0f);
  return x <= 0.04045f ? x / 12.92f : std::pow((x + 0.055f) / 1.055f, 2.4f);
}

Image8 ToneMapToDisplay(const ImageF& linear, float exposure) {
  NERFAR_CHECK(linear.channels >= 1);
  const int out_channels = linear.channels >= 3 ? 3 : 1;
  Image8 out(linear.width, linear.height, out_channels);
  for (size_t p = 0; p < linear.PixelCount(); ++p) {
    const float* in = linear.pixels.data() + p * linear.channels;
    std::uint8_t* dst = out.pixels.data() + p * out_channels;
    bool finite = true;
    for (int c = 0; c < out_channels; ++c) finite = finite && std::isfinite(in[c]);
    for (int c = 0; c < out_channels; ++c) {
      if (!finite) {
        dst[c] = c == 1 ? 0 : 255;  // magenta marks NaN/Inf
        continue;
      }
      const float x = std::max(0.0f, in[c] * exposure);
      dst[c] = static_cast<std::uint8_t>(std::lround(LinearToSrgb(x / (1.0f + x)) * 255.0f));
    }
  }
  return out;
}

ImageF DisplayToLinear(const Image8& image) {
  ImageF out(image.width, image.height, image.channels);
  float table[256];
  for (int i = 0; i < 256; ++i) table[i] = SrgbToLinear(static_cast<float>(i) / 255.0f);
  for (size_t i = 0; i < image.pixels.size(); ++i) out.pixels[i] = table[image.pixels[i]];
  return out;
}

Image8 ToGray(const Image8& rgb) {
  if (rgb.channels == 1) return rgb;
  NERFAR_CHECK_GE(rgb.channels, 3);
  Image8 gray(rgb.width, rgb.height, 1);
  for (size_t p = 0; p < rgb.PixelCount(); ++p) {
    const std::uint8_t* px = rgb.pixels.data() + p * rgb.channels;
    gray.pixels[p] = static_cast<std::uint8_t>((77 * px[0] + 150 * px[1] + 29 * px[2] + 128) >> 8);
  }
  return gray;
}

float ExposureForPercentile(const ImageF& linear, double percentile) {
  if (linear.empty()) return 1.0f;
  std::vector<float> luminance(linear.PixelCount());
  for (size_t p = 0; p < luminance.size(); ++p) {
    const float* px = linear.pixels.data() + p * linear.channels;
    luminance[p] = linear.channels >= 3 ? 0.2126f * px[0] + 0.7152f * px[1] + 0.0722f * px[2] : px[0];
  }
  const size_t k = std::min(luminance.size() - 1, static_cast<size_t>(percentile * (luminance.size() - 1)));
  std::nth_element(luminance.begin(), luminance.begin() + static_cast<ptrdiff_t>(k), luminance.end());
  const float value = luminance[k];
  return value > 0.0f && std::isfinite(value) ? 1.0f / value : 1.0f;
}

}  // namespace nerfar
