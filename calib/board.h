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
  Vec3 up_direction;  // unit, world frame
};

struct Board {
  std::string family = "tag36h11";
  double tag_size_m = 0;  // edge of the outer black square
  std::vector<BoardTag> tags;
  double cell_size_m = 0;     // one cell of the tag's grid; 0 when the file does not say
  double white_margin_m = 0;  // white border around each tag; 0 when the file does not say

  const BoardTag* FindTag(int id) const;
};

// Reads and validates a board file: every problem listed (unknown keys,
// duplicate ids, corners that are not a square of edge tag_size, a centre off
// the corners' mean, an up_direction that is not unit or not along the tag's
// left edge). Documentation keys (units, note, corner_order, orientation,
// tag_size_definition) are accepted.
Board ReadBoard(const std::string& path);
void WriteBoard(const std::string& path, const Board& board);

}  // namespace nerfar
