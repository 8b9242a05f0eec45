#include "calib/linear_image.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "calib/camera_file.h"
#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "calib/core/image_io.h"

namespace nerfar {
namespace fs = std::filesystem;

namespace {

enum class FileKind { kExr, kJpeg, kOther };

FileKind KindOf(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  unsigned char magic[4] = {};
  in.read(reinterpret_cast<char*>(magic), 4);
  if (in.gcount() < 4) return FileKind::kOther;
  if (magic[0] == 0x76 && magic[1] == 0x2f && magic[2] == 0x31 && magic[3] == 0x01) return FileKind::kExr;
  if (magic[0] == 0xff && magic[1] == 0xd8 && magic[2] == 0xff) return FileKind::kJpeg;
  return FileKind::kOther;
}

// JPEG's block transform and its chroma subsampling move saturated values
// down by a few levels where a clipped area meets an unclipped one (an 8-bit
// copy of a shared scene at quality 95, 4:2:0: 42 % of the clipped channels
// decode below 255, 7 % below 250). Within this many 8-bit levels of the top
// a JPEG value counts as clipped: treating a value of 250 as a lower bound
// loses 4 % of its constraint at most, missing a clipped one pulls a lamp down.
constexpr float kJpegClipLevels = 5.0f;

// The file as OpenCV decodes it, 8 or 16 bits, 1 or 3 channels in RGB order.
cv::Mat ReadDisplayReferred(const std::string& path) {
  CheckPngOrJpegHeader(path);
  cv::Mat mat;
  try {
    mat = cv::imread(path, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    ThrowInputError(path, std::string("cannot decode image (") + e.what() + ")");
  }
  if (mat.empty()) ThrowInputError(path, "cannot decode image (expected OpenEXR, PNG or JPEG)");
  if (mat.depth() != CV_8U && mat.depth() != CV_16U)
    ThrowInputError(path, "pixel type is not 8 or 16 bit (expected an 8- or 16-bit PNG or JPEG, or OpenEXR)");
  if (mat.cols > kMaxImageSide || mat.rows > kMaxImageSide || int64_t(mat.total()) > kMaxImagePixels)
    ThrowInputError(path, "image of " + std::to_string(mat.cols) + "x" + std::to_string(mat.rows) +
                              " pixels is too large (at most " + std::to_string(kMaxImageSide) + " a side and " +
                              std::to_string(kMaxImagePixels) + " pixels)");
  cv::Mat rgb;
  switch (mat.channels()) {
    case 1:
      cv::cvtColor(mat, rgb, cv::COLOR_GRAY2RGB);
      break;
    case 3:
      cv::cvtColor(mat, rgb, cv::COLOR_BGR2RGB);
      break;
    case 4:
      cv::cvtColor(mat, rgb, cv::COLOR_BGRA2RGB);
      break;
    default:
      ThrowInputError(path, std::to_string(mat.channels()) + " channels (expected 1, 3 or 4)");
  }
  return rgb;
}

// Linear radiance and clip flags of a decoded frame whose values run to
// `top`; values from `clip_level` up are clipped.
template <typename T>
LinearImage Linearise(const cv::Mat& rgb, const Linearisation& linearisation, float top, float clip_level) {
  LinearImage out;
  out.display_referred = true;
  out.rgb = ImageF(rgb.cols, rgb.rows, 3);
  out.clipped = Image8(rgb.cols, rgb.rows, 1);
  const float to_level = 255.0f / top;  // 16-bit values onto the response's 0..255 levels
  for (int y = 0; y < rgb.rows; ++y) {
    const T* row = rgb.ptr<T>(y);
    for (int x = 0; x < rgb.cols; ++x) {
      std::uint8_t flags = 0;
      for (int c = 0; c < 3; ++c) {
        const float v = float(row[3 * x + c]);
        out.rgb.at(x, y, c) = LinearValue(linearisation, c, v * to_level);
        if (v >= clip_level) flags |= std::uint8_t(1u << c);
      }
      out.clipped.at(x, y) = flags;
    }
  }
  return out;
}

}  // namespace

std::string Linearisation::Describe() const {
  if (response.has_value()) return "the camera response of " + source;
  return "the sRGB curve (no camera response known" + (source.empty() ? std::string() : ": " + source + " has none") +
         ")";
}

Linearisation DatasetLinearisation(const std::string& dataset_dir) {
  Linearisation linearisation;
  const std::string path = (fs::path(dataset_dir) / "camera.json").string();
  std::error_code error;
  if (!fs::is_regular_file(path, error)) return linearisation;
  linearisation.source = path;
  linearisation.response = ReadCameraFile(path).response;
  return linearisation;
}

size_t LinearImage::ClippedPixels() const {
  return size_t(std::count_if(clipped.pixels.begin(), clipped.pixels.end(), [](std::uint8_t f) { return f != 0; }));
}

float LinearValue(const Linearisation& linearisation, int channel, float z) {
  // Level 0 is the sensor's black: no light measured. (A response's g(0) is
  // a stand-in, unconstrained by its fit, whose hat weight is 0 there.)
  if (!(z > 0.0f)) return 0.0f;
  z = std::min(z, float(kResponseLevels - 1));
  if (!linearisation.response.has_value()) return SrgbToLinear(z / float(kResponseLevels - 1));
  const CameraResponse& response = *linearisation.response;
  const int c = std::min(channel, response.channels() - 1);
  const int z0 = std::min(int(z), kResponseLevels - 2);
  const float t = z - float(z0);
  // Interpolated in log exposure: the response is smooth in g, not in exp(g).
  return std::exp((1.0f - t) * response.log_exposure[c][z0] + t * response.log_exposure[c][z0 + 1]);
}

LinearImage ReadLinearImage(const std::string& path, const Linearisation& linearisation) {
  std::error_code error;
  if (!fs::is_regular_file(path, error)) ThrowInputError(path, "no such file (expected an image)");
  const FileKind kind = KindOf(path);
  if (kind == FileKind::kExr) {
    LinearImage out;
    out.rgb = ReadExrRgb(path);
    return out;
  }
  const cv::Mat rgb = ReadDisplayReferred(path);
  const float top = rgb.depth() == CV_8U ? 255.0f : 65535.0f;
  const float margin = kind == FileKind::kJpeg ? kJpegClipLevels * top / 255.0f : 0.0f;
  return rgb.depth() == CV_8U ? Linearise<std::uint8_t>(rgb, linearisation, top, top - margin)
                              : Linearise<std::uint16_t>(rgb, linearisation, top, top - margin);
}

Image8 ReadMask(const std::string& path, int width, int height) {
  const Image8 image = ReadImage8(path);
  if (image.width != width || image.height != height)
    ThrowInputError(path, "mask is " + std::to_string(image.width) + "x" + std::to_string(image.height) +
                              " (expected " + std::to_string(width) + "x" + std::to_string(height) +
                              ", the size of its image)");
  Image8 mask(width, height, 1);
  for (size_t i = 0; i < mask.pixels.size(); ++i) mask.pixels[i] = image.pixels[i * image.channels];
  return mask;
}

}  // namespace nerfar
