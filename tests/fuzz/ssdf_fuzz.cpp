// Fuzzes the .ssdf reader (ParseSsdf): the bytes as they are, and with their
// checksum appended, crc32 and legacy (the corpus holds files without their checksum).
// Any input must be read or rejected with InputError.
#include <cstdint>
#include <string>

#include "calib/core/error.h"
#include "render/ssdf/ssdf.h"
#include "tests/fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  using namespace nerfar;
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  fuzz::Expect([&] { ParseSsdf(bytes, "fuzz.ssdf"); });
  fuzz::Expect([&] { ParseSsdf(fuzz::WithCrc32(bytes), "fuzz.ssdf"); });
  fuzz::Expect([&] { ParseSsdf(fuzz::WithLegacyChecksum(bytes), "fuzz.ssdf"); });
  return 0;
}
