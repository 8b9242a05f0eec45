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
#include "tracking/aruco_reference.h"
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

// Our detector against OpenCV's aruco (DICT_APRILTAG_36h11) on the same
// frames, both through the same board pose: time (CPU ms per frame) and
// median pose error.
void BenchAruco(const std::vector<Image8>& frames, const std::vector<Pose>& truth, const Board& board,
                const CameraIntrinsics& camera, const std::string& label, std::vector<BenchFigure>& figures) {
  if (!ArucoAvailable()) return;
  struct Method {
    const char* name;
    int kind;  // 0, 4, 5: ours fast, accurate, accurate with the edge re-fit; 1..3: aruco refine none, subpix, apriltag
  };
  for (const Method& m : {Method{"ours_fast", 0}, Method{"ours_accurate", 4}, Method{"ours_accurate_edgefit", 5},
                          Method{"aruco_none", 1}, Method{"aruco_subpix", 2}, Method{"aruco_apriltag", 3}}) {
    TagDetectorOptions ours_options = TagDetectorOptions::Preset(m.kind >= 4 ? "accurate" : "fast");
    ours_options.response = "display";  // both frame sets are display tone-mapped
    ours_options.refine_corners = m.kind == 5;
    TagDetector ours(ours_options);
    TrackerOptions o;
    o.filter.kind = FilterKind::kNone;
    o.confirm_frames = 0;
    std::vector<double> rot, trans, cpu;
    for (size_t i = 0; i < frames.size(); ++i) {
      Tracker tracker(board, camera, o);
      const double c0 = CpuSeconds();
      std::vector<TagDetection> found;
      if (m.kind == 0 || m.kind >= 4) {
        ours.Detect(frames[i], found);
      } else {
        found = DetectWithAruco(frames[i], m.kind == 1   ? ArucoRefine::kNone
                                           : m.kind == 2 ? ArucoRefine::kSubpix
                                                         : ArucoRefine::kAprilTag);
      }
      const TrackResult r = tracker.ProcessDetections(found, frames[i].width, frames[i].height);
      cpu.push_back((CpuSeconds() - c0) * 1e3);
      if (!r.measured) continue;
      rot.push_back(RotationAngleBetween(r.T_world_camera.rotation, truth[i].rotation) * 180 / kPi);
      trans.push_back(Length(r.T_world_camera.translation - truth[i].translation) * 1e3);
    }
    const std::string name = label + "_" + m.name;
    figures.push_back({name + "_cpu_ms", MedianOf(cpu), "ms",
                       std::to_string(rot.size()) + "/" + std::to_string(frames.size()) + " posed, 1 thread"});
    figures.push_back({name + "_rot_deg", MedianOf(rot), "deg", "median vs truth"});
    figures.push_back({name + "_trans_mm", MedianOf(trans), "mm", "median vs truth"});
  }
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
    if (std::string(c.name) == "clean") {
      std::vector<Image8> images;
      std::vector<Pose> truth;
      for (const Frame& f : stream) images.push_back(f.image), truth.push_back(*f.T_world_camera_true);
      BenchAruco(images, truth, source.board(), source.camera(), "synth1280", figures);
    }
    for (const char* preset : {"fast", "balanced"}) {
      for (bool regions : {false, true}) {
        if (regions && std::string(c.name) != "clean") continue;
        TrackerOptions o = TrackerOptions::Preset(preset);
        o.detector.threads = 2;
        o.detector.response = "display";  // the stream's frames are display tone-mapped
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

// Static camera: jitter (standard deviation about the mean, position in mm and
// rotation in degrees) of the tracked pose over frames that differ only in
// sensor noise, per filter preset; and each filter's latency: frames to
// reach 90% of a 10 mm step, and lag behind a steady 1 mm/frame motion.
void BenchJitter(const BenchOptions& options, std::vector<BenchFigure>& figures) {
  synth::CameraStreamOptions so;
  so.width = 1280;
  so.height = 720;
  so.samples_per_pixel = 1;
  so.noise_sigma = 2;
  synth::SyntheticCameraSource source(so);
  const int frames = options.quick ? 10 : 40;
  std::vector<Frame> stream;
  for (int i = 0; i < frames; ++i) {
    stream.push_back(source.RenderFrame(9.3, i));  // same instant, new noise each frame
    stream.back().t_ns = (i + 1) * 33333333LL;
  }
  for (const char* preset : {"none", "responsive", "balanced", "smooth"}) {
    TrackerOptions o = TrackerOptions::Preset("fast");
    o.detector.response = "display";
    o.filter = PoseFilterOptions::Preset(preset);
    Tracker tracker(source.board(), source.camera(), o);
    std::vector<Pose> poses;
    for (size_t i = 0; i < stream.size(); ++i) {
      const TrackResult r = tracker.Process(stream[i]);
      if (r.measured && i >= stream.size() / 4) poses.push_back(r.T_world_camera);  // after the filter settles
    }
    double pos2 = 0, rot2 = 0;
    Vec3 mean{0, 0, 0};
    for (const Pose& p : poses) mean += p.translation * (1.0 / poses.size());
    for (const Pose& p : poses) pos2 += std::pow(Length(p.translation - mean) * 1e3, 2) / poses.size();
    // Rotation spread: mean squared angle over all pairs is twice the variance.
    for (size_t i = 0; i < poses.size(); ++i)
      for (size_t j = i + 1; j < poses.size(); ++j)
        rot2 += std::pow(RotationAngleBetween(poses[i].rotation, poses[j].rotation) * 180 / kPi, 2) /
                (poses.size() * (poses.size() - 1.0));
    // Latency, on the filter alone.
    int settle = 0;
    {
      PoseFilter f(PoseFilterOptions::Preset(preset));
      f.Update(Pose{}, 1.0 / 30);
      for (settle = 1; settle < 100; ++settle)
        if (f.Update({Mat3::Identity(), {0.01, 0, 0}}, 1.0 / 30).translation.x >= 0.009) break;
    }
    double lag = 0;
    {
      PoseFilter f(PoseFilterOptions::Preset(preset));
      Pose out;
      for (int i = 0; i < 200; ++i) out = f.Update({Mat3::Identity(), {1e-3 * i, 0, 0}}, 1.0 / 30);
      lag = (0.199 - out.translation.x) / 1e-3;
    }
    const std::string name = std::string("static_filter_") + preset;
    figures.push_back({name + "_jitter_mm", std::sqrt(pos2), "mm",
                       std::to_string(poses.size()) + " frames, 1280x720, noise 2 levels, fast preset"});
    figures.push_back({name + "_jitter_deg", std::sqrt(rot2), "deg", "rotation standard deviation"});
    figures.push_back({name + "_step90_frames", static_cast<double>(settle), "frames", "to 90% of a 10 mm step"});
    figures.push_back({name + "_ramp_lag_frames", lag, "frames", "behind a steady 1 mm/frame motion"});
  }
}

}  // namespace

std::vector<BenchFigure> BenchTracking(const BenchOptions& options) {
  std::vector<BenchFigure> figures;
  BenchStream(options, figures);
  BenchJitter(options, figures);
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
  // Against aruco on the same views, upsampled 2x beforehand for both.
  std::vector<Image8> up2;
  std::vector<Pose> truth;
  for (size_t i = 0; i < small.size(); ++i) {
    cv::Mat in(small[i].height, small[i].width, CV_8UC3, small[i].pixels.data()), out;
    cv::resize(in, out, cv::Size(), 2.0, 2.0, cv::INTER_LINEAR);
    Image8 big(out.cols, out.rows, 3);
    std::copy(out.data, out.data + big.pixels.size(), big.pixels.begin());
    up2.push_back(std::move(big));
    truth.push_back(dataset.frames[i].T_world_camera);
  }
  BenchAruco(up2, truth, board, dataset.camera.Scaled(up2[0].width, up2[0].height), "lamps_test_up2", figures);
  return figures;
}

}  // namespace nerfar
