// Fuzzes the calib/ JSON file readers (transforms.json, board.json,
// camera.json, material and placement files): the bytes are written to a
// temporary file and each reader must either accept them or raise
// InputError; nothing else may escape, crash or read out of bounds.
#include <cstdint>
#include <string>

#include "calib/board.h"
#include "calib/camera_file.h"
#include "calib/core/error.h"
#include "calib/dataset.h"
#include "calib/object.h"
#include "tests/fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  using namespace nerfar;
  static const std::string path = fuzz::ScratchFile("transforms.json");
  if (!fuzz::WriteBytes(path, std::string(reinterpret_cast<const char*>(data), size))) return 0;
  fuzz::Expect([&] { ReadDataset(path, false); });
  fuzz::Expect([&] { ReadBoard(path); });
  fuzz::Expect([&] { ReadCameraFile(path); });
  fuzz::Expect([&] { ReadMaterial(path); });
  fuzz::Expect([&] { ReadObjectPlacement(path); });
  return 0;
}
