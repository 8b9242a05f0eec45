// The trainer whose checkpoints checkpoint_fuzz.cpp reads and make_seeds.cpp
// writes: one 8x6 view of a 20 cm box, the fast preset on a 10 cm grid (one
// brick), so a checkpoint is about 10 kilobytes.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>

#include "render/nerf/nerf_train.h"

namespace nerfar::fuzz {

inline NerfTrainData TinyTrainData() {
  NerfTrainData data;
  data.aabb = Aabb{{-0.1, -0.1, -0.1}, {0.1, 0.1, 0.1}};
  data.source = "fuzz/transforms.json";
  NerfView view;
  view.name = "r_000";
  view.camera.width = 8;
  view.camera.height = 6;
  view.camera.fx = view.camera.fy = 8;
  view.camera.cx = 4;
  view.camera.cy = 3;
  view.T_world_camera = LookAt({0.0, -1.0, 0.3}, {0, 0, 0});
  view.rgb = ImageF(8, 6, 3, 0.5f);
  data.train.push_back(view);
  return data;
}

inline NerfTrainOptions TinyTrainOptions() {
  NerfTrainOptions options = NerfTrainOptions::Preset("fast");
  options.coarse_voxel_m = 0.1;
  options.levels = 1;
  options.rays_per_step = 64;
  options.eval_views = 0;
  return options;
}

// The number of bytes of a checkpoint before its grid: the magic and the
// two identity strings (options, dataset), each a u64 length and its bytes.
inline size_t CheckpointIdentityBytes(const std::string& checkpoint) {
  size_t at = 8;
  for (int i = 0; i < 2 && at + 8 <= checkpoint.size(); ++i) {
    std::uint64_t length = 0;
    std::memcpy(&length, checkpoint.data() + at, 8);
    at += 8 + length;
  }
  return at;
}

}  // namespace nerfar::fuzz
