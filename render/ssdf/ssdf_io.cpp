// The .ssdf file: little-endian binary (the project targets x86-64 and
// AArch64 hosts, both little-endian).
//
//   "NERFSSDF" u32 version  u32 grid dirs components
//   f64 centre[3] radius edge  f64 bounds_min[3] bounds_max[3]
//   str mesh_reference  u8 has_material [f64 albedo[3] roughness metallic f0,
//   str mesh albedo_texture roughness_texture metallic_texture]  str options_json
//   f32 mean[R²]  f32 basis[R²][K]  f32 coefficients[N³][K]
//   u64 checksum of every byte before it (BinaryChecksum)
//
// str = u32 length + bytes (at most 64 KiB). The magic, version and checksum
// are the container of calib/core/binary_file.h; sizes are checked against
// the file length before anything is allocated.
#include <cmath>
#include <cstring>
#include <limits>

#include "calib/core/atomic_file.h"
#include "calib/core/binary_file.h"
#include "render/ssdf/ssdf.h"

namespace nerfar {

namespace {

constexpr BinaryFormat kFormat{"SSDF file", "NERFSSDF", true, kSsdfFileVersion, kSsdfFileVersion, ""};
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

bool FiniteVec3(const Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

}  // namespace

std::string SerializeSsdf(const SsdfField& field) {
  const std::vector<std::string> problems = field.Validate();
  NERFAR_CHECK(problems.empty());
  BinaryFileWriter w(kFormat, kSsdfFileVersion);
  w.Put(static_cast<uint32_t>(field.grid()));
  w.Put(static_cast<uint32_t>(field.dirs()));
  w.Put(static_cast<uint32_t>(field.components()));
  PutVec3(w, field.center());
  w.Put(field.radius());
  w.Put(field.edge());
  PutVec3(w, field.mesh_bounds.min);
  PutVec3(w, field.mesh_bounds.max);
  PutString(w, field.mesh_reference);
  w.Put(static_cast<uint8_t>(field.material ? 1 : 0));
  if (field.material) {
    const Material& m = *field.material;
    PutVec3(w, m.albedo);
    w.Put(m.roughness);
    w.Put(m.metallic);
    w.Put(m.f0);
    PutString(w, m.mesh);
    PutString(w, m.albedo_texture);
    PutString(w, m.roughness_texture);
    PutString(w, m.metallic_texture);
  }
  PutString(w, field.options_json);
  w.PutArray(field.mean());
  w.PutArray(field.basis());
  w.PutArray(field.coefficients());
  return std::move(w).Seal();
}

SsdfField ParseSsdf(const std::string& bytes, const std::string& source) {
  BinaryFile file = OpenBinaryFile(bytes, source, kFormat);
  ByteReader& r = file.fields;
  SsdfField field;
  Problems problems(source);
  const auto grid = r.Get<uint32_t>("grid size"), dirs = r.Get<uint32_t>("direction resolution"),
             components = r.Get<uint32_t>("component count");
  if (grid < 2 || grid > 128) problems.Add("grid", std::to_string(grid) + " (expected 2 to 128)");
  if (dirs < 4 || dirs > 512) problems.Add("dirs", std::to_string(dirs) + " (expected 4 to 512)");
  if (components < 1 || components > 1024)
    problems.Add("components", std::to_string(components) + " (expected 1 to 1024)");
  problems.ThrowIfAny();
  field.grid_ = static_cast<int>(grid);
  field.dirs_ = static_cast<int>(dirs);
  field.components_ = static_cast<int>(components);
  field.center_ = GetVec3(r, "centre");
  field.radius_ = r.Get<double>("radius");
  field.edge_ = r.Get<double>("grid edge");
  field.mesh_bounds.min = GetVec3(r, "mesh bounds");
  field.mesh_bounds.max = GetVec3(r, "mesh bounds");
  field.mesh_reference = GetString(r, "mesh reference");
  const auto has_material = r.Get<uint8_t>("material flag");
  if (has_material > 1) ThrowInputError(source, "material flag " + std::to_string(has_material) + " (expected 0 or 1)");
  if (has_material) {
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
    if (!FiniteVec3(m.albedo) || m.albedo.x < 0 || m.albedo.y < 0 || m.albedo.z < 0)
      problems.Add("material", "albedo not finite and non-negative");
    if (!unit(m.roughness) || !unit(m.metallic) || !unit(m.f0))
      problems.Add("material", "roughness, metallic or f0 outside [0, 1]");
    field.material = m;
  }
  field.options_json = GetString(r, "options");
  const size_t d = static_cast<size_t>(dirs) * dirs, p = static_cast<size_t>(grid) * grid * grid;
  const size_t floats = d + d * components + p * components;
  if (r.remaining() != floats * sizeof(float))
    ThrowInputError(source, std::to_string(r.remaining()) + " bytes of arrays (expected " +
                                std::to_string(floats * sizeof(float)) + " for grid " + std::to_string(grid) +
                                ", dirs " + std::to_string(dirs) + ", components " + std::to_string(components) + ")");
  field.mean_ = r.GetArray<float>(d, "mean");
  field.basis_ = r.GetArray<float>(d * components, "basis");
  field.coefficients_ = r.GetArray<float>(p * components, "coefficients");
  if (!FiniteVec3(field.mesh_bounds.min) || !FiniteVec3(field.mesh_bounds.max))
    problems.Add("mesh bounds", "not finite (expected finite)");
  for (const std::string& problem : field.Validate()) problems.Add("", problem);
  problems.ThrowIfAny();
  return field;
}

void WriteSsdf(const std::string& path, const SsdfField& field) { WriteFileAtomic(path, SerializeSsdf(field)); }

SsdfField ReadSsdf(const std::string& path) { return ParseSsdf(ReadFileBytes(path, kMaxFileBytes), path); }

}  // namespace nerfar
