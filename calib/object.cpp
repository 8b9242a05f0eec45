#include "calib/object.h"

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "calib/core/json.h"

namespace nerfar {
namespace fs = std::filesystem;

namespace {

// object_to_world's rotation block, divided by its scale, must be orthonormal
// within this (files store about 8 decimals).
constexpr double kRigidTolerance = 1e-4;
constexpr long long kMaxMeshElements = 1LL << 31;

std::string FormatNumber(double v) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.6g", v);
  return buffer;
}

Vec3 ToVec3(const std::array<double, 3>& a) { return {a[0], a[1], a[2]}; }
Json ToJson(const Vec3& v) { return Json::array({v.x, v.y, v.z}); }

std::string FolderOf(const std::string& path) {
  const fs::path parent = fs::path(path).parent_path();
  return parent.empty() ? "." : parent.string();
}

std::string Resolve(const std::string& dir, const std::string& file) {
  if (file.empty()) return {};
  const fs::path p(file);
  return p.is_absolute() ? p.lexically_normal().string() : (fs::path(dir) / p).lexically_normal().string();
}

// `path` as seen from `dir` (relative when both are, or both resolve, so that
// a written file keeps pointing at the same mesh after it is moved with it).
std::string RelativeTo(const std::string& dir, const std::string& path) {
  if (path.empty()) return {};
  std::error_code error;
  const fs::path abs_path = fs::absolute(path, error);
  const fs::path abs_dir = fs::absolute(dir, error);
  const fs::path rel = abs_path.lexically_normal().lexically_relative(abs_dir.lexically_normal());
  return rel.empty() ? abs_path.lexically_normal().string() : rel.string();
}

std::optional<Vec3> OptionalVec3(JsonObjectReader& reader, const char* key) {
  if (!reader.Has(key)) {
    reader.Allow({key});
    return std::nullopt;
  }
  return ToVec3(reader.Vec3(key));
}

}  // namespace

Material ReadMaterial(const std::string& path) {
  const Json doc = ReadJsonFile(path);
  Problems problems(path);
  Material material;
  const std::string dir = FolderOf(path);
  JsonObjectReader root(doc, "", problems);
  root.Allow({"units", "note", "notes", "comment"});
  if (root.valid()) {
    material.mesh = Resolve(dir, root.OptionalString("mesh").value_or(""));
    const std::vector<double> albedo = root.Numbers("albedo", 3);
    for (size_t c = 0; c < albedo.size(); ++c)
      if (albedo[c] < 0 || albedo[c] > 1)
        problems.Add("/albedo/" + std::to_string(c), "is " + FormatNumber(albedo[c]) + " (expected 0 to 1)");
    material.albedo = {albedo[0], albedo[1], albedo[2]};
    material.roughness = root.Number("roughness", 0.0, 1.0);
    material.metallic = root.Number("metallic", 0.0, 1.0);
    material.f0 = root.OptionalNumber("f0", 0.0, 1.0).value_or(0.02);
    material.brdf = root.OptionalString("brdf").value_or("");
    material.albedo_texture = Resolve(dir, root.OptionalString("albedo_texture").value_or(""));
    material.roughness_texture = Resolve(dir, root.OptionalString("roughness_texture").value_or(""));
    material.metallic_texture = Resolve(dir, root.OptionalString("metallic_texture").value_or(""));
    material.bbox_min = OptionalVec3(root, "bbox_min");
    material.bbox_max = OptionalVec3(root, "bbox_max");
    material.center_local = OptionalVec3(root, "center_local");
    if (material.bbox_min.has_value() != material.bbox_max.has_value())
      problems.Add(material.bbox_min ? "/bbox_max" : "/bbox_min", "missing (expected bbox_min and bbox_max together)");
    if (material.bbox_min && material.bbox_max) {
      const Vec3 &lo = *material.bbox_min, &hi = *material.bbox_max;
      if (!(lo.x <= hi.x && lo.y <= hi.y && lo.z <= hi.z))
        problems.Add("/bbox_min", "is above bbox_max on some axis (expected min <= max)");
    }
    if (root.Has("n_vertices"))
      material.n_vertices = root.Integer("n_vertices", 0, kMaxMeshElements);
    else
      root.Allow({"n_vertices"});
    if (root.Has("n_triangles"))
      material.n_triangles = root.Integer("n_triangles", 0, kMaxMeshElements);
    else
      root.Allow({"n_triangles"});
    root.Finish();
  }
  problems.ThrowIfAny();
  return material;
}

void WriteMaterial(const std::string& path, const Material& material) {
  const std::string dir = FolderOf(path);
  Json doc = Json::object();
  if (!material.mesh.empty()) doc["mesh"] = RelativeTo(dir, material.mesh);
  doc["albedo"] = ToJson(material.albedo);
  doc["roughness"] = material.roughness;
  doc["metallic"] = material.metallic;
  doc["f0"] = material.f0;
  if (!material.brdf.empty()) doc["brdf"] = material.brdf;
  if (!material.albedo_texture.empty()) doc["albedo_texture"] = RelativeTo(dir, material.albedo_texture);
  if (!material.roughness_texture.empty()) doc["roughness_texture"] = RelativeTo(dir, material.roughness_texture);
  if (!material.metallic_texture.empty()) doc["metallic_texture"] = RelativeTo(dir, material.metallic_texture);
  if (material.bbox_min) doc["bbox_min"] = ToJson(*material.bbox_min);
  if (material.bbox_max) doc["bbox_max"] = ToJson(*material.bbox_max);
  if (material.center_local) doc["center_local"] = ToJson(*material.center_local);
  if (material.n_vertices > 0) doc["n_vertices"] = material.n_vertices;
  if (material.n_triangles > 0) doc["n_triangles"] = material.n_triangles;
  WriteJsonFile(path, doc);
}

ObjectPlacement ReadObjectPlacement(const std::string& path) {
  const Json doc = ReadJsonFile(path);
  Problems problems(path);
  ObjectPlacement placement;
  JsonObjectReader root(doc, "", problems);
  root.Allow({"units", "note", "notes", "comment"});
  if (root.valid()) {
    placement.object = root.OptionalString("object").value_or("");
    placement.mesh = root.OptionalString("mesh").value_or("");
    const size_t before = problems.items().size();
    const std::array<double, 16> m = root.Matrix4("object_to_world");
    if (problems.items().size() == before) {
      if (std::abs(m[12]) > 1e-9 || std::abs(m[13]) > 1e-9 || std::abs(m[14]) > 1e-9 || std::abs(m[15] - 1) > 1e-9)
        problems.Add("/object_to_world/3", "is not [0, 0, 0, 1] (expected an affine transform)");
      const double det = m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) +
                         m[2] * (m[4] * m[9] - m[5] * m[8]);
      if (!(det > 0)) {
        problems.Add("/object_to_world", "rotation block has determinant " + FormatNumber(det) +
                                             " (expected a rotation times a positive scale)");
      } else {
        const double scale = std::cbrt(det);
        double worst = 0;
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) {
            const double dot = (m[i] * m[j] + m[4 + i] * m[4 + j] + m[8 + i] * m[8 + j]) / (scale * scale);
            worst = std::max(worst, std::abs(dot - (i == j ? 1.0 : 0.0)));
          }
        if (worst > kRigidTolerance) {
          problems.Add("/object_to_world", "rotation block is not a rotation times a uniform scale (deviation " +
                                               FormatNumber(worst) + "; expected no shear, no non-uniform scale)");
        } else {
          std::array<double, 16> unscaled = m;
          for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) unscaled[r * 4 + c] /= scale;
          placement.T_world_object = Pose::FromMatrix4(unscaled);
          placement.scale = scale;
        }
      }
    }
    placement.center_world = OptionalVec3(root, "center_world");
    if (const Json* quality = root.Object("placement", false)) {
      JsonObjectReader q(*quality, "/placement", problems);
      PlacementQuality pq;
      pq.score = q.Number("score");
      pq.test_views_partially_occluded = static_cast<int>(q.Integer("test_views_partially_occluded", 0, 1 << 20));
      pq.test_views_mostly_hidden = static_cast<int>(q.Integer("test_views_mostly_hidden", 0, 1 << 20));
      pq.test_views_out_of_frame = static_cast<int>(q.Integer("test_views_out_of_frame", 0, 1 << 20));
      pq.shadow_fraction_on_objects = q.Number("shadow_fraction_on_objects", 0.0, 1.0);
      q.Finish();
      placement.placement = pq;
    }
    root.Finish();
  }
  problems.ThrowIfAny();
  return placement;
}

void WriteObjectPlacement(const std::string& path, const ObjectPlacement& placement) {
  NERFAR_CHECK(placement.scale > 0 && std::isfinite(placement.scale));
  Json doc = Json::object();
  if (!placement.object.empty()) doc["object"] = placement.object;
  if (!placement.mesh.empty()) doc["mesh"] = placement.mesh;
  std::array<double, 16> m = placement.T_world_object.ToMatrix4();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) m[r * 4 + c] *= placement.scale;
  Json rows = Json::array();
  for (int r = 0; r < 4; ++r) rows.push_back(Json::array({m[r * 4], m[r * 4 + 1], m[r * 4 + 2], m[r * 4 + 3]}));
  doc["object_to_world"] = rows;
  if (placement.center_world) doc["center_world"] = ToJson(*placement.center_world);
  if (placement.placement) {
    const PlacementQuality& q = *placement.placement;
    doc["placement"] = Json{{"score", q.score},
                            {"test_views_partially_occluded", q.test_views_partially_occluded},
                            {"test_views_mostly_hidden", q.test_views_mostly_hidden},
                            {"test_views_out_of_frame", q.test_views_out_of_frame},
                            {"shadow_fraction_on_objects", q.shadow_fraction_on_objects}};
  }
  WriteJsonFile(path, doc);
}

std::string ObjectMaterialPath(const std::string& scenes_dir, const std::string& object) {
  return (fs::path(scenes_dir) / "objects" / (object + ".json")).string();
}

}  // namespace nerfar
