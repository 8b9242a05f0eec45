#include "tests/support/support.h"

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace nerfar::testing {
namespace fs = std::filesystem;

TempDir::TempDir() {
  static std::atomic<int> counter{0};
  path_ = (fs::temp_directory_path() / ("nerfar_test_" + std::to_string(::getpid()) + "_" + std::to_string(counter++)))
              .string();
  fs::remove_all(path_);
  fs::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code error;
  fs::remove_all(path_, error);
}

static std::string SourceDir() {
  const char* env = std::getenv("NERFAR_SOURCE_DIR");
  return env != nullptr && *env ? env : NERFAR_SOURCE_DIR;
}

std::string SharedScenesDir() {
  std::error_code error;
  if (const char* env = std::getenv("NERFAR_SCENES"); env != nullptr && *env)
    return fs::is_regular_file(fs::path(env) / "README.md", error) ? env : "";
  const fs::path candidate = fs::path(SourceDir()).parent_path() / "shared" / "scenes";
  return fs::is_regular_file(candidate / "README.md", error) ? candidate.string() : "";
}

std::string TestDataPath(const std::string& name) { return SourceDir() + "/tests/data/" + name; }

void WriteText(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

std::string ReadText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

void WriteTruncatedCopy(const std::string& from, const std::string& to, size_t bytes) {
  const std::string text = ReadText(from);
  WriteText(to, text.substr(0, std::min(bytes, text.size())));
}

CommandResult RunCommand(const std::string& command_line) {
  const std::string command = command_line + " 2>&1";
  FILE* pipe = ::popen(command.c_str(), "r");
  std::string output;
  std::array<char, 4096> buffer{};
  while (pipe != nullptr && std::fgets(buffer.data(), buffer.size(), pipe) != nullptr) output += buffer.data();
  const int status = pipe != nullptr ? ::pclose(pipe) : -1;
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, output};
}

}  // namespace nerfar::testing
