// The live AR pipeline, shared by the window and the headless path (every
// view the window shows is an 8-bit image made here): capture -> tracking
// (the pose of that same frame) -> exposure match -> insertion (render/insert)
// -> views (AR overlay, the NeRF "alongside" view, layers κ | α | incident
// light sphere) with per-stage milliseconds. Threaded: a capture thread and a
// processing thread joined by latest-value queues, so capture never waits for
// a slow stage (stale frames are dropped and counted); or stepped (Step(),
// every frame processed in order, for files). Nothing a frame or the device
// does ends the loop: a source that throws or reports a corrupt or lost frame,
// and a frame whose processing throws, are counted, kept in errors() (shown
// in the HUD and the session report) and skipped; frames that come back after
// the source was lost count as a reconnection (ReconnectingSource,
// tracking/frame_sources.h, reopens a device that is gone). No GL here. World frame = the
// board's (metres, z up); OpenCV camera axes; frames in the camera's 8-bit
// display encoding, composited in the scene field's linear radiance units.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "app/live/display.h"
#include "app/live/latest_queue.h"
#include "calib/board.h"
#include "calib/camera.h"
#include "calib/core/frame_source.h"
#include "calib/core/image.h"
#include "calib/core/math.h"
#include "render/insert/inserter.h"
#include "render/insert/object_visibility.h"
#include "render/lighting/scene_field.h"
#include "render/mesh/mesh.h"
#include "render/sg/brdf.h"
#include "render/ssdf/ssdf.h"
#include "tracking/tracker.h"

namespace nerfar {

using LiveClock = std::chrono::steady_clock;

class NerfScene;
struct NerfInsertOptions;

// A virtual object the user can place: its mesh (local frame, +z up) and, if
// baked, its SSDF field (shadows). Loans to the pipeline.
struct LiveAsset {
  std::string name;
  const TriangleMesh* mesh = nullptr;
  const SsdfField* field = nullptr;  // nullptr: no shadows, no self-shadows
  SgMaterial material;               // initial material
  // Textures at the mesh's UVs (InsertObject's maps); where given they
  // override the material's constant, the panel's edits included.
  const ImageF* albedo_map = nullptr;
  const ImageF* roughness_map = nullptr;
  const ImageF* metallic_map = nullptr;
};

// What the user edits, per object.
struct LiveObjectState {
  bool placed = false;
  Vec3 anchor_world;   // surface point the object stands on (its lowest point), world
  double yaw_rad = 0;  // rotation about the world z axis
  double scale = 1.0;  // uniform scale of the mesh
  SgMaterial material;
  bool dragging = false;  // the user is moving it (InsertObject::dragged, with LiveOptions::drag_hold)
};

struct LiveOptions {
  // Insertion preset (render/insert), of the insertion and of the NeRF
  // scene alike (NerfInsertOptions): fast | balanced | accurate.
  std::string preset = "fast";
  // `--set KEY=VALUE` items (NerfInsertOptions::Set: the insertion's and the
  // NeRF scene's knobs) over whichever preset is in use, the one switched to
  // in the window included.
  std::vector<std::string> insert_sets;
  TrackerOptions tracker = TrackerOptions::Preset("fast");
  // How 8-bit frames map to linear light: "display" (the synthetic camera's
  // sRGB of Reinhard x/(1+x), inverted) or "srgb" (a plain sRGB camera).
  std::string response = "srgb";
  // Release frames at their time stamps (files and the synthetic stream,
  // which would otherwise run as fast as they render); live cameras pace themselves.
  bool pace = true;
  // The AR composite is made at the frame size divided by this (1-4; box
  // filter): tracking keeps the full frame (small tags need the pixels),
  // insertion costs 1/divisor² as much.
  int render_divisor = 1;
  // While an object is dragged (LiveObjectState::dragging), hold its light
  // and reuse γ and κ relative to it (InsertObject::dragged); the full
  // recompute when the drag ends. false: every frame of a drag recomputes
  // them (as nerfar insert does).
  bool drag_hold = true;
  double alongside_scale = 0.5;  // size of the alongside and layers views relative to the frame
  int gain_every = 15;           // frames between exposure-gain updates (NeRF vs camera, coarse grid)
  int gain_grid_step = 8;        // pixel step of that grid
  bool hud = true;               // HUD text drawn into the AR view (fps, stages, state, latency)

  std::vector<std::string> Validate() const;
};

// Views (bit flags): the pipeline only renders what is shown.
enum LiveView : int { kViewAr = 1, kViewAlongside = 2, kViewLayers = 4 };

// Milliseconds spent on one frame by each stage.
struct LiveStageTimes {
  double capture_ms = 0;  // the source's Next() (for the synthetic camera: its rendering)
  double track_ms = 0;    // tag detection + pose + filter
  double expose_ms = 0;   // linearising the frame and the exposure gain
  InsertTimings insert;   // light, fit, raster, shade, occlusion, κ (render/insert)
  double alongside_ms = 0;
  double layers_ms = 0;
  double display_ms = 0;  // tone mapping back to display, HUD
  double process_ms = 0;  // everything after capture, up to the finished views
};

// One processed frame with its views.
struct LiveFrame {
  std::int64_t index = 0;
  Image8 ar;                // camera frame with the objects (always)
  Image8 alongside;         // NeRF rendering from the same pose with the objects (kViewAlongside)
  Image8 layers;            // κ | α | incident-light sphere side by side (kViewLayers)
  CameraIntrinsics camera;  // at the AR view's size
  bool has_pose = false;
  Pose T_world_camera;
  std::optional<Pose> T_world_camera_true;  // synthetic sources
  TrackingState state = TrackingState::kLost;
  int tags_used = 0;
  double exposure_gain = 1;     // camera linear / scene-field radiance
  size_t pixels_rewritten = 0;  // AR pixels the insertion changed (the rest are the camera's own)
  LiveStageTimes times;
  LiveClock::time_point captured;  // when the frame arrived from the source
  LiveClock::time_point finished;  // when its views were done
};

// Per-frame record kept for the session report.
struct LiveFrameRecord {
  std::int64_t index = 0;
  TrackingState state = TrackingState::kLost;
  bool measured = false;
  bool has_pose = false;
  Pose T_world_camera;
  std::optional<Pose> T_world_camera_true;
  LiveStageTimes times;
  double latency_ms = -1;       // capture to display (-1: never displayed)
  double t_s = 0;               // capture time since the start
  double light_fit_loss = -1;   // SG fit loss of object 0's light when it was refitted this frame (-1: not)
  size_t pixels_rewritten = 0;  // AR pixels re-encoded by the display path
};

struct LiveCounters {
  std::uint64_t captured = 0;                // frames the source delivered
  std::uint64_t dropped_before_process = 0;  // captured but superseded before processing
  std::uint64_t processed = 0;
  std::uint64_t dropped_before_display = 0;  // processed but superseded before display
  std::uint64_t displayed = 0;
  std::uint64_t source_errors = 0;  // corrupt or lost frames, and failures (exceptions) of the source
  std::uint64_t reconnects = 0;     // frames arriving again after the source was lost or failed
  std::uint64_t frame_errors = 0;   // frames whose processing failed (skipped)
  std::uint64_t output_errors = 0;  // views that could not be written (recording, screenshots, files)
};

// One failure the loop went on after.
struct LiveError {
  std::int64_t frame = -1;  // the frame it happened on (-1: none, e.g. the source)
  std::string stage;        // "source", "process" or "output"
  std::string what;         // the message
};

class LivePipeline {
 public:
  // Loans: source, scene, assets outlive the pipeline. `camera` is the
  // source's intrinsics (rescaled to frame sizes of the same aspect). A
  // NerfScene takes the NeRF scene's options of the preset with the `--set`
  // items (NerfInsertOptions) here and again at every preset switch, as
  // `nerfar insert` builds its scene; other scene fields (the tests'
  // analytic scenes) are only queried. `environment_distance_m`: as
  // Inserter's (EnvLight::distance_m).
  LivePipeline(FrameSource& source, const Board& board, const CameraIntrinsics& camera, SceneField& scene,
               SgMixture environment, std::vector<LiveAsset> assets, LiveOptions options,
               std::vector<double> environment_distance_m = {});
  ~LivePipeline();
  LivePipeline(const LivePipeline&) = delete;
  LivePipeline& operator=(const LivePipeline&) = delete;

  // Threaded mode: capture and processing threads; TakeLatest() returns the
  // newest finished frame (older ones are dropped and counted).
  void Start();
  void Stop();
  std::optional<LiveFrame> TakeLatest(std::chrono::milliseconds timeout);
  bool finished() const { return source_ended_.load() && output_.closed(); }
  // Stepped mode (no threads): the next frame from the source, processed.
  // nullopt at the end of the stream (source_ended()) or when no frame was
  // processed within `wait` (a lost camera: call again).
  std::optional<LiveFrame> Step(std::chrono::milliseconds wait = std::chrono::seconds(2));
  bool source_ended() const { return source_ended_.load(); }
  // The caller showed (or wrote) this frame now: records its latency.
  void MarkDisplayed(const LiveFrame& frame);

  // Placement: the scene surface under view pixel (x, y) of the AR view of
  // `frame` (the median hit distance of the NeRF along the pixel ray,
  // MedianHitDistance); nullopt where the ray meets no surface (opacity
  // below 0.3).
  std::optional<Vec3> PickSurface(const LiveFrame& frame, double x, double y) const;

  // Edits (thread-safe; applied from the next processed frame).
  size_t object_count() const { return assets_.size(); }
  const std::string& object_name(size_t i) const { return assets_.at(i).name; }
  LiveObjectState object(size_t i) const;
  void set_object(size_t i, const LiveObjectState& state);
  void set_preset(const std::string& preset);  // InputError for an unknown name
  std::string preset() const;
  void set_views(int views) { views_.store(views); }
  int views() const { return views_.load(); }
  void set_hud(bool on) { hud_on_.store(on); }

  // World pose of object i for a state (lowest point on the anchor, yaw about z).
  Pose ObjectPose(size_t i, const LiveObjectState& state) const;

  LiveCounters counters() const;
  std::vector<LiveFrameRecord> records() const;
  // The most recent failures (at most kErrorsKept), oldest first.
  static constexpr size_t kErrorsKept = 32;
  std::vector<LiveError> errors() const;
  // True while the source is lost (no frame since it failed).
  bool source_lost() const { return source_lost_.load(); }
  // A view the caller could not write (recording, screenshot, session file):
  // counted with the loop's own failures.
  void ReportOutputError(const std::string& what);
  const LiveOptions& options() const { return options_; }
  double mean_fps() const;  // displayed frames / seconds since the first capture

 private:
  struct Captured {
    Frame frame;
    LiveClock::time_point captured;
    double capture_ms = 0;
  };
  std::optional<Captured> Capture(bool& end);  // one frame from the source (paced)
  LiveFrame Process(Captured captured);
  // The same behind the per-frame catch: a failure is counted and recorded, nullopt.
  std::optional<Captured> CaptureGuarded(bool& end);
  std::optional<LiveFrame> ProcessGuarded(Captured captured);
  void RecordError(std::int64_t frame, const std::string& stage, const std::string& what);
  // The preset's knobs with options_.insert_sets over them.
  NerfInsertOptions Knobs(const std::string& preset) const;
  // A preset switched while running (processing thread only).
  void SwitchPreset(const std::string& preset);
  // Steps of Process (processing thread only).
  void UpdateGain(const LiveFrame& frame);  // every gain_every frames, from the frame's codes
  std::vector<InsertObject> PlaceObjects(const std::vector<LiveObjectState>& states);
  void MakeSideViews(LiveFrame& out, const std::vector<InsertObject>& objects, const InsertLayers& layers, int views);
  void DrawHud(LiveFrame& out);
  void CaptureLoop();
  void ProcessLoop();

  FrameSource& source_;
  CameraIntrinsics camera_;
  const SceneField& scene_;
  // scene_ where it is a NerfScene, whose options follow the preset; the
  // processing thread changes them while holding scene_options_mutex_,
  // which PickSurface (the window's thread) holds while it queries the scene.
  NerfScene* nerf_scene_ = nullptr;
  mutable std::mutex scene_options_mutex_;
  std::vector<LiveAsset> assets_;
  LiveOptions options_;
  DisplayCodec codec_;
  std::unique_ptr<Tracker> tracker_;
  std::unique_ptr<Inserter> inserter_;

  mutable std::mutex edit_mutex_;
  std::vector<LiveObjectState> states_;
  std::string preset_;
  bool preset_changed_ = false;
  std::atomic<int> views_{kViewAr};
  std::atomic<bool> hud_on_{true};
  // The HUD's text and when it was last renewed (processing thread only).
  TextOverlay hud_;
  LiveClock::time_point hud_updated_;
  int hud_width_ = 0;
  TrackingState hud_state_ = TrackingState::kLost;
  std::uint64_t hud_errors_ = 0;

  // Posed SSDF fields of the objects, kept while each stands still
  // (processing thread only).
  struct PosedField {
    std::unique_ptr<ObjectVisibility> field;
    Pose T_world_object;
    double scale = 1;
  };
  std::vector<PosedField> visibility_;

  // The linear frame the insertion composites into, kept between frames
  // (processing thread only: no 11 MB allocation per 1280x720 frame).
  ImageF composite_;

  // Exposure gain (processing thread only).
  double gain_ = 1;
  bool gain_valid_ = false;
  std::int64_t frames_since_gain_ = 0;

  // Pacing and statistics.
  bool have_start_ = false;
  LiveClock::time_point start_;
  LiveClock::time_point pace_start_;  // pacing anchor: frame time stamp pace_first_t_ns_ is due then
  std::int64_t pace_first_t_ns_ = 0;
  mutable std::mutex stats_mutex_;
  LiveCounters counters_;
  std::vector<LiveFrameRecord> records_;
  std::vector<LiveError> errors_;  // the last kErrorsKept
  std::atomic<bool> source_lost_{false};
  std::vector<double> recent_display_s_;  // display times of the last frames (fps in the HUD)

  LatestQueue<Captured> input_;
  LatestQueue<LiveFrame> output_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> source_ended_{false};
  std::thread capture_thread_, process_thread_;
};

// Distance along the ray o + t·d (d unit) where the scene's opacity over
// [t_near, t] first reaches half of its value over [t_near, t_far] (the median
// of where the ray ends; within (t_far − t_near)/1024); nullopt when the whole
// range holds less than 0.3 opacity (no surface).
std::optional<double> MedianHitDistance(const SceneField& scene, const Vec3& origin, const Vec3& direction,
                                        double t_near, double t_far);

// Stage names and values of LiveStageTimes in a fixed order (tables, JSON).
std::vector<std::pair<std::string, double>> StageList(const LiveStageTimes& times);

}  // namespace nerfar
