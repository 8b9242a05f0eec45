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
  std::string brdf;                                                 // free-text description of the model ("" if none)
  std::optional<Vec3> bbox_min, bbox_max;                           // mesh bounds in the local frame, metres
  std::optional<Vec3> center_local;                                 // object centre in the local frame, metres
  long long n_vertices = 0, n_triangles = 0;                        // mesh counts as recorded (0: not recorded)
};

// Reads and validates a material file; every problem listed (unknown keys,
// values outside [0, 1], bbox_min above bbox_max, ...). Paths (mesh,
// textures) are resolved relative to the file's folder.
Material ReadMaterial(const std::string& path);
void WriteMaterial(const std::string& path, const Material& material);

// How well an automatic placement worked (insert/<name>/pose.json "placement").
struct PlacementQuality {
  double score = 0;
  int test_views_partially_occluded = 0;
  int test_views_mostly_hidden = 0;
  int test_views_out_of_frame = 0;
  double shadow_fraction_on_objects = 0;  // [0, 1]
};

struct ObjectPlacement {
  Pose T_world_object;  // object_to_world; rotation may include no scale
  double scale = 1.0;   // uniform scale applied before T_world_object
  std::optional<Vec3> center_world;
  std::string object;  // object name ("" if not given), e.g. "sphere_glossy"
  std::string mesh;    // the "mesh" entry as written (may carry a note); "" if none
  std::optional<PlacementQuality> placement;
};

// Reads a placement file. object_to_world must be a rotation times a uniform
// positive scale plus a translation (the scale goes to `scale`); shear,
// non-uniform scale and reflections are rejected.
ObjectPlacement ReadObjectPlacement(const std::string& path);
void WriteObjectPlacement(const std::string& path, const ObjectPlacement& placement);

// The material file of a named object in a scenes folder laid out as
// ../shared/scenes: SCENES/objects/<object>.json.
std::string ObjectMaterialPath(const std::string& scenes_dir, const std::string& object);

}  // namespace nerfar
