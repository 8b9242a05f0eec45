// The live display path (app/live/display.h) and the session report's
// pictures (app/live/report.h): the table-driven encoder gives the
// defining formula's code for every float tried; re-encoding only the
// pixels the insertion changed gives, pixel for pixel, what re-encoding the
// whole frame under the same rule gives; the HUD's cached text blends to
// what drawing it gives; the report's PNG and one-file HTML
// page exist and carry the session's series (stages, latency, jitter with
// the value the poses imply, tracking state, light refits).
#include <gtest/gtest.h>

#include <cfloat>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "app/live/display.h"
#include "app/live/report.h"
#include "app/live/report_plots.h"
#include "calib/core/image_io.h"
#include "calib/core/json.h"
#include "calib/core/media.h"
#include "calib/core/random.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

TEST(LiveDisplay, EncoderMatchesTheFormulaEverywhere) {
  for (const bool display : {false, true}) {
    const DisplayCodec codec(display);
    std::vector<float> xs = {0.0f,
                             -0.0f,
                             -1.0f,
                             1e-30f,
                             FLT_MIN,
                             FLT_MAX,
                             std::numeric_limits<float>::denorm_min(),
                             std::numeric_limits<float>::infinity(),
                             -std::numeric_limits<float>::infinity(),
                             std::numeric_limits<float>::quiet_NaN()};
    // Log-spaced over the range a frame holds, each with its float neighbours
    // (code boundaries fall between two adjacent floats).
    for (int i = 0; i <= 200000; ++i) {
      const float x = static_cast<float>(std::pow(10.0, -7.0 + 10.0 * i / 200000.0));
      xs.push_back(x);
      xs.push_back(std::nextafter(x, 0.0f));
      xs.push_back(std::nextafter(x, FLT_MAX));
    }
    for (int v = 0; v < 256; ++v) xs.push_back(codec.Linear(static_cast<std::uint8_t>(v)));
    size_t wrong = 0;
    size_t k = 0;
    for (const float x : xs) {
      const std::uint8_t truth = DisplayCodec::EncodeReference(x, display);
      // EncodeNear with hints at, next to and far from the right code.
      const std::uint8_t hints[] = {truth, static_cast<std::uint8_t>(truth + 1), static_cast<std::uint8_t>(truth - 1),
                                    static_cast<std::uint8_t>(k++ * 37)};
      bool ok = codec.Encode(x) == truth;
      for (const std::uint8_t h : hints) ok = ok && codec.EncodeNear(x, h) == truth;
      if (!ok && ++wrong <= 5)
        ADD_FAILURE() << "display=" << display << " x=" << x << ": " << int(codec.Encode(x)) << " vs " << int(truth);
    }
    EXPECT_EQ(wrong, 0u);
  }
}

// The rule written out for the whole frame: a pixel whose composite is
// still the camera's own linear value keeps the camera's code, any other
// is encoded from the composite by the formula.
Image8 FullFrameReference(const DisplayCodec& codec, const Image8& camera, const ImageF& composite, double gain) {
  const float inv_gain = static_cast<float>(1.0 / gain);
  Image8 out = camera;
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) {
      bool same = true;
      for (int c = 0; c < 3; ++c) same = same && composite.at(x, y, c) == codec.Linear(camera.at(x, y, c)) * inv_gain;
      if (same) continue;
      for (int c = 0; c < 3; ++c)
        out.at(x, y, c) =
            DisplayCodec::EncodeReference(static_cast<float>(composite.at(x, y, c) * gain), codec.display_response());
    }
  return out;
}

TEST(LiveDisplay, PartialPathEqualsTheFullReencode) {
  Rng rng(11, 3, 0, 0);
  for (const bool display : {false, true}) {
    const DisplayCodec codec(display);
    Image8 camera(97, 61, 3);
    for (auto& v : camera.pixels) v = static_cast<std::uint8_t>(rng.Uniform(0, 256));
    const double gain = 1.7;
    ImageF composite;
    codec.Linearise(camera, gain, composite);
    // The insertion's box: an object (new values), a shadow (values scaled
    // by κ < 1), pixels it left alone, a NaN it might have let through.
    const PixelRect touched{20, 10, 70, 50};
    for (int y = touched.y0; y < touched.y1; ++y)
      for (int x = touched.x0; x < touched.x1; ++x) {
        const double u = rng.Uniform(0, 1);
        for (int c = 0; c < 3; ++c) {
          float& v = composite.at(x, y, c);
          if (u < 0.3)
            v = static_cast<float>(rng.Uniform(0, 3));
          else if (u < 0.6)
            v *= static_cast<float>(rng.Uniform(0.2, 1.0));
        }
      }
    composite.at(30, 20, 1) = std::numeric_limits<float>::quiet_NaN();
    Image8 ar = camera;
    const size_t rewritten = CompositeToDisplay(codec, composite, gain, touched, ar);
    const Image8 reference = FullFrameReference(codec, camera, composite, gain);
    size_t differ = 0;
    for (size_t i = 0; i < ar.pixels.size(); ++i) differ += ar.pixels[i] != reference.pixels[i];
    EXPECT_EQ(differ, 0u) << "display=" << display;
    // About 60 % of the box changed; the rest was left as the camera's.
    EXPECT_GT(rewritten, touched.area() / 2);
    EXPECT_LT(rewritten, touched.area());
  }
}

TEST(LiveDisplay, GreyFramesLineariseAsRgb) {
  const DisplayCodec codec(false);
  Image8 grey(4, 2, 1);
  for (size_t i = 0; i < grey.pixels.size(); ++i) grey.pixels[i] = static_cast<std::uint8_t>(30 * i);
  ImageF linear;
  codec.Linearise(grey, 2.0, linear);
  ASSERT_EQ(linear.channels, 3);
  for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(linear.at(3, 1, c), codec.Linear(210) * 0.5f);
}

// The HUD's cached text blends to what drawing it directly gives, over any
// background, within the roundings of OpenCV's stroke-by-stroke blends.
TEST(LiveDisplay, TextOverlayMatchesDrawingTheText) {
  Rng rng(5, 1, 0, 0);
  Image8 frame(320, 60, 3);
  for (auto& v : frame.pixels) v = static_cast<std::uint8_t>(rng.Uniform(0, 256));
  const std::vector<std::string> lines = {"29.9 fps  latency 31 ms  tracking  tags 2",
                                          "ms: track 2.8  insert 19.7 (kappa 8.1)  views 0.0", "errors: (gj|)"};
  Image8 direct = frame;
  for (size_t i = 0; i < lines.size(); ++i) DrawText(direct, lines[i], 4, 4 + 13 * static_cast<int>(i));
  TextOverlay overlay;
  overlay.Set(lines, frame.width);
  Image8 cached = frame;
  overlay.Draw(cached);
  int worst = 0;
  size_t changed = 0;
  double sum = 0;
  for (size_t i = 0; i < frame.pixels.size(); ++i) {
    const int d = std::abs(int(cached.pixels[i]) - int(direct.pixels[i]));
    worst = std::max(worst, d);
    if (direct.pixels[i] != frame.pixels[i]) {
      ++changed;
      sum += d;
    }
  }
  // Each of OpenCV's overlapping anti-aliased strokes rounds its blend to a
  // level, the cached A + B·frame once: a few levels at worst where strokes
  // pile up, well under one on average over the text.
  EXPECT_LE(worst, 8);
  ASSERT_GT(changed, 1000u);  // the text is there
  EXPECT_LT(sum / changed, 0.5) << "mean |difference| over the text's " << changed << " channel values";
  // A frame of another width is left alone (the cache is for its width).
  Image8 other(200, 60, 3, 77);
  overlay.Draw(other);
  for (const auto v : other.pixels) ASSERT_EQ(v, 77);
}

std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

size_t Count(const std::string& text, const std::string& what) {
  size_t n = 0;
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

Json PoseAt(double x_m) { return {{"t", {x_m, 0.0, 0.5}}, {"R", {1, 0, 0, 0, 1, 0, 0, 0, 1}}}; }

// A session of 12 frames: camera x alternating ±1 mm about 0 (second
// difference 4 mm, so each frame's jitter is 4/√6 mm), frames 5-6 lost,
// light refits at frames 0 and 9.
void WriteSession(const std::string& dir) {
  Json frames = Json::array();
  for (int i = 0; i < 12; ++i) {
    const bool lost = i == 5 || i == 6;
    Json f = {{"index", i},
              {"state", lost ? "lost" : "tracking"},
              {"measured", !lost},
              {"t_s", i / 30.0},
              {"latency_ms", i == 3 ? Json(nullptr) : Json(20.0 + i)},
              {"ms",
               {{"capture", 1.0},
                {"track", 5.0},
                {"expose", 1.0},
                {"light", 0.0},
                {"fit", 0.0},
                {"raster", 2.0},
                {"shade", 3.0},
                {"occlusion", 1.0},
                {"kappa", 4.0},
                {"alongside", 0.0},
                {"layers", 0.0},
                {"display", 0.5},
                {"process", 17.5}}}};
    if (!lost) f["pose"] = PoseAt(i % 2 == 0 ? 0.001 : -0.001);
    if (i == 0 || i == 9) f["light_fit_loss"] = 0.01 * (i + 1);
    frames.push_back(f);
  }
  const Json session = {{"format", "nerfar-session"},
                        {"version", 1},
                        {"scene", ""},
                        {"camera", ""},
                        {"objects", Json::array()},
                        {"mode", "headless"},
                        {"wall_s", 0.4},
                        {"threads", 2},
                        {"counters", {{"captured", 12}, {"displayed", 11}}},
                        {"frames", frames}};
  WriteJsonFile(dir + "/session.json", session);
  Image8 ar(64, 36, 3, 90);
  WriteImage8(dir + "/last_ar.png", ar);
}

TEST(LiveReport, PngAndHtmlCarryTheSessionSeries) {
  testing::TempDir dir;
  WriteSession(dir.path());
  std::string report_dir;
  const Json report = BuildReport(dir.path(), &report_dir);
  WriteReport(report, report_dir);
  const Json& series = report.at("series");
  ASSERT_EQ(series.at("t_s").size(), 12u);
  EXPECT_DOUBLE_EQ(series["stages_ms"]["occlusion+kappa"][2].get<double>(), 5.0);
  EXPECT_DOUBLE_EQ(series["stages_ms"]["raster+shade"][2].get<double>(), 5.0);
  EXPECT_TRUE(series["latency_ms"][3].is_null());
  EXPECT_DOUBLE_EQ(series["latency_ms"][4].get<double>(), 24.0);
  // Jitter where a frame and both neighbours are measured: 4 mm / √6.
  EXPECT_NEAR(series["jitter_mm"][2].get<double>(), 4.0 / std::sqrt(6.0), 1e-9);
  EXPECT_TRUE(series["jitter_mm"][0].is_null());  // no frame before it
  EXPECT_TRUE(series["jitter_mm"][4].is_null());  // frame 5 lost
  EXPECT_TRUE(series["jitter_mm"][7].is_null());  // frame 6 lost
  EXPECT_EQ(series["state"][5].get<std::string>(), "lost");
  EXPECT_DOUBLE_EQ(series["light_fit_loss"][9].get<double>(), 0.1);
  EXPECT_TRUE(series["light_fit_loss"][8].is_null());

  ASSERT_TRUE(std::filesystem::is_regular_file(dir.File("report.png")));
  const Image8 page = ReadImage8(dir.File("report.png"));
  EXPECT_EQ(page.width, 1000);
  const std::string html = ReadAll(dir.File("report.html"));
  ASSERT_FALSE(html.empty());
  // One file: the view inline, nothing fetched from elsewhere.
  EXPECT_NE(html.find("src=\"data:image/png;base64,"), std::string::npos);
  EXPECT_EQ(html.find("src=\"http"), std::string::npos);
  EXPECT_EQ(html.find("href="), std::string::npos);
  EXPECT_EQ(Count(html, "<svg"), 4u);
  for (const char* name : {"track", "expose", "light+fit", "raster+shade", "occlusion+kappa", "display", "latency",
                           "jitter", "tracking", "lost"})
    EXPECT_NE(html.find(std::string("data-name=\"") + name + "\""), std::string::npos) << name;
  EXPECT_EQ(Count(html, "<circle class=\"series\" data-name=\"refit\""), 2u);
  // The latency line breaks where frame 3 was never displayed: two pieces.
  EXPECT_EQ(Count(html, "data-name=\"latency\""), 2u);
  EXPECT_NE(html.find("pose vs truth"), std::string::npos);
}

TEST(LiveReport, Base64AndEscaping) {
  EXPECT_EQ(Base64({}), "");
  EXPECT_EQ(Base64({'f'}), "Zg==");
  EXPECT_EQ(Base64({'f', 'o'}), "Zm8=");
  EXPECT_EQ(Base64({'f', 'o', 'o', 'b', 'a', 'r'}), "Zm9vYmFy");
  EXPECT_EQ(HtmlEscape("a<b & \"c\">"), "a&lt;b &amp; &quot;c&quot;&gt;");
}

}  // namespace
}  // namespace nerfar
