// Linear radiance from the images a dataset names. OpenEXR is linear as
// stored. PNG and JPEG frames (8 or 16 bits per channel) are display-referred:
// each value goes through the camera's response (calib/hdr.h, from the
// dataset's camera.json) or, when none is known, the sRGB curve. A channel at
// the top of the sensor's range (for JPEG: within 5 of 255 levels of it, the
// codec's error near saturated areas) is clipped: its radiance is only known
// to be at least the value read, and it is flagged so that training can treat
// it as a lower bound.
#pragma once

#include <optional>
#include <string>

#include "calib/core/image.h"
#include "calib/hdr.h"

namespace nerfar {

// How 8- and 16-bit frames become linear radiance.
struct Linearisation {
  std::optional<CameraResponse> response;  // Debevec g(z) per channel; none: sRGB
  std::string source;                      // the camera.json it came from ("" for sRGB)

  // "the camera response of DIR/camera.json" or "the sRGB curve (...)".
  std::string Describe() const;
};

// The linearisation of a dataset folder: the response in DIR/camera.json when
// the file exists and has one, else sRGB. InputError for a camera.json that
// cannot be read.
Linearisation DatasetLinearisation(const std::string& dataset_dir);

struct LinearImage {
  ImageF rgb;  // linear radiance, 3 channels (a grey file repeated)
  // One byte per pixel, bit c set where channel c was clipped (the file's
  // largest value). Empty for EXR files, which do not clip.
  Image8 clipped;
  bool display_referred = false;  // read from PNG or JPEG

  size_t ClippedPixels() const;
};

// Reads an EXR, PNG or JPEG (by content, not name). InputError naming the
// file when it cannot be read or is not 1 or 3 (or 4: alpha dropped) channels.
LinearImage ReadLinearImage(const std::string& path, const Linearisation& linearisation);

// Linear value of a frame value z in 0..255 (continuous: 16-bit values are
// z = v / 257) of channel c, through the response (interpolated between
// levels) or sRGB; 0 at z = 0 (black: as the shared scenes' empty background).
float LinearValue(const Linearisation& linearisation, int channel, float z);

// A mask image (nerfstudio's mask_path) as one channel, 0 where the pixel is
// to be ignored; InputError if its size is not width x height.
Image8 ReadMask(const std::string& path, int width, int height);

}  // namespace nerfar
