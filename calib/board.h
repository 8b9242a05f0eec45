// Tag boards (board.json of ../shared/scenes): an AprilTag family and, per
// tag, the 3-D world corners of its outer black square in the order
// top-left, top-right, bottom-right, bottom-left of the printed image (the
// order detectors report corners in), its centre and printed-up direction.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "calib/core/math.h"

namespace nerfar {

struct BoardTag {
  int id = 0;
  std::array<Vec3, 4> corners;  // metres, world frame
  Vec3 center;
  Vec3 up_direction;            // unit, world frame
};

struct Board {
  std::string family = "tag36h11";
  double tag_size_m = 0;  // edge of the outer black square
  std::vector<BoardTag> tags;

  const BoardTag* FindTag(int id) const;
};

Board ReadBoard(const std::string& path);
void WriteBoard(const std::string& path, const Board& board);

}  // namespace nerfar
