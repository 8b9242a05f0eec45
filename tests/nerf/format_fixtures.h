// The inputs of the .nerf and checkpoint fixtures in tests/data/formats/
// (written by tests/make_format_fixtures.cpp; the tests read those files to
// show that files written by earlier builds still read): a small field with
// values from a hash (no library RNG, whose sequences may differ between
// standard libraries) and the tiny trainer of tests/support/tiny_trainer.h.
#pragma once

#include <cmath>

#include "calib/core/random.h"
#include "render/nerf/nerf_field.h"
#include "render/nerf/nerf_train.h"
#include "tests/support/tiny_trainer.h"

namespace nerfar::testing {

// A ball of radius 0.3 m in the unit box on an 1/8 m grid (one brick per 4 cells): log-density
// log(0.5..50) / m and log-linear colours spanning 1e-2..1e2 with slopes in ±0.3, from Mix64 of
// the vertex's slot and channel; empty elsewhere.
inline NerfField FormatFixtureField() {
  NerfField f = NerfField::Dense(Aabb{{0, 0, 0}, {1, 1, 1}}, 1.0 / 8, kNerfEmptyDensityRaw, Vec3f(0, 0, 0));
  auto unit = [](uint64_t slot, int channel) { return UnitFloat(Mix64(slot * 16 + uint64_t(channel) + 1)); };
  for (int k = 0; k < f.res[2]; ++k)
    for (int j = 0; j < f.res[1]; ++j)
      for (int i = 0; i < f.res[0]; ++i) {
        const Vec3f p = f.origin + Vec3f(float(i), float(j), float(k)) * f.voxel_m;
        if (Length(p - Vec3f(0.5f, 0.5f, 0.5f)) > 0.3f) continue;
        const int32_t s = f.Slot(i, j, k);
        f.density[s] = std::log(0.5f) + unit(s, 0) * std::log(100.0f);
        float* q = &f.color[size_t(s) * kNerfColorCoeffs];
        for (int m = 0; m < kNerfColorCoeffs; ++m)
          q[m] = m % 4 == 0 ? std::log(1e-2f) + unit(s, m + 1) * std::log(1e4f) : 0.6f * (unit(s, m + 1) - 0.5f);
      }
  f.UpdateOccupancy(1e-3f);
  return f;
}

// Steps trained before tests/data/formats/train_vN.ckpt was written.
inline constexpr int kFormatFixtureTrainSteps = 3;

}  // namespace nerfar::testing
