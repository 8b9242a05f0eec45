// Tests of the trainer's priors (render/nerf/nerf_train): a surface seen only
// from above must not extrapolate its colour below the view-independent value
// towards directions no camera saw; a thin surface seen at grazing angles must
// come out opaque, not translucent; the accurate preset's coarse levels take
// the step counts of balanced's; clipped pixels (8-bit frames) do not pull a
// bright source down that other views see; masked pixels teach nothing.
#include "render/nerf/nerf_train.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "render/nerf/nerf_field.h"
#include "tests/nerf/box_scene.h"

namespace nerfar {
namespace {

// A bright Lambertian emitter (radiance 50 in every direction, HDR against a
// dim table) on a dim table, seen against black by a ring of cameras from
// above only (elevations 0.4..0.8 rad), as the shared scenes' lamps are.
const std::vector<testing::RadiantBox>& Boxes() {
  static const std::vector<testing::RadiantBox> boxes = {
      {Vec3(-0.4, -0.4, -0.04), Vec3(0.4, 0.4, 0.0), Vec3f(0.3f, 0.25f, 0.2f)},
      {Vec3(-0.06, -0.06, 0.15), Vec3(0.06, 0.06, 0.27), Vec3f(50.0f, 45.0f, 30.0f)},  // floating emitter
  };
  return boxes;
}

NerfView View(double azimuth, double elevation, int w, int h) {
  return testing::RingView(Boxes(), azimuth, elevation, 1.2, 0.1, w, h, 3);
}

const NerfTrainData& RingScene() {
  static const NerfTrainData data = [] {
    NerfTrainData d;
    d.aabb = {Vec3(-0.45, -0.45, -0.05), Vec3(0.45, 0.45, 0.35)};
    d.source = "ring of cameras above an emitter";
    for (int n = 0; n < 20; ++n) d.train.push_back(View(2 * kPi * n / 20.0, 0.4 + 0.1 * (n % 5), 32, 24));
    return d;
  }();
  return data;
}

NerfTrainOptions RingOptions(double slope_decay) {
  NerfTrainOptions o;
  o.steps = 200;
  o.rays_per_step = 1024;
  o.coarse_voxel_m = 0.04;
  o.levels = 2;
  o.last_level_start = 0.4;
  o.eval_views = 0;
  o.color_slope_decay = slope_decay;
  return o;
}

// Radiance of the emitter's side face x = -0.06 seen along `dir` (which must
// point into the face, dir.x > 0): colour / opacity of a short ray through it.
Vec3f SeenRadiance(const NerfField& f, const Vec3f& dir, float& opacity) {
  NerfRay ray;
  ray.origin = Vec3f(-0.06f, 0.0f, 0.21f) - dir * 0.08f;
  ray.dir = dir;
  ray.t_near = 0.0f;
  ray.t_far = 0.16f;
  const NerfRayResult r = f.RenderRay(ray);
  opacity = r.opacity;
  return r.color * (1.0f / std::max(r.opacity, 1e-6f));
}

// The emitter's red radiance from below (elevation -0.6 rad, no camera below the
// horizon) over the one seen from a training elevation (0.6 rad), per decay.
struct Extrapolation {
  double seen = 0, below = 0;
};
Extrapolation TrainAndLook(double slope_decay) {
  NerfTrainer trainer(RingScene(), RingOptions(slope_decay));
  while (!trainer.Done()) trainer.Step();
  const float e = 0.6f;
  float o_seen = 0, o_below = 0;
  Extrapolation x;
  x.seen = SeenRadiance(trainer.field(), Normalized(Vec3f(std::cos(e), 0.0f, -std::sin(e))), o_seen).x;
  x.below = SeenRadiance(trainer.field(), Normalized(Vec3f(std::cos(e), 0.0f, std::sin(e))), o_below).x;
  // Precondition: both rays cross the emitter (a 12 cm box through 2 cm voxels).
  EXPECT_GT(o_seen, 0.9f);
  EXPECT_GT(o_below, 0.9f);
  std::printf("slope decay %.2f: emitter red radiance seen %.2f, from below %.2f (truth 50 both)\n", slope_decay,
              x.seen, x.below);
  return x;
}

TEST(NerfTrainColour, UnseenDirectionsMoveBackTowardsTheViewIndependentColour) {
  const Extrapolation off = TrainAndLook(0.0);
  const Extrapolation on = TrainAndLook(1.0);
  // With the prior the seen direction keeps its fit: within 15 % of the truth
  // (measured 48.6; the relative loss's fit of a 50x HDR emitter after 200
  // steps through 2 cm voxels). Without it the fit overshoots (measured 68.5).
  EXPECT_NEAR(on.seen / 50.0, 1.0, 0.15);
  EXPECT_GT(off.seen, 25.0) << "precondition: the emitter is learnt at all";
  // Without the prior Adam moved the slopes as far as the mean colour while the
  // emitter brightened from the start colour, so the view from below falls
  // well under the seen value (measured 12.9 / 68.5 = 0.19): the defect.
  EXPECT_LT(off.below / off.seen, 0.3) << "precondition: the fit without the prior extrapolates dim";
  // With it the unseen direction moves back towards the view-independent
  // colour (measured 26.4 / 48.6 = 0.54; 200 steps decay the unconstrained
  // slope by about e^-2, and the face's interpolation mixes in the outside
  // vertices' colour): at least 0.45 and at least twice the ratio without it.
  EXPECT_GT(on.below / on.seen, 0.45);
  EXPECT_GT(on.below / on.seen, 2.0 * off.below / off.seen);
}

// A thin emitting plate (1 cm thick, radiance 5) seen only at grazing angles
// (elevations 0.1-0.3 rad) against black: each training ray crosses the plate
// over a few centimetres, and a translucent plate with brighter colour renders
// the same pixels as an opaque one. Returns the mean opacity of rays through
// the plate's middle from training-like directions.
const NerfTrainData& GrazingPlateScene() {
  static const NerfTrainData data = [] {
    const std::vector<testing::RadiantBox> plate = {
        {Vec3(-0.15, -0.15, 0.0), Vec3(0.15, 0.15, 0.01), Vec3f(5.0f, 4.0f, 3.0f)}};
    NerfTrainData d;
    d.aabb = {Vec3(-0.2, -0.2, -0.05), Vec3(0.2, 0.2, 0.06)};
    d.source = "thin emitting plate seen at grazing angles";
    for (int n = 0; n < 20; ++n)
      d.train.push_back(testing::RingView(plate, 2 * kPi * n / 20.0, 0.1 + 0.05 * (n % 5), 0.8, 0.005, 32, 24, 3));
    return d;
  }();
  return data;
}

double TrainAndMeasurePlateOpacity(double foreground_weight) {
  NerfTrainOptions o = RingOptions(1.0);
  o.coarse_voxel_m = 0.02;  // finest level 1 cm: the plate is one voxel thick
  o.foreground_weight = foreground_weight;
  NerfTrainer trainer(GrazingPlateScene(), o);
  while (!trainer.Done()) trainer.Step();
  double sum = 0;
  int n = 0;
  for (int a = 0; a < 16; ++a)
    for (int r = 0; r < 3; ++r) {
      const double az = 2 * kPi * (a + 0.5) / 16.0, e = 0.2;
      const Vec3f middle(float(0.04 * r * std::cos(az)), float(0.04 * r * std::sin(az)), 0.005f);
      const Vec3f dir = Normalized(
          Vec3f(float(-std::cos(e) * std::cos(az)), float(-std::cos(e) * std::sin(az)), float(-std::sin(e))));
      NerfRay ray;
      ray.origin = middle - dir * 0.3f;
      ray.dir = dir;
      ray.t_near = 0.0f;
      ray.t_far = 0.6f;
      sum += trainer.field().RenderRay(ray).opacity;
      ++n;
    }
  std::printf("foreground weight %.2f: mean opacity through the grazing plate %.3f\n", foreground_weight, sum / n);
  return sum / n;
}

// The fast preset's foreground weight (1, from 0.1): on the shared scenes the
// penalty at 0.1 left ~30 % of lamps' table pixels below opacity 0.9 (the far,
// grazing part of the table), where the transmittance-0.5 depth falls behind.
// Every other view of the ring clips at 5 (an 8-bit frame exposed for the
// table), the rest see the emitter's radiance 50. The relative loss's fixed
// point is the mean of the targets (sg(C) in the denominator: Σ (C - y_i) = 0),
// so with clipped pixels taken at their value the emitter settles near
// (50 + 5) / 2; taken as a lower bound, the clipped views stop pulling once
// the rendering passes 5 and the others bring it to 50.
TEST(NerfTrainClipped, ClippedViewsDoNotPullABrightSourceDown) {
  const float clip = 5.0f;
  const auto train = [&](bool flag_clipped) {
    NerfTrainData data = RingScene();
    for (size_t n = 1; n < data.train.size(); n += 2) {
      NerfView& v = data.train[n];
      if (flag_clipped) v.clipped = Image8(v.rgb.width, v.rgb.height, 1);
      for (size_t p = 0; p < v.rgb.PixelCount(); ++p)
        for (int ch = 0; ch < 3; ++ch) {
          float& x = v.rgb.pixels[3 * p + ch];
          if (x < clip) continue;
          x = clip;
          if (flag_clipped) v.clipped.pixels[p] |= std::uint8_t(1u << ch);
        }
    }
    NerfTrainOptions options = RingOptions(1.0);
    options.steps = 600;
    NerfTrainer trainer(data, options);
    while (!trainer.Done()) trainer.Step();
    float opacity = 0;
    const float e = 0.6f;
    const double red = SeenRadiance(trainer.field(), Normalized(Vec3f(std::cos(e), 0.0f, -std::sin(e))), opacity).x;
    EXPECT_GT(opacity, 0.9f);  // precondition: the ray crosses the emitter
    std::printf("clipped pixels %s: emitter red radiance %.2f (truth 50, clip %.0f)\n",
                flag_clipped ? "as a lower bound" : "at their value", red, clip);
    return red;
  };
  // Bounds: the two fixed points are 50 and 27.5; 40 and 35 split them with
  // room for the fit's error (measured 50.6 and 30.2 after 600 steps; after
  // 200 both are still rising, 24.9 and 18.6, as half the views pull).
  EXPECT_GT(train(true), 40.0);
  EXPECT_LT(train(false), 35.0);
}

// Masked pixels (a dataset's mask_path) give no loss at all: with every pixel
// masked a step's loss is exactly 0, with none it is not.
TEST(NerfTrainMask, MaskedPixelsTeachNothing) {
  NerfTrainData data = RingScene();
  NerfTrainOptions options = RingOptions(0.0);
  EXPECT_GT(NerfTrainer(data, options).Step(), 0.0);
  for (NerfView& v : data.train) v.mask = Image8(v.rgb.width, v.rgb.height, 1, 0);
  NerfTrainer masked(data, options);
  EXPECT_EQ(masked.Step(), 0.0);
  EXPECT_EQ(masked.Step(), 0.0);
}

TEST(NerfTrainOpacity, ForegroundPenaltyMakesAGrazingPlateOpaque) {
  const double weak = TrainAndMeasurePlateOpacity(0.1);
  const double strong = TrainAndMeasurePlateOpacity(1.0);
  // Precondition: the plate is learnt at all (measured 0.975 at 0.1).
  EXPECT_GT(weak, 0.9);
  // The light let through the plate, 1 - O, falls to under half with the
  // stronger penalty (measured 0.025 -> 0.004; the margin covers the seed-
  // and platform-level float differences of a 200-step fit).
  EXPECT_LT(1.0 - strong, 0.5 * (1.0 - weak));
}

// The steps a preset's schedule runs at each coarse level, counted by
// training it (on the ring scene at a coarse voxel and a few rays per step, so
// that a step costs little; the level schedule depends on the step count only).
std::vector<int> CoarseLevelSteps(const std::string& preset) {
  NerfTrainOptions o = NerfTrainOptions::Preset(preset);
  o.rays_per_step = 16;
  o.coarse_voxel_m = 0.04;
  o.eval_views = 0;
  o.max_seconds = 0;
  NerfTrainer trainer(RingScene(), o);
  std::vector<int> steps(size_t(o.levels), 0);
  while (!trainer.Done() && trainer.level() < o.levels - 1) {
    trainer.Step();
    // The step just run was at the level the trainer is at now (levels change
    // at the start of a step).
    if (trainer.level() < o.levels - 1) ++steps[size_t(trainer.level())];
  }
  steps.pop_back();  // the finest level: not run here
  return steps;
}

TEST(NerfTrainSchedule, AccurateCoarseLevelsTakeBalancedsStepCounts) {
  // Hand count: balanced (2500 steps, finest level from 0.45, the middle one
  // from 0.225) runs steps 0..562 at 1 cm (563 steps: 562 / 2500 < 0.225 <=
  // 563 / 2500) and 563..1124 at 5 mm (562 steps: 1125 / 2500 = 0.45);
  // accurate (5000 steps, 0.225 and 0.1125) the same 563 and 562.
  const std::vector<int> expected = {563, 562};
  EXPECT_EQ(CoarseLevelSteps("balanced"), expected);
  EXPECT_EQ(CoarseLevelSteps("accurate"), expected);
}

}  // namespace
}  // namespace nerfar
