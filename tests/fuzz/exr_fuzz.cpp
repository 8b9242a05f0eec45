// Fuzzes the EXR reader through a real file (OpenEXR reads paths): any input
// must be read or rejected with InputError; no crash, no hang, no huge alloc.
#include <cstdint>
#include <string>

#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "tests/fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  using namespace nerfar;
  static const std::string path = fuzz::ScratchFile("image.exr");
  if (!fuzz::WriteBytes(path, std::string(reinterpret_cast<const char*>(data), size))) return 0;
  fuzz::Expect([&] { ReadExrRgb(path); });
  fuzz::Expect([&] { ReadExrChannel(path, "Y"); });
  return 0;
}
