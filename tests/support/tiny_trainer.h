// The smallest trainer the tests and fuzzers use: one 8x6 view of a 20 cm box
// (its pixels a gradient) and the fast preset on a 10 cm grid (one brick, one
// level, 64 rays a step), so a checkpoint is about 10 kilobytes. The
// checkpoint fixture tests/data/formats/train_vN.ckpt (make_format_fixtures.cpp)
// and the checkpoint fuzz target (tests/fuzz) both train it: a change here
// changes the checkpoint's identity, and the fixture must be written again.
#pragma once

#include "render/nerf/nerf_train.h"

namespace nerfar::testing {

inline NerfTrainData TinyTrainData() {
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

inline NerfTrainOptions TinyTrainOptions() {
  NerfTrainOptions options = NerfTrainOptions::Preset("fast");
  options.coarse_voxel_m = 0.1;
  options.levels = 1;
  options.rays_per_step = 64;
  options.eval_views = 0;
  // The fast preset's slope decay when tests/data/formats' checkpoints were
  // written: a checkpoint keeps its options as its identity, and the old ones
  // must still load (docs/history/nerf.md, "The colour-slope decay and the near field").
  options.color_slope_decay = 1.0;
  return options;
}

}  // namespace nerfar::testing
