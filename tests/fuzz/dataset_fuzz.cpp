// Fuzzes the calib/ file readers (transforms.json, board.json, material and
// placement files): the bytes are written to a temporary transforms.json and
// each reader must either accept them or raise InputError; nothing else may
// escape, crash or read out of bounds.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>

#include "calib/board.h"
#include "calib/core/error.h"
#include "calib/dataset.h"
#include "calib/object.h"

namespace {

// A per-process folder for the input file, removed at exit.
struct TempFolder {
  std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("nerfar_fuzz_dataset_" + std::to_string(::getpid()));
  std::string file;
  TempFolder() {
    std::filesystem::create_directories(dir);
    file = (dir / "transforms.json").string();
  }
  ~TempFolder() {
    std::error_code error;
    std::filesystem::remove_all(dir, error);
  }
};

const std::string& TempPath() {
  static const TempFolder folder;
  return folder.file;
}

template <typename Body>
void Expect(Body body) {
  try {
    body();
  } catch (const nerfar::InputError&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  const std::string& path = TempPath();
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (file == nullptr) return 0;
  if (size > 0) std::fwrite(data, 1, size, file);
  std::fclose(file);
  Expect([&] { nerfar::ReadDataset(path, false); });
  Expect([&] { nerfar::ReadBoard(path); });
  Expect([&] { nerfar::ReadMaterial(path); });
  Expect([&] { nerfar::ReadObjectPlacement(path); });
  return 0;
}
