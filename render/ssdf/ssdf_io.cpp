// The .ssdf file: little-endian binary (the project targets x86-64 and
// AArch64 hosts, both little-endian), in the sectioned container of
// calib/core/binary_file.h ("NERFSSDF", version, section table, crc32).
//
// Version 2 (written), sections:
//   GRID  u32 grid dirs components  f64 centre[3] radius edge
//         f64 bounds_min[3] bounds_max[3]  str mesh_reference  str options_json
//   MATL  (only with a material) f64 albedo[3] roughness metallic f0,
//         str mesh albedo_texture roughness_texture metallic_texture
//   MEAN  f32 mean[R²]   BASI  f32 basis[R²][K]   COEF  f32 coefficients[N³][K]
// Version 1 (read only), flat: u32 version, GRID's fields up to
// mesh_reference, u8 has_material [MATL's fields], str options_json, the
// three arrays, u64 FNV checksum (binary_file.h's legacy one).
//
// str = u32 length + bytes (at most 64 KiB); sizes are checked against the
// bytes there are before anything is allocated.
#include <cmath>
#include <cstring>
#include <limits>

#include "calib/core/atomic_file.h"
#include "calib/core/binary_file.h"
#include "render/ssdf/ssdf.h"

namespace nerfar {

namespace {

constexpr BinaryFormat kFormat{"SSDF file", "NERFSSDF", true, 1, kSsdfFileVersion, 2, ""};
constexpr uint32_t kMaxString = 64 * 1024;
constexpr size_t kMaxFileBytes = size_t{2} << 30;

void PutVec3(ByteWriter& w, const Vec3& v) { w.Put(v.x), w.Put(v.y), w.Put(v.z); }
void PutString(ByteWriter& w, const std::string& s) {
  NERFAR_CHECK_LE(s.size(), size_t{kMaxString});
  w.Put(static_cast<uint32_t>(s.size()));
  w.PutBytes(s);
}

Vec3 GetVec3(ByteReader& r, const char* what) {
  Vec3 v;
  v.x = r.Get<double>(what);
  v.y = r.Get<double>(what);
  v.z = r.Get<double>(what);
  return v;
}
std::string GetString(ByteReader& r, const char* what) {
  const auto size = r.Get<uint32_t>(what);
  if (size > kMaxString)
    r.Fail(std::string(what) + ": length " + std::to_string(size) + " (expected at most " + std::to_string(kMaxString) +
           ")");
  return std::string(r.Take(size, what));
}

void PutShape(ByteWriter& w, const SsdfField& field) {
  w.Put(static_cast<uint32_t>(field.grid()));
  w.Put(static_cast<uint32_t>(field.dirs()));
  w.Put(static_cast<uint32_t>(field.components()));
  PutVec3(w, field.center());
  w.Put(field.radius());
  w.Put(field.edge());
  PutVec3(w, field.mesh_bounds.min);
  PutVec3(w, field.mesh_bounds.max);
}

void PutMaterial(ByteWriter& w, const Material& m) {
  PutVec3(w, m.albedo);
  w.Put(m.roughness);
  w.Put(m.metallic);
  w.Put(m.f0);
  PutString(w, m.mesh);
  PutString(w, m.albedo_texture);
  PutString(w, m.roughness_texture);
  PutString(w, m.metallic_texture);
}

// What GRID holds before its strings: the sizes and the geometry.
struct Shape {
  uint32_t grid = 0, dirs = 0, components = 0;
  Vec3 center;
  double radius = 0, edge = 0;
  Bounds mesh_bounds;
};

// The sizes (refused out of range before anything is allocated for them) and the geometry.
Shape ReadShape(ByteReader& r) {
  Shape shape;
  shape.grid = r.Get<uint32_t>("grid size");
  shape.dirs = r.Get<uint32_t>("direction resolution");
  shape.components = r.Get<uint32_t>("component count");
  Problems problems(r.source());
  if (shape.grid < 2 || shape.grid > 128) problems.Add("grid", std::to_string(shape.grid) + " (expected 2 to 128)");
  if (shape.dirs < 4 || shape.dirs > 512) problems.Add("dirs", std::to_string(shape.dirs) + " (expected 4 to 512)");
  if (shape.components < 1 || shape.components > 1024)
    problems.Add("components", std::to_string(shape.components) + " (expected 1 to 1024)");
  problems.ThrowIfAny();
  shape.center = GetVec3(r, "centre");
  shape.radius = r.Get<double>("radius");
  shape.edge = r.Get<double>("grid edge");
  shape.mesh_bounds.min = GetVec3(r, "mesh bounds");
  shape.mesh_bounds.max = GetVec3(r, "mesh bounds");
  return shape;
}

// The material, its values' problems added to `problems`.
Material ReadMaterial(ByteReader& r, Problems& problems) {
  Material m;
  m.albedo = GetVec3(r, "material albedo");
  m.roughness = r.Get<double>("material roughness");
  m.metallic = r.Get<double>("material metallic");
  m.f0 = r.Get<double>("material f0");
  m.mesh = GetString(r, "material mesh");
  m.albedo_texture = GetString(r, "albedo texture");
  m.roughness_texture = GetString(r, "roughness texture");
  m.metallic_texture = GetString(r, "metallic texture");
  const auto unit = [](double v) { return v >= 0 && v <= 1; };
  if (!Finite(m.albedo) || m.albedo.x < 0 || m.albedo.y < 0 || m.albedo.z < 0)
    problems.Add("material", "albedo not finite and non-negative");
  if (!unit(m.roughness) || !unit(m.metallic) || !unit(m.f0))
    problems.Add("material", "roughness, metallic or f0 outside [0, 1]");
  return m;
}

struct Arrays {
  std::vector<float> mean, basis, coefficients;
};

// The mean, basis and coefficients of the shape's sizes, from one reader each (the same one in a
// flat file, which must then hold exactly the three).
Arrays ReadArrays(const Shape& shape, ByteReader& mean, ByteReader& basis, ByteReader& coefficients) {
  const size_t d = size_t(shape.dirs) * shape.dirs, p = size_t(shape.grid) * shape.grid * shape.grid;
  const size_t k = shape.components, floats = d + d * k + p * k;
  if (&mean == &coefficients && mean.remaining() != floats * sizeof(float))
    mean.Fail(std::to_string(mean.remaining()) + " bytes of arrays (expected " +
              std::to_string(floats * sizeof(float)) + " for grid " + std::to_string(shape.grid) + ", dirs " +
              std::to_string(shape.dirs) + ", components " + std::to_string(k) + ")");
  Arrays arrays;
  arrays.mean = mean.GetArray<float>(d, "mean");
  arrays.basis = basis.GetArray<float>(d * k, "basis");
  arrays.coefficients = coefficients.GetArray<float>(p * k, "coefficients");
  mean.ExpectEnd("the mean");
  basis.ExpectEnd("the basis");
  coefficients.ExpectEnd("the coefficients");
  return arrays;
}

}  // namespace

std::string SerializeSsdf(const SsdfField& field) {
  const std::vector<std::string> problems = field.Validate();
  NERFAR_CHECK(problems.empty());
  BinaryFileWriter w(kFormat, kSsdfFileVersion);
  ByteWriter& grid = w.Section("GRID");
  PutShape(grid, field);
  PutString(grid, field.mesh_reference);
  PutString(grid, field.options_json);
  if (field.material) PutMaterial(w.Section("MATL"), *field.material);
  w.Section("MEAN").PutArray(field.mean());
  w.Section("BASI").PutArray(field.basis());
  w.Section("COEF").PutArray(field.coefficients());
  return std::move(w).Seal();
}

SsdfField ParseSsdf(const std::string& bytes, const std::string& source) {
  const BinaryFile file = OpenBinaryFile(bytes, source, kFormat);
  SsdfField field;
  Problems problems(source);
  Shape shape;
  Arrays arrays;
  if (file.sectioned()) {
    ByteReader grid = file.Section("GRID");
    shape = ReadShape(grid);
    field.mesh_reference = GetString(grid, "mesh reference");
    field.options_json = GetString(grid, "options");
    grid.ExpectEnd("the grid section");
    if (file.HasSection("MATL")) {
      ByteReader material = file.Section("MATL");
      field.material = ReadMaterial(material, problems);
      material.ExpectEnd("the material");
    }
    ByteReader mean = file.Section("MEAN"), basis = file.Section("BASI"), coefficients = file.Section("COEF");
    arrays = ReadArrays(shape, mean, basis, coefficients);
  } else {
    ByteReader r = file.fields;
    shape = ReadShape(r);
    field.mesh_reference = GetString(r, "mesh reference");
    const auto has_material = r.Get<uint8_t>("material flag");
    if (has_material > 1)
      ThrowInputError(source, "material flag " + std::to_string(has_material) + " (expected 0 or 1)");
    if (has_material) field.material = ReadMaterial(r, problems);
    field.options_json = GetString(r, "options");
    arrays = ReadArrays(shape, r, r, r);
  }
  field.grid_ = int(shape.grid), field.dirs_ = int(shape.dirs), field.components_ = int(shape.components);
  field.center_ = shape.center, field.radius_ = shape.radius, field.edge_ = shape.edge;
  field.mesh_bounds = shape.mesh_bounds;
  field.mean_ = std::move(arrays.mean), field.basis_ = std::move(arrays.basis);
  field.coefficients_ = std::move(arrays.coefficients);
  if (!Finite(field.mesh_bounds.min) || !Finite(field.mesh_bounds.max))
    problems.Add("mesh bounds", "not finite (expected finite)");
  for (const std::string& problem : field.Validate()) problems.Add("", problem);
  problems.ThrowIfAny();
  return field;
}

void WriteSsdf(const std::string& path, const SsdfField& field) { WriteFileAtomic(path, SerializeSsdf(field)); }

SsdfField ReadSsdf(const std::string& path) { return ParseSsdf(ReadFileBytes(path, kMaxFileBytes), path); }

}  // namespace nerfar
