// Image folders and OpenCV VideoCapture (video files, network streams).
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "calib/core/image_io.h"
#include "tracking/camera_backends.h"

namespace nerfar::detail {
namespace {
namespace fs = std::filesystem;

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

bool IsImageExtension(const std::string& extension) {
  static const char* kExtensions[] = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".exr"};
  const std::string e = Lower(extension);
  for (const char* k : kExtensions)
    if (e == k) return true;
  return false;
}

class ImageFolderSource : public FrameSource {
 public:
  ImageFolderSource(std::string dir, std::vector<std::string> files, const SourceOptions& options)
      : dir_(std::move(dir)), files_(std::move(files)), options_(options) {}

  std::string Describe() const override { return "images:" + dir_ + " (" + std::to_string(files_.size()) + " frames)"; }

  FrameStatus Next(Frame& frame, int /*timeout_ms*/) override {
    if (next_ >= files_.size()) {
      if (!options_.loop || files_.empty()) return FrameStatus::kEndOfStream;
      next_ = 0;
    }
    const std::string& name = files_[next_];
    const std::string path = (fs::path(dir_) / name).string();
    frame.index = index_++;
    ++next_;
    frame.name = name;
    frame.t_ns = static_cast<std::int64_t>(std::llround(static_cast<double>(frame.index) * 1e9 / options_.file_fps));
    frame.T_world_camera_true.reset();
    try {
      if (Lower(fs::path(name).extension().string()) == ".exr") {
        const ImageF linear = ReadExrRgb(path);
        const float exposure =
            options_.exr_exposure > 0 ? static_cast<float>(options_.exr_exposure) : ExposureForPercentile(linear);
        frame.image = ToneMapToDisplay(linear, exposure);
      } else {
        frame.image = ReadImage8(path);
      }
    } catch (const std::exception& e) {
      frame.image = Image8();
      error_ = e.what();
      return FrameStatus::kCorrupt;
    }
    return FrameStatus::kOk;
  }

  std::string LastError() const override { return error_; }

 private:
  std::string dir_;
  std::vector<std::string> files_;
  SourceOptions options_;
  size_t next_ = 0;
  std::int64_t index_ = 0;
  std::string error_;
};

class VideoSource : public FrameSource {
 public:
  VideoSource(std::string what, std::unique_ptr<cv::VideoCapture> capture, const SourceOptions& options)
      : what_(std::move(what)), capture_(std::move(capture)), options_(options) {
    const double fps = capture_->get(cv::CAP_PROP_FPS);
    fps_ = std::isfinite(fps) && fps > 0 && fps < 1000 ? fps : options_.file_fps;
  }

  std::string Describe() const override {
    return "video:" + what_ + " " + std::to_string(static_cast<int>(capture_->get(cv::CAP_PROP_FRAME_WIDTH))) + "x" +
           std::to_string(static_cast<int>(capture_->get(cv::CAP_PROP_FRAME_HEIGHT))) + " @" + std::to_string(fps_);
  }

  FrameStatus Next(Frame& frame, int /*timeout_ms*/) override {
    cv::Mat bgr;
    bool ok = false;
    try {
      ok = capture_->read(bgr);
    } catch (const cv::Exception& e) {
      error_ = what_ + ": " + e.what();
      return FrameStatus::kCorrupt;
    }
    if (!ok || bgr.empty()) return FrameStatus::kEndOfStream;
    frame.index = index_++;
    frame.name = what_ + "#" + std::to_string(frame.index);
    const double pos_ms = capture_->get(cv::CAP_PROP_POS_MSEC);
    frame.t_ns = std::isfinite(pos_ms) && pos_ms > 0
                     ? static_cast<std::int64_t>(pos_ms * 1e6)
                     : static_cast<std::int64_t>(std::llround(frame.index * 1e9 / fps_));
    frame.T_world_camera_true.reset();
    cv::Mat rgb;
    if (bgr.depth() != CV_8U) {
      error_ = what_ + ": frame " + std::to_string(frame.index) + " is not 8-bit";
      return FrameStatus::kCorrupt;
    }
    if (bgr.channels() == 3) {
      cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
    } else if (bgr.channels() == 4) {
      cv::cvtColor(bgr, rgb, cv::COLOR_BGRA2RGB);
    } else {
      rgb = bgr;
    }
    frame.image = Image8(rgb.cols, rgb.rows, rgb.channels());
    for (int y = 0; y < rgb.rows; ++y)
      std::copy_n(rgb.ptr<std::uint8_t>(y), static_cast<size_t>(rgb.cols) * rgb.channels(), frame.image.Pixel(0, y));
    return FrameStatus::kOk;
  }

  std::string LastError() const override { return error_; }

 private:
  std::string what_;
  std::unique_ptr<cv::VideoCapture> capture_;
  SourceOptions options_;
  double fps_ = 30;
  std::int64_t index_ = 0;
  std::string error_;
};

}  // namespace

std::unique_ptr<FrameSource> OpenImageFolderSource(const std::string& dir, const SourceOptions& options) {
  std::error_code error;
  if (!fs::is_directory(dir, error)) ThrowInputError(dir, "no such directory (expected a folder of images)");
  std::vector<std::string> files;
  for (const auto& entry : fs::directory_iterator(dir, error)) {
    if (!entry.is_regular_file(error)) continue;
    if (IsImageExtension(entry.path().extension().string())) files.push_back(entry.path().filename().string());
  }
  if (error) ThrowInputError(dir, "cannot list (" + error.message() + ")");
  if (files.empty())
    ThrowInputError(dir, "no images (expected .png, .jpg, .jpeg, .bmp, .tif, .tiff, .pgm, .ppm or .exr files)");
  std::sort(files.begin(), files.end());
  return std::make_unique<ImageFolderSource>(dir, std::move(files), options);
}

std::unique_ptr<FrameSource> OpenVideoSource(const std::string& path_or_url, const SourceOptions& options) {
  const bool url = path_or_url.find("://") != std::string::npos;
  std::error_code error;
  if (!url && !fs::is_regular_file(path_or_url, error))
    ThrowInputError(path_or_url, "no such file (expected a video file or a stream URL)");
  auto capture = std::make_unique<cv::VideoCapture>();
  bool opened = false;
  try {
    opened = capture->open(path_or_url, cv::CAP_ANY);
  } catch (const cv::Exception& e) {
    ThrowInputError(path_or_url, std::string("cannot open (") + e.what() + ")");
  }
  if (!opened || !capture->isOpened())
    ThrowInputError(path_or_url, url ? "cannot open the stream (expected a reachable video URL)"
                                     : "cannot decode (expected a video file OpenCV's FFmpeg back end reads)");
  return std::make_unique<VideoSource>(path_or_url, std::move(capture), options);
}

}  // namespace nerfar::detail
