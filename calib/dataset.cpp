#include "calib/dataset.h"

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "calib/camera_keys.h"
#include "calib/core/json.h"

namespace nerfar {
namespace fs = std::filesystem;

namespace {

// More frames than this is a corrupt or hostile file, not a capture.
constexpr size_t kMaxFrames = 1000000;
// Rotation blocks are stored with about 8 decimals: orthonormal within this.
constexpr double kRigidTolerance = 1e-4;
// Camera centres farther than this from the origin (metres) are absurd.
constexpr double kMaxTranslation = 1e6;

std::string FormatNumber(double v) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.6g", v);
  return buffer;
}

// Problems with a row-major 4x4 that should be a rigid transform.
void CheckRigid(const std::array<double, 16>& m, const std::string& pointer, Problems& problems) {
  if (std::abs(m[12]) > 1e-9 || std::abs(m[13]) > 1e-9 || std::abs(m[14]) > 1e-9 || std::abs(m[15] - 1) > 1e-9) {
    problems.Add(pointer + "/3", "is [" + FormatNumber(m[12]) + ", " + FormatNumber(m[13]) + ", " +
                                     FormatNumber(m[14]) + ", " + FormatNumber(m[15]) + "] (expected [0, 0, 0, 1])");
  }
  double worst = 0;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      const double dot = m[i] * m[j] + m[4 + i] * m[4 + j] + m[8 + i] * m[8 + j];  // columns i, j
      worst = std::max(worst, std::abs(dot - (i == j ? 1.0 : 0.0)));
    }
  }
  const double det =
      m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) + m[2] * (m[4] * m[9] - m[5] * m[8]);
  if (worst > kRigidTolerance || det < 0) {
    problems.Add(pointer, "rotation block is not a rotation (largest deviation of R^T R from identity " +
                              FormatNumber(worst) + ", det " + FormatNumber(det) +
                              "; expected a rigid camera-to-world transform without scale)");
  }
  for (int r = 0; r < 3; ++r) {
    if (std::abs(m[r * 4 + 3]) > kMaxTranslation)
      problems.Add(pointer + "/" + std::to_string(r) + "/3",
                   "is " + FormatNumber(m[r * 4 + 3]) + " (expected a position within 1e6 m)");
  }
}

std::string ResolvePath(const std::string& dir, const std::string& file) {
  const fs::path p(file);
  return p.is_absolute() ? p.lexically_normal().string() : (fs::path(dir) / p).lexically_normal().string();
}

}  // namespace

Pose PoseFromTransformMatrix(const std::array<double, 16>& camera_to_world_opengl) {
  // OpenGL camera (x right, y up, -z forward) -> OpenCV camera (x right, y
  // down, z forward): T_world_cv = T_world_gl * diag(1, -1, -1, 1), i.e. the
  // y and z columns of the rotation change sign; the centre stays.
  Pose pose = Pose::FromMatrix4(camera_to_world_opengl);
  for (int r = 0; r < 3; ++r) {
    pose.rotation(r, 1) = -pose.rotation(r, 1);
    pose.rotation(r, 2) = -pose.rotation(r, 2);
  }
  return pose;
}

std::array<double, 16> TransformMatrixFromPose(const Pose& T_world_camera) {
  std::array<double, 16> m = T_world_camera.ToMatrix4();
  for (int r = 0; r < 3; ++r) {
    m[r * 4 + 1] = -m[r * 4 + 1];
    m[r * 4 + 2] = -m[r * 4 + 2];
  }
  return m;
}

Dataset ReadDataset(const std::string& transforms_path, bool check_images) {
  const Json doc = ReadJsonFile(transforms_path);
  Problems problems(transforms_path);
  Dataset dataset;
  dataset.path = transforms_path;
  const fs::path parent = fs::path(transforms_path).parent_path();
  dataset.dir = parent.empty() ? "." : parent.string();

  JsonObjectReader root(doc, "", problems);
  root.Allow({"units", "note", "notes", "comment", "description"});
  if (root.valid()) {
    dataset.camera_model = ReadCameraKeys(root, dataset.camera);
    if (root.Has("aabb")) {
      const Json* aabb = root.Array("aabb");
      const std::string pointer = root.PointerTo("aabb");
      if (aabb != nullptr) {
        bool ok = aabb->size() == 2;
        double v[2][3] = {};
        for (size_t c = 0; ok && c < 2; ++c) {
          const Json& corner = (*aabb)[c];
          ok = corner.is_array() && corner.size() == 3;
          for (size_t k = 0; ok && k < 3; ++k) {
            ok = corner[k].is_number() && std::isfinite(corner[k].get<double>()) &&
                 std::abs(corner[k].get<double>()) <= kMaxTranslation;
            if (ok) v[c][k] = corner[k].get<double>();
          }
        }
        if (!ok) {
          problems.Add(pointer, "is not a box (expected [[min x, y, z], [max x, y, z]] of finite numbers, metres)");
        } else if (!(v[0][0] < v[1][0] && v[0][1] < v[1][1] && v[0][2] < v[1][2])) {
          problems.Add(pointer, "min corner is not below the max corner on every axis (expected min < max)");
        } else {
          dataset.aabb = Aabb{{v[0][0], v[0][1], v[0][2]}, {v[1][0], v[1][1], v[1][2]}};
        }
      }
    }
    const Json* frames = root.Array("frames");
    if (frames != nullptr && frames->size() > kMaxFrames) {
      problems.Add(root.PointerTo("frames"), "has " + std::to_string(frames->size()) + " frames (expected at most " +
                                                 std::to_string(kMaxFrames) + ")");
    } else if (frames != nullptr) {
      dataset.frames.reserve(frames->size());
      size_t missing_images = 0;
      for (size_t i = 0; i < frames->size(); ++i) {
        const std::string pointer = "/frames/" + std::to_string(i);
        JsonObjectReader item((*frames)[i], pointer, problems);
        item.Allow({"note", "comment"});
        DatasetFrame frame;
        frame.file_path = item.String("file_path");
        const size_t before = problems.items().size();
        const std::array<double, 16> m = item.Matrix4("transform_matrix");
        if (item.valid() && problems.items().size() == before && item.Has("transform_matrix"))
          CheckRigid(m, item.PointerTo("transform_matrix"), problems);
        item.Finish();
        if (item.valid() && item.Has("file_path") && frame.file_path.empty())
          problems.Add(item.PointerTo("file_path"), "is empty (expected an image path)");
        if (!frame.file_path.empty()) {
          frame.image_path = ResolvePath(dataset.dir, frame.file_path);
          std::error_code error;
          // Only the first few missing files are listed one by one.
          if (check_images && !fs::is_regular_file(frame.image_path, error) && missing_images++ < 10)
            problems.Add(item.PointerTo("file_path"), "image " + frame.image_path + " does not exist");
        }
        frame.T_world_camera = PoseFromTransformMatrix(m);
        dataset.frames.push_back(std::move(frame));
      }
      if (missing_images > 10)
        problems.Add("/frames", std::to_string(missing_images) + " image files are missing in all");
    }
    root.Finish();
  }
  // A second net under the key checks (they already report these, with pointers).
  if (problems.empty())
    for (const std::string& p : dataset.camera.Validate()) problems.Add("", "camera: " + p);
  problems.ThrowIfAny();
  return dataset;
}

void WriteDataset(const std::string& transforms_path, const Dataset& dataset) {
  Problems problems(transforms_path);
  for (const std::string& p : dataset.camera.Validate()) problems.Add("camera", p);
  problems.ThrowIfAny();
  Json doc = Json::object();
  WriteCameraKeys(dataset.camera, dataset.camera_model, doc);
  if (dataset.aabb) {
    const Aabb& b = *dataset.aabb;
    doc["aabb"] = Json::array({Json::array({b.min.x, b.min.y, b.min.z}), Json::array({b.max.x, b.max.y, b.max.z})});
  }
  Json frames = Json::array();
  for (const DatasetFrame& frame : dataset.frames) {
    const std::array<double, 16> m = TransformMatrixFromPose(frame.T_world_camera);
    Json rows = Json::array();
    for (int r = 0; r < 4; ++r) rows.push_back(Json::array({m[r * 4], m[r * 4 + 1], m[r * 4 + 2], m[r * 4 + 3]}));
    frames.push_back(Json{{"file_path", frame.file_path}, {"transform_matrix", rows}});
  }
  doc["frames"] = std::move(frames);
  WriteJsonFile(transforms_path, doc);
}

std::string DatasetSplitPath(const std::string& dir, const std::string& split) {
  const fs::path split_path = fs::path(dir) / ("transforms_" + split + ".json");
  std::error_code error;
  if (split == "train" && !fs::is_regular_file(split_path, error)) return (fs::path(dir) / "transforms.json").string();
  return split_path.string();
}

}  // namespace nerfar
