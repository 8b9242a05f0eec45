// OpenFrameSource: the source-string parser and the scheme registry.
#include "tracking/frame_sources.h"

#include <algorithm>
#include <filesystem>
#include <map>
#include <mutex>

#include "calib/core/error.h"
#include "tracking/camera_backends.h"

namespace nerfar {
namespace {
namespace fs = std::filesystem;

struct Scheme {
  FrameSourceFactory factory;
  std::string help;
};

std::mutex& RegistryMutex() {
  static std::mutex mutex;
  return mutex;
}
std::map<std::string, Scheme>& Registry() {
  static std::map<std::string, Scheme> registry;
  return registry;
}

const char* kBuiltInHelp[] = {
    "v4l2:/dev/videoN  a V4L2 camera (a bare /dev/videoN works too)",
    "libcamera:N  a libcamera camera by index or id",
    "video:FILE  a video file (a bare file with a video extension works too)",
    "rtsp://... http://... a network stream through OpenCV",
    "images:DIR  a folder of images in name order (a bare folder works too); EXR frames are tone-mapped",
};

bool HasVideoExtension(const std::string& path) {
  std::string e = fs::path(path).extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  for (const char* k : {".mp4", ".avi", ".mkv", ".mov", ".webm", ".m4v", ".mpg", ".mpeg", ".wmv", ".gif"})
    if (e == k) return true;
  return false;
}

void ThrowIfProblems(const std::string& source, const std::vector<std::string>& problems) {
  if (problems.empty()) return;
  Problems list(source);
  for (const std::string& p : problems) list.Add("", p);
  list.ThrowIfAny();
}

}  // namespace

std::vector<std::string> CameraControls::Validate() const {
  std::vector<std::string> problems;
  if (width < 0 || width > kMaxImageSide)
    problems.push_back("width: " + std::to_string(width) + " (expected 0 to 16384)");
  if (height < 0 || height > kMaxImageSide)
    problems.push_back("height: " + std::to_string(height) + " (expected 0 to 16384)");
  if ((width == 0) != (height == 0)) problems.push_back("width and height: give both or neither");
  if (!(fps >= 0 && fps <= 1000)) problems.push_back("fps: " + std::to_string(fps) + " (expected 0 to 1000)");
  if (!(exposure_us >= 0 && exposure_us <= 1e7))
    problems.push_back("exposure_us: " + std::to_string(exposure_us) + " (expected 0 to 1e7 microseconds)");
  if (!(gain < 0 || gain <= 1e6)) problems.push_back("gain: " + std::to_string(gain) + " (expected <= 1e6)");
  if (white_balance_k != 0 && (white_balance_k < 1000 || white_balance_k > 20000))
    problems.push_back("white_balance_k: " + std::to_string(white_balance_k) + " (expected 0 or 1000 to 20000 kelvin)");
  if (buffers < 2 || buffers > 16) problems.push_back("buffers: " + std::to_string(buffers) + " (expected 2 to 16)");
  return problems;
}

std::vector<std::string> SourceOptions::Validate() const {
  std::vector<std::string> problems = camera.Validate();
  if (!(file_fps > 0 && file_fps <= 1000))
    problems.push_back("file_fps: " + std::to_string(file_fps) + " (expected 0 < fps <= 1000)");
  if (!(exr_exposure >= 0 && exr_exposure < 1e12))
    problems.push_back("exr_exposure: " + std::to_string(exr_exposure) +
                       " (expected 0 (automatic) or a positive scale)");
  return problems;
}

void RegisterFrameSourceScheme(const std::string& scheme, FrameSourceFactory factory, const std::string& help) {
  std::lock_guard<std::mutex> lock(RegistryMutex());
  Registry()[scheme] = {std::move(factory), help};
}

std::vector<std::string> FrameSourceSchemes() {
  std::vector<std::string> lines(std::begin(kBuiltInHelp), std::end(kBuiltInHelp));
  std::lock_guard<std::mutex> lock(RegistryMutex());
  for (const auto& [name, scheme] : Registry()) lines.push_back(name + ":...  " + scheme.help);
  return lines;
}

std::unique_ptr<FrameSource> OpenFrameSource(const std::string& source, const SourceOptions& options) {
  ThrowIfProblems("source options", options.Validate());
  if (source.empty()) ThrowInputError("source", "empty (expected e.g. v4l2:/dev/video0, images:DIR, video:FILE)");
  if (source.find("://") != std::string::npos) return detail::OpenVideoSource(source, options);
  const size_t colon = source.find(':');
  // "C:" drive letters do not exist here; a scheme is a word before ':'.
  if (colon != std::string::npos && colon > 0 && source.find('/') > colon) {
    const std::string scheme = source.substr(0, colon), argument = source.substr(colon + 1);
    if (scheme == "v4l2") return detail::OpenV4l2Source(argument, options.camera);
    if (scheme == "libcamera") return detail::OpenLibcameraSource(argument, options.camera);
    if (scheme == "video") return detail::OpenVideoSource(argument, options);
    if (scheme == "images") return detail::OpenImageFolderSource(argument, options);
    FrameSourceFactory factory;
    {
      std::lock_guard<std::mutex> lock(RegistryMutex());
      auto it = Registry().find(scheme);
      if (it != Registry().end()) factory = it->second.factory;
    }
    if (factory) return factory(argument, options);
    std::string known;
    for (const std::string& line : FrameSourceSchemes()) known += "\n  " + line;
    ThrowInputError(source, "unknown source scheme '" + scheme + "' (expected one of:" + known + ")");
  }
  {
    std::lock_guard<std::mutex> lock(RegistryMutex());
    auto it = Registry().find(source);  // a bare registered name ("synthetic")
    if (it != Registry().end()) {
      FrameSourceFactory factory = it->second.factory;
      return factory("", options);
    }
  }
  if (source.rfind("/dev/video", 0) == 0) return detail::OpenV4l2Source(source, options.camera);
  std::error_code error;
  if (fs::is_directory(source, error)) return detail::OpenImageFolderSource(source, options);
  if (fs::is_regular_file(source, error)) {
    if (HasVideoExtension(source)) return detail::OpenVideoSource(source, options);
    ThrowInputError(source, "is a file without a video extension (expected a video, a folder of images or a camera)");
  }
  ThrowInputError(source, "no such file, folder or device (expected e.g. v4l2:/dev/video0, images:DIR, video:FILE)");
}

}  // namespace nerfar
