// The frame-source interface every camera, file and synthetic stream
// implements (tracking/ and render/synth provide them). A source hands out
// frames in capture order; it never throws across Next(): a lost device or a
// corrupt frame is reported as a status so the live loop can keep going.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "calib/core/image.h"
#include "calib/core/math.h"

namespace nerfar {

struct Frame {
  Image8 image;                             // RGB or grey, as the device delivers after conversion
  std::int64_t t_ns = 0;                    // capture time stamp (monotonic clock), nanoseconds
  std::int64_t index = 0;                   // frame number from the start of the stream
  std::string name;                         // file name for file sources, empty otherwise
  std::optional<Pose> T_world_camera_true;  // known pose (synthetic sources only)
};

enum class FrameStatus {
  kOk,           // `frame` holds a new frame
  kEndOfStream,  // a file or finite sequence is exhausted
  kTimeout,      // no frame in time; try again
  kCorrupt,      // this frame was unreadable; the next may be fine
  kLost,         // the device disappeared; the source may recover
};

const char* FrameStatusName(FrameStatus status);

class FrameSource {
 public:
  virtual ~FrameSource() = default;
  // Human-readable description ("v4l2:/dev/video0 1280x720 MJPG @30").
  virtual std::string Describe() const = 0;
  // Waits for the next frame (at most timeout_ms where the source is live).
  virtual FrameStatus Next(Frame& frame, int timeout_ms) = 0;
  // Sets a manual exposure time for the frames that follow (exposure brackets
  // for HDR capture). False where the source cannot (files, synthetic
  // streams, cameras without the control); frames then keep their exposure.
  virtual bool SetExposure(double exposure_us) {
    (void)exposure_us;
    return false;
  }
  // Last error message after a non-kOk status, for the user.
  virtual std::string LastError() const { return {}; }
};

}  // namespace nerfar
