// The live window under Xvfb: views are drawn where they should be, and real
// X mouse events (sent with xdotool) arrive as clicks and drags in the view's
// own pixel coordinates.
#include "app/live/window.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>

#include "app/live/live_ui.h"
#include "app/live/pipeline.h"
#include "calib/core/image_io.h"
#include "render/lighting/scene_field.h"
#include "render/mesh/mesh.h"
#include "render/synth/camera_stream.h"
#include "tests/app/live_scene.h"
#include "tests/support/analytic_scene.h"
#include "tests/support/support.h"
#include "tracking/frame_sources.h"

namespace nerfar {
namespace {

// A 200x100 view: dark grey with a pure red 20x20 square at (150..170, 40..60).
Image8 TestView() {
  Image8 image(200, 100, 3, 40);
  for (int y = 40; y < 60; ++y)
    for (int x = 150; x < 170; ++x) {
      image.at(x, y, 0) = 255;
      image.at(x, y, 1) = 0;
      image.at(x, y, 2) = 0;
    }
  return image;
}

// Under ctest (NERFAR_REQUIRE_DISPLAY=1, tests/CMakeLists.txt) a display
// that is not there and a missing xdotool are failures: CI's virtual display
// that did not start must not pass as skipped tests. Run by hand without a
// display, the tests skip.
bool DisplayRequired() {
  const char* required = std::getenv("NERFAR_REQUIRE_DISPLAY");
  return required != nullptr && std::string(required) == "1";
}

#define NERFAR_REQUIRE(available, what)        \
  do {                                         \
    if (!(available)) {                        \
      if (DisplayRequired()) FAIL() << (what); \
      GTEST_SKIP() << (what);                  \
    }                                          \
  } while (0)

bool XdotoolInstalled() { return std::system("command -v xdotool >/dev/null 2>&1") == 0; }

class WindowTest : public ::testing::Test {
 protected:
  void SetUp() override {
    NERFAR_REQUIRE(LiveWindow::DisplayAvailable(), "no display (run under xvfb-run; its X server did not start?)");
  }
};

TEST_F(WindowTest, DrawsTheViewScaledToFitAndScreenshotsIt) {
  LiveWindow window("nerfar window test", 400, 200);
  const Image8 view = TestView();
  window.Present({&view}, nullptr);
  window.RequestScreenshot();
  window.Present({&view}, nullptr);
  const std::optional<Image8> taken = window.TakeScreenshot();
  ASSERT_TRUE(taken.has_value());
  EXPECT_FALSE(window.TakeScreenshot().has_value());  // handed over once
  const Image8& shot = *taken;
  ASSERT_EQ(shot.width, 400);
  ASSERT_EQ(shot.height, 200);
  // The 200x100 view fills the 400x200 window at scale 2: the square's centre
  // (160, 50) is at window pixel (320, 100).
  double wx = 0, wy = 0;
  ASSERT_TRUE(window.ViewToWindow(0, 160, 50, wx, wy));
  EXPECT_NEAR(wx, 320, 1e-9);
  EXPECT_NEAR(wy, 100, 1e-9);
  EXPECT_GT(shot.at(320, 100, 0), 200);
  EXPECT_LT(shot.at(320, 100, 1), 50);
  EXPECT_LT(shot.at(100, 100, 0), 80);  // grey background of the view
}

// A view is uploaded once per new frame: a redraw marked unchanged shows
// the texture as uploaded (even if the image was since written over, which
// the caller promised it was not), a new frame in the same image shows its
// new pixels, and an image of another size is uploaded even when marked
// unchanged.
TEST_F(WindowTest, ViewsAreUploadedOncePerNewFrame) {
  LiveWindow window("nerfar window test", 400, 200);
  Image8 view = TestView();
  const auto square_at_centre = [&](bool new_views) {
    window.RequestScreenshot();
    window.Present({&view}, nullptr, new_views);
    const std::optional<Image8> shot = window.TakeScreenshot();
    EXPECT_TRUE(shot.has_value());
    return shot ? std::array<int, 3>{shot->at(320, 100, 0), shot->at(320, 100, 1), shot->at(320, 100, 2)}
                : std::array<int, 3>{};
  };
  EXPECT_GT(square_at_centre(true)[0], 200);  // red, uploaded
  for (int y = 40; y < 60; ++y)
    for (int x = 150; x < 170; ++x) {
      view.at(x, y, 0) = 0;
      view.at(x, y, 1) = 255;
    }
  EXPECT_GT(square_at_centre(false)[0], 200);  // still the red uploaded: no upload
  const std::array<int, 3> green = square_at_centre(true);
  EXPECT_LT(green[0], 50);
  EXPECT_GT(green[1], 200);
  view = Image8(100, 50, 3, 250);              // another size, marked unchanged
  EXPECT_GT(square_at_centre(false)[2], 200);  // uploaded all the same: white
}

TEST_F(WindowTest, RealMouseEventsArriveInViewPixels) {
  NERFAR_REQUIRE(XdotoolInstalled(), "xdotool not installed");
  LiveWindow window("nerfar input test", 400, 200);
  const Image8 view = TestView();
  window.Present({&view}, nullptr);
  // Press at view pixel (50, 25) = window (100, 50), drag to (150, 75) = window (300, 150).
  const std::string id = "$(xdotool search --sync --name 'nerfar input test' | head -n 1)";
  const std::string command =
      "xdotool mousemove --window " + id + " 100 50 mousedown 1 mousemove --window " + id + " 300 150 mouseup 1";
  ASSERT_EQ(std::system(("sh -c \"" + command + "\"").c_str()), 0);
  std::vector<InputEvent> events;
  for (int i = 0; i < 50 && (events.empty() || events.back().kind != InputEvent::Kind::kRelease); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    for (const InputEvent& e : window.Present({&view}, nullptr)) events.push_back(e);
  }
  ASSERT_GE(events.size(), 2u);
  EXPECT_EQ(events.front().kind, InputEvent::Kind::kPress);
  EXPECT_EQ(events.front().view, 0);
  // One window pixel is half a view pixel; X positions are integers.
  EXPECT_NEAR(events.front().x, 50, 0.5);
  EXPECT_NEAR(events.front().y, 25, 0.5);
  EXPECT_EQ(events.back().kind, InputEvent::Kind::kRelease);
  EXPECT_NEAR(events.back().x, 150, 0.5);
  EXPECT_NEAR(events.back().y, 75, 0.5);
}

// --- The live app in the window: the synthetic stream (lamps mat, camera
// nearly still) tracked from its tags, an analytic table (plane z = 0, the
// stream's table top) as the scene, a red ball placed by a real click and
// moved by a real drag.

// Pixels whose colour differs by more than 40 levels in some channel between
// two screenshots, inside [x0, x1) x [y0, y1): their centroid and count.
struct Blob {
  double x = 0, y = 0;
  int count = 0;
};
Blob DiffBlob(const Image8& a, const Image8& b, int x0, int y0, int x1, int y1) {
  Blob blob;
  for (int y = std::max(0, y0); y < std::min(a.height, y1); ++y)
    for (int x = std::max(0, x0); x < std::min(a.width, x1); ++x) {
      int d = 0;
      for (int c = 0; c < 3; ++c) d = std::max(d, std::abs(a.at(x, y, c) - b.at(x, y, c)));
      if (d > 40) {
        blob.x += x + 0.5;
        blob.y += y + 0.5;
        ++blob.count;
      }
    }
  if (blob.count > 0) {
    blob.x /= blob.count;
    blob.y /= blob.count;
  }
  return blob;
}

class LiveAppTest : public WindowTest {
 protected:
  static constexpr double kRadius = 0.04;  // the ball, metres

  void SetUp() override {
    WindowTest::SetUp();
    if (IsSkipped() || HasFatalFailure()) return;
    NERFAR_REQUIRE(XdotoolInstalled(), "xdotool not installed");
    source_ = std::make_unique<synth::SyntheticCameraSource>(NearlyStillLampsStream());
    scene_ = std::make_unique<testing::AnalyticScene>(testing::PlainTable());
    ball_ = MakeUvSphere(kRadius, 32, 16);
    LiveAsset asset;
    asset.name = "ball";
    asset.mesh = &ball_;
    asset.material.base_color = {0.9, 0.02, 0.02};
    asset.material.roughness = 0.6;
    LiveOptions options;
    options.response = "display";
    options.hud = false;  // the HUD's numbers change every frame
    options.tracker.confirm_frames = 0;
    options.render_divisor = 2;
    const SgMixture sky = {Sg{{0, 0, 1}, 3.0, {3.0, 3.0, 3.0}}};
    // A second object, not placed (nothing of it is drawn): Tab selects it.
    cube_ = MakeBox({0.03, 0.03, 0.03});
    LiveAsset cube = asset;
    cube.name = "cube";
    cube.mesh = &cube_;
    pipeline_ = std::make_unique<LivePipeline>(*source_, source_->board(), source_->camera(), *scene_, sky,
                                               std::vector<LiveAsset>{asset, cube}, options);
  }

  // Ticks until `done` holds (at most ~20 s; frames keep coming meanwhile).
  template <typename Done>
  bool TickUntil(LiveUi& ui, Done done) {
    for (int i = 0; i < 400; ++i) {
      ui.Tick(std::chrono::milliseconds(50));
      if (done()) return true;
    }
    return false;
  }
  // A screenshot of the next presented frame that was processed after `since`.
  Image8 Shot(LiveWindow& window, LiveUi& ui) {
    const int start = ui.frames_shown();
    TickUntil(ui, [&] { return ui.frames_shown() >= start + 3; });  // frames rendered after any edit
    window.RequestScreenshot();
    ui.Tick(std::chrono::milliseconds(50));
    std::optional<Image8> shot = window.TakeScreenshot();
    return shot ? *shot : Image8();
  }
  // Where the ball's centre shows in window pixels when it stands on the
  // table under view pixel (x, y), from the stream's true pose (independent
  // of the tracker and the pipeline's picking).
  bool ExpectedCentre(LiveWindow& window, const LiveFrame& frame, double x, double y, double& wx, double& wy) {
    const Pose pose = *frame.T_world_camera_true;
    const CameraIntrinsics camera = source_->camera().Scaled(320, 240);  // the AR view's size
    const Vec3 d = pose.Rotate(Unproject(camera, {x, y}));
    const double t = -pose.translation.z / d.z;  // the ray meets the table z = 0
    const Vec3 centre = pose.translation + d * t + Vec3{0, 0, kRadius};
    Vec2 pixel;
    if (!Project(camera, pose.Inverse() * centre, pixel)) return false;
    return window.ViewToWindow(0, pixel.x, pixel.y, wx, wy);
  }

  std::unique_ptr<synth::SyntheticCameraSource> source_;
  std::unique_ptr<testing::AnalyticScene> scene_;
  TriangleMesh ball_, cube_;
  std::unique_ptr<LivePipeline> pipeline_;
};

TEST_F(LiveAppTest, ClickPlacesTheObjectWhereClickedAndDragMovesIt) {
  testing::TempDir dir;
  LiveWindow window("nerfar live test", 640, 480);
  LiveUi ui(window, *pipeline_, dir.path());
  pipeline_->Start();
  ASSERT_TRUE(TickUntil(ui, [&] { return ui.shown() && ui.shown()->state == TrackingState::kTracking; }))
      << "the synthetic stream was never tracked";
  const Image8 without = Shot(window, ui);
  ASSERT_FALSE(without.empty());
  // The 320x240 AR view fills the 640x480 window at scale 2.
  const double view_x = 210, view_y = 150;  // bare table top in this stream's first second (seed 1)
  double click_x = 0, click_y = 0;
  ASSERT_TRUE(window.ViewToWindow(0, view_x, view_y, click_x, click_y));
  const std::string id = "$(xdotool search --sync --name 'nerfar live test' | head -n 1)";
  const auto xdotool = [&](const std::string& actions) {
    return std::system(("sh -c \"xdotool " + actions + "\"").c_str());
  };
  ASSERT_EQ(xdotool("mousemove --window " + id + " " + std::to_string(int(click_x)) + " " +
                    std::to_string(int(click_y)) + " click 1"),
            0);
  ASSERT_TRUE(TickUntil(ui, [&] { return pipeline_->object(0).placed; })) << "the click did not place the ball";
  const Image8 with = Shot(window, ui);
  ASSERT_FALSE(with.empty());
  // Compare within 80 window px of the click (the ball is ~50 px across; the
  // stream's one-sample shading noise differs between frames elsewhere).
  const int cx = int(click_x), cy = int(click_y);
  const Blob placed = DiffBlob(without, with, cx - 80, cy - 80, cx + 80, cy + 80);
  if (std::getenv("NERFAR_WINDOW_TEST_DUMP")) {
    WriteImage8(std::string(std::getenv("NERFAR_WINDOW_TEST_DUMP")) + "/without.png", without);
    WriteImage8(std::string(std::getenv("NERFAR_WINDOW_TEST_DUMP")) + "/with.png", with);
  }
  // A 4 cm ball at ~0.9 m is ~25 view px across = ~1900 window pixels at scale 2.
  ASSERT_GT(placed.count, 400) << "no object in the screenshot";
  double expect_x = 0, expect_y = 0;
  ASSERT_TRUE(ExpectedCentre(window, *ui.shown(), int(click_x) / 2.0, int(click_y) / 2.0, expect_x, expect_y));
  // Tolerance 8 window px (4 view px): the tracked pose against the true one
  // (~1 px), the silhouette's centroid against the projected centre of a
  // ball seen obliquely (~1-2 px), shading making part of the lower rim close
  // to the table's colour (~2 px).
  std::printf("ball centroid (%.1f, %.1f), expected from the true pose (%.1f, %.1f), %d px\n", placed.x, placed.y,
              expect_x, expect_y, placed.count);
  EXPECT_NEAR(placed.x, expect_x, 8) << "clicked at " << click_x << "," << click_y;
  EXPECT_NEAR(placed.y, expect_y, 8);

  // Drag it 100 window px to the right along the table.
  const int from_x = int(placed.x), from_y = int(placed.y) + 10;
  ASSERT_EQ(xdotool("mousemove --window " + id + " " + std::to_string(from_x) + " " + std::to_string(from_y) +
                    " mousedown 1 mousemove --window " + id + " " + std::to_string(from_x + 50) + " " +
                    std::to_string(from_y) + " mousemove --window " + id + " " + std::to_string(from_x + 100) + " " +
                    std::to_string(from_y)),
            0);
  const Vec3 before = pipeline_->object(0).anchor_world;
  ASSERT_TRUE(TickUntil(ui, [&] { return Length(pipeline_->object(0).anchor_world - before) > 0.02; }))
      << "the drag did not move the ball";
  // Marked dragged while the button is down (its light held), no longer once released.
  EXPECT_TRUE(pipeline_->object(0).dragging);
  ASSERT_EQ(xdotool("mouseup 1"), 0);
  ASSERT_TRUE(TickUntil(ui, [&] { return !pipeline_->object(0).dragging; })) << "the release did not end the drag";
  const Image8 dragged = Shot(window, ui);
  const Blob moved = DiffBlob(without, dragged, from_x + 100 - 80, from_y - 80, from_x + 100 + 80, from_y + 80);
  ASSERT_GT(moved.count, 400);
  // The ball follows the cursor: its centroid moved right by about the drag
  // (perspective changes the step a little), and hardly up or down.
  std::printf("after the drag: (%.1f, %.1f)\n", moved.x, moved.y);
  EXPECT_GT(moved.x - placed.x, 60) << placed.x << " -> " << moved.x;
  EXPECT_LT(moved.x - placed.x, 140);
  EXPECT_NEAR(moved.y, placed.y, 20);
  pipeline_->Stop();
  // The latency of the shown frames was measured (capture to display).
  int measured = 0;
  for (const LiveFrameRecord& r : pipeline_->records()) measured += r.latency_ms >= 0;
  EXPECT_GT(measured, 0);
}

TEST_F(LiveAppTest, KeysTakeAScreenshotToggleRecordingAndQuit) {
  testing::TempDir dir;
  LiveWindow window("nerfar keys test", 640, 480);
  LiveUi ui(window, *pipeline_, dir.path());
  pipeline_->Start();
  ASSERT_TRUE(TickUntil(ui, [&] { return ui.shown().has_value(); })) << "no frame shown";
  // Real key presses through the X server (XTEST) to the focused window.
  const std::string id = "$(xdotool search --sync --name 'nerfar keys test' | head -n 1)";
  const auto key = [&](const std::string& name) {
    return std::system(("sh -c \"xdotool windowfocus --sync " + id + " key " + name + "\"").c_str());
  };

  // P: the next presented window is saved as SESSION/screenshot_000.png, as
  // large as the window (the views and the panel as the user sees them).
  const std::string shot = dir.File("screenshot_000.png");
  ASSERT_EQ(key("p"), 0);
  ASSERT_TRUE(TickUntil(ui, [&] { return std::filesystem::is_regular_file(shot); })) << "P wrote no screenshot";
  const Image8 image = ReadImage8(shot);
  EXPECT_EQ(image.width, 640);
  EXPECT_EQ(image.height, 480);

  // R starts recording, R again stops it: SESSION/recording.mp4 holds every
  // frame shown in between (a frame is written when it is shown; the key is
  // handled after the frame of its tick), at the AR view's size.
  ASSERT_EQ(key("r"), 0);
  ASSERT_TRUE(TickUntil(ui, [&] { return ui.recording(); })) << "R did not start recording";
  const int started = ui.frames_shown();
  ASSERT_TRUE(TickUntil(ui, [&] { return ui.frames_shown() >= started + 5; }));
  ASSERT_EQ(key("r"), 0);
  ASSERT_TRUE(TickUntil(ui, [&] { return !ui.recording(); })) << "R did not stop recording";
  const int recorded = ui.frames_shown() - started;
  std::unique_ptr<FrameSource> video = OpenFrameSource("video:" + dir.File("recording.mp4"));
  Frame f;
  int count = 0;
  while (video->Next(f, 1000) == FrameStatus::kOk) {
    EXPECT_EQ(f.image.width, 320);
    EXPECT_EQ(f.image.height, 240);
    ++count;
  }
  EXPECT_EQ(count, recorded);
  EXPECT_GE(count, 5);

  // Tab selects the next object; W (scale) then acts on it alone.
  ASSERT_EQ(ui.selected(), 0u);
  ASSERT_EQ(key("Tab"), 0);
  ASSERT_TRUE(TickUntil(ui, [&] { return ui.selected() == 1; })) << "Tab did not select the second object";
  ASSERT_EQ(key("w"), 0);
  ASSERT_TRUE(TickUntil(ui, [&] { return pipeline_->object(1).scale > 1.05; })) << "W did not scale the selected one";
  EXPECT_NEAR(pipeline_->object(1).scale, 1.1, 1e-12);
  EXPECT_EQ(pipeline_->object(0).scale, 1.0);
  ASSERT_EQ(key("Tab"), 0);
  ASSERT_TRUE(TickUntil(ui, [&] { return ui.selected() == 0; }));

  // Esc closes the window: Tick says so.
  ASSERT_EQ(key("Escape"), 0);
  EXPECT_TRUE(TickUntil(ui, [&] { return window.ShouldClose(); })) << "Esc did not close the window";
  pipeline_->Stop();
}

// A session folder that cannot be made (its parent is a file): recording and
// screenshots fail, are counted as output errors, and frames keep coming.
TEST_F(LiveAppTest, ARecordingOrScreenshotThatCannotBeWrittenIsReportedAndTheSessionGoesOn) {
  testing::TempDir dir;
  testing::WriteText(dir.File("a_file"), "not a folder");
  LiveWindow window("nerfar failing outputs test", 640, 480);
  LiveUi ui(window, *pipeline_, dir.File("a_file/session"));
  pipeline_->Start();
  ASSERT_TRUE(TickUntil(ui, [&] { return ui.shown().has_value(); })) << "no frame shown";
  ui.StartRecording();
  EXPECT_FALSE(ui.recording());
  ui.Screenshot();
  ASSERT_TRUE(TickUntil(ui, [&] { return pipeline_->counters().output_errors >= 2; }))
      << "the screenshot's failure was not reported";
  const int shown = ui.frames_shown();
  EXPECT_TRUE(TickUntil(ui, [&] { return ui.frames_shown() >= shown + 3; })) << "frames stopped after the failures";
  pipeline_->Stop();
  const std::vector<LiveError> errors = pipeline_->errors();
  ASSERT_EQ(errors.size(), 2u);
  for (const LiveError& e : errors) {
    EXPECT_EQ(e.stage, "output");
    EXPECT_NE(e.what.find(dir.File("a_file/session")), std::string::npos) << e.what;
  }
}

}  // namespace
}  // namespace nerfar
