// `nerfar insert` on bad input: every case exits with 2 (bad usage or bad
// input, DESIGN.md) and names what is wrong; nothing crashes.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

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

}  // namespace
}  // namespace nerfar
