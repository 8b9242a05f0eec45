// Fuzzes the readers of 8- and 16-bit frames (PNG and JPEG, as image-folder
// sources, masks and LDR datasets are read): the display-referred reader and
// the linearising one through the sRGB curve. Any input must be read or
// rejected with InputError; no crash, no hang, no huge alloc.
#include <cstdint>
#include <string>

#include "calib/core/error.h"
#include "calib/core/image_io.h"
#include "calib/linear_image.h"
#include "tests/fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  using namespace nerfar;
  static const std::string path = fuzz::ScratchFile("frame.png");
  if (!fuzz::WriteBytes(path, std::string(reinterpret_cast<const char*>(data), size))) return 0;
  fuzz::Expect([&] { ReadImage8(path); });
  fuzz::Expect([&] { ReadLinearImage(path, Linearisation{}); });
  return 0;
}
