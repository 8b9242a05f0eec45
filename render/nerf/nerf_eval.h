// Rendering a NerfField at a dataset split's cameras and scoring it: psnr_tm
// (DESIGN.md metric) against the split's own images and, where the scene has
// insert/bg_XXX.exr (low-noise renders of the test cameras), against those;
// depth error against insert/<object>/depth_XXX.exr (channel Y, depth along
// the viewing axis) on surface pixels, the object's mask_XXX.png excluded.
#pragma once

#include <string>
#include <vector>

#include "render/nerf/nerf_field.h"

namespace nerfar {

struct NerfViewScore {
  std::string name;                    // "r_003"
  double psnr_dataset = 0;             // vs the split's image (noisy), dB
  double psnr_reference = -1;          // vs insert/bg_XXX.exr, dB; -1 when absent
  double depth_median_m = -1;          // median |depth error| on surfaces, metres; -1 when absent
  double surface_depth_median_m = -1;  // the same for the surface depth (transmittance 0.5)
  double render_ms = 0;                // colour+depth+opacity render time
};

struct NerfEvaluation {
  std::vector<NerfViewScore> views;
  double mean_psnr_dataset = 0;
  double mean_psnr_reference = -1;     // -1 when the scene has no insert/ folder
  double depth_median_m = -1;          // median over all surface pixels of all views
  double surface_depth_median_m = -1;  // the same for the surface depth
  std::string reference_folder;        // the folder used for psnr_reference ("" if none)
};

struct NerfEvalOptions {
  std::string split = "test";  // dataset split to render
  std::string output_dir;      // where to write OUT/r_003.exr, _depth, _opacity ("" = nowhere)
  int max_views = 0;           // 0: all views of the split
  // Also write OUT/<name>.png: the render (left) beside the reference or the
  // split's image (right), tone-mapped with the truth's psnr_tm exposure.
  bool write_png = false;
  NerfRenderOptions render;
};

NerfEvaluation EvaluateNerf(const NerfField& field, const std::string& dataset_dir, const NerfEvalOptions& options);

}  // namespace nerfar
