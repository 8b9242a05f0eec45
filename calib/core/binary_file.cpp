#include "calib/core/binary_file.h"

#include "calib/core/atomic_file.h"
#include "calib/core/error.h"

namespace nerfar {

uint64_t BinaryChecksum(std::string_view bytes) {
  uint64_t h = 1469598103934665603ull;
  for (const char c : bytes) h = (h ^ static_cast<unsigned char>(c)) * 1099511628211ull;
  return h;
}

BinaryFileWriter::BinaryFileWriter(const BinaryFormat& format, uint32_t version) {
  NERFAR_CHECK_EQ(format.magic.size(), size_t{8});
  PutBytes(format.magic);
  if (format.versioned) Put(version);
}

std::string BinaryFileWriter::Seal() && {
  Put(BinaryChecksum(bytes_));
  return std::move(bytes_);
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

void ByteReader::Fail(const std::string& what) const { ThrowInputError(source_, what); }

void ByteReader::Truncated(const char* what, uint64_t count, size_t size) const {
  const std::string needed = size == 1 ? std::to_string(count) + " bytes"
                                       : std::to_string(count) + " values of " + std::to_string(size) + " bytes";
  ThrowInputError(source_, std::string("file is truncated while reading ") + what + " at byte " +
                               std::to_string(offset_ + pos_) + " (expected " + needed + ", " +
                               std::to_string(remaining()) + " bytes left)");
}

BinaryFile OpenBinaryFile(std::string_view bytes, const std::string& source, const BinaryFormat& format) {
  const std::string name(format.name), magic(format.magic);
  if (bytes.size() < 8 || bytes.substr(0, 8) != format.magic)
    ThrowInputError(source, "not a " + name + " (expected the magic '" + magic + "' at byte 0)");
  const size_t header = 8 + (format.versioned ? 4 : 0);
  if (bytes.size() < header + 8)
    ThrowInputError(source, "file is truncated: " + std::to_string(bytes.size()) + " bytes (a " + name +
                                " has at least " + std::to_string(header + 8) + ")");
  BinaryFile file{0, ByteReader(bytes.substr(header, bytes.size() - header - 8), source, header)};
  if (format.versioned) {
    std::memcpy(&file.version, bytes.data() + 8, 4);
    if (file.version < format.oldest_version || file.version > format.newest_version) {
      const std::string expected =
          format.oldest_version == format.newest_version
              ? std::to_string(format.newest_version)
              : std::to_string(format.oldest_version) + " to " + std::to_string(format.newest_version);
      ThrowInputError(source, name + " version " + std::to_string(file.version) + " (expected " + expected +
                                  (file.version > format.newest_version ? "; written by a newer nerfar?)" : ")"));
    }
  }
  uint64_t stored = 0;
  std::memcpy(&stored, bytes.data() + bytes.size() - 8, 8);
  if (BinaryChecksum(bytes.substr(0, bytes.size() - 8)) != stored)
    ThrowInputError(source, "checksum mismatch (the file is corrupt or truncated" +
                                (format.remedy.empty() ? std::string() : "; " + std::string(format.remedy)) + ")");
  return file;
}

}  // namespace nerfar
