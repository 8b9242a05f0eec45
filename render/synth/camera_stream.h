// A synthetic camera: 8-bit frames of a synthetic scene along a smooth,
// handheld-like trajectory over the tag mat, each with its true pose
// (Frame::T_world_camera_true, OpenCV camera axes, at the middle of the
// exposure). Fast enough for tests and the live demo: primary rays, the table
// top's direct light (with shadows) baked once on a 5 mm grid, other surfaces
// shaded with one sample per light; optional sensor noise, motion blur
// and slow exposure changes. Display tone mapping of calib/core/image_io.h.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "calib/board.h"
#include "calib/camera.h"
#include "calib/core/frame_source.h"
#include "calib/core/math.h"

namespace nerfar::synth {

struct CameraStreamOptions {
  std::string scene = "lamps";  // a name of SynthSceneNames()
  uint64_t seed = 1;            // fixes the scene, the trajectory and the noise
  int width = 640, height = 480;
  double hfov_deg = 60;           // horizontal field of view
  double fps = 30;                // frame rate of the time stamps (the stream never sleeps)
  int frames = 0;                 // frames before kEndOfStream; 0: endless
  int samples_per_pixel = 4;      // sub-pixel (and, with blur, sub-exposure) samples; 1 is fastest but aliased
  double noise_sigma = 0;         // Gaussian sensor noise, standard deviation in 8-bit levels (0: none)
  double shutter_s = 0;           // exposure time for motion blur, seconds (0: sharp)
  double exposure_variation = 0;  // relative amplitude of slow exposure changes, in [0, 0.9] (0: constant)
  double speed = 1;               // trajectory speed factor (2: twice as fast, more blur)
  bool grayscale = false;         // 1-channel frames instead of RGB

  std::vector<std::string> Validate() const;
};

class SyntheticCameraSource : public FrameSource {
 public:
  // Builds the scene and bakes its light (well under a second at the defaults).
  explicit SyntheticCameraSource(const CameraStreamOptions& options);
  ~SyntheticCameraSource() override;

  std::string Describe() const override;
  FrameStatus Next(Frame& frame, int timeout_ms) override;

  const CameraIntrinsics& camera() const;
  const Board& board() const;
  // The true camera pose (T_world_camera, OpenCV axes) at time t_s after the start.
  Pose PoseAt(double t_s) const;
  // Renders the frame at time t_s with frame number `index` (noise stream).
  Frame RenderFrame(double t_s, int64_t index) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace nerfar::synth
