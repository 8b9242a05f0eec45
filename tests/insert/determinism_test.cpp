// render/insert: results do not depend on the thread count (DESIGN.md). A
// hand-held sequence with the fast paths on (receivers reused from the last
// frame, one receiver normal per world cell, the κ lattice) rendered on one
// thread and on two must give the same κ layers and composites, bit for bit.
// The scene's normals are scattered by ~10° as a NeRF's are (the bench
// grid's scatter by more than 10° between neighbours), so that which
// receiver gives a cell its normal changes κ. Two inserters taking turns on
// one thread must each give what it gives alone (the threads' memos of the
// κ lattice are kept across frames).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "calib/core/parallel.h"
#include "render/insert/inserter.h"
#include "tests/insert/insert_fixtures.h"
#include "tests/insert/test_camera.h"
#include "tests/support/analytic_scene.h"

namespace nerfar {
namespace {

using testing::OneLobe;
using testing::PlainTable;
using testing::SphereObject;

// The analytic scene with every normal turned by up to ~10° by a hash of the
// point's exact coordinates (deterministic per point, different for points
// a fraction of a millimetre apart, like a NeRF's density-gradient normals).
class ScatteredNormals final : public SceneField {
 public:
  explicit ScatteredNormals(const SceneField& scene) : scene_(scene) {}
  Aabb Box() const override { return scene_.Box(); }
  void RenderRays(const SceneRays& rays, SceneSamples& out) const override { scene_.RenderRays(rays, out); }
  void Normals(const std::vector<Vec3f>& points, std::vector<Vec3f>& normals) const override {
    scene_.Normals(points, normals);
    for (size_t i = 0; i < points.size(); ++i) {
      if (!(Dot(normals[i], normals[i]) > 0.25f)) continue;
      uint32_t bits[3];
      std::memcpy(bits, &points[i].x, sizeof bits);
      uint64_t h = 1469598103934665603ull;
      for (uint32_t b : bits) h = (h ^ b) * 1099511628211ull;
      const auto unit = [&h](int shift) { return float((h >> shift) & 0xFFFF) / 65535.0f - 0.5f; };
      const Vec3f tilt{0.35f * unit(0), 0.35f * unit(16), 0.35f * unit(32)};  // |tilt| ≤ 0.3: ≤ ~17°, ~8° typical
      normals[i] = Normalized(normals[i] + tilt);
    }
  }

 private:
  const SceneField& scene_;
};

struct Sequence {
  std::vector<ImageF> kappa, frames;
  std::vector<PixelRect> rects;
};

constexpr int kHandHeldFrames = 5;

// A sharp slanted lobe (its direction `axis`) and a broad sky.
SgMixture HandHeldLight(const Vec3& axis) {
  SgMixture light = OneLobe(axis, 40.0, 5.0);
  light.push_back(OneLobe({0, 0, 1}, 1.0, 0.3)[0]);
  return light;
}

// Frame f of the hand-held sequence (the camera 2 mm further each frame)
// through `inserter`, into s.
void RenderHandHeldFrame(Inserter& inserter, const SgMixture& light, int f, Sequence& s) {
  const SphereObject object({-0.04, 0.1, 0.05}, 0.04);
  const CameraIntrinsics camera = testing::TestCamera(240, 180);
  const Pose cam = LookAt({0.22 + 0.002 * f, -0.3 + 0.001 * f, 0.35}, {-0.1, 0.1, 0.02});
  ImageF frame(camera.width, camera.height, 3, 1.0f);
  InsertLayers layers;
  inserter.Render(camera, cam, {object.Object(&light)}, frame, &layers);
  s.kappa.push_back(layers.kappa);
  s.rects.push_back(layers.kappa_rect);
  s.frames.push_back(frame);
}

Sequence RenderHandHeld(const SceneField& scene, const InsertOptions& options, int threads,
                        const Vec3& axis = {0.8, -0.1, 1.0}) {
  const int saved = ThreadCount();
  SetThreadCount(threads);
  const SgMixture light = HandHeldLight(axis);
  Inserter inserter(scene, {}, options);
  Sequence s;
  for (int f = 0; f < kHandHeldFrames; ++f) RenderHandHeldFrame(inserter, light, f, s);
  SetThreadCount(saved);
  return s;
}

void ExpectIdentical(const Sequence& a, const Sequence& b, const char* what) {
  ASSERT_EQ(a.kappa.size(), b.kappa.size());
  for (size_t f = 0; f < a.kappa.size(); ++f) {
    EXPECT_EQ(a.rects[f].x0, b.rects[f].x0) << what << " frame " << f;
    EXPECT_EQ(a.rects[f].y1, b.rects[f].y1) << what << " frame " << f;
    ASSERT_EQ(a.kappa[f].pixels.size(), b.kappa[f].pixels.size()) << what << " frame " << f;
    size_t differ = 0, shadowed = 0;
    for (size_t i = 0; i < a.kappa[f].pixels.size(); ++i) {
      differ += a.kappa[f].pixels[i] != b.kappa[f].pixels[i];
      shadowed += a.kappa[f].pixels[i] < 0.99f;
    }
    // Exact equality: the same work in another order must give the same bits.
    EXPECT_EQ(differ, 0u) << what << " frame " << f << ": κ differs at " << differ << " pixels";
    EXPECT_GT(shadowed, 100u) << what << " frame " << f << ": the sequence must show a shadow to compare";
    EXPECT_TRUE(a.frames[f].pixels == b.frames[f].pixels) << what << " frame " << f << ": composite differs";
  }
}

TEST(Determinism, HandHeldKappaIsTheSameOnOneAndTwoThreads) {
  testing::AnalyticSceneParams params = PlainTable();
  params.has_sphere = true;  // curved receivers: several normal cells per lattice cell
  const testing::AnalyticScene exact(params);
  const ScatteredNormals scene(exact);
  for (const char* preset : {"fast", "balanced"}) {
    const InsertOptions options = InsertOptions::Preset(preset);
    ASSERT_TRUE(options.kappa_receiver_reuse && options.receiver_normal_per_cell &&
                options.kappa_cache_spacing_radii > 0)
        << preset << ": the test is about these paths";
    const Sequence one = RenderHandHeld(scene, options, 1);
    const Sequence two = RenderHandHeld(scene, options, 2);
    ExpectIdentical(one, two, preset);
  }
}

// Each thread keeps memos of the κ lattice's values across frames while the
// lattice stays. Two inserters lit differently (the same object, so their
// lattices have the same nodes with other values), frame by frame in turn
// on one thread, must each give what it gives alone, bit for bit: a memo
// must never hand one lattice's value to the other.
TEST(Determinism, InsertersInTurnOnOneThreadKeepTheirOwnKappa) {
  const testing::AnalyticScene exact(PlainTable());
  const ScatteredNormals scene(exact);
  const InsertOptions options = InsertOptions::Preset("balanced");
  const Vec3 axis_a{0.8, -0.1, 1.0}, axis_b{-0.3, 0.7, 1.0};
  const Sequence alone_a = RenderHandHeld(scene, options, 1, axis_a);
  const Sequence alone_b = RenderHandHeld(scene, options, 1, axis_b);
  const int saved = ThreadCount();
  SetThreadCount(1);
  const SgMixture light_a = HandHeldLight(axis_a), light_b = HandHeldLight(axis_b);
  Inserter a(scene, {}, options), b(scene, {}, options);
  Sequence turn_a, turn_b;
  for (int f = 0; f < kHandHeldFrames; ++f) {
    RenderHandHeldFrame(a, light_a, f, turn_a);
    RenderHandHeldFrame(b, light_b, f, turn_b);
  }
  SetThreadCount(saved);
  ExpectIdentical(alone_a, turn_a, "light a");
  ExpectIdentical(alone_b, turn_b, "light b");
  // The two lights' shadows must differ, or a mixed-up memo would not show.
  const std::vector<float>& ka = alone_a.frames.back().pixels;
  const std::vector<float>& kb = alone_b.frames.back().pixels;
  size_t differ = 0;
  for (size_t i = 0; i < ka.size(); ++i) differ += std::abs(ka[i] - kb[i]) > 1e-2f;
  EXPECT_GT(differ, 300u) << "the two lights must cast different shadows";
}

// The objects' prepared lights (SG shader, γ table rows, SSDF queries) are
// kept between frames while the lights, their lobes' distances and the
// objects are unchanged. A running inserter whose light, object or lobe
// distances change must give the composite of a fresh inserter that only
// ever saw the new inputs; each change must move the composite, or the
// comparison shows nothing.
TEST(Determinism, PreparedLightKeptBetweenFramesFollowsItsInputs) {
  const testing::AnalyticScene scene(PlainTable());
  const SphereObject object({-0.04, 0.1, 0.05}, 0.04), other({0.02, 0.06, 0.05}, 0.04);
  const CameraIntrinsics camera = testing::TestCamera(240, 180);
  const Pose cam = LookAt({0.22, -0.3, 0.35}, {-0.1, 0.1, 0.02});
  SgMixture light = OneLobe({0.8, -0.1, 1.0}, 40.0, 5.0);
  light.push_back(OneLobe({0, 0, 1}, 1.0, 0.3)[0]);
  SgMixture turned = OneLobe({-0.5, 0.4, 1.0}, 80.0, 5.0);
  turned.push_back(light[1]);
  const std::vector<double> near = {0.15, std::numeric_limits<double>::infinity()};
  const std::vector<double> far = {0.4, std::numeric_limits<double>::infinity()};
  struct Input {
    const SphereObject* object;
    const SgMixture* light;
    const std::vector<double>* distances;
  };
  const auto render = [&](Inserter& inserter, const Input& in) {
    ImageF frame(camera.width, camera.height, 3, 1.0f);
    InsertObject o = in.object->Object(in.light);
    o.light_distances = in.distances;
    inserter.Render(camera, cam, {o}, frame);
    return frame;
  };
  struct Case {
    const char* what;
    const char* preset;
    Input first, second;
  };
  const Case cases[] = {
      {"light changed", "fast", {&object, &light, nullptr}, {&object, &turned, nullptr}},
      {"object changed", "fast", {&object, &light, nullptr}, {&other, &light, nullptr}},
      {"lobe distance changed", "balanced", {&object, &light, &near}, {&object, &light, &far}},
  };
  for (const Case& c : cases) {
    const InsertOptions options = InsertOptions::Preset(c.preset);
    Inserter running(scene, {}, options);
    const ImageF before = render(running, c.first);
    const ImageF switched = render(running, c.second);
    Inserter fresh(scene, {}, options);
    render(fresh, c.second);
    const ImageF after = render(fresh, c.second);
    ASSERT_EQ(before.pixels.size(), after.pixels.size());
    size_t moved = 0, differ = 0;
    // Within float rounding (as KappaKeptBetweenFramesFollowsTheParallaxOption:
    // the two inserters' histories differ); stale preparations are off by
    // more than 1e-3 wherever the change moved the composite.
    for (size_t i = 0; i < after.pixels.size(); ++i) {
      const float v = after.pixels[i];
      moved += std::abs(before.pixels[i] - v) > 1e-3f;
      differ += std::abs(switched.pixels[i] - v) > 1e-5f * std::max(1.0f, std::abs(v));
    }
    EXPECT_GT(moved, 20u) << c.what << ": the change must move the composite, or the test shows nothing";
    EXPECT_EQ(differ, 0u) << c.what << ": the running inserter's composite differs from a fresh one's at " << differ
                          << " values";
  }
}

}  // namespace
}  // namespace nerfar
