// calib/core: EXR and PNG round trips, strict JSON, atomic files, the binary
// container, the --set option parser, math, threads, tone mapping and metrics.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <climits>
#include <cmath>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <nlohmann/json.hpp>
#include <opencv2/videoio.hpp>
#include <string>
#include <vector>

#include "calib/core/atomic_file.h"
#include "calib/core/binary_file.h"
#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "calib/core/image_io.h"
#include "calib/core/json.h"
#include "calib/core/log.h"
#include "calib/core/math.h"
#include "calib/core/media.h"
#include "calib/core/metrics.h"
#include "calib/core/option_fields.h"
#include "calib/core/output_guard.h"
#include "calib/core/parallel.h"
#include "tests/support/support.h"

// The file-system calls of an AtomicFile commit, in order: this program's own
// fsync and rename stand in for the C library's (the static core library
// resolves to them at link time), record what they were called on while
// g_recording is set, and then do the real system call.
namespace {
std::mutex g_calls_mutex;
bool g_recording = false;
std::vector<std::string> g_calls;  // "fsync PATH", "rename FROM -> TO"

std::string PathOfDescriptor(int fd) {
  char target[PATH_MAX] = {};
  const std::string link = "/proc/self/fd/" + std::to_string(fd);
  const ssize_t n = ::readlink(link.c_str(), target, sizeof target - 1);
  return n > 0 ? std::string(target, static_cast<size_t>(n)) : "?";
}

void Record(const std::string& call) {
  std::lock_guard<std::mutex> lock(g_calls_mutex);
  if (g_recording) g_calls.push_back(call);
}
}  // namespace

extern "C" int fsync(int fd) {
  Record("fsync " + PathOfDescriptor(fd));
  return static_cast<int>(::syscall(SYS_fsync, fd));
}

extern "C" int rename(const char* from, const char* to) {
  Record(std::string("rename ") + from + " -> " + to);
  return static_cast<int>(::syscall(SYS_renameat, AT_FDCWD, from, AT_FDCWD, to));
}

namespace nerfar {
namespace {

using testing::InputErrorOf;
using testing::TempDir;

ImageF Ramp(int w, int h, int c) {
  ImageF image(w, h, c);
  for (size_t i = 0; i < image.pixels.size(); ++i) image.pixels[i] = 1e-3f * std::pow(1.02f, float(i % 700));
  return image;
}

TEST(Exr, FloatRoundTripIsExact) {
  TempDir dir;
  const ImageF image = Ramp(17, 9, 3);
  WriteExrRgb(dir.File("a.exr"), image, ExrPixelType::kFloat);
  const ImageF back = ReadExrRgb(dir.File("a.exr"));
  ASSERT_EQ(back.width, 17);
  ASSERT_EQ(back.height, 9);
  EXPECT_EQ(back.pixels, image.pixels);
}

TEST(Exr, HalfRoundTripKeepsThreeDigits) {
  TempDir dir;
  const ImageF image = Ramp(31, 7, 3);
  WriteExrRgb(dir.File("h.exr"), image);
  const ImageF back = ReadExrRgb(dir.File("h.exr"));
  for (size_t i = 0; i < image.pixels.size(); ++i)
    // half has a 10-bit mantissa: relative rounding error <= 2^-11 ≈ 4.9e-4.
    EXPECT_NEAR(back.pixels[i], image.pixels[i], image.pixels[i] * 4.9e-4) << i;
}

TEST(Exr, RadianceBeyondHalfRangeRoundTripsExactly) {
  TempDir dir;
  // A lamp filament of 1e6 in an otherwise ordinary frame; half tops out at
  // 65504 (1e6 would be written as inf), so the file must hold floats.
  ImageF image = Ramp(8, 4, 3);
  image.at(5, 2, 1) = 1e6f;
  image.at(1, 3, 0) = -7e4f;
  for (const ExrPixelType asked : {ExrPixelType::kHalf, ExrPixelType::kFloat}) {
    WriteExrRgb(dir.File("bright.exr"), image, asked);
    const ImageF back = ReadExrRgb(dir.File("bright.exr"));
    EXPECT_EQ(back.pixels, image.pixels);
  }
  // One channel (the Y of depth or κ layers) likewise.
  ImageF depth(3, 2, 1, 2.0f);
  depth.pixels[4] = 1e6f;
  WriteExr(dir.File("y.exr"), depth, {"Y"});
  EXPECT_EQ(ReadExrChannel(dir.File("y.exr")).pixels, depth.pixels);
}

TEST(Exr, AnyChannelsInRequestedOrder) {
  TempDir dir;
  ImageF image(4, 3, 2);
  for (size_t i = 0; i < image.pixels.size(); ++i) image.pixels[i] = float(i);
  WriteExr(dir.File("c.exr"), image, {"depth", "alpha"}, ExrPixelType::kFloat);
  EXPECT_EQ(ReadExrChannelNames(dir.File("c.exr")), (std::vector<std::string>{"alpha", "depth"}));
  const ImageF swapped = ReadExr(dir.File("c.exr"), {"alpha", "depth"});
  EXPECT_EQ(swapped.at(1, 2, 0), image.at(1, 2, 1));
  EXPECT_EQ(swapped.at(1, 2, 1), image.at(1, 2, 0));
  EXPECT_EQ(ReadExrChannel(dir.File("c.exr"), "depth").at(3, 1), image.at(3, 1, 0));
  EXPECT_NE(InputErrorOf([&] { ReadExrChannel(dir.File("c.exr")); }).find("exactly one"), std::string::npos);
}

TEST(Exr, RgbaDropsAlphaAndGreyReplicates) {
  TempDir dir;
  ImageF rgba(2, 2, 4, 0.5f);
  rgba.at(1, 1, 3) = 0.25f;
  WriteExrRgb(dir.File("rgba.exr"), rgba, ExrPixelType::kFloat);
  EXPECT_EQ(ReadExrRgb(dir.File("rgba.exr")).channels, 3);
  ImageF grey(2, 1, 1);
  grey.pixels = {0.25f, 4.0f};
  WriteExr(dir.File("y.exr"), grey, {"Y"}, ExrPixelType::kFloat);
  const ImageF rgb = ReadExrRgb(dir.File("y.exr"));
  EXPECT_EQ(rgb.at(1, 0, 0), 4.0f);
  EXPECT_EQ(rgb.at(1, 0, 2), 4.0f);
}

TEST(Exr, BadFilesGiveErrorsNamingTheFile) {
  TempDir dir;
  WriteExrRgb(dir.File("good.exr"), Ramp(64, 64, 3));
  const auto size = std::filesystem::file_size(dir.File("good.exr"));
  for (size_t cut : {size_t{0}, size_t{3}, size_t{40}, size_t{200}, size / 2, size - 1}) {
    testing::WriteTruncatedCopy(dir.File("good.exr"), dir.File("cut.exr"), cut);
    const std::string message = InputErrorOf([&] { ReadExrRgb(dir.File("cut.exr")); });
    EXPECT_NE(message.find("cut.exr"), std::string::npos) << "cut at " << cut << ": '" << message << "'";
  }
  testing::WriteText(dir.File("text.exr"), "this is not an image");
  EXPECT_NE(InputErrorOf([&] { ReadExrRgb(dir.File("text.exr")); }).find("text.exr"), std::string::npos);
  EXPECT_NE(InputErrorOf([&] { ReadExrRgb(dir.File("missing.exr")); }).find("no such file"), std::string::npos);
  EXPECT_NE(InputErrorOf([&] { ReadExr(dir.File("good.exr"), {"Z"}); }).find("missing channel 'Z'"), std::string::npos);
}

TEST(Exr, NonFinitePixelsAreRejectedWithTheirPosition) {
  TempDir dir;
  ImageF image(5, 4, 3, 1.0f);
  image.at(3, 2, 1) = std::numeric_limits<float>::quiet_NaN();
  image.at(4, 3, 0) = std::numeric_limits<float>::infinity();
  WriteExrRgb(dir.File("nan.exr"), image, ExrPixelType::kFloat);
  const std::string message = InputErrorOf([&] { ReadExrRgb(dir.File("nan.exr")); });
  EXPECT_NE(message.find("2 non-finite values, first at pixel (3, 2)"), std::string::npos) << message;
}

TEST(Exr, WriteNeverLeavesTemporaryFiles) {
  TempDir dir;
  WriteExrRgb(dir.File("x.exr"), Ramp(3, 3, 3));
  WriteExrRgb(dir.File("x.exr"), Ramp(3, 3, 3));
  size_t files = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(dir.path())) ++files;
  EXPECT_EQ(files, 1u);
}

TEST(Png, RoundTripRgbAndGrey) {
  TempDir dir;
  Image8 rgb(5, 3, 3);
  for (size_t i = 0; i < rgb.pixels.size(); ++i) rgb.pixels[i] = static_cast<std::uint8_t>(i * 11);
  WriteImage8(dir.File("a.png"), rgb);
  EXPECT_EQ(ReadImage8(dir.File("a.png")).pixels, rgb.pixels);
  Image8 grey(4, 4, 1, 200);
  WriteImage8(dir.File("g.png"), grey);
  const Image8 back = ReadImage8(dir.File("g.png"));
  EXPECT_EQ(back.channels, 1);
  EXPECT_EQ(back.pixels, grey.pixels);
  testing::WriteText(dir.File("bad.png"), "\x89PNG garbage");
  EXPECT_NE(InputErrorOf([&] { ReadImage8(dir.File("bad.png")); }).find("bad.png"), std::string::npos);
}

TEST(ToneMap, ReinhardThenSrgbMatchesHandComputedValues) {
  ImageF image(3, 1, 1);
  image.pixels = {0.0f, 1.0f, 3.0f};
  const Image8 out = ToneMapToDisplay(image, 1.0f);
  // tm(1) = 0.5 -> sRGB 0.7354 -> 187.5; tm(3) = 0.75 -> sRGB 0.8808 -> 224.6.
  EXPECT_EQ(out.pixels[0], 0);
  EXPECT_NEAR(out.pixels[1], 188, 1);
  EXPECT_NEAR(out.pixels[2], 225, 1);
  for (float v : {0.0f, 0.001f, 0.2f, 0.5f, 1.0f}) EXPECT_NEAR(SrgbToLinear(LinearToSrgb(v)), v, 1e-6f);
}

TEST(Media, ContactSheetPlacesTilesInAGrid) {
  std::vector<Image8> tiles;
  for (std::uint8_t v : {50, 100, 150}) tiles.emplace_back(40, 20, 3, v);
  const Image8 sheet = ContactSheet(tiles, 2, 20);
  // 2 columns of 20 px + 3 gutters of 4 px; 2 rows of 10 px + 3 gutters.
  ASSERT_EQ(sheet.width, 52);
  ASSERT_EQ(sheet.height, 32);
  EXPECT_EQ(sheet.at(4 + 10, 4 + 5, 0), 50);
  EXPECT_EQ(sheet.at(28 + 10, 4 + 5, 0), 100);
  EXPECT_EQ(sheet.at(4 + 10, 18 + 5, 0), 150);
  EXPECT_EQ(sheet.at(28 + 10, 18 + 5, 0), 24);  // empty cell shows the background
}

TEST(Media, VideoFileHasEveryFrame) {
  TempDir dir;
  {
    VideoWriter video(dir.File("v.avi"), 64, 48, 10.0);
    for (int f = 0; f < 7; ++f) video.Write(Image8(64, 48, 3, static_cast<std::uint8_t>(30 * f)));
    video.Close();
    EXPECT_EQ(video.frames_written(), 7);
  }
  ASSERT_TRUE(std::filesystem::exists(dir.File("v.avi")));
  // Read back with OpenCV's decoder (independent of our writer).
  cv::VideoCapture capture(dir.File("v.avi"));
  ASSERT_TRUE(capture.isOpened());
  int frames = 0;
  cv::Mat frame;
  while (capture.read(frame)) {
    // MJPG is lossy: a flat grey frame decodes within a few levels.
    EXPECT_NEAR(frame.at<cv::Vec3b>(24, 32)[1], 30 * frames, 4) << frames;
    ++frames;
  }
  EXPECT_EQ(frames, 7);
}

TEST(Metrics, PsnrTmOfAKnownOffset) {
  // Truth constant 1 -> k = 1, tm = 0.5. Estimate 3 -> tm = 0.75: MSE 0.0625 = 12.04 dB.
  ImageF truth(8, 8, 3, 1.0f), estimate(8, 8, 3, 3.0f);
  EXPECT_NEAR(PsnrTm(estimate, truth), -10.0 * std::log10(0.0625), 1e-9);
  EXPECT_TRUE(std::isinf(PsnrTm(truth, truth)));
  ImageF mask(8, 8, 1, 0.0f);
  EXPECT_TRUE(std::isnan(PsnrTm(estimate, truth, &mask)));
  mask.at(2, 2) = 1.0f;
  estimate.at(2, 2, 0) = estimate.at(2, 2, 1) = estimate.at(2, 2, 2) = 1.0f;
  EXPECT_TRUE(std::isinf(PsnrTm(estimate, truth, &mask)));
}

TEST(Metrics, PooledPsnrIsThePsnrOfAllPixelsTogether) {
  // Two masked "views" of one truth (k = 1): 4 pixels off by tm 0.25 (MSE
  // 0.0625) and 12 pixels exact but one channel of one pixel off by 0.25.
  // Together: squared errors 4·3·0.0625 + 0.0625 over 16·3 values.
  ImageF truth(8, 8, 3, 1.0f), estimate = truth;
  ImageF first(8, 8, 1, 0.0f), second(8, 8, 1, 0.0f), both(8, 8, 1, 0.0f);
  for (int i = 0; i < 4; ++i) {
    first.at(i, 0) = both.at(i, 0) = 1.0f;
    for (int c = 0; c < 3; ++c) estimate.at(i, 0, c) = 3.0f;  // tm 0.75 against 0.5
  }
  for (int i = 0; i < 12; ++i) second.at(i % 8, 1 + i / 8) = both.at(i % 8, 1 + i / 8) = 1.0f;
  estimate.at(0, 1, 0) = 3.0f;
  const double expected = -10.0 * std::log10((4 * 3 * 0.0625 + 0.0625) / 48.0);
  const double pooled = PooledPsnr({PsnrTm(estimate, truth, &first), PsnrTm(estimate, truth, &second)}, {4, 12});
  EXPECT_NEAR(pooled, expected, 1e-9);
  EXPECT_NEAR(pooled, PsnrTm(estimate, truth, &both), 1e-9);  // the same as one mask over both
  // An exact view (infinite psnr) adds pixels without error; a view without
  // pixels or with a NaN psnr is left out; none left: NaN.
  EXPECT_NEAR(PooledPsnr({PsnrTm(estimate, truth, &first), INFINITY, 5.0, NAN}, {4, 12, 0, 7}),
              -10.0 * std::log10(4 * 0.0625 / 16.0), 1e-9);
  EXPECT_TRUE(std::isinf(PooledPsnr({INFINITY}, {3})));
  EXPECT_TRUE(std::isnan(PooledPsnr({NAN, 3.0}, {3, 0})));
}

TEST(Json, SyntaxErrorsNameLineAndColumn) {
  const std::string message = InputErrorOf([] { ParseJson("{\n  \"a\": 1,\n  \"b\": ]\n}", "x.json"); });
  EXPECT_NE(message.find("x.json: line 3, column"), std::string::npos) << message;
}

TEST(Json, OutOfRangeNumbersAreInputErrors) {
  // Found by the fuzzer: 1e400 overflows double and is not a syntax error.
  const std::string message = InputErrorOf([] { ParseJson(R"({"w": 1e400})", "big.json"); });
  EXPECT_NE(message.find("big.json: line 1"), std::string::npos) << message;
}

TEST(Json, ReaderCollectsEveryProblemWithPointers) {
  const Json doc = ParseJson(
      R"({"w": 400, "h": "300", "fl": [1, 2], "tpyo": 1, "m": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0]]})", "t.json");
  Problems problems("t.json");
  JsonObjectReader reader(doc, "", problems);
  EXPECT_EQ(reader.Integer("w", 1, 100000), 400);
  reader.Integer("h", 1, 100000);
  reader.Numbers("fl", 3);
  reader.Number("cx");
  reader.Matrix4("m");
  reader.Finish();
  const std::string message = InputErrorOf([&] { problems.ThrowIfAny(); });
  EXPECT_NE(message.find("t.json: /h: is string (expected an integer)"), std::string::npos) << message;
  EXPECT_NE(message.find("/fl: is array of 2 (expected an array of 3 numbers)"), std::string::npos) << message;
  EXPECT_NE(message.find("/cx: missing"), std::string::npos) << message;
  EXPECT_NE(message.find("/tpyo: unknown key"), std::string::npos) << message;
  EXPECT_NE(message.find("/m/3: is not a row of 4 numbers"), std::string::npos) << message;
}

TEST(Json, RangesAndOptionalKeys) {
  const Json doc = ParseJson(R"({"r": 1.5, "note": "doc only"})", "o.json");
  Problems problems("o.json");
  JsonObjectReader reader(doc, "/obj", problems);
  reader.Allow({"note"});
  reader.Number("r", 0.0, 1.0);
  EXPECT_FALSE(reader.OptionalNumber("k1").has_value());
  reader.Finish();
  ASSERT_EQ(problems.items().size(), 1u);
  EXPECT_NE(problems.items()[0].find("/obj/r: is 1.5"), std::string::npos);
}

TEST(Json, WriteIsAtomicAndReadable) {
  TempDir dir;
  WriteJsonFile(dir.File("a.json"), Json{{"x", 1.5}});
  EXPECT_EQ(ReadJsonFile(dir.File("a.json"))["x"].get<double>(), 1.5);
}

TEST(AtomicFile, UncommittedWritesLeaveTheTargetAlone) {
  TempDir dir;
  testing::WriteText(dir.File("t.txt"), "old");
  {
    AtomicFile file(dir.File("t.txt"));
    testing::WriteText(file.temp_path(), "new");
  }
  EXPECT_EQ(testing::ReadText(dir.File("t.txt")), "old");
  WriteFileAtomic(dir.File("t.txt"), "new");
  EXPECT_EQ(testing::ReadText(dir.File("t.txt")), "new");
}

TEST(AtomicFile, CommitFlushesTheFileBeforeTheRenameAndTheFolderAfter) {
  TempDir dir;
  const std::string canonical_dir = std::filesystem::canonical(dir.path()).string();
  {
    std::lock_guard<std::mutex> lock(g_calls_mutex);
    g_calls.clear();
    g_recording = true;
  }
  std::string temp;
  {
    AtomicFile file(dir.File("data.bin"));
    temp = std::filesystem::path(file.temp_path()).filename().string();
    testing::WriteText(file.temp_path(), "payload");
    file.Commit();
  }
  std::vector<std::string> calls;
  {
    std::lock_guard<std::mutex> lock(g_calls_mutex);
    g_recording = false;
    calls = g_calls;
  }
  // Data on disk before the name points at it; the name itself on disk after.
  const std::vector<std::string> expected = {
      "fsync " + canonical_dir + "/" + temp,
      "rename " + dir.File(temp) + " -> " + dir.File("data.bin"),
      "fsync " + canonical_dir,
  };
  EXPECT_EQ(calls, expected);
  EXPECT_EQ(testing::ReadText(dir.File("data.bin")), "payload");
}

TEST(AtomicFile, AFailedCommitRemovesTheTemporaryFileAndNamesTheTarget) {
  TempDir dir;
  std::filesystem::create_directories(dir.File("target_is_a_folder/inside"));
  std::string message;
  try {
    WriteFileAtomic(dir.File("target_is_a_folder"), "x");
  } catch (const std::runtime_error& e) {
    message = e.what();
  }
  EXPECT_NE(message.find(dir.File("target_is_a_folder")), std::string::npos) << message;
  size_t entries = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(dir.path())) ++entries;
  EXPECT_EQ(entries, 1u) << "only the folder itself: no temporary file left";
}

// What a SIGINT / SIGTERM handler does before the process ends (app/stop_signal.cpp).
extern "C" void RemoveTemporaryFilesOnSignal(int) { RemoveTemporaryFiles(); }

TEST(AtomicFile, ASignalHandlerRemovesTheTemporaryFilesOfWritesInProgress) {
  TempDir dir;
  AtomicFile first(dir.File("a.exr")), second(dir.File("b.json"));
  testing::WriteText(first.temp_path(), "half an image");
  testing::WriteText(second.temp_path(), "{\"half\":");
  testing::WriteText(dir.File("kept.txt"), "a finished file");
  // The temporary name keeps the extension (writers that pick a format by it).
  EXPECT_EQ(std::filesystem::path(first.temp_path()).extension(), ".exr");
  auto* previous = std::signal(SIGUSR1, RemoveTemporaryFilesOnSignal);
  std::raise(SIGUSR1);
  std::signal(SIGUSR1, previous);
  EXPECT_FALSE(std::filesystem::exists(first.temp_path()));
  EXPECT_FALSE(std::filesystem::exists(second.temp_path()));
  EXPECT_EQ(testing::ReadText(dir.File("kept.txt")), "a finished file");
}

TEST(AtomicFile, ReadRefusesFilesOverTheLimit) {
  TempDir dir;
  testing::WriteText(dir.File("in.txt"), "x");
  EXPECT_THROW(ReadFileBytes(dir.File("in.txt"), 0), InputError);
  EXPECT_EQ(ReadFileBytes(dir.File("in.txt"), 1), "x");
}

// The message of the guard's refusal for these lists ("" when it accepts them).
std::string GuardMessage(const std::vector<std::string>& outputs, const std::vector<std::string>& inputs) {
  return InputErrorOf([&] { CheckOutputsSpareInputs(outputs, inputs); });
}

TEST(OutputGuard, AnOutputThatIsAnInputIsRefusedNamingBoth) {
  TempDir dir;
  MakeDirectories(dir.File("in"));
  testing::WriteText(dir.File("in/a.exr"), "a");
  const std::string message = GuardMessage({dir.File("out.json"), dir.File("in/a.exr")}, {dir.File("in/a.exr")});
  EXPECT_NE(message.find("would overwrite the input"), std::string::npos) << message;
  EXPECT_EQ(message.rfind(dir.File("in/a.exr") + ": ", 0), 0u) << message;
  // Nothing shared: accepted; empty paths (options not given) are ignored.
  EXPECT_EQ(GuardMessage({dir.File("out.json"), ""}, {dir.File("in/a.exr"), ""}), "");
}

TEST(OutputGuard, TheSameFileIsFoundThroughRelativePathsLinksAndHardLinks) {
  TempDir dir;
  MakeDirectories(dir.File("in"));
  testing::WriteText(dir.File("in/a.exr"), "a");
  // Dot segments and a relative path from the current folder.
  const std::string relative =
      std::filesystem::relative(dir.File("in/a.exr"), std::filesystem::current_path()).string();
  EXPECT_NE(GuardMessage({dir.File("in/./../in/a.exr")}, {relative}), "");
  // A symbolic link to the file, and an output inside a linked folder.
  std::filesystem::create_symlink(dir.File("in/a.exr"), dir.File("link.exr"));
  std::filesystem::create_directory_symlink(dir.File("in"), dir.File("linked_dir"));
  EXPECT_NE(GuardMessage({dir.File("link.exr")}, {dir.File("in/a.exr")}), "");
  EXPECT_NE(GuardMessage({dir.File("linked_dir/a.exr")}, {dir.File("in/a.exr")}), "");
  // A hard link: another name, the same file.
  std::filesystem::create_hard_link(dir.File("in/a.exr"), dir.File("hard.exr"));
  EXPECT_NE(GuardMessage({dir.File("hard.exr")}, {dir.File("in/a.exr")}), "");
  // A file that does not exist yet beside the input is not the input.
  EXPECT_EQ(GuardMessage({dir.File("linked_dir/b.exr")}, {dir.File("in/a.exr")}), "");
}

TEST(OutputGuard, AFolderInputStandsForItsFilesAndOutputsMustBeDistinct) {
  TempDir dir;
  MakeDirectories(dir.File("frames"));
  testing::WriteText(dir.File("frames/r_000.png"), "p");
  const std::vector<std::string> written = FilesIn(dir.File("frames"), {"r_000.exr", "r_000.png"});
  ASSERT_EQ(written.size(), 2u);
  EXPECT_EQ(written[1], dir.File("frames") + "/r_000.png");
  const std::string message = GuardMessage(written, {dir.File("frames")});
  EXPECT_NE(message.find(dir.File("frames/r_000.png")), std::string::npos) << message;
  EXPECT_EQ(GuardMessage(FilesIn(dir.File("frames"), {"r_000.exr"}), {dir.File("frames")}), "");
  const std::string twice = GuardMessage({dir.File("env.json"), dir.File("./env.json")}, {});
  EXPECT_NE(twice.find("two outputs"), std::string::npos) << twice;
}

TEST(Math, AxisAngleRoundTripOverStratifiedRotations) {
  for (int i = 0; i < 200; ++i) {
    const double angle = kPi * (i + 0.5) / 200.0;  // up to just below pi
    const Vec3 axis{std::cos(i * 0.7), std::sin(i * 1.3), 0.3 * std::cos(i * 2.1)};
    const Mat3 r = RotationFromAxisAngle(axis, angle);
    const Vec3 w = AxisAngleFromRotation(r);
    EXPECT_NEAR(Length(w), angle, 1e-6) << i;
    EXPECT_LT(RotationAngleBetween(r, RotationFromAxisAngle(w, Length(w))), 1e-6) << i;
  }
}

TEST(Math, PoseComposesAndInverts) {
  const Pose T_a_b{RotationFromAxisAngle({0, 0, 1}, 0.5), {1, 2, 3}};
  const Pose T_b_c{RotationFromAxisAngle({1, 0, 0}, -0.25), {0.5, 0, -1}};
  const Vec3 p_c{0.1, -0.2, 0.3};
  const Vec3 direct = (T_a_b * T_b_c) * p_c, chained = T_a_b * (T_b_c * p_c);
  EXPECT_NEAR(Length(direct - chained), 0.0, 1e-12);
  EXPECT_NEAR(Length((T_a_b.Inverse() * T_a_b) * p_c - p_c), 0.0, 1e-12);
  const Pose back = Pose::FromMatrix4(T_a_b.ToMatrix4());
  EXPECT_NEAR(Length(back * p_c - T_a_b * p_c), 0.0, 1e-12);
}

TEST(Math, LookAtHasNoRollAndSeesTheTarget) {
  // From (0,-1,0) towards the origin: forward +y, right +x, image down -z.
  const Pose pose = LookAt({0, -1, 0}, {0, 0, 0});
  EXPECT_NEAR(Length(pose.rotation.Column(0) - Vec3{1, 0, 0}), 0, 1e-12);
  EXPECT_NEAR(Length(pose.rotation.Column(1) - Vec3{0, 0, -1}), 0, 1e-12);
  EXPECT_NEAR(Length(pose.rotation.Column(2) - Vec3{0, 1, 0}), 0, 1e-12);
  // Any target lands on the optical axis; x stays horizontal; straight down is defined.
  const Pose tilted = LookAt({0.3, -0.8, 0.9}, {0.05, 0.02, 0});
  const Vec3 p_camera = tilted.Inverse() * Vec3{0.05, 0.02, 0};
  EXPECT_NEAR(p_camera.x, 0, 1e-12);
  EXPECT_NEAR(p_camera.y, 0, 1e-12);
  EXPECT_GT(p_camera.z, 0);
  EXPECT_NEAR(tilted.rotation.Column(0).z, 0, 1e-12);
  EXPECT_NEAR(Length(LookAt({0, 0, 1}, {0, 0, 0}).rotation.Column(0) - Vec3{1, 0, 0}), 0, 1e-12);
}

TEST(Parallel, ChunksCoverEveryIndexOnceForAnyThreadCount) {
  for (int threads : {1, 2}) {
    SetThreadCount(threads);
    std::vector<int> hits(10007, 0);
    ParallelFor(
        hits.size(), [&](size_t i) { hits[i]++; }, 100);
    for (int h : hits) ASSERT_EQ(h, 1);
  }
  SetThreadCount(0);
}

TEST(Checks, InvariantFailuresPrintBothValues) {
  try {
    NERFAR_CHECK_EQ(2 + 2, 5);
    FAIL() << "no throw";
  } catch (const InvariantError& e) {
    EXPECT_NE(std::string(e.what()).find("(4 vs 5)"), std::string::npos) << e.what();
  }
}

TEST(Log, DurationsReadNaturally) {
  EXPECT_EQ(FormatDuration(0.25), "250ms");
  EXPECT_EQ(FormatDuration(12.34), "12.3s");
  EXPECT_EQ(FormatDuration(65), "1m05s");
}

// ---- the binary container (calib/core/binary_file.h)

// Versions 1 and 2 flat, 3 sectioned.
constexpr BinaryFormat kTestFormat{"test file", "NERFTEST", true, 1, 3, 3, "make it again"};

std::string LittleEndian32(uint32_t v) { return std::string(reinterpret_cast<const char*>(&v), 4); }
std::string LittleEndian64(uint64_t v) { return std::string(reinterpret_cast<const char*>(&v), 8); }

// A version-3 test file: section AAAA holds u16 0x0201 and 1.0f, ZZZZ the byte 7.
std::string TwoSectionFile() {
  BinaryFileWriter w(kTestFormat, 3);
  ByteWriter& a = w.Section("AAAA");
  a.Put(uint16_t{0x0201});
  a.PutArray(std::vector<float>{1.0f});
  w.Section("ZZZZ").Put(uint8_t{7});
  return std::move(w).Seal();
}

TEST(BinaryFile, LegacyChecksumIsFnv1aFromTheFormatsBasis) {
  // FNV-1a: h = (h ^ byte) · 1099511628211 per byte, from the flat formats' basis (binary_file.h).
  constexpr uint64_t kBasis = 1469598103934665603ull, kPrime = 1099511628211ull;
  EXPECT_EQ(LegacyFnv1aChecksum(""), kBasis);
  EXPECT_EQ(LegacyFnv1aChecksum("a"), (kBasis ^ 0x61) * kPrime);
  EXPECT_EQ(LegacyFnv1aChecksum("ab"), (((kBasis ^ 0x61) * kPrime) ^ 0x62) * kPrime);
  EXPECT_NE(LegacyFnv1aChecksum("ab"), LegacyFnv1aChecksum("ba"));
}

TEST(BinaryFile, Crc32IsTheStandardOne) {
  // The published check value of CRC-32 (ISO-HDLC, zlib's): "123456789" -> 0xCBF43926.
  EXPECT_EQ(BinaryCrc32("123456789"), 0xCBF43926u);
  EXPECT_EQ(BinaryCrc32(""), 0u);
}

TEST(BinaryFile, WriterLaysOutHeaderTableSectionsCrc) {
  const std::string bytes = TwoSectionFile();
  const std::string a = std::string("\x01\x02", 2) + std::string("\x00\x00\x80\x3f", 4);  // 1.0f, little-endian
  const std::string body = std::string("NERFTEST") + LittleEndian32(3) + LittleEndian32(2) + "AAAA" +
                           LittleEndian64(6) + "ZZZZ" + LittleEndian64(1) + a + "\x07";
  ASSERT_EQ(bytes.size(), body.size() + 4);
  EXPECT_EQ(bytes.substr(0, body.size()), body);
  EXPECT_EQ(bytes.substr(body.size()), LittleEndian32(BinaryCrc32(body)));
}

TEST(BinaryFile, SectionsReadByTagUnknownOnesSkippedMissingOnesNamed) {
  const std::string bytes = TwoSectionFile();
  const BinaryFile file = OpenBinaryFile(bytes, "t.bin", kTestFormat);
  EXPECT_EQ(file.version, 3u);
  EXPECT_TRUE(file.sectioned());
  EXPECT_EQ(file.fields.remaining(), 0u) << "a sectioned file has no flat fields";
  ByteReader a = file.Section("AAAA");  // ZZZZ is never asked for: skipped
  EXPECT_EQ(a.remaining(), 6u) << "exactly the section's bytes";
  EXPECT_EQ(a.Get<uint16_t>("u16"), 0x0201u);
  EXPECT_EQ(a.Get<float>("f32"), 1.0f);
  // Past its end, even though the file goes on (ZZZZ, the crc): named with the byte in the file,
  // 16 header + 24 table + 6.
  const std::string past = InputErrorOf([&] { a.Get<uint8_t>("more"); });
  EXPECT_NE(past.find("t.bin: file is truncated while reading more at byte 46"), std::string::npos) << past;
  EXPECT_TRUE(file.HasSection("ZZZZ"));
  EXPECT_FALSE(file.HasSection("BBBB"));
  const std::string missing = InputErrorOf([&] { file.Section("BBBB"); });
  EXPECT_NE(missing.find("t.bin: no 'BBBB' section"), std::string::npos) << missing;
}

TEST(BinaryFile, OpenNamesAWrongMagicANewerVersionCorruptionAndTruncation) {
  const std::string good = TwoSectionFile();
  std::string magic = good;
  magic[3] = 'X';
  EXPECT_NE(InputErrorOf([&] { OpenBinaryFile(magic, "t.bin", kTestFormat); }).find("not a test file"),
            std::string::npos);
  std::string newer = good;
  newer[8] = 4;  // the crc no longer matches either: the version is named first
  const std::string newer_message = InputErrorOf([&] { OpenBinaryFile(newer, "t.bin", kTestFormat); });
  EXPECT_NE(newer_message.find("version 4 (expected 1 to 3; written by a newer nerfar?)"), std::string::npos)
      << newer_message;
  // A flipped byte anywhere (header, table, a section, the crc itself) is corruption, by the crc.
  for (size_t at : {size_t{13}, size_t{16}, size_t{42}, good.size() - 1}) {
    std::string flipped = good;
    flipped[at] ^= 0x10;
    const std::string message = InputErrorOf([&] { OpenBinaryFile(flipped, "t.bin", kTestFormat); });
    EXPECT_NE(message.find("t.bin: crc32 mismatch (the file is corrupt; make it again)"), std::string::npos)
        << "byte " << at << ": " << message;
  }
  // Cut anywhere after the version: truncated, with the length the table needs where it was read.
  for (size_t cut : {size_t{12}, size_t{20}, size_t{40}, good.size() - 1}) {
    const std::string message = InputErrorOf([&] { OpenBinaryFile(good.substr(0, cut), "t.bin", kTestFormat); });
    EXPECT_NE(message.find("t.bin: file is truncated: " + std::to_string(cut) + " bytes"), std::string::npos)
        << "cut at " << cut << ": " << message;
  }
  EXPECT_NE(InputErrorOf([&] {
              OpenBinaryFile(good.substr(0, 48), "t.bin", kTestFormat);
            }).find("48 bytes where its section table needs " + std::to_string(good.size())),
            std::string::npos);
  // A flipped size in the table cannot be told from a cut (the crc lies where the table says):
  // both are named.
  std::string size_flipped = good;
  size_flipped[20] ^= 0x10;
  EXPECT_NE(InputErrorOf([&] { OpenBinaryFile(size_flipped, "t.bin", kTestFormat); }).find("(or the table is corrupt)"),
            std::string::npos);
  // A whole file (crc right) whose table disagrees with its length was written wrong: corrupt.
  std::string body = good.substr(0, good.size() - 4);
  body[20] = 5;  // AAAA's size 6 -> 5
  body += LittleEndian32(BinaryCrc32(body));
  EXPECT_NE(InputErrorOf([&] { OpenBinaryFile(body, "t.bin", kTestFormat); }).find("section table states"),
            std::string::npos);
}

TEST(BinaryFile, FlatVersionsOpenWithTheLegacyChecksum) {
  // Version 2 of the test format, as flat files were written: magic, version, fields, FNV.
  std::string flat = std::string("NERFTEST") + LittleEndian32(2) + LittleEndian32(7);
  flat += LittleEndian64(LegacyFnv1aChecksum(flat));
  BinaryFile file = OpenBinaryFile(flat, "t.bin", kTestFormat);
  EXPECT_EQ(file.version, 2u);
  EXPECT_FALSE(file.sectioned());
  EXPECT_EQ(file.fields.remaining(), 4u) << "the fields end before the checksum";
  EXPECT_EQ(file.fields.Get<uint32_t>("seven"), 7u);
  EXPECT_NE(InputErrorOf([&] { file.Section("AAAA"); }).find("no 'AAAA' section"), std::string::npos);
  std::string flipped = flat;
  flipped[13] ^= 0x10;
  const std::string message = InputErrorOf([&] { OpenBinaryFile(flipped, "t.bin", kTestFormat); });
  EXPECT_NE(message.find("t.bin: checksum mismatch (the file is corrupt or truncated; make it again)"),
            std::string::npos)
      << message;
  EXPECT_NE(InputErrorOf([&] { OpenBinaryFile(flat.substr(0, 15), "t.bin", kTestFormat); }).find("truncated"),
            std::string::npos);
}

TEST(BinaryFile, ReaderNeverReadsPastItsSpan) {
  const std::string bytes = "0123456789";
  ByteReader r(std::string_view(bytes).substr(0, 6), "span", 100);
  EXPECT_EQ(r.Get<uint32_t>("first"), 0x33323130u);
  const std::string message = InputErrorOf([&] { r.Get<uint32_t>("second"); });
  EXPECT_NE(message.find("span: file is truncated while reading second at byte 104"), std::string::npos) << message;
  EXPECT_EQ(r.remaining(), 2u) << "a failed read takes nothing";
  // A count that the bytes left cannot hold fails before anything is allocated.
  EXPECT_NE(InputErrorOf([&] { r.GetArray<double>(uint64_t{1} << 61, "huge"); }).find("huge"), std::string::npos);
  EXPECT_NE(InputErrorOf([&] { r.ExpectEnd("the span"); }).find("span: 2 bytes of trailing data after the span"),
            std::string::npos);
  EXPECT_EQ(r.Take(2, "rest"), "45");
  EXPECT_EQ(r.remaining(), 0u);
  EXPECT_NO_THROW(r.ExpectEnd("the span"));
  EXPECT_NE(InputErrorOf([&] { r.Take(1, "more"); }).find("more"), std::string::npos);
}

TEST(BinaryFile, WriteBinaryFileIsAtomicAndReadsBack) {
  TempDir dir;
  BinaryFileWriter w(kTestFormat, 3);
  w.Section("DATA").Put(double{2.5});
  WriteBinaryFile(dir.File("x.bin"), std::move(w));
  const std::string bytes = ReadFileBytes(dir.File("x.bin"));
  const BinaryFile file = OpenBinaryFile(bytes, dir.File("x.bin"), kTestFormat);
  EXPECT_EQ(file.Section("DATA").Get<double>("value"), 2.5);
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir.path()), {}), 1) << "no temporary file left";
}

// The --set parser of every command (train, env): one options struct of
// each kind, set from text and echoed.
struct SetTarget {
  int steps = 3;
  double rate = 0.5;
  float step = 0.5f;
  bool smooth = false;
  uint64_t seed = 1;
  std::vector<OptionField> Fields() {
    return {FieldOf("steps", &steps), FieldOf("rate", &rate), FieldOf("step", &step), FieldOf("smooth", &smooth),
            FieldOf("seed", &seed)};
  }
};

std::string SetError(SetTarget& t, const std::string& key_value) {
  try {
    SetOptionField(t.Fields(), key_value);
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(OptionFields, SetsEveryKindFromText) {
  SetTarget t;
  SetOptionField(t.Fields(), "steps=1e3");
  SetOptionField(t.Fields(), "rate=-0.25");
  SetOptionField(t.Fields(), "step=0.001");
  SetOptionField(t.Fields(), "smooth=true");
  SetOptionField(t.Fields(), "seed=18446744073709551615");  // digits are read exactly, past 2^53
  EXPECT_EQ(t.steps, 1000);
  EXPECT_EQ(t.rate, -0.25);
  EXPECT_EQ(t.step, 0.001f);
  EXPECT_TRUE(t.smooth);
  EXPECT_EQ(t.seed, 18446744073709551615ull);
}

TEST(OptionFields, UnknownKeysAndBadValuesAreRefusedNamingThem) {
  SetTarget t;
  std::string m = SetError(t, "stpes=3");
  EXPECT_NE(m.find("unknown option 'stpes'"), std::string::npos) << m;
  EXPECT_NE(m.find("steps, rate, step, smooth, seed"), std::string::npos) << m;  // the keys there are
  m = SetError(t, "steps=abc");
  EXPECT_NE(m.find("--set steps=abc"), std::string::npos) << m;
  EXPECT_NE(m.find("'abc' is not a valid value of steps (expected a whole number)"), std::string::npos) << m;
  for (const char* bad : {"steps=1.5", "steps=", "steps=3x", "steps=3000000000", "rate=nan", "rate=1e999", "step=1e39",
                          "smooth=1", "smooth=yes", "seed=-1", "seed=1.5"})
    EXPECT_NE(SetError(t, bad), "(no error)") << bad;
  EXPECT_NE(SetError(t, "steps").find("has no '='"), std::string::npos);
  // A refused value leaves the field as it was.
  EXPECT_EQ(t.steps, 3);
  EXPECT_EQ(t.rate, 0.5);
  EXPECT_EQ(t.step, 0.5f);
  EXPECT_FALSE(t.smooth);
  EXPECT_EQ(t.seed, 1u);
}

// Floats are echoed as they were written (0.001, not the float's exact
// double 0.0010000000474974513); doubles, integers and bools as they are.
TEST(OptionFields, EchoWritesValuesAsWritten) {
  SetTarget t;
  for (const char* kv : {"steps=-7", "rate=0.1", "step=0.001", "smooth=true", "seed=42"})
    SetOptionField(t.Fields(), kv);
  EXPECT_EQ(OptionFieldsJson(t.Fields()), R"({"rate":0.1,"seed":42,"smooth":true,"step":0.001,"steps":-7})");
  SetOptionField(t.Fields(), "step=0.3");
  EXPECT_NE(OptionFieldsJson(t.Fields()).find(R"("step":0.3,)"), std::string::npos) << OptionFieldsJson(t.Fields());
}

// A named choice (kChoice): an enum set and echoed by its values' names.
enum class Shape { kBox, kBall, kCone };
struct ChoiceTarget {
  Shape shape = Shape::kBall;
  int count = 1;
  std::vector<OptionField> Fields() {
    return {FieldOf("shape", &shape, {"box", "ball", "cone"}), FieldOf("count", &count)};
  }
};

TEST(OptionFields, ANamedChoiceIsSetAndEchoedByName) {
  ChoiceTarget t;
  EXPECT_EQ(OptionFieldsJson(t.Fields()), R"({"count":1,"shape":"ball"})");
  SetOptionField(t.Fields(), "shape=cone");
  EXPECT_EQ(t.shape, Shape::kCone);
  SetOptionField(t.Fields(), "shape=box");
  EXPECT_EQ(t.shape, Shape::kBox);
  EXPECT_EQ(OptionFieldsJson(t.Fields()), R"({"count":1,"shape":"box"})");
}

TEST(OptionFields, AnUnknownChoiceIsRefusedNamingTheAllowedOnes) {
  ChoiceTarget t;
  for (const char* bad : {"shape=cube", "shape=Box", "shape=", "shape=1", "shape=box "}) {
    std::string m;
    try {
      SetOptionField(t.Fields(), bad, "--shape");
    } catch (const InputError& e) {
      m = e.what();
    }
    EXPECT_NE(m.find(std::string("--shape ") + bad), std::string::npos) << m;
    EXPECT_NE(m.find("(expected box, ball or cone)"), std::string::npos) << bad << ": " << m;
    EXPECT_EQ(t.shape, Shape::kBall) << "a refused name leaves the field as it was";
  }
}

}  // namespace
}  // namespace nerfar
