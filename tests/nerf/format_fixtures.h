// The inputs of the .nerf and checkpoint fixtures in tests/data/formats/
// (written by tests/make_format_fixtures.cpp; the tests read those files to
// show that files written by earlier builds still read): a small field with
// values from a hash (no library RNG, whose sequences may differ between
// standard libraries) and a one-view training set.
#pragma once

#include <cmath>

#include "calib/core/random.h"
#include "render/nerf/nerf_field.h"
#include "render/nerf/nerf_train.h"

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

// One 8x6 view of a 20 cm box, its pixels a gradient.
inline NerfTrainData FormatFixtureTrainData() {
  NerfTrainData data;
  data.aabb = Aabb{{-0.1, -0.1, -0.1}, {0.1, 0.1, 0.1}};
  data.source = "fixture/transforms.json";
  NerfView view;
  view.name = "r_000";
  view.camera.width = 8;
  view.camera.height = 6;
  view.camera.fx = view.camera.fy = 8;
  view.camera.cx = 4;
  view.camera.cy = 3;
  view.T_world_camera = LookAt({0.0, -1.0, 0.3}, {0, 0, 0});
  view.rgb = ImageF(8, 6, 3, 0.0f);
  for (int y = 0; y < 6; ++y)
    for (int x = 0; x < 8; ++x)
      for (int c = 0; c < 3; ++c) view.rgb.Pixel(x, y)[c] = 0.1f + 0.05f * float(x + y + c);
  data.train.push_back(view);
  return data;
}

// The fast preset on a 10 cm grid (one brick), one level, 64 rays a step.
inline NerfTrainOptions FormatFixtureTrainOptions() {
  NerfTrainOptions options = NerfTrainOptions::Preset("fast");
  options.coarse_voxel_m = 0.1;
  options.levels = 1;
  options.rays_per_step = 64;
  options.eval_views = 0;
  return options;
}

// Steps trained before tests/data/formats/train.ckpt was written.
inline constexpr int kFormatFixtureTrainSteps = 3;

}  // namespace nerfar::testing
