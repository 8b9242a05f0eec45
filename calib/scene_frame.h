// Bringing a capture made with other tools (COLMAP, instant-ngp, nerfstudio:
// an arbitrary unit, origin and up) into nerfar's world frame (metres, z up):
// a similarity p_world = scale · R · p_file + t, found from the board's tags
// when the scene has a board, else from the cameras (up) and a known length.
#pragma once

#include <vector>

#include "calib/core/math.h"
#include "calib/dataset.h"

namespace nerfar {

struct Similarity {
  double scale = 1;
  Mat3 rotation;
  Vec3 translation;

  Vec3 Apply(const Vec3& p) const { return rotation * p * scale + translation; }
  // A camera pose in the new frame (its centre moved, its axes turned).
  Pose Apply(const Pose& T_file_camera) const {
    return {rotation * T_file_camera.rotation, Apply(T_file_camera.translation)};
  }
};

// The point nearest to every line (origin, unit direction) in least squares.
// False for fewer than 2 lines or (nearly) parallel ones.
bool ClosestPointToLines(const std::vector<Vec3>& origins, const std::vector<Vec3>& directions, Vec3& point);

// The similarity that maps `from` onto `to` best in least squares (Umeyama
// 1991); needs 3 or more points not on one line. `rms` gets the residual.
Similarity FitSimilarity(const std::vector<Vec3>& from, const std::vector<Vec3>& to, double* rms = nullptr);

// The up direction of cameras held upright (no roll, as people hold them):
// perpendicular to every camera's image-right axis in least squares, on the
// side their image-up axes lean to. Exact for cameras without roll whatever
// their spread (needs two or more not parallel); not defined for cameras that
// all look along one horizontal line.
Vec3 UpFromCameras(const std::vector<Pose>& T_world_cameras);

// The smallest rotation taking unit vector `from` onto unit vector `to`.
Mat3 RotationBetween(const Vec3& from, const Vec3& to);

// The dataset in the new frame: poses, aabb and instant-ngp's box (the axis-
// aligned box around the moved corners).
Dataset TransformDataset(const Dataset& dataset, const Similarity& similarity);

}  // namespace nerfar
