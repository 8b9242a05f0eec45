// The window side of `nerfar live`: shows the pipeline's newest frame (views
// chosen in the panel), turns input into edits (click on the AR or alongside
// view places the selected object on the scene surface under the cursor,
// drag moves it along the surface, keys and sliders rotate, scale and edit
// the material, preset switch), draws the ImGui panel (stage times, tracking
// state, latency, errors) and records video and screenshots into the session
// folder; a recording or screenshot that cannot be written is shown in the
// panel and counted by the pipeline, and the session goes on.
// Keys: Tab selects the next object, A/D rotate ±15°, W/S scale ×1.1 / ÷1.1,
// 1/2/3 preset fast / balanced / accurate, N alongside view, L layers, H HUD,
// R record on/off, P screenshot, Esc quit.
#pragma once

#include <exception>
#include <memory>
#include <optional>
#include <string>

#include "app/live/pipeline.h"
#include "app/live/window.h"

namespace nerfar {

class VideoWriter;

class LiveUi {
 public:
  // Loans: window and pipeline outlive this. Files go to session_dir.
  LiveUi(LiveWindow& window, LivePipeline& pipeline, std::string session_dir);
  ~LiveUi();

  // One display iteration: waits up to `wait` for a new frame, presents the
  // newest (or the last one again), applies the events. False once the user
  // closed the window (or the stream ended and nothing is left to show).
  bool Tick(std::chrono::milliseconds wait);
  void HandleEvent(const InputEvent& event);

  const std::optional<LiveFrame>& shown() const { return shown_; }
  size_t selected() const { return selected_; }
  int frames_shown() const { return frames_shown_; }
  void StartRecording();
  void StopRecording();
  bool recording() const { return video_ != nullptr; }
  // Saves the next presented window as SESSION/screenshot_NNN.png; returns its path.
  std::string Screenshot();

 private:
  void DrawPanel();
  // The selected object placed on the surface under view pixel (x, y),
  // marked as being dragged or not (LiveObjectState::dragging).
  void PlaceAt(int view, double x, double y, bool dragging);
  void EndDrag();  // no object dragged any more
  void ReportFailure(const std::string& what, const std::exception& e);

  LiveWindow& window_;
  LivePipeline& pipeline_;
  std::string session_dir_;
  std::optional<LiveFrame> shown_;
  int frames_shown_ = 0;
  size_t selected_ = 0;
  bool dragging_ = false;
  std::unique_ptr<VideoWriter> video_;
  std::string pending_screenshot_;
  int screenshots_ = 0;
  std::string status_;
  bool hud_ = true;
};

}  // namespace nerfar
