// The live window: GLFW + OpenGL 3.3 core, showing one or more 8-bit views
// side by side (AR overlay, the NeRF "alongside" view, layers) with a Dear
// ImGui control panel drawn by the caller. Mouse input is reported in the
// pixel coordinates of the view under the cursor, so the caller never deals
// with window scaling. GLFW, GL and ImGui types stay in window.cpp; the
// caller's control panel includes imgui.h itself.
#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "calib/core/image.h"

namespace nerfar {

struct InputEvent {
  enum class Kind { kPress, kDrag, kRelease, kScroll, kKey };
  Kind kind = Kind::kPress;
  int view = -1;        // index of the view under the cursor, -1 if none
  double x = 0, y = 0;  // continuous pixel coordinates in that view's image
  int button = 0;       // 0 left, 1 right, 2 middle
  double scroll = 0;    // wheel steps (kScroll)
  int key = 0;          // ASCII upper-case letter or digit, or a KeyCode below
  bool shift = false, control = false;
};

enum KeyCode { kKeyEscape = 256, kKeyTab = 258, kKeyF1 = 290 };

class LiveWindow {
 public:
  // Opens a window; throws std::runtime_error with a plain message when no
  // display can be opened (the caller then runs headless).
  LiveWindow(const std::string& title, int width, int height);
  ~LiveWindow();
  LiveWindow(const LiveWindow&) = delete;
  LiveWindow& operator=(const LiveWindow&) = delete;

  // True if a display is available at all (DISPLAY set and GLFW can start).
  static bool DisplayAvailable();

  bool ShouldClose() const;
  void RequestClose();
  // Draws the views side by side (each scaled to fit, aspect kept) and the
  // caller's ImGui panel, then presents. Events received since the last call
  // are returned (ImGui consumes those over its own widgets). `new_views`
  // false: the views are the images of the last call, unchanged, and their
  // textures are drawn as uploaded then (a view whose image or size differs
  // is uploaded all the same); true: each is uploaded, once.
  std::vector<InputEvent> Present(const std::vector<const Image8*>& views, const std::function<void()>& draw_controls,
                                  bool new_views = true);
  // The next Present() also captures what it shows (RGB, as the user sees
  // it, panel included); TakeScreenshot() hands it over once.
  void RequestScreenshot();
  std::optional<Image8> TakeScreenshot();
  // Window-space cursor position of a view pixel (for tests that inject input).
  bool ViewToWindow(int view, double x, double y, double& window_x, double& window_y) const;
  // Injects a mouse event as if the user did it (tests, scripted demos).
  void InjectMouse(InputEvent::Kind kind, double window_x, double window_y, int button = 0);

  struct Impl;  // GLFW/GL state, defined in window.cpp (public for its callbacks)

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace nerfar
