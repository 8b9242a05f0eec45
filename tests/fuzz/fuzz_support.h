// Shared by the fuzz targets: a per-process scratch file for readers that
// take a path, and the checksum (calib/core/binary_file.h) that the .nerf, .ssdf and checkpoint
// files end with (appended by the targets so that mutated bodies get past
// the checksum and reach the parser; the raw bytes are tried as well), and
// where a checkpoint's identity ends.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>

#include "calib/core/binary_file.h"
#include "calib/core/error.h"

namespace nerfar::fuzz {

// DIR/name in a folder of this process's own, removed at exit.
inline std::string ScratchFile(const std::string& name) {
  struct Folder {
    std::filesystem::path dir = std::filesystem::temp_directory_path() / ("nerfar_fuzz_" + std::to_string(::getpid()));
    Folder() { std::filesystem::create_directories(dir); }
    ~Folder() {
      std::error_code error;
      std::filesystem::remove_all(dir, error);
    }
  };
  static const Folder folder;
  return (folder.dir / name).string();
}

inline bool WriteBytes(const std::string& path, const std::string& bytes) {
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (file == nullptr) return false;
  const bool ok = std::fwrite(bytes.data(), 1, bytes.size(), file) == bytes.size();
  return std::fclose(file) == 0 && ok;
}

// bytes followed by their checksum (little-endian), as the binary formats end.
inline std::string WithChecksum(std::string bytes) {
  const std::uint64_t sum = BinaryChecksum(bytes);
  bytes.append(reinterpret_cast<const char*>(&sum), 8);
  return bytes;
}

// Runs `read`; InputError (bad input, said so) is the one accepted failure.
template <typename Read>
void Expect(Read read) {
  try {
    read();
  } catch (const InputError&) {
  }
}

// The number of bytes of a checkpoint before its grid: the magic and the
// two identity strings (options, dataset), each a u64 length and its bytes.
inline size_t CheckpointIdentityBytes(const std::string& checkpoint) {
  size_t at = 8;
  for (int i = 0; i < 2 && at + 8 <= checkpoint.size(); ++i) {
    std::uint64_t length = 0;
    std::memcpy(&length, checkpoint.data() + at, 8);
    at += 8 + length;
  }
  return at;
}

}  // namespace nerfar::fuzz
