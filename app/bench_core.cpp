// Bench stage "core": the file formats every stage reads and writes.
#include <unistd.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "app/bench.h"
#include "calib/core/exr.h"
#include "calib/core/json.h"

namespace nerfar {

std::vector<BenchFigure> BenchCore(const BenchOptions& options) {
  const int width = options.quick ? 320 : 1280, height = options.quick ? 180 : 720;
  const std::string size = std::to_string(width) + "x" + std::to_string(height) + " RGB";
  ImageF image(width, height, 3);
  for (size_t i = 0; i < image.pixels.size(); ++i) image.pixels[i] = static_cast<float>((i * 7919) % 1000) * 0.01f;
  const std::string dir = std::filesystem::temp_directory_path() / ("nerfar_bench_core_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string half_path = dir + "/half.exr", float_path = dir + "/float.exr";

  std::vector<BenchFigure> figures;
  figures.push_back({"exr_write_half_ms", MedianMilliseconds([&] { WriteExrRgb(half_path, image); }), "ms", size});
  figures.push_back({"exr_read_half_ms", MedianMilliseconds([&] { ReadExrRgb(half_path); }), "ms", size});
  figures.push_back({"exr_write_float_ms",
                     MedianMilliseconds([&] { WriteExrRgb(float_path, image, ExrPixelType::kFloat); }), "ms", size});
  figures.push_back({"exr_read_float_ms", MedianMilliseconds([&] { ReadExrRgb(float_path); }), "ms", size});

  // A transforms.json-sized document: 100 frames with 4x4 matrices.
  std::string text = "{\"frames\": [";
  for (int f = 0; f < 100; ++f) {
    text += std::string(f ? "," : "") + "{\"file_path\": \"train/r_" + std::to_string(f) +
            ".exr\", \"transform_matrix\": [[1,0,0,0.5],[0,1,0,0.25],[0,0,1,0.75],[0,0,0,1]]}";
  }
  text += "]}";
  figures.push_back({"json_parse_100_frames_ms", MedianMilliseconds([&] { ParseJson(text, "bench"); }), "ms",
                     std::to_string(text.size()) + " bytes"});
  std::filesystem::remove_all(dir);
  return figures;
}

}  // namespace nerfar
