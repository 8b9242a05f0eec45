// Fuzzes the mesh loader (ReadMesh: OBJ, PLY, glTF and GLB through assimp, our
// PLY header check and conversion around it). The bytes are written under
// the extension their first bytes suggest ("glTF" a GLB, "ply" a PLY, '{' a
// glTF, else an OBJ), as a user's file would be named. Any input must be
// read or rejected with InputError.
#include <cstdint>
#include <string>

#include "calib/core/error.h"
#include "render/mesh/mesh.h"
#include "tests/fuzz/fuzz_support.h"

namespace {

std::string ExtensionFor(const std::string& bytes) {
  if (bytes.rfind("glTF", 0) == 0) return ".glb";
  if (bytes.rfind("ply", 0) == 0) return ".ply";
  const size_t first = bytes.find_first_not_of(" \t\r\n");
  if (first != std::string::npos && bytes[first] == '{') return ".gltf";
  return ".obj";
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  using namespace nerfar;
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  const std::string path = fuzz::ScratchFile("mesh" + ExtensionFor(bytes));
  if (!fuzz::WriteBytes(path, bytes)) return 0;
  fuzz::Expect([&] { ReadMesh(path); });
  return 0;
}
