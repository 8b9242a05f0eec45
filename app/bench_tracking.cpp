// Bench stage "tracking": tag detection + pose time on 1280x720 frames (the
// shared scenes' test views tone-mapped and resized to 1280x720), per
// detector preset, and pose error against the scenes' true poses at 400x300.
#include <time.h>

#include <algorithm>
#include <opencv2/imgproc.hpp>

#include "app/bench.h"
#include "calib/board.h"
#include "calib/core/exr.h"
#include "calib/core/image_io.h"
#include "calib/dataset.h"
#include "render/synth/camera_stream.h"
#include "tracking/tracker.h"

namespace nerfar {

namespace {

// CPU time of the whole process (every thread), seconds: unlike wall time,
// hardly inflated when other jobs share the cores.
double CpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return ts.tv_sec + ts.tv_nsec * 1e-9;
}

// A tracked 1280x720 synthetic stream (render/synth, lamps scene, handheld
// trajectory at 30 frames/s): time per frame with and without region search
// (rendering excluded) and the pose error against the true poses, per
// condition (clean, sensor noise, motion blur).
void BenchStream(const BenchOptions& options, std::vector<BenchFigure>& figures) {
  struct Condition {
    const char* name;
    double noise, shutter_s;
  };
  const int frames = options.quick ? 8 : 30;
  for (const Condition& c : {Condition{"clean", 0, 0}, Condition{"noise3", 3, 0}, Condition{"blur8ms", 0, 0.008}}) {
    synth::CameraStreamOptions so;
    so.width = 1280;
    so.height = 720;
    so.samples_per_pixel = c.shutter_s > 0 ? 4 : 2;
    so.noise_sigma = c.noise;
    so.shutter_s = c.shutter_s;
    synth::SyntheticCameraSource source(so);
    std::vector<Frame> stream;
    // From 9 s on, 3 to 5 tags are in view (fewer at the start).
    for (int i = 0; i < frames; ++i) stream.push_back(source.RenderFrame(9.0 + i / so.fps, i));
    for (const char* preset : {"fast", "balanced"}) {
      for (bool regions : {false, true}) {
        if (regions && std::string(c.name) != "clean") continue;
        TrackerOptions o = TrackerOptions::Preset(preset);
        o.detector.threads = 2;
        o.filter.kind = FilterKind::kNone;
        o.region_search = regions;
        Tracker tracker(source.board(), source.camera(), o);
        std::vector<double> ms, rot, trans;
        int region_frames = 0;
        double mean = 0, cpu_mean = 0, fraction = 0;
        for (const Frame& f : stream) {
          const double t0 = NowSeconds(), c0 = CpuSeconds();
          const TrackResult r = tracker.Process(f);
          ms.push_back((NowSeconds() - t0) * 1e3);
          mean += ms.back() / stream.size();
          cpu_mean += (CpuSeconds() - c0) * 1e3 / stream.size();
          fraction += r.searched_fraction / stream.size();
          region_frames += r.region_searched;
          if (!r.measured) continue;
          rot.push_back(RotationAngleBetween(r.T_world_camera.rotation, f.T_world_camera_true->rotation) * 180 / kPi);
          trans.push_back(Length(r.T_world_camera.translation - f.T_world_camera_true->translation) * 1e3);
        }
        const std::string name = std::string("stream_") + c.name + "_" + preset + (regions ? "_regions" : "_full");
        const std::string note = std::to_string(rot.size()) + "/" + std::to_string(stream.size()) + " frames posed, " +
                                 std::to_string(region_frames) + " region-searched";
        figures.push_back({name + "_median_ms", MedianOf(ms), "ms", note});
        figures.push_back({name + "_mean_ms", mean, "ms", "1280x720, detector threads 2"});
        figures.push_back({name + "_cpu_mean_ms", cpu_mean, "ms", "CPU time of all threads, per frame"});
        figures.push_back({name + "_searched_fraction", fraction, "", "mean searched area / frame area"});
        figures.push_back({name + "_rot_deg", MedianOf(rot), "deg", "median vs true pose"});
        figures.push_back({name + "_trans_mm", MedianOf(trans), "mm", "median vs true pose"});
      }
    }
  }
}

}  // namespace

std::vector<BenchFigure> BenchTracking(const BenchOptions& options) {
  std::vector<BenchFigure> figures;
  BenchStream(options, figures);
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
      TagDetector detector(o.detector);
      size_t k = 0;
      std::vector<double> prepare, search, refine, pose;
      const double ms = MedianMilliseconds(
          [&] {
            Frame frame;
            frame.image = large[k++ % large.size()];
            const TrackResult r = tracker.Process(frame);
            pose.push_back(r.pose_ms);
          },
          options.quick ? 3 : 16);
      for (const Image8& image : large) {
        std::vector<TagDetection> found;
        detector.Detect(image, found);
        prepare.push_back(detector.last_timings().prepare_ms);
        search.push_back(detector.last_timings().search_ms);
        refine.push_back(detector.last_timings().refine_ms);
      }
      const std::string name = std::string("track_1280x720_") + preset + "_t" + std::to_string(threads);
      figures.push_back({name + "_ms", ms, "ms", "detect + pose, lamps test views resized"});
      figures.push_back({name + "_prepare_ms", MedianOf(prepare), "ms", "grey conversion"});
      figures.push_back({name + "_search_ms", MedianOf(search), "ms", "library quad search + decode"});
      figures.push_back({name + "_refine_ms", MedianOf(refine), "ms", "sub-pixel edge re-fit"});
      figures.push_back({name + "_pose_ms", MedianOf(pose), "ms", "board pose"});
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
