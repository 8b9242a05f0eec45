// The NeRF box of a dataset that does not give one (no "aabb"), in the
// dataset's world frame: around the board's tags when the scene has a board
// (z up, the table at z = 0), else around the point the cameras look at, as
// far as a typical view frames it. instant-ngp's box (aabb_scale, scale,
// offset) bounds it when the file gives one. Each comes with a sentence that
// says how it was found, for the log.
#pragma once

#include <string>
#include <vector>

#include "calib/board.h"
#include "calib/dataset.h"

namespace nerfar {

// Defaults of a box around a board, shared with `nerfar capture`: the tags'
// extent grown by this in x and y (objects stand inside the ring of tags, a
// little beyond it is table), from 5 cm under the table top to this height.
inline constexpr double kBoardBoxMarginM = 0.1;
inline constexpr double kBoardBoxHeightM = 0.6;
inline constexpr double kBoardBoxBelowM = 0.05;

Aabb BoxAroundBoard(const Board& board, double margin_m = kBoardBoxMarginM, double height_m = kBoardBoxHeightM);

// The point closest to every camera's optical axis in the least-squares sense
// (what a capture circling something looks at). False when the axes are
// (nearly) parallel, so that no such point is defined.
bool LookAtPoint(const std::vector<Pose>& T_world_cameras, Vec3& point);

// A cube centred on the look-at point whose half-side is half the diagonal
// of what the median camera frames there (its distance to the point times
// hypot(tan(fov_x / 2), tan(fov_y / 2))): cameras around the point turn their
// frames about it, so together they see a disc of that radius. InputError
// (naming the dataset) when the cameras do not look at a common point.
Aabb BoxFromCameras(const Dataset& dataset, std::string* how = nullptr);

struct SceneBox {
  Aabb box;
  std::string how;  // e.g. "from the board's 12 tags (board.json), ..." for the log
};

// The box of a dataset without "aabb": from the board when given, else from
// the cameras; intersected with instant-ngp's box when the file has one.
SceneBox DeriveSceneBox(const Dataset& dataset, const Board* board);

}  // namespace nerfar
