// `nerfar insert` end to end on a small synthetic scene (every output
// written, named like the dataset's images, the background multiplied by κ
// and nothing else changed away from the object), and on bad input: every
// case exits with 2 (bad usage or bad input, DESIGN.md) and names what is
// wrong; nothing crashes.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "calib/core/exr.h"
#include "calib/core/json.h"
#include "render/lighting/env_light.h"
#include "render/sg/sphere.h"
#include "tests/support/slab_scene.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

namespace fs = std::filesystem;

using Result = testing::CommandResult;

Result RunInsert(const std::string& arguments) {
  return testing::RunCommand(std::string(NERFAR_BINARY) + " insert " + arguments);
}

class InsertCli : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("nerfar_insert_cli_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    Write("garbage.nerf", "not a nerf file at all");
    Write("garbage.ssdf", "not an ssdf");
    Write("pose.json", R"({"object_to_world": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]})");
  }
  void TearDown() override {
    std::error_code error;
    fs::remove_all(dir_, error);
  }
  void Write(const std::string& name, const std::string& text) { std::ofstream(dir_ / name) << text; }
  std::string P(const std::string& name) const { return (dir_ / name).string(); }
  // A complete command line with one argument group replaced.
  std::string Args(const std::string& nerf, const std::string& dataset, const std::string& extra = "") const {
    return "--nerf " + nerf + " --object " + P("garbage.ssdf") + " --pose " + P("pose.json") + " --dataset " + dataset +
           " -o " + P("out") + " " + extra;
  }
  fs::path dir_;
};

TEST_F(InsertCli, UsageErrorsExitWithTwoAndNameTheOption) {
  struct Case {
    std::string args, expected;
  };
  const std::string dataset = P("no_dataset");
  const Case cases[] = {
      {"--object x.ssdf --pose p.json --dataset d -o out", "--nerf"},
      {"--nerf n.nerf --pose p.json --dataset d -o out", "--object"},
      {"--nerf n.nerf --object a.ssdf --object b.ssdf --pose p.json --dataset d -o out", "--pose"},
      {"--nerf n.nerf --object a.ssdf --pose p.json -o out", "--dataset"},
      {"--nerf n.nerf --object a.ssdf --pose p.json --dataset d", "-o"},
      {Args(P("n.nerf"), dataset, "--background sky"), "--background"},
      {Args(P("n.nerf"), dataset, "--preset turbo"), "preset"},
      {Args(P("n.nerf"), dataset, "--kappa-step 0"), "kappa_step"},
      {Args(P("n.nerf"), dataset, "--sg-lobes 1000"), "lobes"},
      {Args(P("n.nerf"), dataset, "--light-source moon"), "moon"},
      {Args(P("n.nerf"), dataset, "--truth-geometry"), "--truth"},
      {Args(P("n.nerf"), dataset, "--kappa-step two"), "two"},
  };
  for (const Case& c : cases) {
    const Result r = RunInsert(c.args);
    EXPECT_EQ(r.exit_code, 2) << c.args << "\n" << r.output;
    EXPECT_NE(r.output.find(c.expected), std::string::npos) << c.args << "\n" << r.output;
  }
}

TEST_F(InsertCli, AMissingDatasetExitsWithTwoAndIsNamed) {
  // The dataset is read first: a missing one is named.
  const Result r = RunInsert(Args(P("garbage.nerf"), P("no_dataset")));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("no_dataset"), std::string::npos) << r.output;
}

TEST_F(InsertCli, CorruptInputsBesideAValidDatasetExitWithTwoAndNameThePath) {
  NERFAR_REQUIRE_SHARED_SCENES(scenes);
  const std::string dataset = scenes + "/lamps";
  Result r = RunInsert(Args(P("garbage.nerf"), dataset));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("garbage.nerf"), std::string::npos) << r.output;
  r = RunInsert(Args(P("missing.nerf"), dataset));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("missing.nerf"), std::string::npos) << r.output;
  // Ground-truth inputs without a NeRF: the .ssdf is read next and is corrupt.
  r = RunInsert("--object " + P("garbage.ssdf") + " --pose " + P("pose.json") + " --dataset " + dataset + " -o " +
                P("out") + " --truth " + dataset + "/insert/monkey_diffuse --truth-geometry --light-probe " + dataset +
                "/insert/monkey_diffuse/probe.exr");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("garbage.ssdf"), std::string::npos) << r.output;
}

// In `dir`: a synthetic lamps scene (`synth_options`: size, views, samples)
// with its insert/ truth in scene/, the torus baked fast as torus.ssdf and an
// opaque slab NeRF whose top is the table plane z = 0 as slab.nerf.
void MakeSlabScene(const testing::TempDir& dir, const std::string& synth_options) {
  const std::string nerfar = std::string(NERFAR_BINARY), scene = dir.File("scene");
  Result r = testing::RunCommand(nerfar + " synth --scene lamps -o " + scene + " " + synth_options + " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = testing::RunCommand(nerfar + " bake " + scene + "/objects/torus_diffuse.json -o " + dir.File("torus.ssdf") +
                          " --preset fast --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  testing::WriteSlabNerf(dir.File("slab.nerf"), Aabb{{-0.6, -0.4, -0.04}, {0.6, 0.4, 0.0}});
}

// A 96 × 72 slab scene (MakeSlabScene) and a one-lobe light from above as
// the environment: a shadow falls on the slab.
TEST(InsertRun, WritesEveryOutputNamedLikeTheDatasetAndMultipliesTheBackgroundByKappa) {
  testing::TempDir dir;
  const std::string scene = dir.File("scene"), out = dir.File("out");
  const std::string nerfar = std::string(NERFAR_BINARY);
  ASSERT_NO_FATAL_FAILURE(
      MakeSlabScene(dir, "--res 96x72 --views 4 --test-views 2 --spp 2 --insert-spp 2 --probe-spp 2"));
  testing::WriteOverheadEnv(dir.File("env.json"));
  const std::string truth = scene + "/insert/torus_diffuse";
  Result r = testing::RunCommand(nerfar + " insert --nerf " + dir.File("slab.nerf") + " --env " + dir.File("env.json") +
                                 " --object " + dir.File("torus.ssdf") + " --pose " + truth + "/pose.json --dataset " +
                                 scene + " -o " + out + " --truth " + truth + " --threads 2 --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* name : {"probe.exr", "timings.json", "options.json", "report.json"})
    EXPECT_TRUE(fs::is_regular_file(out + "/" + name)) << name;
  const Json test_views = ReadJsonFile(scene + "/transforms_test.json");
  ASSERT_EQ(test_views.at("frames").size(), 2u);
  size_t object_pixels = 0, shadowed = 0;
  for (const Json& view : test_views.at("frames")) {
    const std::string stem = fs::path(view.at("file_path").get<std::string>()).stem().string();
    SCOPED_TRACE(stem);
    for (const std::string suffix : {".exr", ".png", "_object.exr", "_alpha.exr", "_kappa.exr", "_sheet.png"})
      EXPECT_TRUE(fs::is_regular_file(out + "/" + stem + suffix)) << stem + suffix;
    const ImageF frame = ReadExrRgb(scene + "/test/" + stem + ".exr");
    const ImageF composite = ReadExrRgb(out + "/" + stem + ".exr");
    const ImageF alpha = ReadExrChannel(out + "/" + stem + "_alpha.exr");
    const ImageF kappa = ReadExrChannel(out + "/" + stem + "_kappa.exr");
    ASSERT_EQ(composite.width, frame.width);
    ASSERT_EQ(composite.height, frame.height);
    ASSERT_EQ(kappa.width, frame.width);
    for (int y = 1; y + 1 < frame.height; ++y)
      for (int x = 1; x + 1 < frame.width; ++x) {
        if (alpha.at(x, y, 0) > 0.5f) ++object_pixels;
        bool near_object = false;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) near_object = near_object || alpha.at(x + dx, y + dy, 0) > 0.0f;
        if (near_object) continue;
        const float k = kappa.at(x, y, 0);
        EXPECT_GE(k, 0.0f);
        EXPECT_LE(k, 1.0f);
        if (k < 0.95f) ++shadowed;
        // Away from the object the composite is the frame times κ; the EXR
        // files are half floats (relative step 2^-11 each way, so 2e-3).
        for (int c = 0; c < 3; ++c)
          ASSERT_NEAR(composite.at(x, y, c), frame.at(x, y, c) * k, 2e-3f * frame.at(x, y, c) + 1e-6f)
              << x << "," << y << " channel " << c;
      }
  }
  // Both views together (measured 60 and 142): the torus covers a few
  // dozen pixels, and its shadow on the slab under the light from above
  // more than that.
  EXPECT_GT(object_pixels, 30u);
  EXPECT_GT(shadowed, 50u);
  const ImageF probe = ReadExrRgb(out + "/probe.exr");
  EXPECT_EQ(probe.width, 256);
  EXPECT_EQ(probe.height, 128);
  const Json report = ReadJsonFile(out + "/report.json");
  EXPECT_TRUE(std::isfinite(report.at("mean_object_psnr_tm_db").get<double>())) << report.dump();
  // The alongside view: the same insertion over the NeRF's own rendering.
  r = testing::RunCommand(nerfar + " insert --nerf " + dir.File("slab.nerf") + " --env " + dir.File("env.json") +
                          " --object " + dir.File("torus.ssdf") + " --pose " + truth + "/pose.json --dataset " + scene +
                          " -o " + dir.File("alongside") + " --background nerf --threads 2 --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(fs::is_regular_file(dir.File("alongside") + "/probe.exr"));
}

// The brightest direction of a probe panorama (luminance per pixel).
Vec3 BrightestDirection(const ImageF& probe) {
  int best_x = 0, best_y = 0;
  float best = -1;
  for (int y = 0; y < probe.height; ++y)
    for (int x = 0; x < probe.width; ++x) {
      const float l = 0.2126f * probe.at(x, y, 0) + 0.7152f * probe.at(x, y, 1) + 0.0722f * probe.at(x, y, 2);
      if (l > best) best = l, best_x = x, best_y = y;
    }
  return EquirectDirection((best_x + 0.5) / probe.width, (best_y + 0.5) / probe.height);
}

// env.json's distance of a light reaches `nerfar insert`: a lamp 0.5 m
// straight above the origin lights the object from where the lamp stands,
// not from the zenith the lobe holds as seen from the origin.
TEST(InsertRun, AnEnvironmentLightAtADistanceIsSeenFromTheObject) {
  testing::TempDir dir;
  const std::string scene = dir.File("scene"), nerfar = std::string(NERFAR_BINARY);
  ASSERT_NO_FATAL_FAILURE(
      MakeSlabScene(dir, "--res 48x36 --views 2 --test-views 1 --spp 1 --insert-spp 1 --probe-spp 1"));
  const Vec3 lamp{0, 0, 0.5};
  EnvLight env;
  env.lobes.push_back(Sg{{0, 0, 1}, 400.0, {50.0, 50.0, 50.0}});
  env.distance_m = {Length(lamp)};
  WriteEnvLight(dir.File("env.json"), env);
  const std::string truth = scene + "/insert/torus_diffuse";
  const Json pose = ReadJsonFile(truth + "/pose.json");
  const Vec3 center{pose.at("center_world")[0].get<double>(), pose.at("center_world")[1].get<double>(),
                    pose.at("center_world")[2].get<double>()};
  const Result r =
      testing::RunCommand(nerfar + " insert --nerf " + dir.File("slab.nerf") + " --env " + dir.File("env.json") +
                          " --object " + dir.File("torus.ssdf") + " --pose " + truth + "/pose.json --dataset " + scene +
                          " -o " + dir.File("out") + " --threads 2 --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const Vec3 brightest = BrightestDirection(ReadExrRgb(dir.File("out") + "/probe.exr"));
  const Vec3 to_lamp = Normalized(lamp - center);
  const double off_lamp = std::acos(std::min(1.0, Dot(brightest, to_lamp))) * 180 / kPi;
  const double off_zenith = std::acos(std::min(1.0, brightest.z)) * 180 / kPi;
  std::printf("object centre %.3f %.3f %.3f: brightest %.1f° from the lamp, %.1f° from the zenith\n", center.x,
              center.y, center.z, off_lamp, off_zenith);
  // The probe's pixels are 1.4° wide and the light's SG fit moves a peak by
  // about as much: 4°. The object stands far enough from the lamp's foot that
  // the zenith is more than twice that from the lamp (the test can fail).
  ASSERT_GT(std::acos(to_lamp.z) * 180 / kPi, 8.0);
  EXPECT_LT(off_lamp, 4.0);
}

}  // namespace
}  // namespace nerfar
