// The live window under Xvfb: views are drawn where they should be, and real
// X mouse events (sent with xdotool) arrive as clicks and drags in the view's
// own pixel coordinates.
#include "app/live/window.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>

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

class WindowTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!LiveWindow::DisplayAvailable()) GTEST_SKIP() << "no display (run under xvfb-run)";
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

TEST_F(WindowTest, RealMouseEventsArriveInViewPixels) {
  if (std::system("command -v xdotool >/dev/null 2>&1") != 0) GTEST_SKIP() << "xdotool not installed";
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

}  // namespace
}  // namespace nerfar

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
