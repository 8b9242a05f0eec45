// Virtual objects as the commands take them. OBJECT is a mesh (OBJ, PLY,
// glTF, GLB) or an object JSON (objects/<name>.json, calib/object.h) naming
// its mesh; its material comes from the JSON, else from the mesh file.
// Material maps are loaded for the inserter (InsertObject::albedo_map, ...):
// RGB albedo in linear [0, 1], roughness and metallic in [0, 1], each
// multiplied by the material's constant (glTF's factor × texture), rows
// ordered so that row 0 is v = 0 of the mesh's UVs (ReadMeshTexture).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "calib/core/image.h"
#include "calib/object.h"
#include "render/mesh/mesh.h"
#include "render/ssdf/ssdf.h"

namespace nerfar {

struct ObjectSource {
  std::string mesh_path;
  std::optional<Material> material;  // the JSON's; empty for a bare mesh (its own material is read with it)
  std::vector<std::string> inputs;   // the files it reads (for CheckOutputsSpareInputs)
};

// A file that an object's file names (its mesh; a texture, "<mesh>#<index>"
// for one embedded in a GLB): as given where it exists, else beside `owner`
// (the file that names it, moved since with what it names); "" when neither.
std::string FindBeside(const std::string& reference, const std::string& owner);

// A mesh file as it is, or an object JSON's material and the mesh it names
// (InputError naming the JSON when it names none).
ObjectSource ResolveObjectSource(const std::string& object);

// The SSDF field of a mesh (paper §4.3) with a progress line, as `nerfar
// bake` writes it and `nerfar insert` bakes it in memory.
SsdfField BakeObjectField(const TriangleMesh& mesh, const SsdfBakeOptions& options,
                          const std::optional<Material>& material, SsdfBakeReport* report = nullptr);

struct MaterialMaps {
  std::optional<ImageF> albedo, roughness, metallic;  // empty where the material has no such texture
};

// The material's textures, read (InputError naming an unreadable one) and
// converted for the inserter. A roughness and metallic texture that are one
// file are glTF's packed image (roughness G, metallic B); a texture of its
// own is read from its first channel. Texture files are found as FindBeside
// finds them beside `owner` (the object's file).
MaterialMaps LoadMaterialMaps(const Material& material, const std::string& owner);

}  // namespace nerfar
