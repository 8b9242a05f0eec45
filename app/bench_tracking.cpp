// Bench stage "tracking": tag detection + pose time on 1280x720 frames (the
// shared scenes' test views tone-mapped and resized to 1280x720), per
// detector preset, and pose error against the scenes' true poses at 400x300.
#include <algorithm>
#include <opencv2/imgproc.hpp>

#include "app/bench.h"
#include "calib/board.h"
#include "calib/core/exr.h"
#include "calib/core/image_io.h"
#include "calib/dataset.h"
#include "tracking/tracker.h"

namespace nerfar {

std::vector<BenchFigure> BenchTracking(const BenchOptions& options) {
  std::vector<BenchFigure> figures;
  if (options.scenes_dir.empty()) return figures;
  const std::string dir = options.scenes_dir + "/lamps";
  const Board board = ReadBoard(dir + "/board.json");
  const Dataset dataset = ReadDataset(DatasetSplitPath(dir, "test"));
  std::vector<Image8> small, large;
  for (const DatasetFrame& f : dataset.frames) {
    const ImageF linear = ReadExrRgb(f.image_path);
    small.push_back(ToneMapToDisplay(linear, ExposureForPercentile(linear)));
    cv::Mat in(small.back().height, small.back().width, CV_8UC3, small.back().pixels.data()), out;
    cv::resize(in, out, cv::Size(1280, 720), 0, 0, cv::INTER_CUBIC);
    Image8 big(1280, 720, 3);
    std::copy(out.data, out.data + big.pixels.size(), big.pixels.begin());
    large.push_back(std::move(big));
  }
  for (const char* preset : {"fast", "balanced", "accurate"}) {
    for (int threads : {1, 2}) {
      TrackerOptions o = TrackerOptions::Preset(preset);
      o.detector.threads = threads;
      o.detector.response = "display";
      o.filter.kind = FilterKind::kNone;
      Tracker tracker(board, dataset.camera.Scaled(1280, 720), o);
      size_t k = 0;
      const double ms = MedianMilliseconds(
          [&] {
            Frame frame;
            frame.image = large[k++ % large.size()];
            tracker.Process(frame);
          },
          options.quick ? 3 : 16);
      figures.push_back({std::string("track_1280x720_") + preset + "_t" + std::to_string(threads) + "_ms", ms, "ms",
                         "detect + pose, lamps test views resized"});
    }
    TrackerOptions o = TrackerOptions::Preset(preset);
    o.detector.upsample = 2;
    o.detector.response = "display";
    o.filter.kind = FilterKind::kNone;
    std::vector<double> rot, trans;
    for (size_t i = 0; i < small.size(); ++i) {
      Tracker tracker(board, dataset.camera, o);
      Frame frame;
      frame.image = small[i];
      const TrackResult r = tracker.Process(frame);
      if (!r.measured) continue;
      rot.push_back(RotationAngleBetween(r.T_world_camera.rotation, dataset.frames[i].T_world_camera.rotation) * 180 /
                    kPi);
      trans.push_back(Length(r.T_world_camera.translation - dataset.frames[i].T_world_camera.translation) * 1e3);
    }
    figures.push_back({std::string("lamps_test_median_rot_") + preset + "_deg", MedianOf(rot), "deg",
                       std::to_string(rot.size()) + "/8 views, 400x300 upsampled 2x"});
    figures.push_back({std::string("lamps_test_median_trans_") + preset + "_mm", MedianOf(trans), "mm", ""});
  }
  return figures;
}

}  // namespace nerfar
