// Fuzzes the .nerf reader (ParseNerf): the bytes as they are, and with their
// checksum appended, crc32 and legacy (the corpus holds files without their checksum), so
// that mutated headers, brick lists and payloads reach the parser. Any input
// must be read or rejected with InputError.
#include <cstdint>
#include <string>

#include "calib/core/error.h"
#include "render/nerf/nerf_file.h"
#include "tests/fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  using namespace nerfar;
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  fuzz::Expect([&] { ParseNerf(bytes, "fuzz.nerf"); });
  fuzz::Expect([&] { ParseNerf(fuzz::WithCrc32(bytes), "fuzz.nerf"); });
  fuzz::Expect([&] { ParseNerf(fuzz::WithLegacyChecksum(bytes), "fuzz.nerf"); });
  return 0;
}
