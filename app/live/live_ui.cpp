#include "app/live/live_ui.h"

#include <imgui.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <vector>

#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "calib/core/image_io.h"
#include "calib/core/log.h"
#include "calib/core/media.h"

namespace nerfar {

namespace fs = std::filesystem;

namespace {
constexpr double kRotateStepRad = 15.0 * kPi / 180.0;
constexpr double kScaleStep = 1.1;
}  // namespace

LiveUi::LiveUi(LiveWindow& window, LivePipeline& pipeline, std::string session_dir)
    : window_(window), pipeline_(pipeline), session_dir_(std::move(session_dir)) {}

LiveUi::~LiveUi() { StopRecording(); }

void LiveUi::ReportFailure(const std::string& what, const std::exception& e) {
  status_ = what + " failed: " + e.what();
  pipeline_.ReportOutputError(e.what());
}

void LiveUi::StartRecording() {
  if (video_ || !shown_) return;
  const std::string path = (fs::path(session_dir_) / "recording.mp4").string();
  try {
    MakeDirectories(session_dir_);
    video_ = std::make_unique<VideoWriter>(path, shown_->ar.width, shown_->ar.height, 30.0);
    status_ = "recording to " + path;
  } catch (const std::exception& e) {
    ReportFailure("recording", e);
  }
}

void LiveUi::StopRecording() {
  if (!video_) return;
  try {
    video_->Close();
    status_ = "recorded " + std::to_string(video_->frames_written()) + " frames";
  } catch (const std::exception& e) {
    ReportFailure("recording", e);
  }
  video_.reset();
}

std::string LiveUi::Screenshot() {
  // The next free name: a screenshot never replaces a file already there.
  std::error_code error;
  do {
    char name[64];
    std::snprintf(name, sizeof name, "screenshot_%03d.png", screenshots_++);
    pending_screenshot_ = (fs::path(session_dir_) / name).string();
  } while (fs::exists(pending_screenshot_, error));
  window_.RequestScreenshot();
  return pending_screenshot_;
}

void LiveUi::PlaceAt(int view, double x, double y, bool dragging) {
  if (!shown_ || pipeline_.object_count() == 0) return;
  if (view == 1 && (pipeline_.views() & kViewAlongside)) {
    // The alongside view is the AR camera at a smaller size.
    const double s = static_cast<double>(shown_->ar.width) / std::max(1, shown_->alongside.width);
    x *= s;
    y *= s;
  } else if (view != 0) {
    return;
  }
  const std::optional<Vec3> hit = pipeline_.PickSurface(*shown_, x, y);
  if (!hit) {
    status_ = "no surface under the cursor";
    return;
  }
  LiveObjectState state = pipeline_.object(selected_);
  state.placed = true;
  state.anchor_world = *hit;
  state.dragging = dragging;
  pipeline_.set_object(selected_, state);
  char text[128];
  std::snprintf(text, sizeof text, "placed at (%.3f, %.3f, %.3f) m", hit->x, hit->y, hit->z);
  status_ = text;
}

void LiveUi::EndDrag() {
  // Every object, in case the selection changed during the drag (Tab).
  for (size_t i = 0; i < pipeline_.object_count(); ++i) {
    LiveObjectState state = pipeline_.object(i);
    if (!state.dragging) continue;
    state.dragging = false;
    pipeline_.set_object(i, state);
  }
}

void LiveUi::HandleEvent(const InputEvent& e) {
  switch (e.kind) {
    case InputEvent::Kind::kPress:
      if (e.button == 0 && e.view >= 0) {
        PlaceAt(e.view, e.x, e.y, true);
        dragging_ = true;
      }
      break;
    case InputEvent::Kind::kDrag:
      if (dragging_ && e.view >= 0) PlaceAt(e.view, e.x, e.y, true);
      break;
    case InputEvent::Kind::kRelease:
      if (dragging_) EndDrag();
      dragging_ = false;
      break;
    case InputEvent::Kind::kScroll: {
      if (pipeline_.object_count() == 0) break;
      LiveObjectState s = pipeline_.object(selected_);
      s.scale *= std::pow(kScaleStep, e.scroll);
      pipeline_.set_object(selected_, s);
      break;
    }
    case InputEvent::Kind::kKey: {
      const int k = e.key;
      if (k == kKeyEscape) window_.RequestClose();
      if (pipeline_.object_count() > 0 && (k == 'A' || k == 'D' || k == 'W' || k == 'S')) {
        LiveObjectState s = pipeline_.object(selected_);
        if (k == 'A') s.yaw_rad -= kRotateStepRad;
        if (k == 'D') s.yaw_rad += kRotateStepRad;
        if (k == 'W') s.scale *= kScaleStep;
        if (k == 'S') s.scale /= kScaleStep;
        pipeline_.set_object(selected_, s);
      }
      if (k == kKeyTab && pipeline_.object_count() > 0) {
        selected_ = (selected_ + 1) % pipeline_.object_count();
        status_ = "selected " + pipeline_.object_name(selected_);
      }
      if (k == '1') pipeline_.set_preset("fast");
      if (k == '2') pipeline_.set_preset("balanced");
      if (k == '3') pipeline_.set_preset("accurate");
      if (k == 'N') pipeline_.set_views(pipeline_.views() ^ kViewAlongside);
      if (k == 'L') pipeline_.set_views(pipeline_.views() ^ kViewLayers);
      if (k == 'R') video_ ? StopRecording() : StartRecording();
      if (k == 'P') status_ = "screenshot " + Screenshot();
      if (k == 'H') {
        hud_ = !hud_;
        pipeline_.set_hud(hud_);
      }
      break;
    }
  }
}

void LiveUi::DrawPanel() {
  ImGui::SetNextWindowPos(ImVec2(8, 8), ImGuiCond_FirstUseEver);
  ImGui::SetNextWindowSize(ImVec2(300, 0), ImGuiCond_FirstUseEver);
  ImGui::SetNextWindowCollapsed(true, ImGuiCond_FirstUseEver);
  ImGui::Begin("nerfar live");
  if (shown_) {
    const LiveFrame& f = *shown_;
    ImGui::Text("%.1f fps  state %s  tags %d", pipeline_.mean_fps(), TrackingStateName(f.state), f.tags_used);
    ImGui::Text("latency %.0f ms (capture to this display)",
                std::chrono::duration<double, std::milli>(LiveClock::now() - f.captured).count());
    for (const auto& [name, ms] : StageList(f.times)) ImGui::Text("  %-10s %7.2f ms", name.c_str(), ms);
    const LiveCounters c = pipeline_.counters();
    ImGui::Text("dropped: %llu before processing, %llu before display", (unsigned long long)c.dropped_before_process,
                (unsigned long long)c.dropped_before_display);
    if (c.frame_errors + c.source_errors + c.output_errors > 0)
      ImGui::Text("errors: %llu frames, %llu source (%llu reconnections), %llu outputs",
                  (unsigned long long)c.frame_errors, (unsigned long long)c.source_errors,
                  (unsigned long long)c.reconnects, (unsigned long long)c.output_errors);
  }
  if (pipeline_.source_lost()) ImGui::TextWrapped("camera lost: opening it again...");
  int views = pipeline_.views();
  bool alongside = views & kViewAlongside, layers = views & kViewLayers;
  if (ImGui::Checkbox("alongside (N)", &alongside)) pipeline_.set_views(views ^ kViewAlongside);
  ImGui::SameLine();
  if (ImGui::Checkbox("layers (L)", &layers)) pipeline_.set_views(pipeline_.views() ^ kViewLayers);
  const char* presets[] = {"fast", "balanced", "accurate"};
  const std::string current = pipeline_.preset();
  int preset = current == "fast" ? 0 : (current == "balanced" ? 1 : 2);
  if (ImGui::Combo("preset", &preset, presets, 3)) pipeline_.set_preset(presets[preset]);
  if (pipeline_.object_count() > 1) {
    // Which object clicks, keys and sliders act on (Tab cycles).
    std::vector<const char*> names;
    for (size_t i = 0; i < pipeline_.object_count(); ++i) names.push_back(pipeline_.object_name(i).c_str());
    int selected = static_cast<int>(selected_);
    if (ImGui::Combo("object (Tab)", &selected, names.data(), static_cast<int>(names.size())))
      selected_ = static_cast<size_t>(selected);
  }
  if (pipeline_.object_count() > 0) {
    LiveObjectState s = pipeline_.object(selected_);
    bool changed = false;
    float yaw_deg = static_cast<float>(s.yaw_rad * 180 / kPi), scale = static_cast<float>(s.scale);
    float colour[3] = {static_cast<float>(s.material.base_color.x), static_cast<float>(s.material.base_color.y),
                       static_cast<float>(s.material.base_color.z)};
    float roughness = static_cast<float>(s.material.roughness), metallic = static_cast<float>(s.material.metallic);
    changed |= ImGui::SliderFloat("yaw (A/D)", &yaw_deg, -180, 180, "%.0f deg");
    changed |= ImGui::SliderFloat("scale (W/S)", &scale, 0.1f, 5.0f, "%.2f", ImGuiSliderFlags_Logarithmic);
    changed |= ImGui::ColorEdit3("base colour", colour);
    changed |= ImGui::SliderFloat("roughness", &roughness, 0.02f, 1.0f);
    changed |= ImGui::SliderFloat("metallic", &metallic, 0.0f, 1.0f);
    if (changed) {
      s.yaw_rad = yaw_deg * kPi / 180;
      s.scale = scale;
      s.material.base_color = {colour[0], colour[1], colour[2]};
      s.material.roughness = roughness;
      s.material.metallic = metallic;
      pipeline_.set_object(selected_, s);
    }
    if (!s.placed) ImGui::TextWrapped("click the scene to place the object");
  }
  if (ImGui::Button(video_ ? "stop recording (R)" : "record (R)")) video_ ? StopRecording() : StartRecording();
  ImGui::SameLine();
  if (ImGui::Button("screenshot (P)")) status_ = "screenshot " + Screenshot();
  if (!status_.empty()) ImGui::TextWrapped("%s", status_.c_str());
  ImGui::End();
}

bool LiveUi::Tick(std::chrono::milliseconds wait) {
  if (window_.ShouldClose()) return false;
  std::optional<LiveFrame> frame = pipeline_.TakeLatest(wait);
  if (frame) {
    shown_ = std::move(frame);
    ++frames_shown_;
  } else if (!shown_ && pipeline_.finished()) {
    return false;
  }
  std::vector<const Image8*> views;
  Image8 waiting;
  if (shown_) {
    views.push_back(&shown_->ar);
    if ((pipeline_.views() & kViewAlongside) && !shown_->alongside.empty()) views.push_back(&shown_->alongside);
    if ((pipeline_.views() & kViewLayers) && !shown_->layers.empty()) views.push_back(&shown_->layers);
  } else {
    waiting = Image8(320, 240, 3, 30);
    DrawText(waiting, "waiting for the first frame...", 8, 8);
    views.push_back(&waiting);
  }
  // A redraw without a new frame (the panel, the cursor) keeps the textures.
  const std::vector<InputEvent> events = window_.Present(
      views, [this] { DrawPanel(); }, frame.has_value() || !shown_);
  if (frame) {
    pipeline_.MarkDisplayed(*shown_);
    if (video_) {
      try {
        video_->Write(shown_->ar);
      } catch (const std::exception& e) {
        ReportFailure("recording", e);
        video_.reset();
      }
    }
  }
  if (!pending_screenshot_.empty()) {
    if (std::optional<Image8> shot = window_.TakeScreenshot()) {
      try {
        MakeDirectories(session_dir_);
        WriteImage8(pending_screenshot_, *shot);
        LogInfo("live: wrote " + pending_screenshot_);
      } catch (const std::exception& e) {
        ReportFailure("screenshot", e);
      }
      pending_screenshot_.clear();
    }
  }
  for (const InputEvent& e : events) HandleEvent(e);
  return !window_.ShouldClose();
}

}  // namespace nerfar
