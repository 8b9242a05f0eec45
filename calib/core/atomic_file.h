// Files are written as a temporary file beside the target and renamed over it
// in one step: a reader never sees half a file, a crash leaves the old file
// whole, and inputs are never overwritten (CheckNotSameFile guards that).
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace nerfar {

// Owns a temporary path next to `target`; Commit() renames it onto the target.
// If destroyed without Commit() the temporary file is removed.
class AtomicFile {
 public:
  explicit AtomicFile(std::string target);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  const std::string& temp_path() const { return temp_path_; }
  const std::string& target() const { return target_; }
  // Throws std::runtime_error naming the target if the rename fails.
  void Commit();

 private:
  std::string target_;
  std::string temp_path_;
  bool committed_ = false;
};

void WriteFileAtomic(const std::string& path, std::string_view bytes);

// Reads a whole file; InputError if it is missing, unreadable, or larger than
// max_bytes (so a wrong path to a huge file cannot exhaust memory).
std::string ReadFileBytes(const std::string& path, size_t max_bytes = size_t{1} << 30);

// InputError if `output` names the same file as any of `inputs` (after
// resolving links), so no command can overwrite what it reads.
void CheckNotSameFile(const std::string& output, const std::vector<std::string>& inputs);

// Creates a directory and its parents; runtime_error naming it on failure.
void MakeDirectories(const std::string& path);

}  // namespace nerfar
