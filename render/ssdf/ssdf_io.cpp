// The .ssdf file: little-endian binary (the project targets x86-64 and
// AArch64 hosts, both little-endian).
//
//   "NERFSSDF" u32 version  u32 grid dirs components
//   f64 centre[3] radius edge  f64 bounds_min[3] bounds_max[3]
//   str mesh_reference  u8 has_material [f64 albedo[3] roughness metallic f0,
//   str mesh albedo_texture roughness_texture metallic_texture]  str options_json
//   f32 mean[R²]  f32 basis[R²][K]  f32 coefficients[N³][K]
//   u64 FNV-1a of every byte before it
//
// str = u32 length + bytes (at most 64 KiB). Sizes are checked against the
// file length before anything is allocated.
#include <cmath>
#include <cstring>
#include <limits>

#include "calib/core/atomic_file.h"
#include "render/ssdf/ssdf.h"

namespace nerfar {

namespace {

constexpr char kMagic[8] = {'N', 'E', 'R', 'F', 'S', 'S', 'D', 'F'};
constexpr uint32_t kMaxString = 64 * 1024;
constexpr size_t kMaxFileBytes = size_t{2} << 30;

uint64_t Fnv1a(const char* data, size_t size) {
  uint64_t h = 1469598103934665603ull;
  for (size_t i = 0; i < size; ++i) {
    h ^= static_cast<unsigned char>(data[i]);
    h *= 1099511628211ull;
  }
  return h;
}

class Writer {
 public:
  template <typename T>
  void Put(const T& value) {
    const size_t at = bytes_.size();
    bytes_.resize(at + sizeof(T));
    std::memcpy(bytes_.data() + at, &value, sizeof(T));
  }
  void PutVec3(const Vec3& v) { Put(v.x), Put(v.y), Put(v.z); }
  void PutString(const std::string& s) {
    NERFAR_CHECK_LE(s.size(), size_t{kMaxString});
    Put(static_cast<uint32_t>(s.size()));
    bytes_ += s;
  }
  void PutFloats(const std::vector<float>& values) {
    const size_t at = bytes_.size();
    bytes_.resize(at + values.size() * sizeof(float));
    std::memcpy(bytes_.data() + at, values.data(), values.size() * sizeof(float));
  }
  std::string& bytes() { return bytes_; }

 private:
  std::string bytes_;
};

// Bounds-checked reading; the first shortfall throws naming the field.
class Reader {
 public:
  Reader(const std::string& bytes, const std::string& source) : bytes_(bytes), source_(source) {}
  template <typename T>
  T Get(const char* what) {
    Need(sizeof(T), what);
    T value;
    std::memcpy(&value, bytes_.data() + at_, sizeof(T));
    at_ += sizeof(T);
    return value;
  }
  Vec3 GetVec3(const char* what) {
    Vec3 v;
    v.x = Get<double>(what);
    v.y = Get<double>(what);
    v.z = Get<double>(what);
    return v;
  }
  std::string GetString(const char* what) {
    const auto size = Get<uint32_t>(what);
    if (size > kMaxString)
      ThrowInputError(source_, std::string(what) + ": length " + std::to_string(size) + " (expected at most " +
                                   std::to_string(kMaxString) + ")");
    Need(size, what);
    std::string s = bytes_.substr(at_, size);
    at_ += size;
    return s;
  }
  void GetFloats(std::vector<float>* values, size_t count, const char* what) {
    Need(count * sizeof(float), what);
    values->resize(count);
    std::memcpy(values->data(), bytes_.data() + at_, count * sizeof(float));
    at_ += count * sizeof(float);
  }
  size_t remaining() const { return bytes_.size() - at_; }

 private:
  void Need(size_t n, const char* what) const {
    if (n > bytes_.size() - at_)
      ThrowInputError(source_, std::string("file ends inside ") + what + " at byte " + std::to_string(at_) +
                                   " (expected " + std::to_string(n) + " more bytes; truncated?)");
  }
  const std::string& bytes_;
  const std::string& source_;
  size_t at_ = 0;
};

bool FiniteVec3(const Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

}  // namespace

std::string SerializeSsdf(const SsdfField& field) {
  const std::vector<std::string> problems = field.Validate();
  NERFAR_CHECK(problems.empty());
  Writer w;
  w.bytes().append(kMagic, sizeof kMagic);
  w.Put(kSsdfFileVersion);
  w.Put(static_cast<uint32_t>(field.grid()));
  w.Put(static_cast<uint32_t>(field.dirs()));
  w.Put(static_cast<uint32_t>(field.components()));
  w.PutVec3(field.center());
  w.Put(field.radius());
  w.Put(field.edge());
  w.PutVec3(field.mesh_bounds.min);
  w.PutVec3(field.mesh_bounds.max);
  w.PutString(field.mesh_reference);
  w.Put(static_cast<uint8_t>(field.material ? 1 : 0));
  if (field.material) {
    const Material& m = *field.material;
    w.PutVec3(m.albedo);
    w.Put(m.roughness);
    w.Put(m.metallic);
    w.Put(m.f0);
    w.PutString(m.mesh);
    w.PutString(m.albedo_texture);
    w.PutString(m.roughness_texture);
    w.PutString(m.metallic_texture);
  }
  w.PutString(field.options_json);
  w.PutFloats(field.mean());
  w.PutFloats(field.basis());
  w.PutFloats(field.coefficients());
  w.Put(Fnv1a(w.bytes().data(), w.bytes().size()));
  return std::move(w.bytes());
}

SsdfField ParseSsdf(const std::string& bytes, const std::string& source) {
  if (bytes.size() < sizeof kMagic || std::memcmp(bytes.data(), kMagic, sizeof kMagic) != 0)
    ThrowInputError(source, "not an SSDF file (expected the magic \"NERFSSDF\" at the start)");
  if (bytes.size() < sizeof kMagic + 8)
    ThrowInputError(source, "file ends inside the header (expected a version and sizes; truncated?)");
  const uint64_t stored = [&] {
    uint64_t v = 0;
    std::memcpy(&v, bytes.data() + bytes.size() - 8, 8);
    return v;
  }();
  Reader r(bytes, source);
  r.Get<uint64_t>("magic");
  const auto version = r.Get<uint32_t>("version");
  if (version != kSsdfFileVersion)
    ThrowInputError(source,
                    "version " + std::to_string(version) + " (expected " + std::to_string(kSsdfFileVersion) + ")");
  if (Fnv1a(bytes.data(), bytes.size() - 8) != stored)
    ThrowInputError(source,
                    "checksum mismatch (expected the FNV-1a of the contents; the file is corrupt or truncated)");

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
  field.center_ = r.GetVec3("centre");
  field.radius_ = r.Get<double>("radius");
  field.edge_ = r.Get<double>("grid edge");
  field.mesh_bounds.min = r.GetVec3("mesh bounds");
  field.mesh_bounds.max = r.GetVec3("mesh bounds");
  field.mesh_reference = r.GetString("mesh reference");
  const auto has_material = r.Get<uint8_t>("material flag");
  if (has_material > 1) ThrowInputError(source, "material flag " + std::to_string(has_material) + " (expected 0 or 1)");
  if (has_material) {
    Material m;
    m.albedo = r.GetVec3("material albedo");
    m.roughness = r.Get<double>("material roughness");
    m.metallic = r.Get<double>("material metallic");
    m.f0 = r.Get<double>("material f0");
    m.mesh = r.GetString("material mesh");
    m.albedo_texture = r.GetString("albedo texture");
    m.roughness_texture = r.GetString("roughness texture");
    m.metallic_texture = r.GetString("metallic texture");
    const auto unit = [](double v) { return v >= 0 && v <= 1; };
    if (!FiniteVec3(m.albedo) || m.albedo.x < 0 || m.albedo.y < 0 || m.albedo.z < 0)
      problems.Add("material", "albedo not finite and non-negative");
    if (!unit(m.roughness) || !unit(m.metallic) || !unit(m.f0))
      problems.Add("material", "roughness, metallic or f0 outside [0, 1]");
    field.material = m;
  }
  field.options_json = r.GetString("options");
  const size_t d = static_cast<size_t>(dirs) * dirs, p = static_cast<size_t>(grid) * grid * grid;
  const size_t floats = d + d * components + p * components;
  if (r.remaining() != floats * sizeof(float) + 8)
    ThrowInputError(source, std::to_string(r.remaining() - 8) + " bytes of arrays (expected " +
                                std::to_string(floats * sizeof(float)) + " for grid " + std::to_string(grid) +
                                ", dirs " + std::to_string(dirs) + ", components " + std::to_string(components) + ")");
  r.GetFloats(&field.mean_, d, "mean");
  r.GetFloats(&field.basis_, d * components, "basis");
  r.GetFloats(&field.coefficients_, p * components, "coefficients");
  if (!FiniteVec3(field.mesh_bounds.min) || !FiniteVec3(field.mesh_bounds.max))
    problems.Add("mesh bounds", "not finite (expected finite)");
  for (const std::string& problem : field.Validate()) problems.Add("", problem);
  problems.ThrowIfAny();
  return field;
}

void WriteSsdf(const std::string& path, const SsdfField& field) { WriteFileAtomic(path, SerializeSsdf(field)); }

SsdfField ReadSsdf(const std::string& path) { return ParseSsdf(ReadFileBytes(path, kMaxFileBytes), path); }

}  // namespace nerfar
