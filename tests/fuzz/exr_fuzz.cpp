// Fuzzes the EXR reader through a real file (OpenEXR reads paths): any input
// must be read or rejected with InputError; no crash, no hang, no huge alloc.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <string>

#include "calib/core/error.h"
#include "calib/core/exr.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  static const std::string path = "/tmp/nerfar_fuzz_exr_" + std::to_string(::getpid()) + ".exr";
  FILE* file = std::fopen(path.c_str(), "wb");
  if (file == nullptr) return 0;
  std::fwrite(data, 1, size, file);
  std::fclose(file);
  try {
    nerfar::ReadExrRgb(path);
  } catch (const nerfar::InputError&) {
  }
  std::remove(path.c_str());
  return 0;
}
