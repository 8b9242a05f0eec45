// Datasets in the instant-ngp / nerfstudio transforms.json convention, as in
// ../shared/scenes/README.md: shared intrinsics (fl_x, fl_y, cx, cy, w, h,
// camera_angle_x/y, camera_model, k1 k2 p1 p2 [k3]), aabb (NeRF box, metres,
// world frame), frames with file_path and a camera-to-world transform_matrix
// in the OpenGL camera convention (x right, y up, -z forward). Inside nerfar
// every pose is OpenCV (x right, y down, z forward): the one conversion is
// PoseFromTransformMatrix / TransformMatrixFromPose, used only at this file
// boundary.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <vector>

#include "calib/camera.h"
#include "calib/core/math.h"

namespace nerfar {

struct Aabb {
  Vec3 min, max;  // metres, world frame
};

struct DatasetFrame {
  std::string file_path;   // as written in the JSON, relative to the dataset folder
  std::string image_path;  // resolved path
  Pose T_world_camera;     // OpenCV camera convention
};

struct Dataset {
  std::string path;  // the transforms file read or written
  std::string dir;   // folder that file_path is relative to
  std::string camera_model = "OPENCV";
  CameraIntrinsics camera;
  std::optional<Aabb> aabb;
  std::vector<DatasetFrame> frames;
};

// The one OpenGL <-> OpenCV conversion (right-multiplication by diag(1,-1,-1,1)).
Pose PoseFromTransformMatrix(const std::array<double, 16>& camera_to_world_opengl);
std::array<double, 16> TransformMatrixFromPose(const Pose& T_world_camera);

// Reads and validates a transforms file (every problem listed, unknown keys
// rejected, image files checked to exist when check_images).
Dataset ReadDataset(const std::string& transforms_path, bool check_images = true);
// Writes a transforms file (atomic) in the same convention.
void WriteDataset(const std::string& transforms_path, const Dataset& dataset);

// The split files of a dataset folder: DIR/transforms_<split>.json (split
// "train", "test"), falling back to DIR/transforms.json for "train".
std::string DatasetSplitPath(const std::string& dir, const std::string& split);

}  // namespace nerfar
