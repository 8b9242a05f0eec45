// nerfar import SRC -o DST [--board B] [--up auto|file] [--distance M | --scale F] [--test-every K]
// A capture made with other tools (COLMAP, instant-ngp, nerfstudio, any
// transforms.json) brought into nerfar's world frame: metres, z up. With the
// board's tags in view (board.json) the frame is the board's: tags found in
// the images (tracking's detector), their corners triangulated from the
// file's poses and fitted to board.json by a similarity (scale, turn,
// origin), so the table is z = 0. Without tags: up from the cameras (--up
// auto), the unit from a known length (--distance or --scale), the origin at
// the point the cameras look at. DST gets transforms_train/test.json pointing
// at SRC's images, camera.json and board.json when known, and the NeRF box;
// the report says how each was found.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>

#include "app/cli.h"
#include "app/command_files.h"
#include "app/commands.h"
#include "calib/board.h"
#include "calib/camera_file.h"
#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "calib/core/image_io.h"
#include "calib/core/log.h"
#include "calib/dataset.h"
#include "calib/linear_image.h"
#include "calib/scene_box.h"
#include "calib/scene_frame.h"
#include "tracking/tag_detector.h"

namespace nerfar {
namespace {

namespace fs = std::filesystem;

struct ImportJob {
  std::string source, output, board_path, camera_path, up = "auto";
  double distance_m = 0, scale = 0;
  int test_every = 10;
};

// Board corners seen in fewer views than this are not triangulated (two rays
// always meet somewhere; a third checks them).
constexpr int kMinViewsPerCorner = 3;
// Below this image width the board's tags are a few pixels per cell: detect
// on the image upsampled twice (as for the shared scenes' 400x300 views).
constexpr int kUpsampleBelowWidth = 1000;

std::string Format(const char* format, double a, double b = 0, double c = 0) {
  char buffer[160];
  std::snprintf(buffer, sizeof buffer, format, a, b, c);
  return buffer;
}

struct Splits {
  Dataset train, test;
  std::string how;
};

// SRC's train and test files, or transforms.json with every K-th frame held out.
Splits ReadSplits(const std::string& source, int test_every) {
  Splits splits;
  const std::string train_path = DatasetSplitPath(source, "train"), test_path = DatasetSplitPath(source, "test");
  splits.train = ReadDataset(train_path);
  std::error_code error;
  if (fs::is_regular_file(test_path, error)) {
    splits.test = ReadDataset(test_path);
    splits.how = "train and test frames as " + source + " splits them";
    return splits;
  }
  splits.test = splits.train;
  splits.test.frames.clear();
  std::vector<DatasetFrame> train;
  for (size_t i = 0; i < splits.train.frames.size(); ++i)
    (test_every > 0 && i % size_t(test_every) == size_t(test_every) - 1 ? splits.test.frames : train)
        .push_back(splits.train.frames[i]);
  splits.train.frames = std::move(train);
  splits.how = "every " + std::to_string(test_every) + "th frame of " + train_path + " held out for testing";
  return splits;
}

// The rays from the camera through every detected corner of the board's tags,
// per (tag id, corner), over all frames.
std::map<std::pair<int, int>, std::pair<std::vector<Vec3>, std::vector<Vec3>>> CornerRays(const Dataset& set,
                                                                                          const Board& board) {
  TagDetectorOptions options = TagDetectorOptions::Preset("accurate");
  options.family = board.family;
  options.response = "display";
  std::map<std::pair<int, int>, std::pair<std::vector<Vec3>, std::vector<Vec3>>> rays;
  const Linearisation linearisation = DatasetLinearisation(set.dir);
  for (const DatasetFrame& frame : set.frames) {
    const CameraIntrinsics& camera = set.CameraOf(frame);
    options.upsample = camera.width < kUpsampleBelowWidth ? 2 : 1;
    TagDetector detector(options);
    const ImageF linear = ReadLinearImage(frame.image_path, linearisation).rgb;
    std::vector<TagDetection> detections;
    detector.Detect(ToneMapToDisplay(linear, ExposureForPercentile(linear)), detections);
    for (const TagDetection& d : detections) {
      if (board.FindTag(d.id) == nullptr) continue;
      for (int k = 0; k < 4; ++k) {
        auto& [origins, directions] = rays[{d.id, k}];
        origins.push_back(frame.T_world_camera.translation);
        directions.push_back(frame.T_world_camera.Rotate(Unproject(camera, d.corners[k])));
      }
    }
  }
  return rays;
}

// The board's frame: its tags' corners triangulated in the file's frame and
// fitted to board.json.
Similarity FrameFromBoard(const Dataset& set, const Board& board, std::string& how) {
  std::vector<Vec3> triangulated, on_board;
  std::map<int, int> tags;
  for (const auto& [key, lines] : CornerRays(set, board)) {
    Vec3 point;
    if (int(lines.first.size()) < kMinViewsPerCorner || !ClosestPointToLines(lines.first, lines.second, point))
      continue;
    triangulated.push_back(point);
    on_board.push_back(board.FindTag(key.first)->corners[key.second]);
    ++tags[key.first];
  }
  if (tags.size() < 2)
    ThrowInputError(set.path, "the board's tags were found in too few views (" + std::to_string(tags.size()) +
                                  " tags with corners in " + std::to_string(kMinViewsPerCorner) +
                                  " views or more; expected 2 or more): check --board, or import without it "
                                  "(--up auto with --distance)");
  double rms = 0;
  const Similarity s = FitSimilarity(triangulated, on_board, &rms);
  how = "frame and scale from the board: " + std::to_string(tags.size()) + " tags, " +
        std::to_string(triangulated.size()) + " corners triangulated" +
        Format(", 1 file unit = %.6g m, corners off board.json by %.2f mm RMS", s.scale, 1000 * rms);
  if (rms > 0.25 * board.tag_size_m)
    LogWarning("import: the triangulated tags fit board.json poorly (" + Format("%.1f mm RMS", 1000 * rms) +
               "): is it the board in the images, printed at its scale?");
  return s;
}

// Without a board: up from the cameras or the file, the unit from a known
// length or the file, the origin where the cameras look.
Similarity FrameFromCameras(const Dataset& set, const ImportJob& job, std::string& how) {
  std::vector<Pose> poses;
  for (const DatasetFrame& f : set.frames) poses.push_back(f.T_world_camera);
  Similarity s;
  if (job.up == "auto") {
    const Vec3 up = UpFromCameras(poses);
    s.rotation = RotationBetween(up, {0, 0, 1});
    how = "up from the cameras (perpendicular to their image-right axes: held without roll), " +
          Format("(%.3f, %.3f, %.3f)", up.x, up.y, up.z) + " in the file";
  } else {
    how = "up as in the file (+z)";
  }
  Vec3 target;
  if (!LookAtPoint(poses, target))
    ThrowInputError(set.path, "the cameras do not look at a common point (fewer than 2 frames or parallel axes)");
  std::vector<double> distances;
  for (const Pose& pose : poses) distances.push_back(Length(pose.translation - target));
  std::nth_element(distances.begin(), distances.begin() + distances.size() / 2, distances.end());
  const double median = distances[distances.size() / 2];
  if (job.scale > 0) {
    s.scale = job.scale;
    how += Format("; scale %.6g m per file unit (--scale)", s.scale);
  } else if (job.distance_m > 0) {
    s.scale = job.distance_m / median;
    how += Format("; scale from --distance: the median camera is %.4g file units from what they look at, %.4g m",
                  median, job.distance_m);
  } else {
    how += Format(
        "; no scale known: file units taken as metres (the median camera is %.4g units from what they "
        "look at; give --distance or a board)",
        median);
    if (median < 0.2 || median > 5)
      LogWarning("import: a tabletop capture is 0.2-5 m from its cameras; this one " + Format("%.3g", median) +
                 " file units: the unit is probably not the metre (give --distance M or --board)");
  }
  s.translation = s.rotation * target * (-s.scale);
  how += "; origin at the point the cameras look at (z = 0 there, not at the table)";
  return s;
}

// A frame's paths as seen from DST (the images stay where they are).
void PointPathsFrom(const std::string& dst, Dataset& set) {
  const fs::path base = fs::absolute(dst);
  for (DatasetFrame& f : set.frames) {
    f.file_path = fs::absolute(f.image_path).lexically_relative(base).string();
    if (!f.mask_path.empty()) f.mask_file = fs::absolute(f.mask_path).lexically_relative(base).string();
  }
  set.dir = dst;
}

}  // namespace

int RunImport(const CommandArgs& args) {
  ImportJob job;
  ArgParser parser("import", "Bring a capture made with other tools into nerfar's frame (metres, z up, a NeRF box).");
  parser.Positional("SRC", &job.source, "folder with transforms.json (instant-ngp, nerfstudio, COLMAP conversions)");
  parser.Option("-o", &job.output, "DST", "dataset folder to write (the images stay in SRC)");
  parser.Required("-o");
  parser.Option("--board", &job.board_path, "B", "board.json of tags seen in the images: frame, scale and box from it");
  parser.Option("--up", &job.up, "U", "without a board: auto (default: from the cameras) or file (keep the file's +z)");
  parser.Option("--distance", &job.distance_m, "M", "without a board: the median camera-to-subject distance, metres");
  parser.Option("--scale", &job.scale, "F", "without a board: metres per file unit");
  parser.Option("--camera", &job.camera_path, "C", "camera.json with the camera's response (default SRC/camera.json)");
  parser.Option("--test-every", &job.test_every, "K",
                "without a test split: every K-th frame is held out (default 10)");
  parser.Epilog(
      "Then: nerfar train DST -o scene.nerf\nExample: nerfar import ~/captures/mug -o mug --up auto --distance 0.6");
  if (!parser.Parse(args)) return 0;
  Problems usage("nerfar import");
  if (job.up != "auto" && job.up != "file") usage.Add("--up", "'" + job.up + "' (expected auto or file)");
  if (job.distance_m < 0 || job.scale < 0) usage.Add("--distance, --scale", "must be > 0");
  if (job.distance_m > 0 && job.scale > 0) usage.Add("--distance, --scale", "give one of them");
  if (!job.board_path.empty() && (job.distance_m > 0 || job.scale > 0 || job.up != "auto"))
    usage.Add("--board", "sets frame and scale itself (expected no --up, --distance or --scale with it)");
  if (job.test_every < 2) usage.Add("--test-every", "must be 2 or more");
  usage.ThrowIfAny();

  Splits splits = ReadSplits(job.source, job.test_every);
  std::optional<Board> board;
  if (!job.board_path.empty()) board = ReadBoard(job.board_path);
  std::string frame_how;
  Dataset all = splits.train;
  all.frames.insert(all.frames.end(), splits.test.frames.begin(), splits.test.frames.end());
  const Similarity s = board ? FrameFromBoard(all, *board, frame_how) : FrameFromCameras(all, job, frame_how);
  Dataset train = TransformDataset(splits.train, s), test = TransformDataset(splits.test, s);
  std::string box_how = "box: the file's aabb, moved";
  if (!train.aabb) {
    const SceneBox box = DeriveSceneBox(train, board ? &*board : nullptr);
    train.aabb = box.box;
    box_how = box.how;
  }
  test.aabb = train.aabb;

  const fs::path dst(job.output);
  const std::string camera_path =
      !job.camera_path.empty() ? job.camera_path : (fs::path(job.source) / "camera.json").string();
  CheckOutputsSpareInputs(
      FilesIn(job.output, {"transforms_train.json", "transforms_test.json", "camera.json", "board.json"}),
      Paths(DatasetInputs(splits.train), DatasetInputs(splits.test), camera_path, job.board_path));
  MakeDirectories(job.output);
  PointPathsFrom(job.output, train);
  PointPathsFrom(job.output, test);
  WriteDataset((dst / "transforms_train.json").string(), train);
  WriteDataset((dst / "transforms_test.json").string(), test);
  std::error_code error;
  if (fs::is_regular_file(camera_path, error))
    WriteCameraFile((dst / "camera.json").string(), ReadCameraFile(camera_path));
  if (board) WriteBoard((dst / "board.json").string(), *board);
  std::printf("import: %zu train + %zu test frames (%s) into %s\n  %s\n  %s\n", train.frames.size(), test.frames.size(),
              splits.how.c_str(), job.output.c_str(), frame_how.c_str(), box_how.c_str());
  return 0;
}

}  // namespace nerfar
