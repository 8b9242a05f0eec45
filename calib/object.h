// A virtual object's description: material JSON (objects/<name>.json of
// ../shared/scenes: mesh file, albedo, roughness, metallic, f0) and its
// placement (insert/<name>/pose.json: object_to_world, centre).
#pragma once

#include <optional>
#include <string>

#include "calib/core/math.h"

namespace nerfar {

// Simplified Disney BRDF parameters (DESIGN.md): F0 = mix(f0, albedo, metallic).
struct Material {
  Vec3 albedo{0.8, 0.8, 0.8};  // linear RGB base colour
  double roughness = 0.5;      // [0, 1]; GGX alpha = roughness^2
  double metallic = 0.0;       // [0, 1]
  double f0 = 0.02;            // dielectric normal-incidence reflectance
  std::string mesh;            // mesh file, resolved relative to the JSON's folder ("" if none)
  std::string albedo_texture, roughness_texture, metallic_texture;  // optional maps ("" if none)
};

Material ReadMaterial(const std::string& path);
void WriteMaterial(const std::string& path, const Material& material);

struct ObjectPlacement {
  Pose T_world_object;              // object_to_world; rotation may include no scale
  double scale = 1.0;               // uniform scale applied before T_world_object
  std::optional<Vec3> center_world;
};

ObjectPlacement ReadObjectPlacement(const std::string& path);
void WriteObjectPlacement(const std::string& path, const ObjectPlacement& placement);

}  // namespace nerfar
