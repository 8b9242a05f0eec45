// Fuzzes the 8-bit frame reader (PNG, JPEG and whatever else OpenCV
// decodes, as image-folder sources and masks are read): any input must be
// read or rejected with InputError; no crash, no hang, no huge alloc.
#include <cstdint>
#include <string>

#include "calib/core/error.h"
#include "calib/core/image_io.h"
#include "tests/fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  using namespace nerfar;
  static const std::string path = fuzz::ScratchFile("frame.png");
  if (!fuzz::WriteBytes(path, std::string(reinterpret_cast<const char*>(data), size))) return 0;
  fuzz::Expect([&] { ReadImage8(path); });
  return 0;
}
