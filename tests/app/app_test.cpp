// The `nerfar` executable as a user meets it: help, exit codes 0/1/2 and
// messages that name what is wrong.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <string>

#include "app/cli.h"
#include "calib/core/error.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

struct Result {
  int exit_code;
  std::string output;  // stdout and stderr together
};

Result RunNerfar(const std::string& arguments) {
  const std::string command = std::string(NERFAR_BINARY) + " " + arguments + " 2>&1";
  FILE* pipe = ::popen(command.c_str(), "r");
  std::string output;
  std::array<char, 4096> buffer{};
  while (pipe != nullptr && std::fgets(buffer.data(), buffer.size(), pipe) != nullptr) output += buffer.data();
  const int status = pipe != nullptr ? ::pclose(pipe) : -1;
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, output};
}

TEST(App, HelpListsTheCommands) {
  const Result result = RunNerfar("help");
  EXPECT_EQ(result.exit_code, 0);
  EXPECT_NE(result.output.find("bench"), std::string::npos) << result.output;
  EXPECT_EQ(RunNerfar("").exit_code, 0);
}

TEST(App, EveryCommandHasHelp) {
  for (const char* command : {"bench", "version"}) {
    const Result result = RunNerfar(std::string(command) + " --help");
    EXPECT_EQ(result.exit_code, 0) << command;
    EXPECT_NE(result.output.find("usage: nerfar"), std::string::npos) << command << ": " << result.output;
  }
}

TEST(App, UnknownCommandAndBadFlagsExitTwo) {
  Result result = RunNerfar("frobnicate");
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_NE(result.output.find("unknown command 'frobnicate'"), std::string::npos);
  result = RunNerfar("bench --no-such-flag");
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_NE(result.output.find("unknown option --no-such-flag"), std::string::npos) << result.output;
  result = RunNerfar("bench --threads two");
  EXPECT_EQ(result.exit_code, 2);
  result = RunNerfar("bench nosuchstage");
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_NE(result.output.find("unknown stage 'nosuchstage'"), std::string::npos);
}

TEST(App, BenchWritesTableAndJson) {
  testing::TempDir dir;
  const Result result = RunNerfar("bench core --quick --threads 1 --json " + dir.File("b.json"));
  ASSERT_EQ(result.exit_code, 0) << result.output;
  EXPECT_NE(result.output.find("exr_read_half_ms"), std::string::npos);
  const std::string json = testing::ReadText(dir.File("b.json"));
  EXPECT_NE(json.find("\"threads\": 1"), std::string::npos) << json;
  EXPECT_NE(json.find("exr_write_float_ms"), std::string::npos);
}

TEST(ArgParser, ParsesOptionsPositionalsAndRejectsMisuse) {
  std::string input, output;
  int count = 3;
  double scale = 1.0;
  bool flag = false;
  ArgParser parser("test", "a test command");
  parser.Positional("INPUT", &input, "input");
  parser.Option("-o", &output, "FILE", "output");
  parser.Option("--count", &count, "N", "count");
  parser.Option("--scale", &scale, "S", "scale");
  parser.Flag("--flag", &flag, "a flag");
  ASSERT_TRUE(parser.Parse({"in.json", "-o", "out", "--count=7", "--scale", "-0.5", "--flag", "--threads", "1"}));
  EXPECT_EQ(input, "in.json");
  EXPECT_EQ(output, "out");
  EXPECT_EQ(count, 7);
  EXPECT_EQ(scale, -0.5);
  EXPECT_TRUE(flag);
  EXPECT_THROW(ArgParser("t", "").Parse({"extra"}), InputError);
  ArgParser missing("t", "");
  missing.Positional("X", &input, "x");
  EXPECT_THROW(missing.Parse({}), InputError);
  ArgParser twice("t", "");
  twice.Option("--count", &count, "N", "");
  EXPECT_THROW(twice.Parse({"--count", "1", "--count", "2"}), InputError);
  EXPECT_THROW(twice.Parse({"--count", "1x"}), InputError);
  EXPECT_THROW(twice.Parse({"--quiet", "--verbose"}), InputError);
}

}  // namespace
}  // namespace nerfar
