#include "app/live/pipeline.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>

#include "calib/core/error.h"
#include "calib/core/image_io.h"
#include "calib/core/log.h"
#include "calib/core/media.h"
#include "calib/core/metrics.h"
#include "calib/core/parallel.h"
#include "render/insert/nerf_insert_options.h"
#include "render/insert/nerf_scene.h"
#include "render/insert/ssdf_visibility.h"
#include "render/sg/fit.h"
#include "render/sg/sg.h"

namespace nerfar {

namespace {

double MsSince(LiveClock::time_point t0) {
  return std::chrono::duration<double, std::milli>(LiveClock::now() - t0).count();
}

// A ray "meets a surface" at this scene opacity: a fast-preset NeRF reaches
// only ~0.6 on its solid table top, so 0.5 would miss half of it.
constexpr float kSurfaceOpacity = 0.3f;

// How often the HUD's text is renewed (its numbers are read, not watched).
constexpr auto kHudRefresh = std::chrono::milliseconds(250);

// After the source threw: a device that fails at once on every call must not
// make the capture loop spin (ReconnectingSource paces its own reopening).
constexpr auto kFailedSourcePause = std::chrono::milliseconds(50);
// Frames whose time stamps fall this far behind their due time (a source that
// came back, a file that restarted) re-anchor the pacing instead of bursting.
constexpr auto kPaceSlack = std::chrono::seconds(1);
// Failures logged as they happen; later ones are counted (session report).
constexpr std::uint64_t kErrorsLogged = 20;

std::string ExceptionText(const std::exception_ptr& error) {
  try {
    std::rethrow_exception(error);
  } catch (const std::exception& e) {
    return e.what();
  } catch (...) {
    return "unknown exception";
  }
}

// Box-filtered 1/divisor size (edges that do not fill a box are dropped).
Image8 Downsample(const Image8& image, int divisor) {
  if (divisor == 1) return image;
  Image8 out(image.width / divisor, image.height / divisor, image.channels);
  const int area = divisor * divisor;
  for (int y = 0; y < out.height; ++y)
    for (int x = 0; x < out.width; ++x)
      for (int c = 0; c < image.channels; ++c) {
        int sum = 0;
        for (int dy = 0; dy < divisor; ++dy)
          for (int dx = 0; dx < divisor; ++dx) sum += image.at(x * divisor + dx, y * divisor + dy, c);
        out.at(x, y, c) = static_cast<std::uint8_t>((sum + area / 2) / area);
      }
  return out;
}

bool SamePose(const Pose& a, const Pose& b) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      if (a.rotation(r, c) != b.rotation(r, c)) return false;
  return a.translation == b.translation;
}

Image8 ToRgb(const Image8& image) {
  if (image.channels == 3) return image;
  Image8 rgb(image.width, image.height, 3);
  for (size_t p = 0; p < image.PixelCount(); ++p)
    for (int c = 0; c < 3; ++c)
      rgb.pixels[p * 3 + c] = image.pixels[p * image.channels + (image.channels >= 3 ? c : 0)];
  return rgb;
}

// Nearest-neighbour resample of a 1-channel layer in [0, 1] to an RGB tile.
Image8 LayerTile(const ImageF& layer, int width, int height) {
  Image8 tile(width, height, 3);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const int sx = std::min(layer.width - 1, x * layer.width / width);
      const int sy = std::min(layer.height - 1, y * layer.height / height);
      const float v = layer.empty() ? 0.0f : layer.at(sx, sy, 0);
      const auto g = static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.0f, 1.0f) * 255.0f));
      for (int c = 0; c < 3; ++c) tile.at(x, y, c) = g;
    }
  return tile;
}

// The incident light as seen on a mirror ball from the camera (a light probe):
// pixel -> ball normal n (camera frame) -> reflected view direction in the world.
Image8 LightSphereTile(const SgMixture& light, const Pose& T_world_camera, int width, int height) {
  ImageF sphere(width, height, 3, 0.0f);
  const double radius = 0.45 * std::min(width, height);
  const double cx = 0.5 * width, cy = 0.5 * height;
  double peak = 0;
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const double u = (x + 0.5 - cx) / radius, v = (y + 0.5 - cy) / radius;
      const double r2 = u * u + v * v;
      if (r2 > 1) continue;
      const Vec3 n_camera{u, v, -std::sqrt(1 - r2)};  // facing the camera (OpenCV: z forward)
      const Vec3 view{0, 0, 1};
      const Vec3 reflected = view - n_camera * (2 * Dot(view, n_camera));
      const Vec3 d_world = T_world_camera.Rotate(reflected);
      const Vec3 L = Evaluate(light, Normalized(d_world));
      for (int c = 0; c < 3; ++c) sphere.at(x, y, c) = static_cast<float>(L[c]);
      peak = std::max(peak, 0.2126 * L.x + 0.7152 * L.y + 0.0722 * L.z);
    }
  return ToneMapToDisplay(sphere, peak > 0 ? static_cast<float>(2.0 / peak) : 1.0f);
}

Image8 SideBySide(const std::vector<Image8>& tiles) {
  int width = 0, height = 0;
  for (const Image8& t : tiles) {
    width += t.width;
    height = std::max(height, t.height);
  }
  Image8 out(width, height, 3, 30);
  int x0 = 0;
  for (const Image8& t : tiles) {
    for (int y = 0; y < t.height; ++y)
      for (int x = 0; x < t.width; ++x)
        for (int c = 0; c < 3; ++c) out.at(x0 + x, y, c) = t.at(x, y, c);
    x0 += t.width;
  }
  return out;
}

// The camera frame as the AR view's starting point: at divisor 1 the frame
// itself (moved, not copied: the display path rewrites only what the
// insertion changed), else box-filtered; always RGB.
Image8 ArBase(Image8 frame, int divisor) {
  if (divisor != 1) frame = Downsample(frame, divisor);
  return frame.channels == 3 ? std::move(frame) : ToRgb(frame);
}

}  // namespace

std::vector<std::string> LiveOptions::Validate() const {
  std::vector<std::string> p;
  const bool known_preset = preset == "fast" || preset == "balanced" || preset == "accurate";
  if (!known_preset) p.push_back("preset: '" + preset + "' (expected fast, balanced or accurate)");
  if (response != "display" && response != "srgb")
    p.push_back("response: '" + response + "' (expected display or srgb)");
  if (!(alongside_scale > 0.05 && alongside_scale <= 1))
    p.push_back("alongside_scale: " + std::to_string(alongside_scale) + " (expected (0.05, 1])");
  if (render_divisor < 1 || render_divisor > 4)
    p.push_back("render_divisor: " + std::to_string(render_divisor) + " (expected 1..4)");
  if (gain_every < 1) p.push_back("gain_every: " + std::to_string(gain_every) + " (expected >= 1)");
  if (gain_grid_step < 1 || gain_grid_step > 64)
    p.push_back("gain_grid_step: " + std::to_string(gain_grid_step) + " (expected 1..64)");
  for (const std::string& s : tracker.Validate()) p.push_back("tracker." + s);
  if (known_preset) {
    try {
      for (const std::string& s : NerfInsertOptions::Preset(preset, insert_sets).Validate()) p.push_back(s);
    } catch (const InputError& e) {  // an unknown key, or a value that is not of its field's kind
      p.push_back(e.what());
    }
  }
  return p;
}

std::vector<std::pair<std::string, double>> StageList(const LiveStageTimes& t) {
  return {{"capture", t.capture_ms},    {"track", t.track_ms},
          {"expose", t.expose_ms},      {"light", t.insert.light_ms},
          {"fit", t.insert.fit_ms},     {"raster", t.insert.raster_ms},
          {"shade", t.insert.shade_ms}, {"occlusion", t.insert.occlusion_ms},
          {"kappa", t.insert.kappa_ms}, {"alongside", t.alongside_ms},
          {"layers", t.layers_ms},      {"display", t.display_ms},
          {"process", t.process_ms}};
}

LivePipeline::LivePipeline(FrameSource& source, const Board& board, const CameraIntrinsics& camera, SceneField& scene,
                           SgMixture environment, std::vector<LiveAsset> assets, LiveOptions options,
                           std::vector<double> environment_distance_m)
    : source_(source),
      camera_(camera),
      scene_(scene),
      nerf_scene_(dynamic_cast<NerfScene*>(&scene)),
      assets_(std::move(assets)),
      options_(std::move(options)),
      codec_(options_.response == "display") {
  {
    Problems problems("live options");
    for (const std::string& p : options_.Validate()) problems.Add("", p);
    for (size_t i = 0; i < assets_.size(); ++i)
      if (assets_[i].mesh == nullptr) problems.Add("objects[" + std::to_string(i) + "]", "no mesh");
    problems.ThrowIfAny();
  }
  tracker_ = std::make_unique<Tracker>(board, camera_, options_.tracker);
  const NerfInsertOptions knobs = Knobs(options_.preset);
  if (nerf_scene_ != nullptr) nerf_scene_->set_options(knobs.nerf);
  inserter_ =
      std::make_unique<Inserter>(scene_, std::move(environment), knobs.insert, std::move(environment_distance_m));
  preset_ = options_.preset;
  hud_on_.store(options_.hud);
  for (const LiveAsset& a : assets_) {
    LiveObjectState s;
    s.material = a.material;
    states_.push_back(s);
  }
}

LivePipeline::~LivePipeline() { Stop(); }

LiveObjectState LivePipeline::object(size_t i) const {
  std::lock_guard<std::mutex> lock(edit_mutex_);
  return states_.at(i);
}

void LivePipeline::set_object(size_t i, const LiveObjectState& state) {
  std::lock_guard<std::mutex> lock(edit_mutex_);
  states_.at(i) = state;
}

NerfInsertOptions LivePipeline::Knobs(const std::string& preset) const {
  return NerfInsertOptions::Preset(preset, options_.insert_sets);
}

void LivePipeline::SwitchPreset(const std::string& preset) {
  const NerfInsertOptions knobs = Knobs(preset);
  if (nerf_scene_ != nullptr) {
    const std::lock_guard<std::mutex> lock(scene_options_mutex_);
    nerf_scene_->set_options(knobs.nerf);
  }
  // A new Inserter rather than new options for the old one: what it keeps
  // between frames (the lights, γ, κ's receivers and lattice) was taken
  // from the scene as its old options rendered it.
  inserter_ =
      std::make_unique<Inserter>(scene_, inserter_->environment(), knobs.insert, inserter_->environment_distance_m());
}

void LivePipeline::set_preset(const std::string& preset) {
  (void)Knobs(preset);  // InputError for an unknown name
  std::lock_guard<std::mutex> lock(edit_mutex_);
  if (preset != preset_) preset_changed_ = true;
  preset_ = preset;
}

std::string LivePipeline::preset() const {
  std::lock_guard<std::mutex> lock(edit_mutex_);
  return preset_;
}

Pose LivePipeline::ObjectPose(size_t i, const LiveObjectState& state) const {
  const Bounds bounds = ComputeBounds(*assets_.at(i).mesh);
  Pose pose;
  pose.rotation = RotationFromAxisAngle({0, 0, 1}, state.yaw_rad);
  // The mesh's lowest point (local z = bounds.min.z, scaled) rests on the anchor.
  pose.translation = state.anchor_world - Vec3{0, 0, bounds.min.z * state.scale};
  return pose;
}

std::optional<Vec3> LivePipeline::PickSurface(const LiveFrame& frame, double x, double y) const {
  if (!frame.has_pose) return std::nullopt;
  const Vec3 d_camera = Unproject(frame.camera, {x, y});
  const Vec3 origin = frame.T_world_camera.translation;
  const Vec3 direction = Normalized(frame.T_world_camera.Rotate(d_camera));
  const auto range = IntersectBox(scene_.Box(), origin, direction);
  if (!range) return std::nullopt;
  const std::lock_guard<std::mutex> lock(scene_options_mutex_);  // not while a preset switch changes them
  const std::optional<double> t = MedianHitDistance(scene_, origin, direction, range->first, range->second);
  if (!t) return std::nullopt;
  return origin + direction * *t;
}

std::optional<double> MedianHitDistance(const SceneField& scene, const Vec3& origin, const Vec3& direction,
                                        double t_near, double t_far) {
  // Why the median and not the expected depth Σ T α t / Ô: a NeRF's thin fog
  // in front of a surface pulls the expected depth towards the camera (and
  // fog behind it away), by centimetres on a fast model; the distance where
  // half of the ray's opacity has accumulated stays on the surface as long
  // as the fog in front holds less than half of it. Two passes of kSteps
  // rays each over nested brackets: (t_far − t_near)/kSteps² resolution.
  constexpr int kSteps = 32;
  SceneRays rays;
  SceneSamples samples;
  rays.Add(Vec3f(origin), Vec3f(direction), static_cast<float>(t_near), static_cast<float>(t_far));
  scene.RenderRays(rays, samples);
  const float total = samples.opacity[0];
  if (!(total >= kSurfaceOpacity) || !std::isfinite(total)) return std::nullopt;
  const float half = 0.5f * total;
  double lo = t_near, hi = t_far;
  for (int pass = 0; pass < 2; ++pass) {
    rays.Clear();
    const double step = (hi - lo) / kSteps;
    for (int k = 1; k <= kSteps; ++k)
      rays.Add(Vec3f(origin), Vec3f(direction), static_cast<float>(t_near), static_cast<float>(lo + step * k));
    scene.RenderRays(rays, samples);
    // Opacity over [t_near, t] grows with t: the first t reaching half.
    int k = 0;
    while (k < kSteps - 1 && !(samples.opacity[k] >= half)) ++k;
    hi = lo + step * (k + 1);
    lo = hi - step;
  }
  const double t = 0.5 * (lo + hi);
  return std::isfinite(t) ? std::optional<double>(t) : std::nullopt;
}

std::optional<LivePipeline::Captured> LivePipeline::Capture(bool& end) {
  end = false;
  Captured c;
  const auto t0 = LiveClock::now();
  const FrameStatus status = source_.Next(c.frame, 100);
  c.capture_ms = MsSince(t0);
  if (status == FrameStatus::kEndOfStream) {
    end = true;
    return std::nullopt;
  }
  if (status == FrameStatus::kTimeout) return std::nullopt;
  if (status != FrameStatus::kOk) {
    {
      std::lock_guard<std::mutex> lock(stats_mutex_);
      ++counters_.source_errors;
    }
    // A lost device is recorded once, when it goes; every corrupt frame is.
    const bool lost = status == FrameStatus::kLost;
    if (!(lost && source_lost_.exchange(true)))
      RecordError(-1, "source", std::string(FrameStatusName(status)) + ": " + source_.LastError());
    return std::nullopt;
  }
  if (source_lost_.exchange(false)) {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++counters_.reconnects;
    LogInfo("live: frames again from the source (frame " + std::to_string(c.frame.index) + ")");
  }
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    if (!have_start_) {
      have_start_ = true;
      start_ = pace_start_ = LiveClock::now();
      pace_first_t_ns_ = c.frame.t_ns;
    }
  }
  if (options_.pace) {
    const auto now = LiveClock::now();
    auto due = pace_start_ + std::chrono::nanoseconds(c.frame.t_ns - pace_first_t_ns_);
    if (due + kPaceSlack < now || due > now + kPaceSlack) {
      pace_start_ = due = now;
      pace_first_t_ns_ = c.frame.t_ns;
    }
    if (due > now) std::this_thread::sleep_until(due);
  }
  c.captured = LiveClock::now();
  std::lock_guard<std::mutex> lock(stats_mutex_);
  ++counters_.captured;
  return c;
}

std::optional<LivePipeline::Captured> LivePipeline::CaptureGuarded(bool& end) {
  try {
    return Capture(end);
  } catch (...) {
    end = false;
    {
      std::lock_guard<std::mutex> lock(stats_mutex_);
      ++counters_.source_errors;
    }
    source_lost_.store(true);
    RecordError(-1, "source", ExceptionText(std::current_exception()));
    std::this_thread::sleep_for(kFailedSourcePause);
    return std::nullopt;
  }
}

std::optional<LiveFrame> LivePipeline::ProcessGuarded(Captured captured) {
  const std::int64_t index = captured.frame.index;
  try {
    return Process(std::move(captured));
  } catch (...) {
    {
      std::lock_guard<std::mutex> lock(stats_mutex_);
      ++counters_.frame_errors;
    }
    RecordError(index, "process", ExceptionText(std::current_exception()));
    return std::nullopt;
  }
}

void LivePipeline::RecordError(std::int64_t frame, const std::string& stage, const std::string& what) {
  std::uint64_t count = 0;
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    errors_.push_back({frame, stage, what});
    if (errors_.size() > kErrorsKept) errors_.erase(errors_.begin());
    count = counters_.source_errors + counters_.frame_errors + counters_.output_errors;
  }
  if (count <= kErrorsLogged)
    LogWarning("live: " + stage + (frame >= 0 ? " (frame " + std::to_string(frame) + ")" : "") + ": " + what +
               (count == kErrorsLogged ? " (further errors are counted in the session report only)" : ""));
}

void LivePipeline::ReportOutputError(const std::string& what) {
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++counters_.output_errors;
  }
  RecordError(-1, "output", what);
}

std::vector<LiveError> LivePipeline::errors() const {
  std::lock_guard<std::mutex> lock(stats_mutex_);
  return errors_;
}

void LivePipeline::UpdateGain(const LiveFrame& frame) {
  if (gain_valid_ && ++frames_since_gain_ < options_.gain_every) return;
  frames_since_gain_ = 0;
  const Image8& image = frame.ar;
  const int step = options_.gain_grid_step;
  // Skip clipped and near-black pixels: the ratio there says little.
  const float white = codec_.Linear(255);
  SceneRays rays;
  std::vector<float> camera_lum;
  for (int y = step / 2; y < image.height; y += step)
    for (int x = step / 2; x < image.width; x += step) {
      const std::uint8_t* code = image.Pixel(x, y);
      const float px[3] = {codec_.Linear(code[0]), codec_.Linear(code[1]), codec_.Linear(code[2])};
      const float lum = Luminance(px, 3);
      if (!(lum > 1e-3f && px[0] < 0.9f * white && px[1] < 0.9f * white && px[2] < 0.9f * white)) continue;
      const Vec3 d = Normalized(frame.T_world_camera.Rotate(Unproject(frame.camera, {x + 0.5, y + 0.5})));
      const auto range = IntersectBox(scene_.Box(), frame.T_world_camera.translation, d);
      if (!range) continue;
      rays.Add(Vec3f(frame.T_world_camera.translation), Vec3f(d), static_cast<float>(range->first),
               static_cast<float>(range->second));
      camera_lum.push_back(lum);
    }
  SceneSamples samples;
  scene_.RenderRays(rays, samples);
  std::vector<double> ratios;
  for (size_t i = 0; i < rays.size(); ++i) {
    // Rays that met a surface, compared by their radiance Ĉ/Ô (a fast NeRF
    // often stays below full opacity on solid surfaces).
    const float o = samples.opacity[i];
    if (!(o >= kSurfaceOpacity)) continue;
    const float c[3] = {samples.colour[i].x / o, samples.colour[i].y / o, samples.colour[i].z / o};
    const float scene_lum = Luminance(c, 3);
    if (scene_lum > 1e-6f && std::isfinite(scene_lum)) ratios.push_back(std::log(camera_lum[i] / scene_lum));
  }
  LogVerbose("live: exposure gain from " + std::to_string(ratios.size()) + " of " + std::to_string(rays.size()) +
             " rays");
  if (ratios.size() >= 8) {
    std::nth_element(ratios.begin(), ratios.begin() + ratios.size() / 2, ratios.end());
    const double g = std::exp(ratios[ratios.size() / 2]);
    gain_ = gain_valid_ ? std::exp(0.7 * std::log(gain_) + 0.3 * std::log(g)) : g;
    gain_valid_ = true;
  }
}

std::vector<InsertObject> LivePipeline::PlaceObjects(const std::vector<LiveObjectState>& states) {
  // A posed SSDF field is kept while its object stands still: the
  // inserter's caches (per-vertex self-shadow, κ lattice) are keyed by the
  // objects' fields and poses, so a still object reuses them frame after
  // frame and a moved one recomputes them.
  std::vector<InsertObject> objects;
  visibility_.resize(states.size());
  for (size_t i = 0; i < states.size(); ++i) {
    if (!states[i].placed) continue;
    InsertObject o;
    o.mesh = assets_[i].mesh;
    o.T_world_object = ObjectPose(i, states[i]);
    o.scale = states[i].scale;
    o.material = states[i].material;
    o.albedo_map = assets_[i].albedo_map;
    o.roughness_map = assets_[i].roughness_map;
    o.metallic_map = assets_[i].metallic_map;
    o.dragged = options_.drag_hold && states[i].dragging;
    if (assets_[i].field != nullptr) {
      PosedField& posed = visibility_[i];
      if (!posed.field || !SamePose(posed.T_world_object, o.T_world_object) || posed.scale != o.scale) {
        posed.field = std::make_unique<SsdfVisibility>(*assets_[i].field, o.T_world_object, o.scale);
        posed.T_world_object = o.T_world_object;
        posed.scale = o.scale;
      }
      o.visibility = posed.field.get();
    }
    objects.push_back(o);
  }
  return objects;
}

void LivePipeline::MakeSideViews(LiveFrame& out, const std::vector<InsertObject>& objects, const InsertLayers& layers,
                                 int views) {
  const int w = out.ar.width, h = out.ar.height;
  const int side_w = std::max(16, static_cast<int>(std::lround(w * options_.alongside_scale)));
  const int side_h = std::max(16, static_cast<int>(std::lround(h * options_.alongside_scale)));
  if (views & kViewAlongside) {
    const auto t0 = LiveClock::now();
    if (out.has_pose) {
      const CameraIntrinsics small = out.camera.Scaled(side_w, side_h);
      ImageF background = inserter_->RenderBackground(small, out.T_world_camera);
      if (!objects.empty()) inserter_->Render(small, out.T_world_camera, objects, background);
      out.alongside = codec_.ToDisplay(background, gain_);
    } else {
      out.alongside = Image8(side_w, side_h, 3, 40);
      DrawText(out.alongside, "no pose yet", 4, 4);
    }
    out.times.alongside_ms = MsSince(t0);
  }
  if (views & kViewLayers) {
    const auto t0 = LiveClock::now();
    Image8 kappa = LayerTile(ExpandLayer(layers.kappa, layers.kappa_rect, w, h, 1.0f), side_w, side_h);
    Image8 alpha = LayerTile(ExpandLayer(layers.alpha, layers.gbuffer.rect, w, h, 0.0f), side_w, side_h);
    Image8 sphere = !objects.empty() && out.has_pose
                        ? LightSphereTile(inserter_->Light(0), out.T_world_camera, side_h, side_h)
                        : Image8(side_h, side_h, 3, 20);
    DrawText(kappa, "kappa", 3, 3);
    DrawText(alpha, "alpha", 3, 3);
    DrawText(sphere, objects.empty() ? "light (place an object)" : "incident light", 3, 3);
    out.layers = SideBySide({kappa, alpha, sphere});
    out.times.layers_ms = MsSince(t0);
  }
}

void LivePipeline::DrawHud(LiveFrame& out) {
  // The numbers change every frame, but nobody reads them faster than a few
  // times a second: the text is renewed every kHudRefresh, and at once when
  // the tracking state or the error count changes, and drawn from the
  // overlay's cache in between (a blend of its pixels).
  std::uint64_t errors = 0;
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    errors = counters_.frame_errors + counters_.source_errors + counters_.output_errors;
  }
  const auto now = LiveClock::now();
  if (now - hud_updated_ >= kHudRefresh || out.ar.width != hud_width_ || out.state != hud_state_ ||
      errors != hud_errors_) {
    hud_updated_ = now;
    hud_width_ = out.ar.width;
    hud_state_ = out.state;
    hud_errors_ = errors;
    double fps = 0, latency = -1;
    LiveCounters counts;
    std::string last_error;
    {
      std::lock_guard<std::mutex> lock(stats_mutex_);
      counts = counters_;
      if (!errors_.empty()) last_error = errors_.back().stage + ": " + errors_.back().what;
      if (recent_display_s_.size() >= 2)
        fps = (recent_display_s_.size() - 1) / std::max(1e-9, recent_display_s_.back() - recent_display_s_.front());
      for (auto it = records_.rbegin(); it != records_.rend(); ++it)
        if (it->latency_ms >= 0) {
          latency = it->latency_ms;
          break;
        }
    }
    std::vector<std::string> lines;
    char line[256];
    std::snprintf(line, sizeof line, "%.1f fps  latency %.0f ms  %s  tags %d", fps, latency,
                  TrackingStateName(out.state), out.tags_used);
    lines.push_back(line);
    const InsertTimings& it = out.times.insert;
    std::snprintf(line, sizeof line, "ms: track %.1f  insert %.1f (kappa %.1f)  views %.1f", out.times.track_ms,
                  it.total_ms, it.kappa_ms, out.times.alongside_ms + out.times.layers_ms);
    lines.push_back(line);
    if (!last_error.empty()) {
      std::snprintf(line, sizeof line, "errors: %llu frames, %llu source, %llu outputs; last %.60s",
                    static_cast<unsigned long long>(counts.frame_errors),
                    static_cast<unsigned long long>(counts.source_errors),
                    static_cast<unsigned long long>(counts.output_errors), last_error.c_str());
      lines.push_back(line);
    }
    hud_.Set(lines, out.ar.width);
  }
  hud_.Draw(out.ar);
}

LiveFrame LivePipeline::Process(Captured captured) {
  const auto t_start = LiveClock::now();
  LiveFrame out;
  out.index = captured.frame.index;
  out.captured = captured.captured;
  out.times.capture_ms = captured.capture_ms;
  out.T_world_camera_true = captured.frame.T_world_camera_true;
  // Tracking: the pose of this very frame (at its full size).
  auto t0 = LiveClock::now();
  const TrackResult track = tracker_->Process(captured.frame);
  out.times.track_ms = MsSince(t0);
  out.ar = ArBase(std::move(captured.frame.image), options_.render_divisor);
  out.has_pose = track.has_pose;
  out.T_world_camera = track.T_world_camera;
  out.state = track.state;
  out.tags_used = track.tags_used;
  out.camera = (out.ar.width == camera_.width && out.ar.height == camera_.height)
                   ? camera_
                   : camera_.Scaled(out.ar.width, out.ar.height);

  // The user's edits as of now.
  std::vector<LiveObjectState> states;
  std::optional<std::string> switched_preset;
  {
    std::lock_guard<std::mutex> lock(edit_mutex_);
    states = states_;
    if (preset_changed_) switched_preset = preset_;
    preset_changed_ = false;
  }
  if (switched_preset) SwitchPreset(*switched_preset);
  const int views = views_.load();
  t0 = LiveClock::now();
  if (out.has_pose) UpdateGain(out);
  out.exposure_gain = gain_;
  out.times.expose_ms = MsSince(t0);
  const std::vector<InsertObject> objects = PlaceObjects(states);

  // AR: the objects over the camera frame, linearised once into a buffer
  // the loop keeps; back in the display encoding only the pixels the
  // insertion changed (the rest keep the camera's own values exactly).
  InsertLayers layers;
  double fit_loss = -1;
  if (out.has_pose && !objects.empty()) {
    t0 = LiveClock::now();
    codec_.Linearise(out.ar, gain_, composite_);
    out.times.expose_ms += MsSince(t0);
    out.times.insert = inserter_->Render(out.camera, out.T_world_camera, objects, composite_, &layers);
    if (out.times.insert.lights_recomputed > 0) {
      const IncidentLight& cache = inserter_->LightCache(0);
      if (cache.valid() && !cache.samples().directions.empty())
        fit_loss = SgFitLoss(cache.samples(), cache.light(), inserter_->options().light.fit.hdr_floor);
    }
    t0 = LiveClock::now();
    out.pixels_rewritten =
        CompositeToDisplay(codec_, composite_, gain_, Union(layers.gbuffer.rect, layers.kappa_rect), out.ar);
    out.times.display_ms += MsSince(t0);
  }
  MakeSideViews(out, objects, layers, views);

  // HUD (in the image itself, so the window and the files show the same).
  t0 = LiveClock::now();
  if (hud_on_.load()) DrawHud(out);
  out.times.display_ms += MsSince(t0);
  out.times.process_ms = MsSince(t_start);
  out.finished = LiveClock::now();

  LiveFrameRecord record;
  record.index = out.index;
  record.state = out.state;
  record.measured = track.measured;
  record.has_pose = out.has_pose;
  record.T_world_camera = out.T_world_camera;
  record.T_world_camera_true = out.T_world_camera_true;
  record.times = out.times;
  record.light_fit_loss = fit_loss;
  record.pixels_rewritten = out.pixels_rewritten;
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    record.t_s = std::chrono::duration<double>(out.captured - start_).count();
    records_.push_back(record);
    ++counters_.processed;
  }
  return out;
}

void LivePipeline::MarkDisplayed(const LiveFrame& frame) {
  const auto now = LiveClock::now();
  std::lock_guard<std::mutex> lock(stats_mutex_);
  ++counters_.displayed;
  const double t = std::chrono::duration<double>(now - start_).count();
  recent_display_s_.push_back(t);
  if (recent_display_s_.size() > 30) recent_display_s_.erase(recent_display_s_.begin());
  for (auto it = records_.rbegin(); it != records_.rend(); ++it)
    if (it->index == frame.index) {
      it->latency_ms = std::chrono::duration<double, std::milli>(now - frame.captured).count();
      break;
    }
}

std::optional<LiveFrame> LivePipeline::Step(std::chrono::milliseconds wait) {
  const auto give_up = LiveClock::now() + wait;
  do {
    bool end = false;
    std::optional<Captured> c = CaptureGuarded(end);
    if (end) {
      source_ended_.store(true);
      return std::nullopt;
    }
    if (c)
      if (std::optional<LiveFrame> f = ProcessGuarded(std::move(*c))) return f;
  } while (LiveClock::now() < give_up);
  return std::nullopt;
}

void LivePipeline::CaptureLoop() {
  while (!stop_.load()) {
    bool end = false;
    std::optional<Captured> c = CaptureGuarded(end);
    if (end) break;
    if (c) input_.Push(std::move(*c));
  }
  source_ended_.store(true);
  input_.Close();
}

void LivePipeline::ProcessLoop() {
  while (!stop_.load()) {
    std::optional<Captured> c = input_.Pop(std::chrono::milliseconds(100));
    if (!c) {
      if (input_.closed()) break;
      continue;
    }
    if (std::optional<LiveFrame> f = ProcessGuarded(std::move(*c))) output_.Push(std::move(*f));
  }
  output_.Close();
}

void LivePipeline::Start() {
  if (capture_thread_.joinable()) return;
  stop_.store(false);
  capture_thread_ = std::thread([this] { CaptureLoop(); });
  process_thread_ = std::thread([this] { ProcessLoop(); });
}

void LivePipeline::Stop() {
  stop_.store(true);
  if (capture_thread_.joinable()) capture_thread_.join();
  if (process_thread_.joinable()) process_thread_.join();
}

std::optional<LiveFrame> LivePipeline::TakeLatest(std::chrono::milliseconds timeout) { return output_.Pop(timeout); }

LiveCounters LivePipeline::counters() const {
  std::lock_guard<std::mutex> lock(stats_mutex_);
  LiveCounters c = counters_;
  c.dropped_before_process = input_.dropped();
  c.dropped_before_display = output_.dropped();
  return c;
}

std::vector<LiveFrameRecord> LivePipeline::records() const {
  std::lock_guard<std::mutex> lock(stats_mutex_);
  return records_;
}

double LivePipeline::mean_fps() const {
  std::lock_guard<std::mutex> lock(stats_mutex_);
  if (counters_.displayed < 2 || !have_start_) return 0;
  const double seconds = std::chrono::duration<double>(LiveClock::now() - start_).count();
  return seconds > 0 ? counters_.displayed / seconds : 0;
}

}  // namespace nerfar
