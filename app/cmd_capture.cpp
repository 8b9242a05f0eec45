// nerfar capture --source S --board B --camera C -o DATASET [--brackets N --ev-step E]
// A capture session: frames from a camera, video or image folder are tracked
// from the board's tags; sharp frames with a good pose whose viewing
// direction is not yet covered become views. Each view is an exposure
// bracket merged to linear HDR where the camera can change its exposure (a
// single frame through the camera response otherwise; EXR frames of an
// image folder are taken as they are). The dataset (transforms_*.json, EXR
// views) is rewritten after every view, so an interrupted session resumes;
// SIGINT / SIGTERM end it after the view in progress.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "app/cli.h"
#include "app/command_files.h"
#include "app/commands.h"
#include "app/sources.h"
#include "app/stop_signal.h"
#include "calib/board.h"
#include "calib/camera_file.h"
#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "calib/core/image_io.h"
#include "calib/core/json.h"
#include "calib/core/log.h"
#include "calib/dataset.h"
#include "calib/hdr.h"
#include "calib/scene_box.h"
#include "tracking/frame_sources.h"
#include "tracking/tracker.h"

namespace nerfar {
namespace {

namespace fs = std::filesystem;

struct CaptureOptions {
  std::string source, board_path, camera_path, output;
  int views = 100;                  // views to collect (train + test)
  int test_every = 10;              // every k-th view goes to the test split (0: none)
  int brackets = 1;                 // exposures per view (odd counts centre on the base exposure)
  double ev_step = 2.0;             // stops between exposures of a bracket
  double base_exposure_us = 10000;  // exposure of the middle frame where the camera takes manual exposure
  double min_separation_deg = 4;    // a view's direction must be this far from every kept one
  double sharpness_ratio = 0.5;     // frames below this fraction of the median sharpness are blurred
  double max_rms_px = 1.0;          // pose quality needed
  int min_tags = 2;
  int max_frames = 100000;                  // frames read at most
  double aabb_margin_m = kBoardBoxMarginM;  // NeRF box: tag extents grown by this in x and y
  double aabb_height_m = kBoardBoxHeightM;  // NeRF box top (z); bottom at -kBoardBoxBelowM
};

// Variance of the Laplacian of the grey frame: high for sharp frames.
double Sharpness(const Image8& image) {
  const Image8 grey = ToGray(image);
  cv::Mat mat(grey.height, grey.width, CV_8UC1, const_cast<std::uint8_t*>(grey.pixels.data())), laplacian;
  cv::Laplacian(mat, laplacian, CV_32F);
  cv::Scalar mean, stddev;
  cv::meanStdDev(laplacian, mean, stddev);
  return stddev[0] * stddev[0];
}

// Coverage of viewing directions around the board centre: 12 azimuth x 4
// elevation cells (0-15, 15-35, 35-55, 55-90 degrees).
struct DirectionCoverage {
  static constexpr int kAzimuthBins = 12, kElevationBins = 4;
  int counts[kElevationBins][kAzimuthBins] = {};
  std::vector<Vec3> directions;

  static Vec3 DirectionOf(const Pose& T_world_camera, const Vec3& center) {
    return Normalized(T_world_camera.translation - center);
  }
  void Add(const Vec3& direction) {
    directions.push_back(direction);
    const double azimuth = std::atan2(direction.y, direction.x) + kPi;  // 0..2pi
    const double elevation_deg = std::asin(std::clamp(direction.z, -1.0, 1.0)) * 180 / kPi;
    const int a = std::min(kAzimuthBins - 1, static_cast<int>(azimuth / (2 * kPi) * kAzimuthBins));
    const int e = elevation_deg < 15 ? 0 : elevation_deg < 35 ? 1 : elevation_deg < 55 ? 2 : 3;
    counts[e][a]++;
  }
  double MinSeparationDeg(const Vec3& direction) const {
    double best = 180;
    for (const Vec3& d : directions) best = std::min(best, std::acos(std::clamp(Dot(d, direction), -1.0, 1.0)));
    return directions.empty() ? 180 : best * 180 / kPi;
  }
  // Rows from high to low elevation; '.' empty, digits 1-9 views, '#' more.
  std::string Render() const {
    static const char* names[kElevationBins] = {" 0-15", "15-35", "35-55", "55-90"};
    std::string out = "elevation  azimuth -180 .. 180 deg\n";
    for (int e = kElevationBins - 1; e >= 0; --e) {
      out += std::string("  ") + names[e] + "    ";
      for (int a = 0; a < kAzimuthBins; ++a)
        out += counts[e][a] == 0 ? '.' : (counts[e][a] > 9 ? '#' : static_cast<char>('0' + counts[e][a]));
      out += '\n';
    }
    return out;
  }
  int EmptyCells(int min_elevation_bin) const {
    int empty = 0;
    for (int e = min_elevation_bin; e < kElevationBins; ++e)
      for (int a = 0; a < kAzimuthBins; ++a) empty += counts[e][a] == 0;
    return empty;
  }
};

// The folder an image-folder source reads (for the EXR originals), or "".
std::string ImageFolderOf(const std::string& source) {
  const std::string path = source.rfind("images:", 0) == 0 ? source.substr(7) : source;
  std::error_code error;
  return fs::is_directory(path, error) ? path : "";
}

class CaptureSession {
 public:
  CaptureSession(const CaptureOptions& options, const CameraFile& camera_file, Board board)
      : options_(options), camera_file_(camera_file), board_(std::move(board)) {
    for (const BoardTag& tag : board_.tags) board_center_ += tag.center * (1.0 / board_.tags.size());
  }

  // Loads an earlier session's views from the output folder, if any.
  void Resume() {
    const std::string train = options_.output + "/transforms_train.json";
    if (!fs::exists(train)) return;
    for (const std::string split : {"train", "test"}) {
      const std::string path = options_.output + "/transforms_" + split + ".json";
      if (!fs::exists(path)) continue;
      Dataset part = ReadDataset(path, true);
      for (DatasetFrame& frame : part.frames) {
        coverage_.Add(DirectionCoverage::DirectionOf(frame.T_world_camera, board_center_));
        (split == "train" ? train_ : test_).push_back(frame);
      }
    }
    const std::string log_path = options_.output + "/capture_log.json";
    if (fs::exists(log_path)) {
      const Json log = ReadJsonFile(log_path);
      Problems problems(log_path);
      JsonObjectReader root(log, "", problems);
      if (const Json* views = root.Array("views")) {
        for (size_t i = 0; i < views->size(); ++i) {
          JsonObjectReader view((*views)[i], "/views/" + std::to_string(i), problems);
          ViewRecord record;
          record.file_path = view.String("file_path");
          record.source_frame = view.String("source_frame");
          record.frame_index = view.Integer("frame_index", 0, 1LL << 62);
          record.t_ns = view.Integer("t_ns", -(1LL << 62), 1LL << 62);
          record.rms_px = view.Number("rms_px");
          record.tags = static_cast<int>(view.Integer("tags", 0, 100000));
          view.Finish();
          log_.push_back(record);
        }
      }
      root.Finish();
      problems.ThrowIfAny();
    }
    LogInfo("capture: resuming with " + std::to_string(ViewCount()) + " views from " + options_.output);
  }

  int ViewCount() const { return static_cast<int>(train_.size() + test_.size()); }
  const DirectionCoverage& coverage() const { return coverage_; }

  // Decides whether a tracked frame becomes a view; returns the reason it does not ("" when it does).
  std::string Consider(const Frame& frame, const TrackResult& track) {
    if (!track.measured) return "no pose";
    if (track.tags_used < options_.min_tags) return "too few tags";
    if (track.rms_px > options_.max_rms_px) return "poor pose";
    const double sharpness = Sharpness(frame.image);
    sharpness_history_.push_back(sharpness);
    std::vector<double> sorted = sharpness_history_;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    if (sharpness < options_.sharpness_ratio * sorted[sorted.size() / 2]) return "blurred";
    const Vec3 direction = DirectionCoverage::DirectionOf(track.T_world_camera_raw, board_center_);
    if (coverage_.MinSeparationDeg(direction) < options_.min_separation_deg) return "direction already covered";
    return "";
  }

  // Where each view came from (source frame, time, pose quality), written as
  // DATASET/capture_log.json beside the splits: the session's record.
  struct ViewRecord {
    std::string file_path, source_frame;
    std::int64_t frame_index = 0, t_ns = 0;
    double rms_px = 0;
    int tags = 0;
  };

  void AddView(const ImageF& hdr, const Pose& T_world_camera, const Frame& source_frame, const TrackResult& track) {
    const int index = ViewCount();
    const bool test = options_.test_every > 0 && index % options_.test_every == options_.test_every - 1;
    std::vector<DatasetFrame>& split = test ? test_ : train_;
    char name[32];
    std::snprintf(name, sizeof name, "r_%03zu.exr", split.size());
    const std::string folder = test ? "test" : "train";
    MakeDirectories(options_.output + "/" + folder);
    DatasetFrame frame;
    frame.file_path = folder + "/" + name;
    frame.image_path = options_.output + "/" + frame.file_path;
    frame.T_world_camera = T_world_camera;
    WriteExrRgb(frame.image_path, hdr);
    split.push_back(frame);
    coverage_.Add(DirectionCoverage::DirectionOf(T_world_camera, board_center_));
    log_.push_back(
        {frame.file_path, source_frame.name, source_frame.index, source_frame.t_ns, track.rms_px, track.tags_used});
    WriteSplits(hdr.width, hdr.height);
    WriteLog();
  }

 private:
  void WriteSplits(int width, int height) {
    Dataset dataset;
    dataset.dir = options_.output;
    dataset.camera = camera_file_.camera;
    if (dataset.camera.width != width || dataset.camera.height != height)
      dataset.camera = dataset.camera.Scaled(width, height);
    dataset.camera_model = camera_file_.camera_model;
    dataset.aabb = BoxAroundBoard(board_, options_.aabb_margin_m, options_.aabb_height_m);
    dataset.frames = train_;
    WriteDataset(options_.output + "/transforms_train.json", dataset);
    WriteDataset(options_.output + "/transforms.json", dataset);
    dataset.frames = test_;
    WriteDataset(options_.output + "/transforms_test.json", dataset);
  }

  void WriteLog() const {
    Json views = Json::array();
    for (const ViewRecord& r : log_)
      views.push_back({{"file_path", r.file_path},
                       {"source_frame", r.source_frame},
                       {"frame_index", r.frame_index},
                       {"t_ns", r.t_ns},
                       {"rms_px", r.rms_px},
                       {"tags", r.tags}});
    WriteJsonFile(options_.output + "/capture_log.json", Json{{"views", views}});
  }

  CaptureOptions options_;
  std::vector<ViewRecord> log_;
  CameraFile camera_file_;
  Board board_;
  Vec3 board_center_;
  DirectionCoverage coverage_;
  std::vector<DatasetFrame> train_, test_;
  std::vector<double> sharpness_history_;
};

// Linear HDR of a view: the EXR original of an image folder, the merged
// bracket, or the single frame through the camera response (sRGB when the
// camera has none recorded).
ImageF LinearView(const Frame& frame, const std::string& image_folder, const CameraFile& camera,
                  const std::vector<ExposureFrame>& bracket) {
  if (!image_folder.empty() && fs::path(frame.name).extension() == ".exr")
    return ReadExrRgb(image_folder + "/" + frame.name);
  if (bracket.size() > 1 && camera.response) return MergeExposures(bracket, *camera.response);
  ImageF linear =
      camera.response ? MergeExposures({{frame.image, 1.0}}, *camera.response) : DisplayToLinear(frame.image);
  if (linear.channels == 1) {
    ImageF rgb(linear.width, linear.height, 3);
    for (size_t p = 0; p < linear.PixelCount(); ++p)
      rgb.pixels[3 * p] = rgb.pixels[3 * p + 1] = rgb.pixels[3 * p + 2] = linear.pixels[p];
    return rgb;
  }
  return linear;
}

}  // namespace

int RunCapture(const CommandArgs& args) {
  CaptureOptions options;
  ArgParser parser("capture", "A capture session: tracked, sharp, well-spread HDR views written as a dataset.");
  parser.Option("--source", &options.source, "S", "camera, video or image folder");
  parser.Option("--board", &options.board_path, "B", "board.json of the tags on the table");
  parser.Option("--camera", &options.camera_path, "C", "camera.json from 'nerfar calibrate' or a transforms.json");
  parser.Option("-o", &options.output, "DATASET", "dataset folder to write (resumed if it exists)");
  for (const char* name : {"--source", "--board", "--camera", "-o"}) parser.Required(name);
  parser.Option("--views", &options.views, "N", "views to collect, train + test (default 100)");
  parser.Option("--test-every", &options.test_every, "K", "every K-th view goes to the test split (default 10)");
  parser.Option("--brackets", &options.brackets, "N", "exposures per view where the camera allows (default 1)");
  parser.Option("--ev-step", &options.ev_step, "E", "stops between bracket exposures (default 2)");
  parser.Option("--exposure-us", &options.base_exposure_us, "T", "middle exposure of a bracket (default 10000)");
  parser.Option("--min-separation", &options.min_separation_deg, "DEG",
                "a new view's direction differs this much from every kept one (default 4)");
  parser.Option("--max-frames", &options.max_frames, "N", "frames read at most (default 100000)");
  parser.Option("--height", &options.aabb_height_m, "M", "top of the NeRF box above the table (default 0.6)");
  parser.Epilog(SourceHelp());
  if (!parser.Parse(args)) return 0;
  Problems usage("nerfar capture");
  if (options.views < 1 || options.brackets < 1 || options.brackets > 9 || options.ev_step <= 0 ||
      options.test_every < 0 || options.max_frames < 1)
    usage.Add("", "--views >= 1, --brackets 1..9, --ev-step > 0, --test-every >= 0, --max-frames >= 1");
  usage.ThrowIfAny();

  CheckOutputsSpareInputs(CaptureOutputs(options.output, options.views),
                          Paths(options.board_path, options.camera_path, SourceInputs(options.source)));
  const Board board = ReadBoard(options.board_path);
  const CameraFile camera = ReadCameraFile(options.camera_path);
  MakeDirectories(options.output);
  CaptureSession session(options, camera, board);
  session.Resume();
  std::unique_ptr<FrameSource> source = OpenSource(options.source);
  LogInfo("capture: " + source->Describe());
  const std::string image_folder = ImageFolderOf(options.source);
  bool brackets = options.brackets > 1 && source->SetExposure(options.base_exposure_us);
  if (options.brackets > 1 && !brackets)
    LogWarning("capture: " + source->Describe() + " cannot set its exposure; views are single frames");
  if (brackets && !camera.response)
    LogWarning("capture: " + options.camera_path + " has no camera response; brackets are merged as linear");

  TrackerOptions tracker_options = TrackerOptions::Preset("accurate");
  tracker_options.filter = PoseFilterOptions::Preset("none");
  tracker_options.confirm_frames = 0;
  Tracker tracker(board, camera.camera, tracker_options);
  std::map<std::string, int> skipped;
  Progress progress("capture", static_cast<size_t>(options.views));
  Frame frame;
  int frames_read = 0;
  const StopScope stop_scope;  // a signal ends the session after the view in progress
  while (session.ViewCount() < options.views && frames_read < options.max_frames && !StopRequested()) {
    const FrameStatus status = source->Next(frame, 1000);
    if (status == FrameStatus::kEndOfStream) break;
    if (status != FrameStatus::kOk) {
      tracker.MarkLost(FrameStatusName(status));
      skipped[FrameStatusName(status)]++;
      if (status == FrameStatus::kLost) break;
      continue;
    }
    ++frames_read;
    const TrackResult track = tracker.Process(frame);
    const std::string reason = session.Consider(frame, track);
    if (!reason.empty()) {
      skipped[reason]++;
      continue;
    }
    std::vector<ExposureFrame> bracket;
    if (brackets) {
      // Exposures centred on the base one; the pose is the base frame's.
      for (int b = 0; b < options.brackets; ++b) {
        const double ev = options.ev_step * (b - (options.brackets - 1) / 2.0);
        const double exposure_us = options.base_exposure_us * std::pow(2.0, ev);
        Frame shot;
        if (ev == 0) {
          bracket.push_back({frame.image, exposure_us});
        } else if (source->SetExposure(exposure_us) && source->Next(shot, 1000) == FrameStatus::kOk) {
          bracket.push_back({shot.image, exposure_us});
        }
      }
      source->SetExposure(options.base_exposure_us);
    }
    session.AddView(LinearView(frame, image_folder, camera, bracket), track.T_world_camera_raw, frame, track);
    progress.Update(static_cast<size_t>(session.ViewCount()),
                    std::to_string(session.coverage().EmptyCells(1)) + " direction cells above 15 deg empty");
  }
  progress.Finish(std::to_string(session.ViewCount()) + " views from " + std::to_string(frames_read) + " frames");
  std::printf("views: %d (wanted %d)\n%s", session.ViewCount(), options.views, session.coverage().Render().c_str());
  for (const auto& [reason, count] : skipped) std::printf("  frames skipped (%s): %d\n", reason.c_str(), count);
  std::printf("wrote %s/transforms_train.json and transforms_test.json\n", options.output.c_str());
  if (StopRequested()) {
    LogInfo("capture: stopped by a signal; run the same command to resume");
    return StopExitCode();
  }
  if (session.ViewCount() == 0) {
    std::fprintf(stderr, "error: capture: no frame gave a usable view (see the reasons above)\n");
    return 1;
  }
  return 0;
}

}  // namespace nerfar
