// The files each command reads and writes, listed before any work so that
// CheckOutputsSpareInputs (calib/core/output_guard.h) can refuse to write
// over an input. A command calls it once, e.g.
//   CheckOutputsSpareInputs(RenderOutputs(output, dataset), Paths(model, DatasetInputs(dataset)));
// The output lists name every file the command may write (those it writes
// only with some options too): keep them in step with the commands.
#pragma once

#include <string>
#include <type_traits>
#include <vector>

#include "calib/core/output_guard.h"
#include "calib/dataset.h"

namespace nerfar {

using PathList = std::vector<std::string>;

// Paths and lists of paths, one after the other, in one list.
template <typename... Parts>
PathList Paths(const Parts&... parts) {
  PathList all;
  const auto add = [&all](const auto& part) {
    if constexpr (std::is_convertible_v<decltype(part), const std::string&>)
      all.push_back(part);
    else
      all.insert(all.end(), part.begin(), part.end());
  };
  (add(parts), ...);
  return all;
}

// What a frame-source string reads: the video file or the image folder
// ("video:FILE", "images:DIR" or a bare path); nothing for devices, streams
// and the synthetic camera.
PathList SourceInputs(const std::string& source);

// A dataset split's transforms file and its images.
PathList DatasetInputs(const Dataset& dataset);
// Every split present in a dataset folder (train, test, val): transforms files and images.
PathList DatasetFolderInputs(const std::string& dir);

// `nerfar insert -o FOLDER`: per view <name>.exr, .png, _object, _alpha,
// _kappa .exr, _sheet.png; probe.exr (probe_<i>.exr per further object),
// probe_samples.exr, probe_opacity.exr, options.json, timings.json, report.json.
PathList InsertOutputs(const std::string& folder, const Dataset& dataset, size_t objects);
// `nerfar insert --orbit | --camera-path -o FOLDER` with `views` views:
// frame_NNNN.png, video.mp4, probe.exr (probe_<i>.exr per further object),
// options.json, timings.json.
PathList VideoOutputs(const std::string& folder, size_t views, size_t objects);
// A video's frame i without its extension ("frame_0007"), and the printf
// pattern of their PNG files.
std::string VideoFrameName(size_t i);
inline const char* VideoFramePattern() { return "frame_%04d.png"; }
// The ground truth `nerfar insert --truth DIR` reads: DIR and the folder above it (bg_XXX.exr).
PathList InsertTruthInputs(const std::string& truth_dir);

// `nerfar render -o FOLDER`: per view <name>.exr, _depth, _surface_depth,
// _opacity .exr, .png; report.json.
PathList RenderOutputs(const std::string& folder, const Dataset& dataset);
// What `nerfar render` reads besides the model and the split: the scene's
// insert/ references (bg_XXX.exr; per object depth_XXX.exr, mask_XXX.png).
PathList RenderReferenceInputs(const std::string& dataset_dir);

// `nerfar capture -o FOLDER` with at most `views` views: the transforms
// files, capture_log.json and {train,test}/r_NNN.exr.
PathList CaptureOutputs(const std::string& folder, int views);

// `nerfar live`'s session folder: session.json, report.json, report.png, report.html,
// last_ar.png, last_alongside.png, last_layers.png, recording.mp4.
PathList LiveSessionOutputs(const std::string& session_dir);

}  // namespace nerfar
