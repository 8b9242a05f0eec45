// Test support shared by every test program: temporary directories, the
// shared-scenes locator (skip with a clear message where absent), tolerance
// helpers that state their reason, and a few file-corruption helpers.
#pragma once

#include <gtest/gtest.h>

#include <functional>
#include <string>
#include <vector>

#include "calib/core/error.h"

namespace nerfar::testing {

// Message of the InputError thrown by body, or "" if none was thrown.
template <typename Body>
std::string InputErrorOf(Body body) {
  try {
    body();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

// A fresh empty directory, removed when the object goes out of scope.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::string& path() const { return path_; }
  std::string File(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

// ../shared/scenes (or $NERFAR_SCENES); empty when absent.
std::string SharedScenesDir();
// Absolute path of a file under tests/data.
std::string TestDataPath(const std::string& name);

void WriteText(const std::string& path, const std::string& text);
std::string ReadText(const std::string& path);
// Copies the first `bytes` bytes of `from` to `to` (a truncated file).
void WriteTruncatedCopy(const std::string& from, const std::string& to, size_t bytes);

// SOURCE/relative: a file of the source tree (NERFAR_SOURCE_DIR overrides its root).
std::string SourcePath(const std::string& relative);

// A finished shell command: its exit code (-1 when it did not exit normally)
// and its stdout and stderr together.
struct CommandResult {
  int exit_code;
  std::string output;
};
// Runs `command_line` through the shell and waits for it (for tests of the
// `nerfar` binary's exit codes and messages).
CommandResult RunCommand(const std::string& command_line);

// A child process (no shell) whose stdout and stderr are read into one text,
// for tests that signal a command while it runs. The destructor kills
// (SIGKILL) and reaps a child still running.
class ChildProcess {
 public:
  explicit ChildProcess(const std::vector<std::string>& argv);
  ~ChildProcess();
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  // Reads the output until `text` appears in it (true) or timeout_s passes.
  bool WaitForOutput(const std::string& text, double timeout_s);
  void Signal(int signal);
  // Waits for the end (at most timeout_s, then kills it): the exit code,
  // 128 + n when a signal n ended it, -1 when it had to be killed.
  int Wait(double timeout_s);
  const std::string& output() const { return output_; }

 private:
  bool ReadSome(int timeout_ms);  // false at the end of the output
  int pid_ = -1, fd_ = -1;
  std::string output_;
};

// Polls `done` every 20 ms for at most timeout_s; its last value.
bool WaitUntil(const std::function<bool()>& done, double timeout_s);

}  // namespace nerfar::testing

// Skips the current test, naming what is missing, when the shared scenes are absent.
#define NERFAR_REQUIRE_SHARED_SCENES(dir_var)                       \
  const std::string dir_var = ::nerfar::testing::SharedScenesDir(); \
  if (dir_var.empty()) GTEST_SKIP() << "../shared/scenes not found (set NERFAR_SCENES to run this test)"

// EXPECT_NEAR with a stated reason, printed on failure.
#define EXPECT_NEAR_WHY(actual, expected, tolerance, why) \
  EXPECT_NEAR(actual, expected, tolerance) << "tolerance " << (tolerance) << ": " << (why)
