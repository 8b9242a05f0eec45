// nerfar track --source S --board B --camera C [-o poses.json] [--overlay out.mp4]
// Joins a frame source with the tracker; poses.json lists per frame the
// image name, the tracking state and the camera-to-world matrix in the
// transforms.json (OpenGL) convention, so it compares directly with a dataset.
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "app/cli.h"
#include "app/command_files.h"
#include "app/commands.h"
#include "app/sources.h"
#include "calib/board.h"
#include "calib/camera_file.h"
#include "calib/core/json.h"
#include "calib/core/log.h"
#include "calib/core/media.h"
#include "calib/dataset.h"
#include "tracking/frame_sources.h"
#include "tracking/tracker.h"

namespace nerfar {

int RunTrack(const CommandArgs& args) {
  std::string source_name, board_path, camera_path, output, overlay, filter = "constant-velocity", preset = "balanced";
  std::string response, strength = "balanced";
  int upsample = 0, max_frames = 0, full_search_every = 0, threads = 0;
  bool whole_frames = false;
  ArgParser parser("track", "Track the camera pose from the AprilTags of a board, frame by frame.");
  parser.Option("--source", &source_name, "S", "frames: images:DIR, video:FILE, v4l2:/dev/videoN, synthetic, ...");
  parser.Option("--board", &board_path, "B", "board.json");
  parser.Option("--camera", &camera_path, "C", "camera.json or a transforms.json (its intrinsics)");
  for (const char* name : {"--source", "--board", "--camera"}) parser.Required(name);
  parser.Option("-o", &output, "FILE", "write poses.json");
  parser.Option("--overlay", &overlay, "FILE", "write a video with the detections and the state drawn");
  parser.Option("--filter", &filter, "KIND",
                "none | exponential | constant-velocity (default); none for unordered images");
  parser.Option("--preset", &preset, "NAME", "detector preset: fast | balanced (default) | accurate");
  parser.Option("--upsample", &upsample, "N", "1 or 2 (default: 2 for EXR image folders, else 1)");
  parser.Option("--response", &response, "R", "srgb | display | linear (default: display for EXR folders, else srgb)");
  parser.Option("--max-frames", &max_frames, "N", "stop after N frames (0: all)");
  parser.Option("--filter-strength", &strength, "S",
                "smooth | balanced (default) | responsive: less jitter or less latency");
  parser.Flag("--whole-frames", &whole_frames, "search every frame whole (no region search around predicted tags)");
  parser.Option("--full-search-every", &full_search_every, "N",
                "whole-frame search at least every N frames while tracking (default 10)");
  parser.Option("--detector-threads", &threads, "N", "threads of the tag detector (default 1)");
  parser.Epilog(SourceHelp());
  if (!parser.Parse(args)) return 0;

  CheckOutputsSpareInputs({output, overlay}, Paths(board_path, camera_path, SourceInputs(source_name)));
  const Board board = ReadBoard(board_path);
  const CameraFile camera = ReadCameraFile(camera_path);
  bool exr_folder = false;
  {
    std::string dir = source_name.rfind("images:", 0) == 0 ? source_name.substr(7) : source_name;
    std::error_code error;
    if (std::filesystem::is_directory(dir, error))
      for (const auto& entry : std::filesystem::directory_iterator(dir, error))
        exr_folder = exr_folder || entry.path().extension() == ".exr";
  }
  TrackerOptions options = TrackerOptions::Preset(preset);
  options.detector.upsample = upsample > 0 ? upsample : (exr_folder ? 2 : 1);
  options.detector.response = !response.empty() ? response : (exr_folder ? "display" : "srgb");
  options.filter = PoseFilterOptions::Preset(strength);
  options.filter.kind = ParseFilterKind(filter);
  options.region_search = !whole_frames;
  if (full_search_every > 0) options.full_search_every = full_search_every;
  if (threads > 0) options.detector.threads = threads;
  if (options.filter.kind == FilterKind::kNone) options.confirm_frames = 0;
  std::unique_ptr<FrameSource> source = OpenSource(source_name);
  Tracker tracker(board, camera.camera, options);
  LogInfo("track: " + source->Describe() + ", filter " + filter + ", upsample " +
          std::to_string(options.detector.upsample) + ", response " + options.detector.response);

  std::unique_ptr<VideoWriter> video;
  Json frames = Json::array();
  int counts[3] = {0, 0, 0};
  for (int n = 0; max_frames <= 0 || n < max_frames;) {
    Frame frame;
    const FrameStatus status = source->Next(frame, 1000);
    if (status == FrameStatus::kEndOfStream) break;
    if (status == FrameStatus::kTimeout) continue;
    ++n;
    const TrackResult r = status == FrameStatus::kOk ? tracker.Process(frame) : tracker.MarkLost(source->LastError());
    ++counts[static_cast<int>(r.state)];
    Json item = {{"name", frame.name},
                 {"index", frame.index},
                 {"state", TrackingStateName(r.state)},
                 {"measured", r.measured},
                 {"tags_detected", r.tags_detected},
                 {"tags_used", r.tags_used},
                 {"rms_px", r.rms_px}};
    if (!r.note.empty()) item["note"] = r.note;
    if (r.has_pose) {
      const std::array<double, 16> m = TransformMatrixFromPose(r.T_world_camera);
      item["transform_matrix"] = {
          {m[0], m[1], m[2], m[3]}, {m[4], m[5], m[6], m[7]}, {m[8], m[9], m[10], m[11]}, {m[12], m[13], m[14], m[15]}};
    }
    frames.push_back(item);
    if (!overlay.empty() && !frame.image.empty()) {
      Image8 rgb(frame.image.width, frame.image.height, 3);
      for (size_t p = 0; p < rgb.PixelCount(); ++p)
        for (int c = 0; c < 3; ++c)
          rgb.pixels[p * 3 + c] = frame.image.pixels[p * frame.image.channels + (frame.image.channels >= 3 ? c : 0)];
      for (const TagDetection& d : r.detections)
        for (const Vec2& corner : d.corners)
          for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
              const int x = static_cast<int>(corner.x) + dx, y = static_cast<int>(corner.y) + dy;
              if (x < 0 || y < 0 || x >= rgb.width || y >= rgb.height) continue;
              rgb.at(x, y, 0) = 0;
              rgb.at(x, y, 1) = 255;
              rgb.at(x, y, 2) = 0;
            }
      DrawText(rgb, std::string(TrackingStateName(r.state)) + "  tags " + std::to_string(r.tags_used), 4, 4);
      if (!video) video = std::make_unique<VideoWriter>(overlay, rgb.width, rgb.height, 30.0);
      video->Write(rgb);
    }
  }
  if (video) video->Close();
  std::printf("track: %zu frames: %d tracking, %d recovering, %d lost\n", frames.size(), counts[0], counts[2],
              counts[1]);
  if (!output.empty()) {
    WriteJsonFile(output,
                  Json{{"source", source_name},
                       {"board", board_path},
                       {"camera", camera_path},
                       {"convention", "transform_matrix: camera-to-world, OpenGL camera axes (transforms.json)"},
                       {"frames", frames}});
    LogInfo("track: wrote " + output);
  }
  return 0;
}

}  // namespace nerfar
