// Datasets in the instant-ngp / nerfstudio transforms.json convention, as in
// ../shared/scenes/README.md: shared intrinsics (fl_x, fl_y, cx, cy, w, h,
// camera_angle_x/y, camera_model, k1 k2 p1 p2 [k3]), aabb (NeRF box, metres,
// world frame), frames with file_path and a camera-to-world transform_matrix
// in the OpenGL camera convention (x right, y up, -z forward). Inside nerfar
// every pose is OpenCV (x right, y down, z forward): the one conversion is
// PoseFromTransformMatrix / TransformMatrixFromPose, used only at this file
// boundary.
//
// The files other tools write are read as they are: instant-ngp (sizes as
// whole floats, aabb_scale / scale / offset, per-frame sharpness, file paths
// without an extension), nerfstudio (per-frame intrinsics, mask_path,
// applied_transform, ply_file_path) and the COLMAP conversions of both. A key
// nerfar does not read is ignored and listed once (Dataset::ignored_keys, and
// the log); a key within a typo of one it reads is an error.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <vector>

#include "calib/camera.h"
#include "calib/core/error.h"
#include "calib/core/math.h"

namespace nerfar {

struct Aabb {
  Vec3 min, max;  // metres, world frame
};

struct DatasetFrame {
  std::string file_path;   // as written in the JSON, relative to the dataset folder
  std::string image_path;  // resolved path
  Pose T_world_camera;     // OpenCV camera convention
  // nerfstudio's mask_path: a grey image, 0 where the pixel is not to be
  // learnt from (a moving person, the tripod). Both empty when none.
  std::string mask_file;  // as written
  std::string mask_path;  // resolved
  // This frame's own intrinsics, when Dataset::per_frame_cameras (read them
  // through Dataset::CameraOf).
  CameraIntrinsics camera;
};

struct Dataset {
  std::string path;  // the transforms file read or written
  std::string dir;   // folder that file_path is relative to
  std::string camera_model = "OPENCV";
  CameraIntrinsics camera;         // the shared intrinsics (the first frame's when frames give their own)
  bool per_frame_cameras = false;  // frames carry their own intrinsics (written per frame)
  std::optional<Aabb> aabb;
  // instant-ngp's reconstruction box in the file's frame: 0.5 ± aabb_scale / 2
  // in its unit cube, mapped back through scale and offset (defaults 0.33 and
  // 0.5 as its loader has them). Present when the file gives aabb_scale.
  std::optional<Aabb> ngp_box;
  // Keys read but not used, each "key" or "frames[].key (in N frames)", listed once.
  std::vector<std::string> ignored_keys;
  std::vector<DatasetFrame> frames;

  // The intrinsics of one of its frames.
  const CameraIntrinsics& CameraOf(const DatasetFrame& frame) const {
    return per_frame_cameras ? frame.camera : camera;
  }
};

// The one OpenGL <-> OpenCV conversion (right-multiplication by diag(1,-1,-1,1)).
Pose PoseFromTransformMatrix(const std::array<double, 16>& camera_to_world_opengl);
std::array<double, 16> TransformMatrixFromPose(const Pose& T_world_camera);

// Adds a problem at `pointer` unless the row-major 4x4 is a rigid transform
// (last row 0 0 0 1, orthonormal rotation within the 8 decimals files
// store, a position within 1e6 m).
void CheckRigidTransform(const std::array<double, 16>& m, const std::string& pointer, Problems& problems);

// Reads and validates a transforms file (every problem listed, typos of our
// keys rejected, image and mask files checked to exist when check_images).
Dataset ReadDataset(const std::string& transforms_path, bool check_images = true);
// Writes a transforms file (atomic) in the same convention.
void WriteDataset(const std::string& transforms_path, const Dataset& dataset);

// The split files of a dataset folder: DIR/transforms_<split>.json (split
// "train", "test"), falling back to DIR/transforms.json for "train".
std::string DatasetSplitPath(const std::string& dir, const std::string& split);

}  // namespace nerfar
