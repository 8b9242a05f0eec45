// The frame sources behind calib/core/frame_source.h: V4L2 cameras (through
// libv4l2, mmap streaming), libcamera cameras, OpenCV VideoCapture (video
// files, network streams) and image folders (frames in name order; 8-bit
// images as stored, EXR frames tone-mapped for display). OpenFrameSource
// parses a source string; the app adds schemes of other modules (the
// synthetic stream of render/synth) with RegisterFrameSourceScheme.
// Time stamps are nanoseconds on the monotonic clock (file sources: frame
// index / fps).
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "calib/core/frame_source.h"

namespace nerfar {

// Camera settings; 0 (or negative where stated) leaves the device's choice.
struct CameraControls {
  int width = 0, height = 0;  // requested size; the nearest the device offers
  double fps = 0;             // requested frame rate
  double exposure_us = 0;     // manual exposure time in microseconds; 0: automatic
  double gain = -1;           // analogue gain (device units; libcamera: factor); < 0: automatic/unchanged
  int white_balance_k = 0;    // white balance colour temperature in kelvin; 0: automatic
  int buffers = 4;            // mmap buffers (2-16): more absorbs hiccups, adds latency

  std::vector<std::string> Validate() const;
};

struct SourceOptions {
  CameraControls camera;
  // Image folders and video files: frame rate assigned to time stamps.
  double file_fps = 30.0;
  // EXR frames: exposure before tone mapping; 0 picks one per frame that maps
  // the 99th-percentile luminance to 1 (ExposureForPercentile).
  double exr_exposure = 0.0;
  // Image folders: loop forever (a live-like stream for demos).
  bool loop = false;

  std::vector<std::string> Validate() const;
};

// Opens a source from its string:
//   v4l2:/dev/video0 (or a bare /dev/videoN)   libcamera:0 (index or camera id)
//   video:FILE or a bare video file            a stream URL (rtsp://, http://, ...)
//   images:DIR or a bare directory             any scheme registered by the app
// InputError "source: what is wrong (expected ...)" for a bad string, a
// missing file or device, or invalid options.
std::unique_ptr<FrameSource> OpenFrameSource(const std::string& source, const SourceOptions& options = {});

// Lets the app join a source of another module (e.g. "synthetic") without
// tracking/ depending on it. `factory` receives the text after "scheme:".
using FrameSourceFactory =
    std::function<std::unique_ptr<FrameSource>(const std::string& argument, const SourceOptions& options)>;
void RegisterFrameSourceScheme(const std::string& scheme, FrameSourceFactory factory, const std::string& help);
// "scheme: help" lines of every scheme, built-in and registered.
std::vector<std::string> FrameSourceSchemes();

// What is attached.
struct CameraFormat {
  std::string fourcc;  // "YUYV", "MJPG", ...
  std::string description;
  std::vector<std::string> sizes;  // "1280x720 @30,15" or "640x480-1920x1080 (stepwise)"
};
struct CameraInfo {
  std::string backend;  // "v4l2" or "libcamera"
  std::string source;   // source string that opens it
  std::string name;     // card / model name
  std::string bus;      // bus info or camera id
  std::vector<CameraFormat> formats;
  std::vector<std::string> controls;  // "exposure_absolute 1..5000 (default 156)"
  std::string error;                  // why the device could not be queried, if it could not
};
// V4L2 capture devices (/dev/video*).
std::vector<CameraInfo> ListV4l2Cameras();
// libcamera cameras; `note` receives why none could be listed (no cameras,
// the library not built in).
std::vector<CameraInfo> ListLibcameraCameras(std::string& note);

}  // namespace nerfar
