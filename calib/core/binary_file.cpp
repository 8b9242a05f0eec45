#include "calib/core/binary_file.h"

#include <zlib.h>

#include <algorithm>

#include "calib/core/atomic_file.h"
#include "calib/core/error.h"

namespace nerfar {
namespace {

constexpr size_t kTagBytes = 4;
constexpr size_t kTableEntryBytes = kTagBytes + 8;  // tag, u64 size
constexpr size_t kCrcBytes = 4, kLegacyChecksumBytes = 8;
// More sections than any format has: a corrupt count is refused before the table is read.
constexpr uint32_t kMaxSections = 64;
constexpr uint64_t kMaxSectionBytes = uint64_t{1} << 48;

template <typename T>
T LoadLittleEndian(std::string_view bytes, size_t at) {
  T value;
  std::memcpy(&value, bytes.data() + at, sizeof(T));
  return value;
}

std::string Quoted(std::string_view tag) { return "'" + std::string(tag) + "'"; }

// The version after the magic, refused when this build does not read it.
uint32_t CheckVersion(std::string_view bytes, const std::string& source, const BinaryFormat& format) {
  const uint32_t version = LoadLittleEndian<uint32_t>(bytes, 8);
  if (version >= format.oldest_version && version <= format.newest_version) return version;
  const std::string expected =
      format.oldest_version == format.newest_version
          ? std::to_string(format.newest_version)
          : std::to_string(format.oldest_version) + " to " + std::to_string(format.newest_version);
  ThrowInputError(source, std::string(format.name) + " version " + std::to_string(version) + " (expected " + expected +
                              (version > format.newest_version ? "; written by a newer nerfar?)" : ")"));
}

// state: what the reader can tell ("corrupt"; a flat file's checksum cannot tell a cut from a flip).
[[noreturn]] void ThrowCorrupt(const std::string& source, const BinaryFormat& format, const std::string& what,
                               const char* state = "corrupt") {
  ThrowInputError(source, what + " (the file is " + state +
                              (format.remedy.empty() ? std::string() : "; " + std::string(format.remedy)) + ")");
}

[[noreturn]] void ThrowTooShort(const std::string& source, const BinaryFormat& format, size_t size, size_t least) {
  ThrowInputError(source, "file is truncated: " + std::to_string(size) + " bytes (a " + std::string(format.name) +
                              " has at least " + std::to_string(least) + ")");
}

}  // namespace

uint64_t LegacyFnv1aChecksum(std::string_view bytes) {
  uint64_t h = 1469598103934665603ull;
  for (const char c : bytes) h = (h ^ static_cast<unsigned char>(c)) * 1099511628211ull;
  return h;
}

uint32_t BinaryCrc32(std::string_view bytes) {
  // crc32_z takes a size_t length (checkpoints may pass 4 GiB).
  return uint32_t(crc32_z(crc32(0L, Z_NULL, 0), reinterpret_cast<const Bytef*>(bytes.data()), bytes.size()));
}

BinaryFileWriter::BinaryFileWriter(const BinaryFormat& format, uint32_t version) {
  NERFAR_CHECK_EQ(format.magic.size(), size_t{8});
  NERFAR_CHECK(format.versioned && version >= format.sectioned_since && version <= format.newest_version);
  header_.append(format.magic);
  header_.append(reinterpret_cast<const char*>(&version), 4);
}

ByteWriter& BinaryFileWriter::Section(std::string_view tag) {
  NERFAR_CHECK_EQ(tag.size(), kTagBytes);
  for (const auto& section : sections_) NERFAR_CHECK(section.first != tag);
  NERFAR_CHECK_LT(sections_.size(), size_t{kMaxSections});
  return sections_.emplace_back(std::string(tag), ByteWriter()).second;
}

std::string BinaryFileWriter::Seal() && {
  ByteWriter file;
  file.PutBytes(header_);
  file.Put(uint32_t(sections_.size()));
  size_t total = header_.size() + 4 + sections_.size() * kTableEntryBytes + kCrcBytes;
  for (auto& [tag, section] : sections_) {
    file.PutBytes(tag);
    file.Put(uint64_t(section.size()));
    total += section.size();
  }
  file.bytes().reserve(total);
  for (auto& section : sections_) file.PutBytes(section.second.bytes());
  file.Put(BinaryCrc32(file.bytes()));
  return std::move(file.bytes());
}

void WriteBinaryFile(const std::string& path, BinaryFileWriter&& writer) {
  WriteFileAtomic(path, std::move(writer).Seal());
}

std::string_view ByteReader::Take(size_t n, const char* what) {
  if (n > remaining()) Truncated(what, n, 1);
  const std::string_view taken = bytes_.substr(pos_, n);
  pos_ += n;
  return taken;
}

void ByteReader::ExpectEnd(const std::string& what) const {
  if (remaining() != 0) Fail(std::to_string(remaining()) + " bytes of trailing data after " + what);
}

void ByteReader::Fail(const std::string& what) const { ThrowInputError(source_, what); }

void ByteReader::Truncated(const char* what, uint64_t count, size_t size) const {
  const std::string needed = size == 1 ? std::to_string(count) + " bytes"
                                       : std::to_string(count) + " values of " + std::to_string(size) + " bytes";
  ThrowInputError(source_, std::string("file is truncated while reading ") + what + " at byte " +
                               std::to_string(offset_ + pos_) + " (expected " + needed + ", " +
                               std::to_string(remaining()) + " bytes left)");
}

const BinaryFile::Entry* BinaryFile::Find(std::string_view tag) const {
  for (const Entry& entry : sections_)
    if (entry.tag == tag) return &entry;
  return nullptr;
}

bool BinaryFile::HasSection(std::string_view tag) const { return Find(tag) != nullptr; }

ByteReader BinaryFile::Section(std::string_view tag) const {
  const Entry* entry = Find(tag);
  if (entry == nullptr)
    ThrowInputError(source_,
                    "no " + Quoted(tag) + " section (a " + name_ + " version " + std::to_string(version) + " has one)");
  return ByteReader(bytes_.substr(entry->offset, entry->size), source_, entry->offset);
}

namespace {

// A flat file: its fields end before the FNV checksum, which must match.
void OpenFlat(std::string_view bytes, const std::string& source, const BinaryFormat& format, size_t header,
              ByteReader& fields) {
  if (bytes.size() < header + kLegacyChecksumBytes)
    ThrowTooShort(source, format, bytes.size(), header + kLegacyChecksumBytes);
  const size_t end = bytes.size() - kLegacyChecksumBytes;
  if (LegacyFnv1aChecksum(bytes.substr(0, end)) != LoadLittleEndian<uint64_t>(bytes, end))
    ThrowCorrupt(source, format, "checksum mismatch", "corrupt or truncated");
  fields = ByteReader(bytes.substr(header, end - header), source, header);
}

}  // namespace

BinaryFile OpenBinaryFile(std::string_view bytes, const std::string& source, const BinaryFormat& format) {
  const std::string name(format.name), magic(format.magic);
  if (bytes.size() < 8 || bytes.substr(0, 8) != format.magic)
    ThrowInputError(source, "not a " + name + " (expected the magic '" + magic + "' at byte 0)");
  BinaryFile file(bytes, source);
  file.name_ = name;
  if (!format.versioned) {
    OpenFlat(bytes, source, format, 8, file.fields);
    return file;
  }
  if (bytes.size() < 12) ThrowTooShort(source, format, bytes.size(), 12 + kLegacyChecksumBytes);
  file.version = CheckVersion(bytes, source, format);
  if (file.version < format.sectioned_since) {
    OpenFlat(bytes, source, format, 12, file.fields);
    return file;
  }
  // Sectioned: the crc first (a whole file whose table is wrong was written wrong, not cut short),
  // then the table against the length.
  constexpr size_t kHeader = 16;
  if (bytes.size() < kHeader + kCrcBytes) ThrowTooShort(source, format, bytes.size(), kHeader + kCrcBytes);
  const size_t end = bytes.size() - kCrcBytes;
  const bool crc_matches = BinaryCrc32(bytes.substr(0, end)) == LoadLittleEndian<uint32_t>(bytes, end);
  const uint32_t count = LoadLittleEndian<uint32_t>(bytes, 12);
  if (count > kMaxSections) {
    if (crc_matches) ThrowCorrupt(source, format, std::to_string(count) + " sections (expected at most 64)");
    ThrowCorrupt(source, format, "crc32 mismatch");
  }
  // The length the table states, each size capped far above any file (64 of them cannot wrap a
  // u64 around).
  uint64_t stated = kHeader + uint64_t(count) * kTableEntryBytes + kCrcBytes;
  for (uint32_t i = 0; i < count && kHeader + (i + 1) * kTableEntryBytes <= bytes.size(); ++i) {
    const uint64_t size = LoadLittleEndian<uint64_t>(bytes, kHeader + i * kTableEntryBytes + kTagBytes);
    stated += std::min<uint64_t>(size, kMaxSectionBytes);
  }
  if (!crc_matches) {
    if (stated > bytes.size())
      ThrowInputError(source, "file is truncated: " + std::to_string(bytes.size()) +
                                  " bytes where its section table needs " + std::to_string(stated) +
                                  " (or the table is corrupt)");
    ThrowCorrupt(source, format, "crc32 mismatch");
  }
  if (stated != bytes.size())
    ThrowCorrupt(
        source, format,
        "section table states " + std::to_string(stated) + " bytes, the file has " + std::to_string(bytes.size()));
  file.sectioned_ = true;
  size_t offset = kHeader + size_t(count) * kTableEntryBytes;
  for (uint32_t i = 0; i < count; ++i) {
    const size_t entry = kHeader + i * kTableEntryBytes;
    BinaryFile::Entry section{std::string(bytes.substr(entry, kTagBytes)), offset,
                              size_t(LoadLittleEndian<uint64_t>(bytes, entry + kTagBytes))};
    if (file.Find(section.tag) != nullptr) ThrowCorrupt(source, format, "section " + Quoted(section.tag) + " twice");
    offset += section.size;
    file.sections_.push_back(std::move(section));
  }
  return file;
}

}  // namespace nerfar
