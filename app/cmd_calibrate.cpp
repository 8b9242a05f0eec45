// nerfar calibrate --board B (--images DIR | --source S) -o camera.json
// Joins tag detection (tracking/) with intrinsics from correspondences
// (calib/intrinsics.h): every frame's detected board corners become one
// calibration view. On a live source it guides the user (coverage and what
// is missing) until the gate passes or the frame budget runs out.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <string>

#include "app/cli.h"
#include "app/command_files.h"
#include "app/commands.h"
#include "app/sources.h"
#include "calib/board.h"
#include "calib/camera_file.h"
#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "calib/core/log.h"
#include "calib/intrinsics.h"
#include "tracking/frame_sources.h"
#include "tracking/tag_detector.h"

namespace nerfar {
namespace {

struct CalibrateJob {
  std::string board_path, images_dir, source, output;
  int max_frames = 600;  // frames read from a live source before giving up
  int every = 1;         // use every k-th frame (live sources repeat views)
  int max_views = 60;    // views kept (more adds little and slows the fit)
  int min_tags = 2;      // tags a frame needs to count as a view
  bool fit_k3 = false;
  bool no_tangential = false;  // lens known to be centred: p1 = p2 = 0
  bool square_pixels = false;  // fx = fy
  double max_rms_px = 0.5;
  std::string detector_preset = "accurate";
};

// The detected corners of board tags as one calibration view (board frame).
// Tags cut by the image border are left out: their outer corners are
// extrapolated by the detector and may even lie outside the image.
bool ViewFromDetections(const std::vector<TagDetection>& detections, const Board& board, int width, int height,
                        int min_tags, CalibrationView& view) {
  const auto inside = [&](const Vec2& p) { return p.x >= 1 && p.y >= 1 && p.x <= width - 1 && p.y <= height - 1; };
  int tags = 0;
  for (const TagDetection& detection : detections) {
    const BoardTag* tag = board.FindTag(detection.id);
    if (tag == nullptr || !std::all_of(detection.corners.begin(), detection.corners.end(), inside)) continue;
    ++tags;
    for (int k = 0; k < 4; ++k) {
      view.object_points.push_back(tag->corners[k]);
      view.image_points.push_back(detection.corners[k]);
    }
  }
  return tags >= min_tags;
}

// camera.json's content: the intrinsics and the record of how well they fit.
CameraFile CameraFileOf(const IntrinsicsResult& result) {
  CameraFile file;
  file.camera = result.camera;
  CalibrationRecord record;
  record.rms_px = result.rms_px;
  record.views_used = result.views_used;
  for (const ViewReport& v : result.views) record.views_rejected += v.rejected ? 1 : 0;
  record.coverage = result.coverage.FractionCovered();
  record.sigma_fx = result.sigma.fx;
  record.sigma_fy = result.sigma.fy;
  record.sigma_cx = result.sigma.cx;
  record.sigma_cy = result.sigma.cy;
  file.calibration = record;
  return file;
}

// The intrinsics with their uncertainties, the errors, the coverage map and the verdict.
void PrintCalibration(const IntrinsicsResult& result, const CalibrationRecord& record, const std::string& output) {
  const CameraIntrinsics& c = result.camera;
  std::printf("camera %dx%d  fx %.2f ± %.2f  fy %.2f ± %.2f  cx %.2f ± %.2f  cy %.2f ± %.2f\n", c.width, c.height, c.fx,
              result.sigma.fx, c.fy, result.sigma.fy, c.cx, result.sigma.cx, c.cy, result.sigma.cy);
  std::printf("distortion k1 %.5f k2 %.5f p1 %.5f p2 %.5f k3 %.5f\n", c.k1, c.k2, c.p1, c.p2, c.k3);
  std::printf("RMS %.3f px over %d views (%d rejected)\n", result.rms_px, result.views_used, record.views_rejected);
  for (const ViewReport& v : result.views)
    if (v.rejected || GetLogLevel() == LogLevel::kVerbose)
      std::printf("  %-24s %4d points  RMS %.3f px%s\n", v.name.c_str(), v.points, v.rms_px,
                  v.rejected ? "  rejected" : "");
  std::printf("coverage (%.0f%% of cells):\n%s", record.coverage * 100, result.coverage.Render().c_str());
  std::printf("%s\nwrote %s\n", result.verdict.c_str(), output.c_str());
}

}  // namespace

int RunCalibrate(const CommandArgs& args) {
  CalibrateJob job;
  ArgParser parser("calibrate", "Camera intrinsics and distortion from views of an AprilTag board.");
  parser.Option("--board", &job.board_path, "B", "board.json of the tag board");
  parser.Option("--images", &job.images_dir, "DIR", "a folder of board images (name order)");
  parser.Option("--source", &job.source, "S", "a live or video source instead of --images");
  parser.Option("-o", &job.output, "FILE", "camera.json to write");
  parser.Required("--board");
  parser.Required("-o");
  parser.Option("--max-frames", &job.max_frames, "N", "frames read from --source at most (default 600)");
  parser.Option("--every", &job.every, "K", "use every K-th frame of --source (default 1)");
  parser.Option("--max-views", &job.max_views, "N", "views kept for the fit (default 60)");
  parser.Option("--min-tags", &job.min_tags, "N", "board tags a view needs (default 2)");
  parser.Flag("--fit-k3", &job.fit_k3, "also fit k3 (wide-angle lenses)");
  parser.Flag("--no-tangential", &job.no_tangential, "keep p1 = p2 = 0 (a centred lens; steadier with few views)");
  parser.Flag("--square-pixels", &job.square_pixels, "force fx = fy (steadier with few views)");
  parser.Option("--max-rms", &job.max_rms_px, "PX", "gate: RMS reprojection error to pass (default 0.5)");
  parser.Option("--detector", &job.detector_preset, "P",
                "tag detector preset fast|balanced|accurate (default accurate)");
  parser.Epilog(SourceHelp() +
                "\nExit code 0 when the calibration passes its gate, 1 when it does not (the file is\n"
                "still written, with the verdict), 2 for bad input.");
  if (!parser.Parse(args)) return 0;
  Problems usage("nerfar calibrate");
  if (job.images_dir.empty() == job.source.empty()) usage.Add("", "give exactly one of --images DIR or --source S");
  if (job.every < 1 || job.max_views < 3 || job.min_tags < 1 || job.max_frames < 1)
    usage.Add("", "--every >= 1, --max-views >= 3, --min-tags >= 1 and --max-frames >= 1 are required");
  usage.ThrowIfAny();
  if (!job.images_dir.empty() && !std::filesystem::is_directory(job.images_dir))
    ThrowInputError(job.images_dir, "no such folder (expected a folder of board images)");
  CheckOutputsSpareInputs({job.output}, Paths(job.board_path, job.images_dir, SourceInputs(job.source)));

  const Board board = ReadBoard(job.board_path);
  TagDetector detector(TagDetectorOptions::Preset(job.detector_preset));
  const bool live = job.images_dir.empty();
  std::unique_ptr<FrameSource> source = OpenSource(live ? job.source : "images:" + job.images_dir);
  LogInfo("calibrate: " + source->Describe());

  IntrinsicsOptions options;
  options.fit_k3 = job.fit_k3;
  options.fit_tangential = !job.no_tangential;
  options.fix_aspect_ratio = job.square_pixels;
  options.max_rms_px = job.max_rms_px;
  std::vector<CalibrationView> views;
  int width = 0, height = 0, frames_read = 0, frames_without_board = 0;
  Progress progress("calibrate", live ? static_cast<size_t>(job.max_frames) : 0);
  Frame frame;
  std::vector<TagDetection> detections;
  while (frames_read < job.max_frames && static_cast<int>(views.size()) < job.max_views) {
    const FrameStatus status = source->Next(frame, 1000);
    if (status == FrameStatus::kEndOfStream) break;
    if (status != FrameStatus::kOk) {
      LogWarning("calibrate: frame skipped (" + std::string(FrameStatusName(status)) + ": " + source->LastError() +
                 ")");
      if (status == FrameStatus::kLost) break;
      continue;
    }
    ++frames_read;
    if ((frames_read - 1) % job.every != 0) continue;
    if (width == 0) {
      width = frame.image.width;
      height = frame.image.height;
    } else if (frame.image.width != width || frame.image.height != height) {
      LogWarning("calibrate: " + frame.name + " is " + std::to_string(frame.image.width) + "x" +
                 std::to_string(frame.image.height) + ", not " + std::to_string(width) + "x" + std::to_string(height) +
                 "; skipped");
      continue;
    }
    detector.Detect(frame.image, detections);
    CalibrationView view;
    view.name = frame.name.empty() ? "frame " + std::to_string(frame.index) : frame.name;
    if (!ViewFromDetections(detections, board, width, height, job.min_tags, view)) {
      ++frames_without_board;
      continue;
    }
    views.push_back(std::move(view));
    std::string status_text = std::to_string(views.size()) + " views";
    if (live && views.size() % 10 == 0) {
      // Guide the user: where in the image corners are still missing.
      std::vector<std::vector<Vec2>> points;
      for (const CalibrationView& v : views) points.push_back(v.image_points);
      const CoverageGrid coverage =
          ComputeCoverage(points, width, height, options.coverage_cols, options.coverage_rows);
      const std::string gaps = coverage.DescribeGaps();
      LogInfo("calibrate: " + std::to_string(views.size()) + " views, coverage " +
              std::to_string(static_cast<int>(coverage.FractionCovered() * 100)) + "%" +
              (gaps.empty() ? "" : "; move the board towards the " + gaps));
    }
    progress.Update(static_cast<size_t>(frames_read), status_text);
  }
  progress.Finish(std::to_string(views.size()) + " views from " + std::to_string(frames_read) + " frames");
  if (views.size() < 3)
    ThrowInputError(live ? job.source : job.images_dir,
                    "only " + std::to_string(views.size()) + " frames show at least " + std::to_string(job.min_tags) +
                        " board tags (expected 3 or more; " + std::to_string(frames_without_board) +
                        " frames had too few)");

  const IntrinsicsResult result = CalibrateIntrinsics(views, width, height, options);
  const CameraFile file = CameraFileOf(result);
  WriteCameraFile(job.output, file);
  PrintCalibration(result, *file.calibration, job.output);
  return result.passed ? 0 : 1;
}

}  // namespace nerfar
