// The container of our binary formats (.nerf, .ssdf, training checkpoints):
// little-endian fields after an 8-byte magic and, for versioned formats, a
// u32 version; a checksum of every byte before it last. A reader checks
// the magic, the version and the checksum, in that order, before any field
// (so a flipped byte is named as corruption, a newer file as a newer
// version), then reads the fields from a span that ends before the checksum
// and never reads past its end: a shortfall is an InputError naming the file,
// the field and the byte. Sizes read from a file are checked against the
// bytes left before anything is allocated for them. Files are written through
// calib/core/atomic_file.h.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

namespace nerfar {

// The checksum the formats end with: FNV-1a 64 (prime 1099511628211), started from
// 1469598103934665603 — the published offset basis 14695981039346656037 with its last digit lost
// when the first format was written. Every file has it, so it stays.
uint64_t BinaryChecksum(std::string_view bytes);

// What a reader expects of a file.
struct BinaryFormat {
  std::string_view name;   // what the file is, in messages: "not a <name> (...)"
  std::string_view magic;  // its first 8 bytes
  // A u32 version follows the magic, and the versions this build reads. Unversioned formats
  // put their version in the magic (a file of another one is "not a <name>").
  bool versioned = false;
  uint32_t oldest_version = 0, newest_version = 0;
  std::string_view remedy;  // appended to the corruption message: what the user can do ("" for nothing)
};

// Appends little-endian fields to a byte string.
class ByteWriter {
 public:
  template <typename T>
  void Put(const T& value) {
    static_assert(std::is_trivially_copyable_v<T>);
    bytes_.append(reinterpret_cast<const char*>(&value), sizeof(T));
  }
  // The values as they lie in memory (no count).
  template <typename T>
  void PutArray(const std::vector<T>& values) {
    static_assert(std::is_trivially_copyable_v<T>);
    bytes_.append(reinterpret_cast<const char*>(values.data()), values.size() * sizeof(T));
  }
  void PutBytes(std::string_view bytes) { bytes_.append(bytes); }
  std::string& bytes() { return bytes_; }
  size_t size() const { return bytes_.size(); }

 protected:
  std::string bytes_;
};

// A file of a format: its magic and version first; Seal() appends the checksum.
class BinaryFileWriter : public ByteWriter {
 public:
  // version: written after the magic when the format is versioned (ignored otherwise).
  explicit BinaryFileWriter(const BinaryFormat& format, uint32_t version = 0);
  // The file's bytes, checksum last.
  std::string Seal() &&;
};

// Writes the file atomically (a temporary file, then a rename).
void WriteBinaryFile(const std::string& path, BinaryFileWriter&& writer);

// Reads little-endian fields from a byte span, never past its end.
class ByteReader {
 public:
  // source names the bytes in messages; offset: where the span starts in its file (for messages).
  ByteReader(std::string_view bytes, std::string source, size_t offset = 0)
      : bytes_(bytes), source_(std::move(source)), offset_(offset) {}

  template <typename T>
  T Get(const char* what) {
    static_assert(std::is_trivially_copyable_v<T>);
    T value;
    std::memcpy(&value, Take(sizeof(T), what).data(), sizeof(T));
    return value;
  }
  // The next n bytes.
  std::string_view Take(size_t n, const char* what);
  // count values of T (checked against the bytes left before allocating).
  template <typename T>
  std::vector<T> GetArray(uint64_t count, const char* what) {
    static_assert(std::is_trivially_copyable_v<T>);
    if (count > remaining() / sizeof(T)) Truncated(what, count, sizeof(T));
    std::vector<T> values(count);
    const std::string_view bytes = Take(count * sizeof(T), what);
    if (count > 0) std::memcpy(values.data(), bytes.data(), count * sizeof(T));  // an empty vector's data() may be null
    return values;
  }
  size_t pos() const { return pos_; }  // bytes read so far
  size_t remaining() const { return bytes_.size() - pos_; }
  const std::string& source() const { return source_; }
  // InputError "source: what" (for a field that reads but holds a wrong value).
  [[noreturn]] void Fail(const std::string& what) const;

 private:
  [[noreturn]] void Truncated(const char* what, uint64_t count, size_t size) const;
  std::string_view bytes_;
  std::string source_;
  size_t offset_ = 0;
  size_t pos_ = 0;
};

// A file of a format, checked: its version (0 for unversioned formats) and a reader of the
// fields between the version and the checksum.
struct BinaryFile {
  uint32_t version = 0;
  ByteReader fields;
};

// Checks the magic, the version and the checksum of `bytes` (a whole file), each failure an
// InputError naming source. The reader borrows `bytes`: keep them alive while reading.
BinaryFile OpenBinaryFile(std::string_view bytes, const std::string& source, const BinaryFormat& format);

}  // namespace nerfar
