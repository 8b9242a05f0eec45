// The live loop survives what a frame or the device does (app/live/pipeline.h):
// a source that throws, reports a lost device or corrupt frames for a while,
// and a frame whose processing throws, are counted and recorded, the loop
// goes on with the frames that follow (stepped and threaded), the HUD shows
// the count and the session file and report carry it. The stream and scene
// are the live tests' (a nearly still synthetic camera over a plain table,
// a red ball placed under the image centre); the failures are injected by a
// source wrapper and a scene wrapper.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <memory>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <vector>

#include "app/live/pipeline.h"
#include "app/live/report.h"
#include "calib/core/json.h"
#include "render/mesh/mesh.h"
#include "tests/app/live_scene.h"
#include "tests/support/analytic_scene.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

enum class Failure { kThrow, kLost, kCorrupt };

// Calls [from, from + count) of Next() fail as `failure` says; the others
// take the next frame of `stream` (which does not advance meanwhile).
class FailingForAWhile : public FrameSource {
 public:
  FailingForAWhile(FrameSource& stream, int from, int count, Failure failure)
      : stream_(stream), from_(from), count_(count), failure_(failure) {}
  std::string Describe() const override { return "failing " + stream_.Describe(); }
  FrameStatus Next(Frame& frame, int timeout_ms) override {
    const int call = calls_++;
    if (call < from_ || call >= from_ + count_) return stream_.Next(frame, timeout_ms);
    if (failure_ == Failure::kThrow) throw std::runtime_error("camera unplugged");
    return failure_ == Failure::kLost ? FrameStatus::kLost : FrameStatus::kCorrupt;
  }
  std::string LastError() const override { return "injected"; }

 private:
  FrameSource& stream_;
  int from_, count_, calls_ = 0;
  Failure failure_;
};

// The table, whose rendering throws `throws` times when asked to.
class FailingScene : public SceneField {
 public:
  FailingScene() : table_(testing::PlainTable()) {}
  Aabb Box() const override { return table_.Box(); }
  void RenderRays(const SceneRays& rays, SceneSamples& out) const override {
    FailIfAsked();
    table_.RenderRays(rays, out);
  }
  void Normals(const std::vector<Vec3f>& points, std::vector<Vec3f>& normals) const override {
    FailIfAsked();
    table_.Normals(points, normals);
  }
  mutable std::atomic<int> throws{0};

 private:
  void FailIfAsked() const {
    if (throws.load() > 0 && throws.fetch_sub(1) > 0) throw std::runtime_error("scene query failed");
  }
  testing::AnalyticScene table_;
};

struct FailingRun {
  synth::SyntheticCameraSource stream{NearlyStillLampsStream()};
  std::unique_ptr<FailingForAWhile> source;
  FailingScene scene;
  TriangleMesh ball = MakeUvSphere(0.04, 32, 16);
  std::unique_ptr<LivePipeline> pipeline;

  FailingRun(int from, int count, Failure failure, bool hud = false) {
    source = std::make_unique<FailingForAWhile>(stream, from, count, failure);
    LiveAsset asset;
    asset.name = "ball";
    asset.mesh = &ball;
    asset.material.base_color = {0.9, 0.02, 0.02};
    LiveOptions options;
    options.preset = "fast";
    options.response = "display";
    options.hud = hud;
    options.tracker.confirm_frames = 0;
    options.render_divisor = 2;
    options.pace = false;  // frames as fast as they come: the test waits for nothing
    pipeline = std::make_unique<LivePipeline>(*source, stream.board(), stream.camera(), scene,
                                              SgMixture{Sg{{0, 0, 1}, 3.0, {2.0, 2.0, 2.0}}},
                                              std::vector<LiveAsset>{asset}, options);
    const Pose pose = stream.PoseAt(0);
    const CameraIntrinsics& camera = stream.camera();
    const Vec3 d = pose.Rotate(Unproject(camera, {camera.width * 0.5, camera.height * 0.5}));
    LiveObjectState state = pipeline->object(0);
    state.placed = true;
    state.anchor_world = pose.translation + d * (-pose.translation.z / d.z);
    pipeline->set_object(0, state);
  }

  // Moves the ball a little: its light and shadows are computed again (the scene is queried).
  void Nudge() {
    LiveObjectState state = pipeline->object(0);
    state.yaw_rad += 0.3;
    state.anchor_world.x += 0.01;
    pipeline->set_object(0, state);
  }
};

TEST(LiveFailures, ASourceFailingForAWhileIsCountedAndItsFramesResume) {
  for (const Failure failure : {Failure::kThrow, Failure::kLost, Failure::kCorrupt}) {
    SCOPED_TRACE(static_cast<int>(failure));
    FailingRun run(/*from=*/2, /*count=*/3, failure);
    std::vector<std::int64_t> indices;
    for (int i = 0; i < 5; ++i) {
      const std::optional<LiveFrame> frame = run.pipeline->Step();
      ASSERT_TRUE(frame.has_value()) << "step " << i;
      indices.push_back(frame->index);
    }
    // The stream's frames 0..4, in order: the failures cost no frame.
    EXPECT_EQ(indices, (std::vector<std::int64_t>{0, 1, 2, 3, 4}));
    const LiveCounters c = run.pipeline->counters();
    EXPECT_EQ(c.source_errors, 3u);
    EXPECT_EQ(c.processed, 5u);
    EXPECT_EQ(c.frame_errors, 0u);
    // Lost and thrown: the source was gone and came back once; corrupt frames are no loss.
    EXPECT_EQ(c.reconnects, failure == Failure::kCorrupt ? 0u : 1u);
    const std::vector<LiveError> errors = run.pipeline->errors();
    ASSERT_FALSE(errors.empty());
    EXPECT_EQ(errors.front().stage, "source");
    // A lost device is recorded once, when it goes; each exception and corrupt frame is.
    EXPECT_EQ(errors.size(), failure == Failure::kLost ? 1u : 3u);
    if (failure == Failure::kThrow) {
      EXPECT_NE(errors.front().what.find("camera unplugged"), std::string::npos);
    }
  }
}

TEST(LiveFailures, AFrameWhoseProcessingThrowsIsSkippedAndTheNextIsWhole) {
  FailingRun run(0, 0, Failure::kThrow);
  ASSERT_TRUE(run.pipeline->Step().has_value());
  run.Nudge();
  run.scene.throws = 1;  // the first scene query of the next frame fails
  const std::optional<LiveFrame> after = run.pipeline->Step();
  ASSERT_TRUE(after.has_value());
  EXPECT_EQ(after->index, 2) << "frame 1 failed and was skipped";
  EXPECT_TRUE(after->has_pose);
  const LiveCounters c = run.pipeline->counters();
  EXPECT_EQ(c.frame_errors, 1u);
  EXPECT_EQ(c.processed, 2u);
  const std::vector<LiveError> errors = run.pipeline->errors();
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_EQ(errors[0].stage, "process");
  EXPECT_EQ(errors[0].frame, 1);
  EXPECT_EQ(errors[0].what, "scene query failed");

  // Frame 2 is what a run that never failed shows for the same edit.
  FailingRun clean(0, 0, Failure::kThrow);
  ASSERT_TRUE(clean.pipeline->Step().has_value());
  clean.Nudge();
  ASSERT_TRUE(clean.pipeline->Step().has_value());  // frame 1, processed
  const std::optional<LiveFrame> reference = clean.pipeline->Step();
  ASSERT_TRUE(reference.has_value());
  ASSERT_EQ(reference->index, 2);
  int max = 0;
  for (size_t i = 0; i < after->ar.pixels.size(); ++i)
    max = std::max(max, std::abs(after->ar.pixels[i] - reference->ar.pixels[i]));
  // The light refitted for the moved ball from frame 2 in one run, frame 1 in
  // the other (same pose to 1e-4 m/s of camera motion): 2 levels of rounding.
  EXPECT_LE(max, 2);
}

TEST(LiveFailures, TheThreadedLoopGoesOnAfterSourceAndFrameFailures) {
  FailingRun run(/*from=*/3, /*count=*/4, Failure::kThrow);
  run.pipeline->Start();
  std::int64_t last = -1;
  for (int i = 0; i < 400 && last < 8; ++i) {
    if (i == 2) {
      run.Nudge();
      run.scene.throws = 1;
    }
    if (std::optional<LiveFrame> f = run.pipeline->TakeLatest(std::chrono::milliseconds(100))) {
      run.pipeline->MarkDisplayed(*f);
      last = f->index;
    }
  }
  run.pipeline->Stop();
  EXPECT_GE(last, 8) << "frames kept coming after the failures";
  const LiveCounters c = run.pipeline->counters();
  EXPECT_EQ(c.source_errors, 4u);
  EXPECT_EQ(c.reconnects, 1u);
  EXPECT_EQ(c.frame_errors, 1u);
}

// Rows 33-44 of the AR view: the HUD's error line (baseline at row 40), below
// the reach of the second line's descenders (its baseline is row 27; the
// parentheses reach about 5 rows below it with their outline).
int ErrorLineDifference(const Image8& a, const Image8& b) {
  int differing = 0;
  for (int y = 33; y < 45; ++y)
    for (int x = 0; x < a.width; ++x)
      for (int c = 0; c < 3; ++c) differing += a.at(x, y, c) != b.at(x, y, c);
  return differing;
}

TEST(LiveFailures, TheHudAndTheSessionReportShowTheErrors) {
  testing::TempDir dir;
  FailingRun failing(/*from=*/1, /*count=*/1, Failure::kCorrupt, /*hud=*/true);
  FailingRun clean(0, 0, Failure::kCorrupt, /*hud=*/true), clean_again(0, 0, Failure::kCorrupt, /*hud=*/true);
  LiveFrame shown, reference, reference_again;
  for (int i = 0; i < 3; ++i) {
    shown = *failing.pipeline->Step();
    reference = *clean.pipeline->Step();
    reference_again = *clean_again.pipeline->Step();
  }
  ASSERT_EQ(shown.index, reference.index);
  // The same frame with and without the error line (the rows above hold the
  // fps and latency, which differ between runs; these rows do not, without errors).
  EXPECT_GT(ErrorLineDifference(shown.ar, reference.ar), 100);
  EXPECT_EQ(ErrorLineDifference(reference.ar, reference_again.ar), 0);

  SessionInfo info;
  info.mode = "headless";
  WriteSession(dir.path(), info, *failing.pipeline);
  const Json session = ReadJsonFile(dir.File("session.json"));
  EXPECT_EQ(session.at("counters").at("source_errors").get<int>(), 1);
  ASSERT_EQ(session.at("errors").size(), 1u);
  EXPECT_EQ(session["errors"][0]["stage"], "source");
  const Json report = BuildReport(dir.path());
  EXPECT_EQ(report.at("errors").at("source").get<int>(), 1);
  EXPECT_EQ(report["errors"]["recent"].size(), 1u);
}

}  // namespace
}  // namespace nerfar
