// No-reference quality of rendered views (paper §4.2): BRISQUE (Mittal et al.
// 2012) through OpenCV's quality module with the LIVE model from opencv-data.
// Scores run from about 0 (natural, clean) to 100 (noisy, distorted); the
// paper rejects NeRF views that score above 50. HDR renderings are tone mapped
// for display (calib/core/image_io.h) before scoring, as a person would see them.
#pragma once

#include <memory>
#include <string>

#include "calib/core/image.h"

namespace nerfar {

// Folder holding brisque_model_live.yml and brisque_range_live.yml: $NERFAR_BRISQUE_DIR
// if set, else the opencv-data install folders; "" when none has both files.
std::string FindBrisqueModelDir();

class BrisqueScorer {
 public:
  // Loads the model once (InputError naming the folder when its files are missing or unreadable).
  explicit BrisqueScorer(const std::string& model_dir = FindBrisqueModelDir());
  ~BrisqueScorer();
  BrisqueScorer(const BrisqueScorer&) = delete;
  BrisqueScorer& operator=(const BrisqueScorer&) = delete;

  // Score of an 8-bit grey or RGB image (at least 16 x 16). Not thread-safe: one scorer per thread.
  double Score(const Image8& image) const;
  // Score of a linear HDR RGB image, tone mapped with the exposure that puts
  // its 99th-percentile luminance at 1.
  double ScoreLinear(const ImageF& linear_rgb) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace nerfar
