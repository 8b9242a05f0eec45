// env.json: round trip, strictness, and the preview panorama.
#include "render/lighting/env_light.h"

#include <gtest/gtest.h>

#include <cmath>

#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "render/sg/sphere.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

const char* kGood =
    R"({"format":"nerfar-env","version":1,"lobes":[{"axis":[0,0,1],"sharpness":2,"amplitude":[1,1,1]}],)"
    R"("negligible":false,"energy":{"env_to_near_surface":0.5,"env_to_near_center":0.4,"threshold":0.05}})";

EnvLight SampleLight() {
  EnvLight env;
  for (int k = 0; k < 32; ++k) {
    Sg lobe;
    const double a = 0.37 * k, b = 0.11 * k - 1.5;
    lobe.axis = Normalized(Vec3{std::cos(a) * std::cos(b), std::sin(a) * std::cos(b), std::sin(b)});
    lobe.sharpness = std::pow(10.0, -4.0 + 8.0 * k / 31.0);  // the whole DESIGN.md range
    lobe.amplitude = {k * 0.1, 1e6 * (k == 5), 1.0 / (k + 1)};
    env.lobes.push_back(lobe);
  }
  env.negligible = true;
  env.env_to_near_surface = 0.0123;
  env.env_to_near_center = 1.5e-3;
  env.threshold = 0.05;
  env.source = "scene.nerf";
  env.options_json = R"({"pixels_per_view":64})";
  env.fit = {6400, 0.31, 0.052, true, 0.57, 0.19};
  return env;
}

TEST(EnvLightFile, RoundTripIsExact) {
  testing::TempDir dir;
  const EnvLight env = SampleLight();
  WriteEnvLight(dir.File("env.json"), env);
  const EnvLight back = ReadEnvLight(dir.File("env.json"));
  ASSERT_EQ(back.lobes.size(), env.lobes.size());
  for (size_t k = 0; k < env.lobes.size(); ++k) {
    // nlohmann writes doubles with round-trip precision; the axis is
    // renormalised on both sides, so equality up to one ulp-level rounding.
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(back.lobes[k].axis[i], env.lobes[k].axis[i], 1e-15);
      EXPECT_EQ(back.lobes[k].amplitude[i], env.lobes[k].amplitude[i]);
    }
    EXPECT_EQ(back.lobes[k].sharpness, env.lobes[k].sharpness);
  }
  EXPECT_TRUE(back.negligible);
  EXPECT_EQ(back.env_to_near_surface, env.env_to_near_surface);
  EXPECT_EQ(back.env_to_near_center, env.env_to_near_center);
  EXPECT_EQ(back.threshold, env.threshold);
  EXPECT_EQ(back.source, env.source);
  EXPECT_EQ(back.options_json, env.options_json);
  EXPECT_EQ(back.fit.samples, 6400);
  EXPECT_EQ(back.fit.relative_rms, env.fit.relative_rms);
  EXPECT_EQ(back.fit.loss, env.fit.loss);
  EXPECT_TRUE(back.fit.near_only_fitted);
  EXPECT_EQ(back.fit.near_only_relative_rms, env.fit.near_only_relative_rms);
  EXPECT_EQ(back.fit.near_only_loss, env.fit.near_only_loss);
}

// A source placed at a distance keeps it through the file; distant lobes
// write no distance, and a file whose lobes all lack one reads as all
// distant (an empty list, as before the format had them).
TEST(EnvLightFile, DistancesRoundTripAndAreOptional) {
  EnvLight env = SampleLight();
  env.distance_m.assign(env.lobes.size(), 0.0);
  env.distance_m[3] = 1.72;
  env.distance_m[31] = 0.535;
  const std::string text = SerializeEnvLight(env);
  size_t count = 0;
  for (size_t at = text.find("distance_m"); at != std::string::npos; at = text.find("distance_m", at + 1)) ++count;
  EXPECT_EQ(count, 2u) << text;
  const EnvLight back = ParseEnvLight(text, "mem");
  EXPECT_EQ(back.distance_m, env.distance_m);
  env.distance_m.assign(env.lobes.size(), 0.0);
  EXPECT_TRUE(ParseEnvLight(SerializeEnvLight(env), "mem").distance_m.empty());
  EXPECT_TRUE(ParseEnvLight(kGood, "old.json").distance_m.empty());
  env.distance_m = {1.0};  // not one per lobe
  EXPECT_FALSE(ValidateEnvLight(env).empty());
}

// Insertion drops a negligible estimate's lobes and their distances alike.
TEST(EnvLightFile, NegligibleDropsLobesAndDistances) {
  EnvLight env = SampleLight();
  env.distance_m.assign(env.lobes.size(), 2.0);
  env.negligible = false;
  EXPECT_FALSE(DropIfNegligible(env));
  EXPECT_EQ(env.lobes.size(), 32u);
  env.negligible = true;
  EXPECT_TRUE(DropIfNegligible(env));
  EXPECT_TRUE(env.lobes.empty());
  EXPECT_TRUE(env.distance_m.empty());
}

// The fit's residual is documentation added to the format later: files
// without it (or without its near-field-only part) still read.
TEST(EnvLightFile, FitResidualIsOptional) {
  EnvLight env = SampleLight();
  env.fit = {};
  const std::string without = SerializeEnvLight(env);
  EXPECT_EQ(without.find("\"fit\""), std::string::npos) << without;
  EXPECT_EQ(ParseEnvLight(without, "old.json").fit.samples, 0);
  env.fit = {100, 0.2, 0.01, false, 0, 0};
  const std::string no_near = SerializeEnvLight(env);
  EXPECT_EQ(no_near.find("near_field_only"), std::string::npos) << no_near;
  const EnvLight back = ParseEnvLight(no_near, "mem");
  EXPECT_EQ(back.fit.samples, 100);
  EXPECT_FALSE(back.fit.near_only_fitted);
}

TEST(EnvLightFile, EmptyMixtureIsValid) {
  EnvLight env;
  env.negligible = true;
  const EnvLight back = ParseEnvLight(SerializeEnvLight(env), "mem");
  EXPECT_TRUE(back.lobes.empty());
  EXPECT_TRUE(back.negligible);
}

void ExpectError(const std::string& text, const std::string& needle) {
  try {
    ParseEnvLight(text, "bad.json");
    ADD_FAILURE() << "accepted: " << text;
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("bad.json"), std::string::npos) << e.what();
  }
}

std::string Replace(std::string text, const std::string& from, const std::string& to) {
  const size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return text.replace(at, from.size(), to);
}

TEST(EnvLightFile, BadFilesNameEveryProblem) {
  EXPECT_NO_THROW(ParseEnvLight(kGood, "good.json"));
  ExpectError("{", "line");
  ExpectError(Replace(kGood, "nerfar-env", "other"), "/format");
  ExpectError(Replace(kGood, "\"version\":1", "\"version\":2"), "/version");
  ExpectError(Replace(kGood, "[0,0,1]", "[0,0,2]"), "/lobes/0/axis");
  ExpectError(Replace(kGood, "[0,0,1]", "[0,0]"), "/lobes/0/axis");
  ExpectError(Replace(kGood, "\"sharpness\":2", "\"sharpness\":0"), "/lobes/0/sharpness");
  ExpectError(Replace(kGood, "\"sharpness\":2", "\"sharpness\":1e5"), "/lobes/0/sharpness");
  ExpectError(Replace(kGood, "[1,1,1]", "[1,-1,1]"), "/lobes/0/amplitude/1");
  ExpectError(Replace(kGood, "[1,1,1]", "[1,\"x\",1]"), "/lobes/0/amplitude/1");
  ExpectError(Replace(kGood, "\"sharpness\":2", "\"sharpness\":2,\"sharpnes\":3"), "sharpnes");
  ExpectError(Replace(kGood, "\"sharpness\":2", "\"sharpness\":2,\"distance_m\":-1"), "/lobes/0/distance_m");
  ExpectError(Replace(kGood, "\"negligible\":false", "\"negligible\":0"), "/negligible");
  ExpectError(Replace(kGood, "\"negligible\":false,", ""), "negligible");
  ExpectError(Replace(kGood, "\"threshold\":0.05", "\"threshold\":2"), "/energy/threshold");
  ExpectError(Replace(kGood, "0.5", "-0.5"), "/energy/env_to_near_surface");
  const std::string with_fit =
      Replace(kGood, "\"threshold\":0.05}", R"("threshold":0.05},"fit":{"samples":9,"relative_rms":0.3,"loss":0.1})");
  EXPECT_NO_THROW(ParseEnvLight(with_fit, "good.json"));
  ExpectError(Replace(with_fit, "\"relative_rms\":0.3", "\"relative_rms\":-1"), "/fit/relative_rms");
  ExpectError(Replace(with_fit, "\"loss\":0.1", "\"loss\":0.1,\"los\":2"), "los");
  ExpectError(Replace(with_fit, "\"loss\":0.1", "\"loss\":0.1,\"near_field_only\":{\"loss\":1}"),
              "/fit/near_field_only");
  // Two problems in one file: both reported at once.
  try {
    ParseEnvLight(Replace(Replace(kGood, "[0,0,1]", "[0,0,2]"), "\"threshold\":0.05", "\"threshold\":2"), "b.json");
    ADD_FAILURE();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/lobes/0/axis"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("/energy/threshold"), std::string::npos);
  }
  std::string many = R"({"format":"nerfar-env","version":1,"lobes":[)";
  for (int k = 0; k <= kMaxSgLobes; ++k)
    many += std::string(k ? "," : "") + R"({"axis":[0,0,1],"sharpness":2,"amplitude":[1,1,1]})";
  many += R"(],"negligible":false,"energy":{"env_to_near_surface":0,"env_to_near_center":0,"threshold":0.05}})";
  ExpectError(many, "at most");
  testing::TempDir dir;
  EXPECT_THROW(ReadEnvLight(dir.File("missing.json")), InputError);
}

TEST(EnvLightFile, PreviewFollowsTheSceneConvention) {
  // One sharp lobe towards +y must light the panorama's column at u = 0.25
  // (scenes/README.md: u = 0.25 is +y), row at the horizon.
  EnvLight env;
  Sg lobe;
  lobe.axis = {0, 1, 0};
  lobe.sharpness = 200;
  lobe.amplitude = {5, 4, 3};
  env.lobes.push_back(lobe);
  testing::TempDir dir;
  WriteEnvPreview(dir.File("env.exr"), env);
  const ImageF pano = ReadExrRgb(dir.File("env.exr"));
  ASSERT_EQ(pano.width, 256);
  ASSERT_EQ(pano.height, 128);
  int best_x = 0, best_y = 0;
  for (int y = 0; y < pano.height; ++y)
    for (int x = 0; x < pano.width; ++x)
      if (pano.at(x, y, 0) > pano.at(best_x, best_y, 0)) best_x = x, best_y = y;
  // Pixel centres at (i + 0.5)/256: the lobe axis falls between columns 63 and 64, rows 63 and 64.
  EXPECT_TRUE(best_x == 63 || best_x == 64) << best_x;
  EXPECT_TRUE(best_y == 63 || best_y == 64) << best_y;
  // Near the axis the value approaches μ (within one pixel of 1.4°: exp(−200·(1−cos 1°)) ≈ 0.97).
  EXPECT_NEAR(pano.at(best_x, best_y, 0), 5.0, 0.2);
}

}  // namespace
}  // namespace nerfar
