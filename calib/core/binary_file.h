// The container of our binary formats (.nerf, .ssdf, training checkpoints),
// little-endian:
//   magic[8]  u32 version  u32 section_count
//   section_count x (tag[4] u64 size)   the section table
//   the sections' bytes, in table order
//   u32 crc32 (zlib's) of every byte before it
// A reader checks the magic, the version, the crc and the length, in that
// order, before any field (so a flipped byte is named as corruption, a cut
// file as truncated, a newer file as a newer version), then asks for
// sections by tag: each a reader over exactly its bytes that never reads past
// them (a shortfall is an InputError naming the file, the field and the
// byte). Sections a reader does not ask for are skipped (a later version may
// add some); a missing one it requires is an InputError naming the file and
// the tag. Sizes read from a file are checked against the bytes left before
// anything is allocated for them. Files are written through
// calib/core/atomic_file.h.
//
// Files written before the container had sections (a format's versions
// below its sectioned_since, and unversioned formats) are flat: the magic, the
// version if any, the fields, and LegacyFnv1aChecksum last. They are read
// only: OpenBinaryFile gives their fields as one reader.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

namespace nerfar {

// The checksum flat (pre-section) files end with: FNV-1a 64 (prime 1099511628211), started from
// 1469598103934665603 — the published offset basis 14695981039346656037 with its last digit lost
// when the first format was written. Kept to read those files.
uint64_t LegacyFnv1aChecksum(std::string_view bytes);
// zlib's crc32 of the bytes: what a sectioned file ends with.
uint32_t BinaryCrc32(std::string_view bytes);

// What a reader expects of a file.
struct BinaryFormat {
  std::string_view name;   // what the file is, in messages: "not a <name> (...)"
  std::string_view magic;  // its first 8 bytes
  // A u32 version follows the magic, and the versions this build reads. Unversioned formats
  // put their version in the magic (a file of another one is "not a <name>").
  bool versioned = false;
  uint32_t oldest_version = 0, newest_version = 0;
  // The first version with sections and crc32; older ones (and unversioned formats) are flat.
  uint32_t sectioned_since = 0;
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

// A sectioned file of a format: Section(tag) starts a section (what is put in it until the next
// Section() or Seal() is its bytes); Seal() lays out the header, the table, the sections and the crc.
class BinaryFileWriter {
 public:
  // version: at least the format's sectioned_since.
  BinaryFileWriter(const BinaryFormat& format, uint32_t version);
  // tag: 4 characters, each tag once per file.
  ByteWriter& Section(std::string_view tag);
  // The file's bytes, crc32 last.
  std::string Seal() &&;

 private:
  std::string header_;  // magic and version
  std::vector<std::pair<std::string, ByteWriter>> sections_;
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
  size_t pos() const { return pos_; }        // bytes read so far
  size_t offset() const { return offset_; }  // where the span starts in its file
  size_t remaining() const { return bytes_.size() - pos_; }
  const std::string& source() const { return source_; }
  // InputError "source: N bytes of trailing data after what" unless every byte was read.
  void ExpectEnd(const std::string& what) const;
  // InputError "source: what" (for a field that reads but holds a wrong value).
  [[noreturn]] void Fail(const std::string& what) const;

 private:
  [[noreturn]] void Truncated(const char* what, uint64_t count, size_t size) const;
  std::string_view bytes_;
  std::string source_;
  size_t offset_ = 0;
  size_t pos_ = 0;
};

// A file of a format, checked: its version (0 for unversioned formats) and its fields.
class BinaryFile {
 public:
  uint32_t version = 0;
  bool sectioned() const { return sectioned_; }
  // A flat file's fields (between the version and the checksum); empty in a sectioned file.
  ByteReader fields;
  // A reader over exactly the bytes of the section `tag`; InputError naming the file and the tag
  // when the file has none (a flat file has no sections).
  ByteReader Section(std::string_view tag) const;
  bool HasSection(std::string_view tag) const;

 private:
  friend BinaryFile OpenBinaryFile(std::string_view, const std::string&, const BinaryFormat&);
  struct Entry {
    std::string tag;
    size_t offset = 0, size = 0;
  };
  BinaryFile(std::string_view bytes, std::string source)
      : fields({}, source), bytes_(bytes), source_(std::move(source)) {}
  const Entry* Find(std::string_view tag) const;
  bool sectioned_ = false;
  std::string_view bytes_;
  std::string source_, name_;
  std::vector<Entry> sections_;
};

// Checks the magic, the version, the checksum and (sectioned) the section table of `bytes` (a
// whole file), each failure an InputError naming source. The result borrows `bytes`: keep them
// alive while reading.
BinaryFile OpenBinaryFile(std::string_view bytes, const std::string& source, const BinaryFormat& format);

}  // namespace nerfar
