// How far one κ layer is from a reference, in the units the insertion tests
// state their tolerances in: the summed |κ − κ_ref| over the reference's
// shadow mass Σ(1 − κ_ref), and the worst pixel.
#pragma once

#include <algorithm>
#include <cmath>

#include "calib/core/error.h"
#include "calib/core/image.h"

namespace nerfar::testing {

struct KappaDifference {
  double sum = 0;     // Σ |κ − κ_ref|
  double shadow = 0;  // Σ (1 − κ_ref)
  double max = 0;     // max |κ − κ_ref|
  double Relative() const { return sum / shadow; }
};

inline KappaDifference CompareKappa(const ImageF& kappa, const ImageF& reference) {
  NERFAR_CHECK(kappa.pixels.size() == reference.pixels.size());
  KappaDifference d;
  for (size_t i = 0; i < kappa.pixels.size(); ++i) {
    const double diff = std::abs(static_cast<double>(kappa.pixels[i]) - reference.pixels[i]);
    d.sum += diff;
    d.max = std::max(d.max, diff);
    d.shadow += 1 - reference.pixels[i];
  }
  return d;
}

}  // namespace nerfar::testing
