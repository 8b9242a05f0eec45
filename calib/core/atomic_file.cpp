#include "calib/core/atomic_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
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
  name.append(path.stem().string()).append(".tmp").append(std::to_string(::getpid()));
  name.append("_").append(std::to_string(counter++)).append(path.extension().string());
  return (path.parent_path() / name).string();
}

// The temporary files alive now, where a signal handler can reach them: fixed
// slots (no allocation, no locks), each free, being filled, or holding a path.
constexpr int kTempSlots = 128;
enum SlotState : int { kFree = 0, kFilling = 1, kHeld = 2 };
struct TempSlot {
  std::atomic<int> state{kFree};
  char path[4096];
};
std::array<TempSlot, kTempSlots> g_temp_slots;

int RegisterTemp(const std::string& path) {
  if (path.size() >= sizeof(TempSlot::path)) return -1;
  for (int i = 0; i < kTempSlots; ++i) {
    int expected = kFree;
    if (!g_temp_slots[i].state.compare_exchange_strong(expected, kFilling)) continue;
    std::memcpy(g_temp_slots[i].path, path.c_str(), path.size() + 1);
    g_temp_slots[i].state.store(kHeld);
    return i;
  }
  return -1;  // more writes at once than slots: this one is not removed on a signal
}

void UnregisterTemp(int slot) {
  if (slot >= 0) g_temp_slots[slot].state.store(kFree);
}

// fsync of a file or folder by path; errno-style message, "" when done.
std::string Sync(const std::string& path, bool folder) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | (folder ? O_DIRECTORY : 0));
  if (fd < 0) return std::strerror(errno);
  std::string why;
  // A folder on a file system without fsync for folders (EINVAL) is as durable as it gets.
  if (::fsync(fd) != 0 && !(folder && errno == EINVAL)) why = std::strerror(errno);
  ::close(fd);
  return why;
}

std::string FolderOf(const std::string& path) {
  const fs::path parent = fs::path(path).parent_path();
  return parent.empty() ? "." : parent.string();
}

}  // namespace

AtomicFile::AtomicFile(std::string target)
    : target_(std::move(target)), temp_path_(UniqueTempPath(target_)), registry_slot_(RegisterTemp(temp_path_)) {}

AtomicFile::~AtomicFile() {
  // Removed before it leaves the registry: a signal in between finds nothing to remove.
  if (!committed_) std::remove(temp_path_.c_str());
  UnregisterTemp(registry_slot_);
}

void AtomicFile::Commit() {
  const auto fail = [&](const std::string& what) {
    std::remove(temp_path_.c_str());
    throw std::runtime_error(target_ + ": cannot write (" + what + ")");
  };
  if (const std::string why = Sync(temp_path_, false); !why.empty()) fail("flushing to disk: " + why);
  if (::rename(temp_path_.c_str(), target_.c_str()) != 0) fail(std::strerror(errno));
  committed_ = true;
  UnregisterTemp(registry_slot_);
  registry_slot_ = -1;
  if (const std::string why = Sync(FolderOf(target_), true); !why.empty())
    throw std::runtime_error(target_ + ": written, but its folder could not be flushed to disk (" + why + ")");
}

void RemoveTemporaryFiles() {
  for (TempSlot& slot : g_temp_slots)
    if (slot.state.load() == kHeld) ::unlink(slot.path);
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

void MakeDirectories(const std::string& path) {
  std::error_code error;
  fs::create_directories(path, error);
  if (error) throw std::runtime_error(path + ": cannot create directory (" + error.message() + ")");
}

}  // namespace nerfar
