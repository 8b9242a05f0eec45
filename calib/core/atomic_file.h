// Files are written as a temporary file beside the target and renamed over it
// in one step: a reader never sees half a file, a crash leaves the old file
// whole, and inputs are never overwritten (calib/core/output_guard.h guards
// that). Commit() makes the write durable: the file's data reaches the disk
// before the rename and the folder's entry after it, so a power cut leaves
// the old file or the new one, never an empty one. Temporary files are
// removed when the write fails, when its owner is destroyed uncommitted, and
// on SIGINT / SIGTERM (RemoveTemporaryFiles, from the signal handler).
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace nerfar {

// Owns a temporary path next to `target` (".NAME.tmpPID_N.EXT": the target's
// extension kept, for writers that pick a format by it); Commit() renames it
// onto the target. If destroyed without Commit() the temporary file is removed.
class AtomicFile {
 public:
  explicit AtomicFile(std::string target);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  const std::string& temp_path() const { return temp_path_; }
  const std::string& target() const { return target_; }
  // Flushes the temporary file to disk, renames it onto the target and
  // flushes the folder; std::runtime_error naming the target if any step
  // fails (the temporary file is then removed).
  void Commit();

 private:
  std::string target_;
  std::string temp_path_;
  int registry_slot_ = -1;  // where the signal handler finds temp_path_ (-1: not registered)
  bool committed_ = false;
};

void WriteFileAtomic(const std::string& path, std::string_view bytes);

// Removes every temporary file of an AtomicFile alive in this process.
// Async-signal-safe (unlink only): for SIGINT / SIGTERM handlers.
void RemoveTemporaryFiles();

// Reads a whole file; InputError if it is missing, unreadable, or larger than
// max_bytes (so a wrong path to a huge file cannot exhaust memory).
std::string ReadFileBytes(const std::string& path, size_t max_bytes = size_t{1} << 30);

// Creates a directory and its parents; runtime_error naming it on failure.
void MakeDirectories(const std::string& path);

}  // namespace nerfar
