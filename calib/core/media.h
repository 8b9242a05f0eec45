// Pictures and videos for people: contact sheets (a grid of views with
// optional captions) and MP4/AVI video files written frame by frame through
// OpenCV's video I/O. 8-bit RGB in, as produced by ToneMapToDisplay.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "calib/core/image.h"

namespace nerfar {

// Tiles scaled (nearest-neighbour downscale by area average) to tile_width,
// aspect kept, laid out in `columns` columns with a 4-pixel dark gutter.
// Captions are drawn under each tile when given (same count as tiles).
Image8 ContactSheet(const std::vector<Image8>& tiles, int columns, int tile_width,
                    const std::vector<std::string>& captions = {});

// Draws text into an RGB image at (x, y) (top-left of the text), white with a
// dark outline so it reads on any background; scale 1 is ~10 px tall.
void DrawText(Image8& image, const std::string& text, int x, int y, double scale = 1.0);

// Writes frames of one size to a video file (container from the extension:
// .mp4 with MPEG-4 Part 2, .avi with MJPG). The file appears under its name
// only when Close() succeeds (written to a temporary file, then renamed).
class VideoWriter {
 public:
  VideoWriter(const std::string& path, int width, int height, double fps);
  ~VideoWriter();
  VideoWriter(const VideoWriter&) = delete;
  VideoWriter& operator=(const VideoWriter&) = delete;

  // Frames of another size are resized to the video's size.
  void Write(const Image8& frame);
  void Close();
  int frames_written() const { return frames_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  int frames_ = 0;
};

}  // namespace nerfar
