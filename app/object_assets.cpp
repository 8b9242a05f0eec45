#include "app/object_assets.h"

#include <filesystem>

#include "calib/core/error.h"
#include "calib/core/image_io.h"
#include "calib/core/log.h"

namespace nerfar {

namespace {

// The texture's channel `channel` (or its RGB with channel −1) as floats,
// rows flipped so that row 0 is the image's bottom (v = 0 of the mesh's UVs),
// each value × its factor; sRGB-decoded for colour, linear for data maps.
ImageF MapOf(const Image8& texture, int channel, const Vec3& factor, bool srgb) {
  const int out_channels = channel < 0 ? 3 : 1;
  ImageF map(texture.width, texture.height, out_channels);
  for (int y = 0; y < texture.height; ++y)
    for (int x = 0; x < texture.width; ++x)
      for (int c = 0; c < out_channels; ++c) {
        const int source = std::min(channel < 0 ? c : channel, texture.channels - 1);
        const float value = texture.Pixel(x, texture.height - 1 - y)[source] / 255.0f;
        map.at(x, y, c) = (srgb ? SrgbToLinear(value) : value) * static_cast<float>(factor[c]);
      }
  return map;
}

// A texture reference found beside `owner` when it is not where it says
// (left as it is then, for the error to name).
std::string TextureBeside(const std::string& reference, const std::string& owner) {
  const std::string found = FindBeside(reference, owner);
  return found.empty() ? reference : found;
}

}  // namespace

std::string FindBeside(const std::string& reference, const std::string& owner) {
  std::error_code error;
  if (std::filesystem::is_regular_file(reference, error)) return reference;
  // An embedded texture's file is the part before '#'.
  const size_t hash = reference.rfind('#');
  const std::string file = hash == std::string::npos ? reference : reference.substr(0, hash);
  const std::string tail = hash == std::string::npos ? "" : reference.substr(hash);
  if (file.empty()) return "";
  if (std::filesystem::is_regular_file(file, error)) return reference;
  const std::filesystem::path p(file);
  if (p.is_absolute()) return "";
  const std::filesystem::path beside = std::filesystem::path(owner).parent_path() / p;
  return std::filesystem::is_regular_file(beside, error) ? beside.string() + tail : "";
}

ObjectSource ResolveObjectSource(const std::string& object) {
  ObjectSource source{object, std::nullopt, {object}};
  if (std::filesystem::path(object).extension() == ".json") {
    source.material = ReadMaterial(object);
    if (source.material->mesh.empty())
      ThrowInputError(object, "no \"mesh\" entry (expected the mesh file of the object)");
    source.mesh_path = source.material->mesh;
    source.inputs.push_back(source.mesh_path);
  }
  return source;
}

SsdfField BakeObjectField(const TriangleMesh& mesh, const SsdfBakeOptions& options,
                          const std::optional<Material>& material, SsdfBakeReport* report) {
  Progress progress("bake", static_cast<size_t>(options.grid) * options.grid * options.grid);
  SsdfField field = BakeSsdf(mesh, options, material, &progress, report);
  progress.Finish();
  return field;
}

MaterialMaps LoadMaterialMaps(const Material& material, const std::string& owner) {
  MaterialMaps maps;
  if (!material.albedo_texture.empty())
    maps.albedo = MapOf(ReadMeshTexture(TextureBeside(material.albedo_texture, owner)), -1, material.albedo, true);
  const bool packed = !material.roughness_texture.empty() && material.roughness_texture == material.metallic_texture;
  const Vec3 roughness(material.roughness, material.roughness, material.roughness);
  const Vec3 metallic(material.metallic, material.metallic, material.metallic);
  if (packed) {
    const Image8 texture = ReadMeshTexture(TextureBeside(material.roughness_texture, owner));
    maps.roughness = MapOf(texture, 1, roughness, false);
    maps.metallic = MapOf(texture, 2, metallic, false);
    return maps;
  }
  if (!material.roughness_texture.empty())
    maps.roughness = MapOf(ReadMeshTexture(TextureBeside(material.roughness_texture, owner)), 0, roughness, false);
  if (!material.metallic_texture.empty())
    maps.metallic = MapOf(ReadMeshTexture(TextureBeside(material.metallic_texture, owner)), 0, metallic, false);
  return maps;
}

}  // namespace nerfar
