#include "calib/core/media.h"

#include <algorithm>
#include <filesystem>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <stdexcept>

#include "calib/core/atomic_file.h"
#include "calib/core/error.h"

namespace nerfar {
namespace {

cv::Mat AsMat(const Image8& image) {
  return cv::Mat(image.height, image.width, CV_8UC(image.channels), const_cast<std::uint8_t*>(image.pixels.data()));
}

cv::Mat ToRgb(const Image8& image) {
  cv::Mat rgb;
  if (image.channels == 1) {
    cv::cvtColor(AsMat(image), rgb, cv::COLOR_GRAY2RGB);
  } else if (image.channels == 4) {
    cv::cvtColor(AsMat(image), rgb, cv::COLOR_RGBA2RGB);
  } else {
    rgb = AsMat(image).clone();
  }
  return rgb;
}

}  // namespace

void DrawText(Image8& image, const std::string& text, int x, int y, double scale) {
  NERFAR_CHECK_EQ(image.channels, 3);
  cv::Mat mat = AsMat(image);
  const int baseline_y = y + static_cast<int>(10 * scale);
  const cv::Point origin(x, baseline_y);
  cv::putText(mat, text, origin, cv::FONT_HERSHEY_SIMPLEX, 0.4 * scale, cv::Scalar(20, 20, 20),
              std::max(2, static_cast<int>(3 * scale)), cv::LINE_AA);
  cv::putText(mat, text, origin, cv::FONT_HERSHEY_SIMPLEX, 0.4 * scale, cv::Scalar(240, 240, 240),
              std::max(1, static_cast<int>(scale)), cv::LINE_AA);
}

Image8 ContactSheet(const std::vector<Image8>& tiles, int columns, int tile_width,
                    const std::vector<std::string>& captions) {
  NERFAR_CHECK(!tiles.empty());
  NERFAR_CHECK(columns > 0 && tile_width > 0);
  NERFAR_CHECK(captions.empty() || captions.size() == tiles.size());
  const int gutter = 4, caption_height = captions.empty() ? 0 : 16;
  int tile_height = 1;
  for (const Image8& tile : tiles)
    tile_height = std::max(tile_height, tile.width > 0 ? tile.height * tile_width / tile.width : 1);
  const int rows = static_cast<int>((tiles.size() + columns - 1) / columns);
  const int cell_height = tile_height + caption_height;
  Image8 sheet(gutter + columns * (tile_width + gutter), gutter + rows * (cell_height + gutter), 3, 24);
  cv::Mat sheet_mat = AsMat(sheet);
  for (size_t i = 0; i < tiles.size(); ++i) {
    if (tiles[i].empty()) continue;
    const int height = std::max(1, tiles[i].height * tile_width / tiles[i].width);
    cv::Mat scaled;
    cv::resize(ToRgb(tiles[i]), scaled, cv::Size(tile_width, height), 0, 0, cv::INTER_AREA);
    const int x = gutter + static_cast<int>(i % columns) * (tile_width + gutter);
    const int y = gutter + static_cast<int>(i / columns) * (cell_height + gutter);
    scaled.copyTo(sheet_mat(cv::Rect(x, y, tile_width, height)));
    if (!captions.empty()) DrawText(sheet, captions[i], x + 2, y + height + 2);
  }
  return sheet;
}

struct VideoWriter::Impl {
  explicit Impl(const std::string& path) : file(path) {}
  AtomicFile file;  // OpenCV picks the container from the name: the temporary keeps the extension
  int width = 0, height = 0;
  cv::VideoWriter writer;
};

VideoWriter::VideoWriter(const std::string& path, int width, int height, double fps) {
  NERFAR_CHECK(width > 0 && height > 0 && fps > 0);
  const std::string extension = std::filesystem::path(path).extension().string();
  int fourcc = 0;
  if (extension == ".mp4" || extension == ".m4v" || extension == ".mov") {
    fourcc = cv::VideoWriter::fourcc('m', 'p', '4', 'v');
  } else if (extension == ".avi") {
    fourcc = cv::VideoWriter::fourcc('M', 'J', 'P', 'G');
  } else {
    ThrowInputError(path, "unknown video extension '" + extension + "' (expected .mp4 or .avi)");
  }
  impl_ = std::make_unique<Impl>(path);
  impl_->width = width;
  impl_->height = height;
  if (!impl_->writer.open(impl_->file.temp_path(), cv::CAP_FFMPEG, fourcc, fps, cv::Size(width, height)))
    throw std::runtime_error(path + ": cannot open a video writer (is OpenCV built with FFmpeg?)");
}

VideoWriter::~VideoWriter() = default;  // an unclosed video's temporary file goes with its AtomicFile

void VideoWriter::Write(const Image8& frame) {
  NERFAR_CHECK(impl_->writer.isOpened());
  cv::Mat rgb = ToRgb(frame), bgr;
  if (rgb.cols != impl_->width || rgb.rows != impl_->height)
    cv::resize(rgb, rgb, cv::Size(impl_->width, impl_->height), 0, 0, cv::INTER_AREA);
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  impl_->writer.write(bgr);
  ++frames_;
}

void VideoWriter::Close() {
  if (!impl_->writer.isOpened()) return;
  impl_->writer.release();
  impl_->file.Commit();
}

}  // namespace nerfar
