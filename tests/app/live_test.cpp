// The live pipeline without a window (app/live/pipeline.h): edits made while
// it runs (material, preset) reach the very next frame and change the
// object visibly, and a run edited mid-stream shows exactly what a run
// started with the edited values shows (the differential check); the
// surface pick finds the true table through fog; a NeRF scene takes the
// preset's options. The synthetic stream (lamps mat, camera nearly still) is
// tracked from its tags; the scene is an analytic table (plane z = 0, the
// stream's table top) or the benches' NeRF table, the object a red ball.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <vector>

#include "app/bench.h"
#include "app/live/pipeline.h"
#include "render/insert/nerf_scene.h"
#include "render/insert/rasterizer.h"
#include "render/lighting/scene_field.h"
#include "render/mesh/mesh.h"
#include "render/ssdf/ssdf.h"
#include "render/synth/camera_stream.h"
#include "tests/app/live_scene.h"
#include "tests/support/analytic_scene.h"

namespace nerfar {
namespace {

constexpr double kRadius = 0.04;  // the ball, metres

SgMaterial Red() {
  SgMaterial m;
  m.base_color = {0.9, 0.02, 0.02};
  m.roughness = 0.6;
  m.metallic = 0;
  return m;
}

// One pipeline over its own stream (every run renders the same frames), by
// default over the analytic table; `nerf`: over that NeRF scene instead,
// with the `--set` items `sets`.
struct LiveRun {
  std::unique_ptr<synth::SyntheticCameraSource> source;
  std::unique_ptr<testing::AnalyticScene> table;
  TriangleMesh ball;
  std::unique_ptr<LivePipeline> pipeline;

  LiveRun(const SgMaterial& material, const std::string& preset, const SsdfField* field = nullptr,
          NerfScene* nerf = nullptr, const std::vector<std::string>& sets = {}) {
    source = std::make_unique<synth::SyntheticCameraSource>(NearlyStillLampsStream());
    table = std::make_unique<testing::AnalyticScene>(testing::PlainTable());
    ball = MakeUvSphere(kRadius, 32, 16);
    LiveAsset asset;
    asset.name = "ball";
    asset.mesh = &ball;
    asset.material = material;
    asset.field = field;
    LiveOptions options;
    options.preset = preset;
    options.insert_sets = sets;
    options.response = "display";
    options.hud = false;  // the HUD's numbers differ between runs
    options.tracker.confirm_frames = 0;
    options.render_divisor = 2;
    // A sky from above and a warm side light: shading with structure, so
    // that roughness and metallic show.
    const SgMixture light = {Sg{{0, 0, 1}, 3.0, {2.0, 2.0, 2.0}},
                             Sg{Normalized(Vec3{1, -1, 0.6}), 40.0, {30.0, 25.0, 20.0}}};
    SceneField& scene = nerf != nullptr ? static_cast<SceneField&>(*nerf) : *table;
    pipeline = std::make_unique<LivePipeline>(*source, source->board(), source->camera(), scene, light,
                                              std::vector<LiveAsset>{asset}, options);
    // The ball on the table under the image centre of the true first pose.
    const Pose pose = source->PoseAt(0);
    const CameraIntrinsics& camera = source->camera();
    const Vec3 d = pose.Rotate(Unproject(camera, {camera.width * 0.5, camera.height * 0.5}));
    LiveObjectState state = pipeline->object(0);
    state.placed = true;
    state.anchor_world = pose.translation + d * (-pose.translation.z / d.z);
    pipeline->set_object(0, state);
  }

  LiveFrame Step() {
    std::optional<LiveFrame> f = pipeline->Step();
    if (!f) throw std::runtime_error("the stream ended");
    return std::move(*f);
  }
};

// The ball's silhouette rasterised at the frame's tracked pose, eroded by
// 2 px: the interior, whose pixels do not change when the tracked pose moves
// the edges by a fraction of a pixel between frames.
struct Mask {
  PixelRect rect;
  std::vector<uint8_t> in;
  int width = 0;
  bool At(int x, int y) const { return rect.Contains(x, y) && in[(y - rect.y0) * width + (x - rect.x0)] != 0; }
  int covered = 0;
};
Mask Interior(const LiveRun& run, const LiveFrame& frame) {
  const LiveObjectState s = run.pipeline->object(0);
  const ObjectGBuffer g =
      Rasterize(frame.camera, frame.T_world_camera, {RasterObject{&run.ball, run.pipeline->ObjectPose(0, s), 1.0}});
  Mask m;
  m.rect = g.rect;
  m.width = g.rect.width();
  m.in.assign(g.rect.area(), 0);
  for (int y = g.rect.y0; y < g.rect.y1; ++y)
    for (int x = g.rect.x0; x < g.rect.x1; ++x) {
      bool all = true;
      for (int dy = -2; dy <= 2 && all; ++dy)
        for (int dx = -2; dx <= 2 && all; ++dx)
          all = g.rect.Contains(x + dx, y + dy) && g.object[g.Index(x + dx, y + dy)] >= 0;
      if (all) {
        m.in[(y - g.rect.y0) * m.width + (x - g.rect.x0)] = 1;
        ++m.covered;
      }
    }
  return m;
}
// Mean colour of `image` over the mask.
struct MaskStats {
  double rgb[3] = {0, 0, 0};
  int pixels = 0;
};
MaskStats MeanOver(const Image8& image, const Mask& g) {
  MaskStats m;
  for (int y = g.rect.y0; y < g.rect.y1; ++y)
    for (int x = g.rect.x0; x < g.rect.x1; ++x) {
      if (!g.At(x, y)) continue;
      for (int c = 0; c < 3; ++c) m.rgb[c] += image.at(x, y, c);
      ++m.pixels;
    }
  for (double& v : m.rgb) v /= std::max(1, m.pixels);
  return m;
}
// Mean and largest absolute difference of two images over the silhouette.
void DiffOver(const Image8& a, const Image8& b, const Mask& g, double& mean, int& max) {
  mean = 0;
  max = 0;
  int n = 0;
  for (int y = g.rect.y0; y < g.rect.y1; ++y)
    for (int x = g.rect.x0; x < g.rect.x1; ++x) {
      if (!g.At(x, y)) continue;
      for (int c = 0; c < 3; ++c) {
        const int d = std::abs(a.at(x, y, c) - b.at(x, y, c));
        mean += d;
        max = std::max(max, d);
      }
      ++n;
    }
  mean /= std::max(1, 3 * n);
}
int MaxDiff(const Image8& a, const Image8& b) {
  int max = 0;
  for (size_t i = 0; i < a.pixels.size(); ++i) max = std::max(max, std::abs(a.pixels[i] - b.pixels[i]));
  return max;
}

TEST(LivePipeline, MaterialEditsReachTheNextFrameAndEqualARunStartedWithThem) {
  struct Edit {
    const char* what;
    SgMaterial material;
  };
  SgMaterial blue = Red(), smooth = Red(), metal = Red();
  blue.base_color = {0.02, 0.02, 0.9};
  smooth.roughness = 0.08;
  metal.metallic = 1.0;
  // The unedited frame 1: edits are compared on the same frame and pose, so
  // any difference is the edit's.
  LiveRun plain(Red(), "fast");
  plain.Step();
  const LiveFrame unedited = plain.Step();
  for (const Edit& edit : {Edit{"base colour", blue}, Edit{"roughness", smooth}, Edit{"metallic", metal}}) {
    SCOPED_TRACE(edit.what);
    LiveRun edited(Red(), "fast");
    const LiveFrame before = edited.Step();
    ASSERT_TRUE(before.has_pose);
    LiveObjectState s = edited.pipeline->object(0);
    s.material = edit.material;
    edited.pipeline->set_object(0, s);  // what the panel's sliders do
    const LiveFrame after = edited.Step();
    ASSERT_TRUE(after.has_pose);
    LiveRun fresh(edit.material, "fast");
    fresh.Step();
    const LiveFrame reference = fresh.Step();
    // Same frames, same poses, same light (fitted at frame 0 for the same
    // object position in both runs), same material at frame 1: the same
    // picture. 1 level allows a rounding difference and nothing more.
    EXPECT_LE(MaxDiff(after.ar, reference.ar), 1);

    const Mask g = Interior(edited, after);
    ASSERT_GT(g.covered, 100) << "the ball is not in view";
    double mean = 0;
    int max = 0;
    DiffOver(unedited.ar, after.ar, g, mean, max);
    const MaskStats was = MeanOver(unedited.ar, g), is = MeanOver(after.ar, g);
    std::printf("%s: mean |change| inside the ball %.1f levels (max %d); rgb (%.0f %.0f %.0f) -> (%.0f %.0f %.0f)\n",
                edit.what, mean, max, was.rgb[0], was.rgb[1], was.rgb[2], is.rgb[0], is.rgb[1], is.rgb[2]);
    // Visible: the same frame without the edit differs by several levels on
    // average inside the ball (measured: base colour ~90, metallic ~20,
    // roughness ~6 under this light), where nothing else can differ.
    EXPECT_GT(mean, 3.0);
    if (std::string(edit.what) == "base colour") {
      // A diffuse ball takes the colour of its albedo: red before, blue after.
      EXPECT_GT(was.rgb[0], 2 * was.rgb[2]);
      EXPECT_GT(is.rgb[2], 2 * is.rgb[0]);
    }
  }
}

TEST(LivePipeline, PresetSwitchTakesEffectAndMatchesARunStartedWithIt) {
  LiveRun edited(Red(), "fast");
  const LiveFrame before = edited.Step();
  ASSERT_TRUE(before.has_pose);
  edited.pipeline->set_preset("accurate");  // what the 1/2/3 keys and the panel's combo do
  EXPECT_EQ(edited.pipeline->preset(), "accurate");
  const LiveFrame after = edited.Step();
  // The light is refitted for the new preset's options (not kept from fast).
  EXPECT_GT(after.times.insert.lights_recomputed, 0);
  LiveRun fresh(Red(), "accurate");
  fresh.Step();
  const LiveFrame reference = fresh.Step();
  const Mask g = Interior(edited, after);
  ASSERT_GT(g.covered, 100);
  double mean_ref = 0, mean_switch = 0;
  int max_ref = 0, max_switch = 0;
  DiffOver(after.ar, reference.ar, g, mean_ref, max_ref);
  DiffOver(before.ar, after.ar, g, mean_switch, max_switch);
  std::printf("switched vs started accurate: mean %.2f max %d; fast -> accurate: mean %.2f max %d levels\n", mean_ref,
              max_ref, mean_switch, max_switch);
  // The presets differ in light directions and lobes, so the switched run
  // refits from scratch at the same centre as the fresh run did at frame 0:
  // the same light, the same picture (1 level: rounding).
  EXPECT_LE(max_ref, 1);
  // Visible: the same frame and pose rendered with the fast preset differs
  // inside the ball (more light directions and lobes change its shading).
  LiveRun plain(Red(), "fast");
  plain.Step();
  const LiveFrame unswitched = plain.Step();
  double mean_preset = 0;
  int max_preset = 0;
  DiffOver(unswitched.ar, after.ar, g, mean_preset, max_preset);
  std::printf("frame 1, fast vs accurate: mean %.2f max %d levels\n", mean_preset, max_preset);
  EXPECT_GT(mean_preset, 1.0);
  EXPECT_THROW(edited.pipeline->set_preset("turbo"), InputError);
  EXPECT_EQ(edited.pipeline->preset(), "accurate");
}

// The NeRF scene's options follow the preset as `nerfar insert`'s do
// (NerfSceneOptions::Preset) with the `--set` items over them, from the
// start and from the frame after a switch; one list of `--set` items holds
// knobs of the scene and of the insertion (kappa_step) alike.
TEST(LivePipeline, TheNerfSceneTakesThePresetsOptionsWithTheSetsAndFollowsASwitch) {
  const NerfField field = BenchTabletopNerf();  // a table top at z = 0 under the stream's camera
  NerfScene scene(field);                       // the default options, which no preset has
  const std::vector<std::string> sets = {"seen_views=7", "nerf_step_voxels=0.75", "kappa_step=3"};
  LiveRun run(Red(), "balanced", nullptr, &scene, sets);
  // What `nerfar insert --preset P --set ...` builds its scene with, and
  // the values that tells apart (nerf_scene.cpp's presets, named here).
  const auto expected = [](const std::string& preset) {
    NerfSceneOptions o = NerfSceneOptions::Preset(preset);
    o.seen.views = 7;
    o.render.step_voxels = 0.75f;
    return o.ToJson();
  };
  EXPECT_EQ(scene.options().ToJson(), expected("balanced"));
  EXPECT_EQ(scene.options().seen.group_m, 0.01);
  EXPECT_TRUE(scene.options().cache_views);
  EXPECT_EQ(scene.options().seen.views, 7);
  EXPECT_EQ(scene.options().render.step_voxels, 0.75f);
  ASSERT_TRUE(run.Step().has_pose);
  EXPECT_GT(scene.LightSamples(), 0u) << "the object's light was not taken through the NeRF scene";

  run.pipeline->set_preset("fast");
  const LiveFrame fast = run.Step();
  EXPECT_GT(fast.times.insert.lights_recomputed, 0);
  EXPECT_EQ(scene.options().ToJson(), expected("fast"));
  EXPECT_EQ(scene.options().seen.group_m, 0.02);
  EXPECT_TRUE(scene.options().cache_views);
  EXPECT_EQ(scene.options().seen.views, 7);

  run.pipeline->set_preset("accurate");
  run.Step();
  EXPECT_EQ(scene.options().ToJson(), expected("accurate"));
  EXPECT_EQ(scene.options().seen.group_m, 0.0);
  EXPECT_FALSE(scene.options().cache_views);
  EXPECT_EQ(scene.options().render.step_voxels, 0.75f);
}

TEST(LivePipeline, TheLightIsReusedWhileTheObjectStandsStillAndRefittedWhenItMoves) {
  LiveRun run(Red(), "fast");
  std::vector<int> recomputed;
  for (int i = 0; i < 3; ++i) recomputed.push_back(run.Step().times.insert.lights_recomputed);
  LiveObjectState s = run.pipeline->object(0);
  s.anchor_world = s.anchor_world + Vec3{0.05, 0, 0};  // what a drag does
  run.pipeline->set_object(0, s);
  for (int i = 0; i < 2; ++i) recomputed.push_back(run.Step().times.insert.lights_recomputed);
  s.yaw_rad += 0.3;  // a rotation about the vertical keeps the centre: the light stays
  run.pipeline->set_object(0, s);
  recomputed.push_back(run.Step().times.insert.lights_recomputed);
  EXPECT_EQ(recomputed, (std::vector<int>{1, 0, 0, 1, 0, 0}));
}

TEST(LivePipeline, ShadowCachesAreReusedWhileTheObjectStandsStillAndRebuiltWhenItMoves) {
  // The ball with a (coarse) baked SSDF: self-shadow γ per vertex and κ on
  // the table, both cached by the inserter while nothing moves, as long as
  // the pipeline hands it the same posed field every frame.
  SsdfBakeOptions bake = SsdfBakeOptions::Preset("fast");
  bake.grid = 8;
  bake.dirs = 12;
  bake.components = 8;
  const SsdfField field = BakeSsdf(MakeUvSphere(kRadius, 32, 16), bake, std::nullopt);
  LiveRun run(Red(), "fast", &field);
  std::vector<InsertTimings> t;
  for (int i = 0; i < 3; ++i) t.push_back(run.Step().times.insert);
  LiveObjectState s = run.pipeline->object(0);
  s.anchor_world = s.anchor_world + Vec3{0.05, 0, 0};  // a drag
  run.pipeline->set_object(0, s);
  t.push_back(run.Step().times.insert);
  for (size_t i = 0; i < t.size(); ++i)
    std::printf("frame %zu: gamma rebuilt %d, kappa evaluated %zu, kappa %.1f ms\n", i, t[i].gamma_recomputed ? 1 : 0,
                t[i].kappa_evaluated, t[i].kappa_ms);
  EXPECT_TRUE(t[0].gamma_recomputed);
  EXPECT_FALSE(t[1].gamma_recomputed);
  EXPECT_FALSE(t[2].gamma_recomputed);
  EXPECT_TRUE(t[3].gamma_recomputed);
  ASSERT_GT(t[0].kappa_evaluated, 100u) << "no shadow receivers: the test sees nothing";
  // Still: the camera moves by a fraction of a millimetre per frame, so the
  // receivers fall on lattice nodes already computed; a tenth allows for
  // the few new ones at the shadow's edge.
  EXPECT_LT(t[2].kappa_evaluated, t[0].kappa_evaluated / 10);
  // Moved: the shadow is somewhere else, computed afresh.
  EXPECT_GT(t[3].kappa_evaluated, t[0].kappa_evaluated / 2);
}

TEST(LivePipeline, MedianHitDistanceFindsTheTableBehindFog) {
  // A plane at z = 0 under a ball of thin fog (σ = 3/m, radius 0.1 m: 0.45
  // opacity through its centre) whose centre is 0.12 m above the table. A
  // ray straight down through the fog: the expected depth Σ T α t / Ô is
  // pulled ~5 cm towards the camera by the fog; the median stays on the
  // table (opacity there jumps from 0.45 to 1 > half of 1).
  testing::AnalyticSceneParams p;
  p.has_sphere = false;
  p.checker_size_m = 0;
  p.medium_center = {0.0, 0.0, 0.12};
  p.medium_radius = 0.1;
  p.medium_density = 3.0;
  const testing::AnalyticScene scene(p);
  const Vec3 origin{0.0, 0.0, 0.5}, down{0, 0, -1};
  const std::optional<double> t = MedianHitDistance(scene, origin, down, 0.0, 0.55);
  ASSERT_TRUE(t.has_value());
  // The table is 0.5 m down; the bracket resolution is 0.55/1024 ≈ 0.5 mm.
  EXPECT_NEAR(*t, 0.5, 1e-3);
  // A range that ends inside the fog (2 cm of it, opacity 0.06): below the
  // 0.3 surface opacity, no hit.
  const std::optional<double> none = MedianHitDistance(scene, origin, down, 0.0, 0.3);
  EXPECT_FALSE(none.has_value());
  // The analytic ray integral (depth is Σ T α t there): the expected depth
  // is nearer than the table, so the median really is the better pick.
  Vec3 colour;
  double opacity = 0, depth = 0;
  scene.RenderOne(origin, down, 0.0, 0.55, colour, opacity, depth);
  EXPECT_LT(depth / opacity, 0.48);
}

}  // namespace
}  // namespace nerfar
