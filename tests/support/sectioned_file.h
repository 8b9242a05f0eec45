// Helpers for tests of the sectioned binary files (calib/core/binary_file.h): find a section in a
// file's bytes, and make a file's crc32 right again after a test changed a field (so that the
// change reaches the format's parser past the crc).
#pragma once

#include <cstring>
#include <string>
#include <string_view>

#include "calib/core/binary_file.h"

namespace nerfar::testing {

// A reader of section `tag` of a sectioned file (its offset() is where the section starts in the
// file). The file's own magic and version are taken as the expected ones.
inline ByteReader SectionOf(const std::string& bytes, std::string_view tag) {
  uint32_t version = 0;
  std::memcpy(&version, bytes.data() + 8, 4);
  const BinaryFormat format{"test file", std::string_view(bytes).substr(0, 8), true, version, version, version, ""};
  return OpenBinaryFile(bytes, "test file", format).Section(tag);
}

// The bytes of section `tag` of a sectioned file.
inline std::string SectionBytes(const std::string& bytes, std::string_view tag) {
  ByteReader section = SectionOf(bytes, tag);
  return std::string(section.Take(section.remaining(), "section"));
}

// The bytes with their last 4 replaced by the crc32 of everything before them.
inline std::string Resealed(std::string bytes) {
  const uint32_t crc = BinaryCrc32(std::string_view(bytes).substr(0, bytes.size() - 4));
  std::memcpy(bytes.data() + bytes.size() - 4, &crc, 4);
  return bytes;
}

}  // namespace nerfar::testing
