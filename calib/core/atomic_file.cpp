#include "calib/core/atomic_file.h"

#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <system_error>

#include "calib/core/error.h"

namespace nerfar {
namespace fs = std::filesystem;

namespace {
std::string UniqueTempPath(const std::string& target) {
  static std::atomic<unsigned> counter{0};
  const fs::path path(target);
  // Built by appending: operator+ chains trip a GCC 12 -Wrestrict false positive.
  std::string name = ".";
  name.append(path.filename().string()).append(".tmp").append(std::to_string(::getpid()));
  name.append("_").append(std::to_string(counter++));
  return (path.parent_path() / name).string();
}
}  // namespace

AtomicFile::AtomicFile(std::string target) : target_(std::move(target)), temp_path_(UniqueTempPath(target_)) {}

AtomicFile::~AtomicFile() {
  if (!committed_) std::remove(temp_path_.c_str());
}

void AtomicFile::Commit() {
  std::error_code error;
  fs::rename(temp_path_, target_, error);
  if (error) {
    std::remove(temp_path_.c_str());
    throw std::runtime_error(target_ + ": cannot write (" + error.message() + ")");
  }
  committed_ = true;
}

void WriteFileAtomic(const std::string& path, std::string_view bytes) {
  AtomicFile file(path);
  {
    std::ofstream out(file.temp_path(), std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    out.flush();
    if (!out) throw std::runtime_error(path + ": cannot write (disk full or no permission?)");
  }
  file.Commit();
}

std::string ReadFileBytes(const std::string& path, size_t max_bytes) {
  std::error_code error;
  if (!fs::exists(path, error)) ThrowInputError(path, "no such file");
  if (fs::is_directory(path, error)) ThrowInputError(path, "is a directory (expected a file)");
  const auto size = fs::file_size(path, error);
  if (error) ThrowInputError(path, "cannot read (" + error.message() + ")");
  if (size > max_bytes)
    ThrowInputError(path,
                    "file is " + std::to_string(size) + " bytes (expected at most " + std::to_string(max_bytes) + ")");
  std::ifstream in(path, std::ios::binary);
  if (!in) ThrowInputError(path, "cannot open for reading");
  std::string bytes(size, '\0');
  in.read(bytes.data(), static_cast<std::streamsize>(size));
  if (static_cast<size_t>(in.gcount()) != size) ThrowInputError(path, "short read");
  return bytes;
}

void CheckNotSameFile(const std::string& output, const std::vector<std::string>& inputs) {
  std::error_code error;
  if (!fs::exists(output, error)) return;
  for (const std::string& input : inputs) {
    if (fs::exists(input, error) && fs::equivalent(output, input, error))
      ThrowInputError(output, "is also an input (" + input + "); refusing to overwrite an input");
  }
}

void MakeDirectories(const std::string& path) {
  std::error_code error;
  fs::create_directories(path, error);
  if (error) throw std::runtime_error(path + ": cannot create directory (" + error.message() + ")");
}

}  // namespace nerfar
