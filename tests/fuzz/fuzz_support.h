// Shared by the fuzz targets: a per-process scratch file for readers that
// take a path, and the checksums (calib/core/binary_file.h) that the .nerf, .ssdf and checkpoint
// files end with, crc32 (sectioned files) or the legacy FNV (flat files), appended by the targets
// so that mutated bodies get past the checksum and reach the parser (the raw bytes are tried as
// well).
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
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

// The bytes with each checksum a file may end with appended: crc32 (sectioned files) and the
// legacy FNV (flat ones).
inline std::string WithCrc32(std::string bytes) {
  const std::uint32_t crc = BinaryCrc32(bytes);
  return bytes.append(reinterpret_cast<const char*>(&crc), 4);
}
inline std::string WithLegacyChecksum(std::string bytes) {
  const std::uint64_t sum = LegacyFnv1aChecksum(bytes);
  return bytes.append(reinterpret_cast<const char*>(&sum), 8);
}

// Runs `read`; InputError (bad input, said so) is the one accepted failure.
template <typename Read>
void Expect(Read read) {
  try {
    read();
  } catch (const InputError&) {
  }
}

}  // namespace nerfar::fuzz
