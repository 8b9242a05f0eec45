#include "render/nerf/nerf_eval.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>

#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "calib/core/image_io.h"
#include "calib/core/metrics.h"
#include "calib/dataset.h"
#include "calib/linear_image.h"

namespace nerfar {
namespace {

// "r_003" -> "003" (the digits the insert/ files share); "" when there are none.
std::string IndexDigits(const std::string& name) {
  size_t start = name.size();
  while (start > 0 && std::isdigit(static_cast<unsigned char>(name[start - 1]))) --start;
  return name.substr(start);
}

double Median(std::vector<float>& values) {
  if (values.empty()) return -1;
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  return values[mid];
}

}  // namespace

NerfEvaluation EvaluateNerf(const NerfField& field, const std::string& dataset_dir, const NerfEvalOptions& options) {
  namespace fs = std::filesystem;
  const Dataset set = ReadDataset(DatasetSplitPath(dataset_dir, options.split));
  const Linearisation linearisation = DatasetLinearisation(dataset_dir);
  NerfEvaluation eval;
  std::error_code error;
  const fs::path insert = fs::path(dataset_dir) / "insert";
  const bool has_insert = options.split == "test" && fs::is_directory(insert, error);
  if (has_insert) eval.reference_folder = insert.string();
  std::vector<fs::path> object_dirs;
  if (has_insert)
    for (const auto& entry : fs::directory_iterator(insert, error))
      if (entry.is_directory()) object_dirs.push_back(entry.path());
  std::sort(object_dirs.begin(), object_dirs.end());
  if (!options.output_dir.empty()) MakeDirectories(options.output_dir);

  std::vector<float> all_depth_errors, all_surface_errors;
  double sum_dataset = 0, sum_reference = 0;
  int count_reference = 0;
  const size_t n_views =
      options.max_views > 0 ? std::min(set.frames.size(), size_t(options.max_views)) : set.frames.size();
  for (size_t v = 0; v < n_views; ++v) {
    const DatasetFrame& frame = set.frames[v];
    NerfViewScore score;
    score.name = fs::path(frame.file_path).stem().string();
    const auto t0 = std::chrono::steady_clock::now();
    const NerfImages images = RenderView(field, set.CameraOf(frame), frame.T_world_camera, options.render);
    score.render_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    const ImageF truth = ReadLinearImage(frame.image_path, linearisation).rgb;
    if (truth.width != images.color.width || truth.height != images.color.height)
      ThrowInputError(frame.image_path, "image size differs from the transforms file's w, h");
    score.psnr_dataset = PsnrTm(images.color, truth);
    sum_dataset += score.psnr_dataset;
    const std::string digits = IndexDigits(score.name);
    ImageF preview_truth = truth;
    if (has_insert && !digits.empty()) {
      const fs::path bg = insert / ("bg_" + digits + ".exr");
      if (fs::is_regular_file(bg, error)) {
        preview_truth = ReadExrRgb(bg.string());
        score.psnr_reference = PsnrTm(images.color, preview_truth);
        sum_reference += score.psnr_reference;
        ++count_reference;
      }
      std::vector<float> errors, surface_errors;
      for (const fs::path& object : object_dirs) {
        const fs::path depth_path = object / ("depth_" + digits + ".exr");
        const fs::path mask_path = object / ("mask_" + digits + ".png");
        if (!fs::is_regular_file(depth_path, error) || !fs::is_regular_file(mask_path, error)) continue;
        const ImageF depth = ReadExrChannel(depth_path.string(), "Y");
        const Image8 mask = ReadImage8(mask_path.string());
        if (depth.width != images.depth.width || depth.height != images.depth.height || mask.width != depth.width ||
            mask.height != depth.height)
          ThrowInputError(depth_path.string(), "depth or mask size differs from the camera's");
        for (size_t p = 0; p < depth.PixelCount(); ++p) {
          if (!(depth.pixels[p] > 0) || mask.pixels[p * mask.channels] > 127) continue;
          errors.push_back(std::fabs(images.depth.pixels[p] - depth.pixels[p]));
          surface_errors.push_back(std::fabs(images.surface_depth.pixels[p] - depth.pixels[p]));
        }
      }
      all_depth_errors.insert(all_depth_errors.end(), errors.begin(), errors.end());
      all_surface_errors.insert(all_surface_errors.end(), surface_errors.begin(), surface_errors.end());
      score.depth_median_m = Median(errors);
      score.surface_depth_median_m = Median(surface_errors);
    }
    if (!options.output_dir.empty()) {
      const fs::path out(options.output_dir);
      const std::string color_path = (out / (score.name + ".exr")).string();
      WriteExrRgb(color_path, images.color, ExrPixelType::kFloat);
      WriteExr((out / (score.name + "_depth.exr")).string(), images.depth, {"Y"}, ExrPixelType::kFloat);
      WriteExr((out / (score.name + "_surface_depth.exr")).string(), images.surface_depth, {"Y"}, ExrPixelType::kFloat);
      WriteExr((out / (score.name + "_opacity.exr")).string(), images.opacity, {"Y"}, ExrPixelType::kHalf);
      if (options.write_png) {
        const int w = images.color.width, h = images.color.height;
        ImageF both(2 * w, h, 3);
        for (int y = 0; y < h; ++y)
          for (int x = 0; x < w; ++x)
            for (int c = 0; c < 3; ++c) {
              both.pixels[(size_t(y) * 2 * w + x) * 3 + c] = images.color.Pixel(x, y)[c];
              both.pixels[(size_t(y) * 2 * w + w + x) * 3 + c] = preview_truth.Pixel(x, y)[c];
            }
        WriteImage8((out / (score.name + ".png")).string(),
                    ToneMapToDisplay(both, ExposureForPercentile(preview_truth, 0.99)));
      }
    }
    eval.views.push_back(score);
  }
  if (n_views > 0) eval.mean_psnr_dataset = sum_dataset / double(n_views);
  if (count_reference > 0) eval.mean_psnr_reference = sum_reference / count_reference;
  eval.depth_median_m = Median(all_depth_errors);
  eval.surface_depth_median_m = Median(all_surface_errors);
  return eval;
}

}  // namespace nerfar
