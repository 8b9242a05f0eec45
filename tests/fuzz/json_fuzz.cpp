// Fuzzes the strict JSON parser and object reader: any input must either
// parse or raise InputError; nothing else may escape or crash.
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>

#include "calib/core/error.h"
#include "calib/core/json.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const nerfar::Json doc = nerfar::ParseJson(text, "fuzz.json");
    nerfar::Problems problems("fuzz.json");
    nerfar::JsonObjectReader reader(doc, "", problems);
    reader.Integer("w", 1, 16384);
    reader.Number("fl_x", 1e-3, 1e6);
    reader.Numbers("aabb", 0);
    reader.Matrix4("transform_matrix");
    reader.OptionalString("file_path");
    if (const nerfar::Json* frames = reader.Array("frames", false)) {
      (void)frames;
    }
    reader.Finish();
  } catch (const nerfar::InputError&) {
  }
  return 0;
}
