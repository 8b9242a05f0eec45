#include "calib/dataset.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>

#include "calib/camera_keys.h"
#include "calib/core/json.h"
#include "calib/core/log.h"

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

std::string ResolvePath(const std::string& dir, const std::string& file) {
  const fs::path p(file);
  return p.is_absolute() ? p.lexically_normal().string() : (fs::path(dir) / p).lexically_normal().string();
}

// An image path as instant-ngp resolves it: NeRF-synthetic files name their
// images without the extension ("./train/r_0" for train/r_0.png).
std::string ResolveImagePath(const std::string& dir, const std::string& file) {
  const std::string path = ResolvePath(dir, file);
  std::error_code error;
  if (fs::path(path).has_extension() || fs::is_regular_file(path, error)) return path;
  return fs::is_regular_file(path + ".png", error) ? path + ".png" : path;
}

// Keys of documentation only, accepted everywhere.
const std::vector<std::string>& DocumentationKeys() {
  static const std::vector<std::string> keys = {"units", "note", "notes", "comment", "description"};
  return keys;
}

// Optimal string alignment distance (edits, swaps of neighbours count one).
size_t EditDistance(const std::string& a, const std::string& b) {
  std::vector<std::vector<size_t>> d(a.size() + 1, std::vector<size_t>(b.size() + 1));
  for (size_t i = 0; i <= a.size(); ++i) d[i][0] = i;
  for (size_t j = 0; j <= b.size(); ++j) d[0][j] = j;
  for (size_t i = 1; i <= a.size(); ++i)
    for (size_t j = 1; j <= b.size(); ++j) {
      d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1)});
      if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1])
        d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
    }
  return d[a.size()][b.size()];
}

// The key of `read` that `key` is a typo of, or "" when it is none: one edit
// away for keys of up to 4 characters ("fl_z"), two for longer ones
// ("trasform_matrix"). Other tools' keys are further from ours than that.
std::string TypoOf(const std::string& key, const std::vector<std::string>& read) {
  for (const std::string& known : read) {
    const size_t allowed = std::max(key.size(), known.size()) <= 4 ? 1 : 2;
    if (EditDistance(key, known) <= allowed) return known;
  }
  return "";
}

// Keys of `object` outside `read`: a typo of one of them is a problem (so it
// never silently becomes a default); any other is accepted and counted in
// `ignored` (key -> objects that had it).
void SortUnknownKeys(const Json& object, const std::vector<std::string>& read, JsonObjectReader& reader,
                     std::map<std::string, size_t>& ignored) {
  if (!object.is_object()) return;
  for (auto it = object.begin(); it != object.end(); ++it) {
    const std::string& key = it.key();
    if (std::find(read.begin(), read.end(), key) != read.end()) continue;
    const std::string typo_of = TypoOf(key, read);
    if (typo_of.empty()) {
      ++ignored[key];
    } else {
      reader.problems().Add(reader.PointerTo(key.c_str()), "unknown key (a typo of \"" + typo_of + "\"?)");
    }
    reader.Allow({key.c_str()});
  }
}

std::vector<std::string> Concat(std::initializer_list<const std::vector<std::string>*> lists) {
  std::vector<std::string> out;
  for (const auto* list : lists) out.insert(out.end(), list->begin(), list->end());
  return out;
}

const std::vector<std::string>& RootKeys() {
  static const std::vector<std::string> own = {"aabb", "aabb_scale", "scale", "offset", "frames"};
  static const std::vector<std::string> keys = Concat({&own, &CameraKeyNames(), &DocumentationKeys()});
  return keys;
}

const std::vector<std::string>& FrameKeys() {
  static const std::vector<std::string> own = {"file_path", "transform_matrix", "mask_path"};
  static const std::vector<std::string> keys = Concat({&own, &CameraKeyNames(), &DocumentationKeys()});
  return keys;
}

bool HasCameraKeys(const Json& object) {
  if (!object.is_object()) return false;
  for (const std::string& key : CameraKeyNames())
    if (object.contains(key)) return true;
  return false;
}

std::optional<Aabb> ReadAabb(JsonObjectReader& root) {
  if (!root.Has("aabb")) return std::nullopt;
  const Json* aabb = root.Array("aabb");
  if (aabb == nullptr) return std::nullopt;
  const std::string pointer = root.PointerTo("aabb");
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
    root.problems().Add(pointer, "is not a box (expected [[min x, y, z], [max x, y, z]] of finite numbers, metres)");
    return std::nullopt;
  }
  if (!(v[0][0] < v[1][0] && v[0][1] < v[1][1] && v[0][2] < v[1][2])) {
    root.problems().Add(pointer, "min corner is not below the max corner on every axis (expected min < max)");
    return std::nullopt;
  }
  return Aabb{{v[0][0], v[0][1], v[0][2]}, {v[1][0], v[1][1], v[1][2]}};
}

// instant-ngp maps a file position p to p · scale + offset (before it cycles
// the axes) and reconstructs the cube 0.5 ± aabb_scale / 2 of that space.
std::optional<Aabb> ReadNgpBox(JsonObjectReader& root) {
  const std::optional<double> aabb_scale = root.OptionalNumber("aabb_scale", 1.0, 1024.0);
  const double scale = root.OptionalNumber("scale", 1e-9, 1e9).value_or(0.33);
  std::array<double, 3> offset = {0.5, 0.5, 0.5};
  if (root.Has("offset")) offset = root.Vec3("offset");
  if (!aabb_scale.has_value() || !(scale > 0)) return std::nullopt;
  Aabb box;
  for (int k = 0; k < 3; ++k) {
    box.min[k] = (0.5 - 0.5 * *aabb_scale - offset[k]) / scale;
    box.max[k] = (0.5 + 0.5 * *aabb_scale - offset[k]) / scale;
  }
  return box;
}

// One frame's intrinsics: the file's shared keys overlaid with the frame's
// own (a frame that gives fl_x or camera_angle_x gives both of its own).
CameraIntrinsics ReadFrameCamera(const Json& root, const Json& frame, const std::string& pointer, Problems& problems,
                                 std::string& model) {
  Json merged = Json::object();
  for (const std::string& key : CameraKeyNames())
    if (root.contains(key)) merged[key] = root[key];
  for (const auto& [fl, angle] : {std::pair{"fl_x", "camera_angle_x"}, std::pair{"fl_y", "camera_angle_y"}})
    if (frame.contains(fl) || frame.contains(angle)) {
      merged.erase(fl);
      merged.erase(angle);
    }
  for (const std::string& key : CameraKeyNames())
    if (frame.contains(key)) merged[key] = frame[key];
  JsonObjectReader reader(merged, pointer, problems);
  CameraIntrinsics camera;
  model = ReadCameraKeys(reader, camera);
  return camera;
}

std::string IgnoredKeysLine(const std::map<std::string, size_t>& root, const std::map<std::string, size_t>& frames,
                            std::vector<std::string>& list) {
  for (const auto& [key, count] : root) list.push_back(key);
  for (const auto& [key, count] : frames)
    list.push_back("frames[]." + key + " (in " + std::to_string(count) + " frame" + (count == 1 ? "" : "s") + ")");
  std::string line;
  for (const std::string& item : list) line += (line.empty() ? "" : ", ") + item;
  return line;
}

}  // namespace

void CheckRigidTransform(const std::array<double, 16>& m, const std::string& pointer, Problems& problems) {
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

namespace {

// What reading the frames shares: the file, the options and the tallies.
struct FramesReading {
  const Json& root;
  bool check_images = true;
  Dataset& dataset;
  Problems& problems;
  size_t missing_files = 0;               // only the first few are listed one by one
  std::map<std::string, size_t> ignored;  // other tools' frame keys -> frames that had them
};

// One frame: path, mask, pose and (with per-frame cameras) intrinsics.
DatasetFrame ReadFrame(const Json& frame_json, size_t index, FramesReading& reading) {
  Dataset& dataset = reading.dataset;
  Problems& problems = reading.problems;
  const std::string pointer = "/frames/" + std::to_string(index);
  JsonObjectReader item(frame_json, pointer, problems);
  SortUnknownKeys(frame_json, FrameKeys(), item, reading.ignored);
  for (const std::string& key : DocumentationKeys()) item.Allow({key.c_str()});
  DatasetFrame frame;
  if (dataset.per_frame_cameras && item.valid()) {
    std::string model;
    frame.camera = ReadFrameCamera(reading.root, frame_json, pointer, problems, model);
    if (index == 0) dataset.camera_model = model;
  }
  for (const std::string& key : CameraKeyNames()) item.Allow({key.c_str()});
  frame.file_path = item.String("file_path");
  frame.mask_file = item.OptionalString("mask_path").value_or("");
  const size_t before = problems.items().size();
  const std::array<double, 16> m = item.Matrix4("transform_matrix");
  if (item.valid() && problems.items().size() == before && item.Has("transform_matrix"))
    CheckRigidTransform(m, item.PointerTo("transform_matrix"), problems);
  item.Finish();
  if (item.valid() && item.Has("file_path") && frame.file_path.empty())
    problems.Add(item.PointerTo("file_path"), "is empty (expected an image path)");
  std::error_code error;
  const auto check_file = [&](const std::string& path, const char* key, const char* what) {
    if (reading.check_images && !fs::is_regular_file(path, error) && reading.missing_files++ < 10)
      problems.Add(item.PointerTo(key), std::string(what) + " " + path + " does not exist");
  };
  if (!frame.file_path.empty()) {
    frame.image_path = ResolveImagePath(dataset.dir, frame.file_path);
    check_file(frame.image_path, "file_path", "image");
  }
  if (!frame.mask_file.empty()) {
    frame.mask_path = ResolvePath(dataset.dir, frame.mask_file);
    check_file(frame.mask_path, "mask_path", "mask");
  }
  frame.T_world_camera = PoseFromTransformMatrix(m);
  return frame;
}

}  // namespace

Dataset ReadDataset(const std::string& transforms_path, bool check_images) {
  const Json doc = ReadJsonFile(transforms_path);
  Problems problems(transforms_path);
  Dataset dataset;
  dataset.path = transforms_path;
  const fs::path parent = fs::path(transforms_path).parent_path();
  dataset.dir = parent.empty() ? "." : parent.string();

  JsonObjectReader root(doc, "", problems);
  std::map<std::string, size_t> ignored_root;
  FramesReading reading{doc, check_images, dataset, problems, 0, {}};
  SortUnknownKeys(doc, RootKeys(), root, ignored_root);
  for (const std::string& key : DocumentationKeys()) root.Allow({key.c_str()});
  if (root.valid()) {
    const Json* frames = root.Array("frames");
    // nerfstudio writes the intrinsics into every frame when the images come
    // from several cameras; the file's own keys are then defaults.
    dataset.per_frame_cameras = frames != nullptr && !frames->empty() && HasCameraKeys((*frames)[0]);
    if (dataset.per_frame_cameras) {
      for (const std::string& key : CameraKeyNames()) root.Allow({key.c_str()});
    } else {
      dataset.camera_model = ReadCameraKeys(root, dataset.camera);
    }
    dataset.aabb = ReadAabb(root);
    dataset.ngp_box = ReadNgpBox(root);
    if (frames != nullptr && frames->size() > kMaxFrames) {
      problems.Add(root.PointerTo("frames"), "has " + std::to_string(frames->size()) + " frames (expected at most " +
                                                 std::to_string(kMaxFrames) + ")");
    } else if (frames != nullptr) {
      dataset.frames.reserve(frames->size());
      for (size_t i = 0; i < frames->size(); ++i) dataset.frames.push_back(ReadFrame((*frames)[i], i, reading));
      if (reading.missing_files > 10)
        problems.Add("/frames", std::to_string(reading.missing_files) + " image and mask files are missing in all");
      if (dataset.per_frame_cameras && !dataset.frames.empty()) dataset.camera = dataset.frames[0].camera;
    }
    root.Finish();
  }
  // A second net under the key checks (they already report these, with pointers).
  if (problems.empty() && !dataset.per_frame_cameras)
    for (const std::string& p : dataset.camera.Validate()) problems.Add("", "camera: " + p);
  if (problems.empty() && dataset.per_frame_cameras)
    for (size_t i = 0; i < dataset.frames.size(); ++i)
      for (const std::string& p : dataset.frames[i].camera.Validate())
        problems.Add("/frames/" + std::to_string(i), "camera: " + p);
  problems.ThrowIfAny();
  const std::string ignored = IgnoredKeysLine(ignored_root, reading.ignored, dataset.ignored_keys);
  if (!ignored.empty()) LogInfo(transforms_path + ": ignored (not used by nerfar): " + ignored);
  return dataset;
}

void WriteDataset(const std::string& transforms_path, const Dataset& dataset) {
  Problems problems(transforms_path);
  for (const std::string& p : dataset.camera.Validate()) problems.Add("camera", p);
  problems.ThrowIfAny();
  Json doc = Json::object();
  if (!dataset.per_frame_cameras) WriteCameraKeys(dataset.camera, dataset.camera_model, doc);
  if (dataset.aabb) {
    const Aabb& b = *dataset.aabb;
    doc["aabb"] = Json::array({Json::array({b.min.x, b.min.y, b.min.z}), Json::array({b.max.x, b.max.y, b.max.z})});
  }
  Json frames = Json::array();
  for (const DatasetFrame& frame : dataset.frames) {
    const std::array<double, 16> m = TransformMatrixFromPose(frame.T_world_camera);
    Json rows = Json::array();
    for (int r = 0; r < 4; ++r) rows.push_back(Json::array({m[r * 4], m[r * 4 + 1], m[r * 4 + 2], m[r * 4 + 3]}));
    Json item{{"file_path", frame.file_path}, {"transform_matrix", rows}};
    if (!frame.mask_file.empty()) item["mask_path"] = frame.mask_file;
    if (dataset.per_frame_cameras) WriteCameraKeys(frame.camera, dataset.camera_model, item);
    frames.push_back(std::move(item));
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
