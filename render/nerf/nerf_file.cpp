#include "render/nerf/nerf_file.h"

#include <cmath>
#include <cstring>

#include "calib/core/atomic_file.h"
#include "calib/core/error.h"

namespace nerfar {
namespace {

constexpr char kMagic[8] = {'N', 'E', 'R', 'F', 'A', 'R', 'F', '1'};
constexpr uint32_t kColorModelLogLinear = 1;  // log L = a + b·d per channel
constexpr int kValuesPerVertex = 1 + kNerfColorCoeffs;

uint64_t Fnv1a(const char* data, size_t size) {
  uint64_t h = 1469598103934665603ull;
  for (size_t n = 0; n < size; ++n) {
    h ^= static_cast<unsigned char>(data[n]);
    h *= 1099511628211ull;
  }
  return h;
}

uint16_t ToHalfBits(float v) {
  const _Float16 h = static_cast<_Float16>(v);
  uint16_t bits;
  std::memcpy(&bits, &h, 2);
  return bits;
}
float FromHalfBits(uint16_t bits) {
  _Float16 h;
  std::memcpy(&h, &bits, 2);
  return static_cast<float>(h);
}

class Writer {
 public:
  template <typename T>
  void Put(const T& v) {
    const size_t at = bytes.size();
    bytes.resize(at + sizeof(T));
    std::memcpy(bytes.data() + at, &v, sizeof(T));
  }
  std::string bytes;
};

class Reader {
 public:
  Reader(const std::string& bytes, const std::string& source) : bytes_(bytes), source_(source) {}
  template <typename T>
  T Get(const char* what) {
    if (bytes_.size() - pos_ < sizeof(T))
      ThrowInputError(source_, std::string("file is truncated while reading ") + what + " at byte " +
                                   std::to_string(pos_) + " (expected " + std::to_string(sizeof(T)) +
                                   " more bytes, file has " + std::to_string(bytes_.size()) + ")");
    T v;
    std::memcpy(&v, bytes_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  size_t pos() const { return pos_; }
  size_t remaining() const { return bytes_.size() - pos_; }

 private:
  const std::string& bytes_;
  const std::string& source_;
  size_t pos_ = 0;
};

// Which vertices of each brick some occupied cell needs (bit per local vertex).
std::vector<uint64_t> NeededMasks(const NerfField& f) {
  std::vector<uint64_t> masks(f.BrickCount(), 0);
  for (size_t b = 0; b < f.BrickCount(); ++b) {
    const uint64_t bits = f.occupancy[b];
    if (bits == 0) continue;
    const int bx = f.brick_coords[3 * b], by = f.brick_coords[3 * b + 1], bz = f.brick_coords[3 * b + 2];
    for (int cell = 0; cell < 64; ++cell) {
      if (!((bits >> cell) & 1u)) continue;
      const int i = bx * 4 + (cell & 3), j = by * 4 + ((cell >> 2) & 3), k = bz * 4 + (cell >> 4);
      for (int n = 0; n < 8; ++n) {
        const int32_t s = f.Slot(i + (n & 1), j + ((n >> 1) & 1), k + (n >> 2));
        if (s >= 0) masks[size_t(s) / kNerfBrickSlots] |= uint64_t{1} << (s % kNerfBrickSlots);
      }
    }
  }
  return masks;
}

}  // namespace

std::string SerializeNerf(const NerfField& f) {
  const std::vector<std::string> problems = f.Validate();
  NERFAR_CHECK(problems.empty());
  const std::vector<uint64_t> masks = NeededMasks(f);
  // Bricks in table order (canonical), only those with stored vertices.
  std::vector<int32_t> order;
  uint64_t stored = 0;
  for (int32_t b : f.brick_table)
    if (b >= 0 && masks[b] != 0) {
      order.push_back(b);
      stored += uint64_t(__builtin_popcountll(masks[b]));
    }
  Writer w;
  w.bytes.reserve(128 + order.size() * 28 + stored * kValuesPerVertex * 2);
  w.bytes.append(kMagic, 8);
  w.Put(kNerfFileVersion);
  w.Put(kColorModelLogLinear);
  for (int a = 0; a < 3; ++a) w.Put(float(f.aabb.min[a]));
  for (int a = 0; a < 3; ++a) w.Put(float(f.aabb.max[a]));
  for (int a = 0; a < 3; ++a) w.Put(f.origin[a]);
  w.Put(f.voxel_m);
  w.Put(f.occupancy_sigma);
  for (int a = 0; a < 3; ++a) w.Put(int32_t(f.res[a]));
  w.Put(uint32_t(order.size()));
  w.Put(stored);
  for (int32_t b : order) {
    for (int a = 0; a < 3; ++a) w.Put(int32_t(f.brick_coords[3 * size_t(b) + a]));
    w.Put(masks[b]);
    w.Put(f.occupancy[b]);
  }
  for (int32_t b : order)
    for (int v = 0; v < kNerfBrickSlots; ++v) {
      if (!((masks[b] >> v) & 1u)) continue;
      const size_t s = size_t(b) * kNerfBrickSlots + v;
      w.Put(ToHalfBits(f.density[s]));
      for (int m = 0; m < kNerfColorCoeffs; ++m) w.Put(ToHalfBits(f.color[s * kNerfColorCoeffs + m]));
    }
  w.Put(Fnv1a(w.bytes.data(), w.bytes.size()));
  return std::move(w.bytes);
}

NerfField ParseNerf(const std::string& bytes, const std::string& source) {
  if (bytes.size() < 8 || std::memcmp(bytes.data(), kMagic, 8) != 0)
    ThrowInputError(source, "not a nerfar NeRF file (expected the magic 'NERFARF1' at byte 0)");
  if (bytes.size() < 16)
    ThrowInputError(source, "file is truncated in its header (" + std::to_string(bytes.size()) + " bytes)");
  Reader r(bytes, source);
  r.Get<uint64_t>("magic");
  const uint32_t version = r.Get<uint32_t>("version");
  if (version != kNerfFileVersion)
    ThrowInputError(source,
                    "file version " + std::to_string(version) + " (expected " + std::to_string(kNerfFileVersion) + ")");
  // The checksum covers everything: check it first, so any flipped byte is named as corruption.
  if (bytes.size() < 8 + 8) ThrowInputError(source, "file is truncated (no checksum)");
  uint64_t stored_sum;
  std::memcpy(&stored_sum, bytes.data() + bytes.size() - 8, 8);
  const uint32_t model = r.Get<uint32_t>("colour model");
  if (model != kColorModelLogLinear)
    ThrowInputError(
        source, "colour model " + std::to_string(model) + " (expected " + std::to_string(kColorModelLogLinear) + ")");
  NerfField f;
  float box[6], origin[3];
  for (float& v : box) v = r.Get<float>("aabb");
  for (float& v : origin) v = r.Get<float>("origin");
  f.voxel_m = r.Get<float>("voxel size");
  f.occupancy_sigma = r.Get<float>("occupancy threshold");
  for (int& v : f.res) v = r.Get<int32_t>("resolution");
  const uint32_t brick_count = r.Get<uint32_t>("brick count");
  const uint64_t vertex_count = r.Get<uint64_t>("stored vertex count");
  Problems problems(source);
  for (float v : box)
    if (!std::isfinite(v)) problems.Add("aabb", "not finite (expected metres)");
  for (float v : origin)
    if (!std::isfinite(v)) problems.Add("origin", "not finite (expected metres)");
  for (int a = 0; a < 3; ++a)
    if (!(box[a + 3] > box[a])) problems.Add("aabb", "max not above min on axis " + std::to_string(a));
  if (!(f.voxel_m > 0) || !std::isfinite(f.voxel_m))
    problems.Add("voxel size", std::to_string(f.voxel_m) + " (expected > 0)");
  if (!(f.occupancy_sigma >= 0) || !std::isfinite(f.occupancy_sigma))
    problems.Add("occupancy threshold", "not a finite non-negative number");
  for (int a = 0; a < 3; ++a)
    if (f.res[a] < 2 || f.res[a] > 8192) problems.Add("resolution", std::to_string(f.res[a]) + " (expected 2..8192)");
  problems.ThrowIfAny();
  for (int a = 0; a < 3; ++a) {
    f.aabb.min[a] = box[a];
    f.aabb.max[a] = box[a + 3];
    f.origin[a] = origin[a];
    f.bricks[a] = (f.res[a] + 3) / 4;
  }
  const size_t table = size_t(f.bricks[0]) * f.bricks[1] * f.bricks[2];
  if (brick_count > table)
    ThrowInputError(source, std::to_string(brick_count) + " bricks (expected at most " + std::to_string(table) + ")");
  if (vertex_count > uint64_t(brick_count) * kNerfBrickSlots)
    ThrowInputError(source, std::to_string(vertex_count) + " stored vertices for " + std::to_string(brick_count) +
                                " bricks (expected at most 64 each)");
  const uint64_t expected_size = r.pos() + uint64_t(brick_count) * 28 + vertex_count * kValuesPerVertex * 2 + 8;
  if (bytes.size() != expected_size)
    ThrowInputError(source, "file has " + std::to_string(bytes.size()) + " bytes (expected " +
                                std::to_string(expected_size) + " for " + std::to_string(brick_count) +
                                " bricks; truncated or trailing data)");
  if (Fnv1a(bytes.data(), bytes.size() - 8) != stored_sum)
    ThrowInputError(source, "checksum mismatch (the file is corrupt)");

  f.brick_table.assign(table, -1);
  std::vector<uint64_t> masks(brick_count);
  uint64_t mask_total = 0;
  for (uint32_t b = 0; b < brick_count; ++b) {
    int32_t c[3];
    for (int32_t& v : c) v = r.Get<int32_t>("brick coordinates");
    masks[b] = r.Get<uint64_t>("brick mask");
    const uint64_t occ = r.Get<uint64_t>("brick occupancy");
    if (c[0] < 0 || c[1] < 0 || c[2] < 0 || c[0] >= f.bricks[0] || c[1] >= f.bricks[1] || c[2] >= f.bricks[2])
      ThrowInputError(source, "brick " + std::to_string(b) + " lies outside the grid");
    if (f.brick_table[(size_t(c[2]) * f.bricks[1] + c[1]) * f.bricks[0] + c[0]] >= 0)
      ThrowInputError(source, "brick " + std::to_string(b) + " is listed twice");
    if (masks[b] == 0)
      ThrowInputError(source, "brick " + std::to_string(b) + " stores no vertex (expected at least one)");
    f.AllocateBrick(c[0], c[1], c[2]);
    f.occupancy[b] = occ;
    mask_total += uint64_t(__builtin_popcountll(masks[b]));
  }
  if (mask_total != vertex_count)
    ThrowInputError(source, "brick masks hold " + std::to_string(mask_total) + " vertices (header says " +
                                std::to_string(vertex_count) + ")");
  for (uint32_t b = 0; b < brick_count; ++b)
    for (int v = 0; v < kNerfBrickSlots; ++v) {
      if (!((masks[b] >> v) & 1u)) continue;
      const size_t s = size_t(b) * kNerfBrickSlots + v;
      const float d = FromHalfBits(r.Get<uint16_t>("density"));
      if (!std::isfinite(d) || d < kNerfDensityRawMin || d > kNerfDensityRawMax)
        ThrowInputError(source, "density of brick " + std::to_string(b) + " is " + std::to_string(d) +
                                    " (expected a finite value in [-30, 14])");
      f.density[s] = d;
      for (int m = 0; m < kNerfColorCoeffs; ++m) {
        const float q = FromHalfBits(r.Get<uint16_t>("colour"));
        if (!std::isfinite(q) || std::fabs(q) > 1000.0f)
          ThrowInputError(source, "colour of brick " + std::to_string(b) + " is " + std::to_string(q) +
                                      " (expected a finite log radiance)");
        f.color[s * kNerfColorCoeffs + m] = q;
      }
    }
  // Every corner of an occupied cell that lies in a listed brick must be stored
  // (else the reader would invent an empty corner where the field had a value).
  for (uint32_t b = 0; b < brick_count; ++b) {
    const uint64_t bits = f.occupancy[b];
    const int bx = f.brick_coords[3 * b], by = f.brick_coords[3 * b + 1], bz = f.brick_coords[3 * b + 2];
    for (int cell = 0; cell < 64; ++cell) {
      if (!((bits >> cell) & 1u)) continue;
      const int i = bx * 4 + (cell & 3), j = by * 4 + ((cell >> 2) & 3), k = bz * 4 + (cell >> 4);
      if (i >= f.res[0] - 1 || j >= f.res[1] - 1 || k >= f.res[2] - 1)
        ThrowInputError(source, "brick " + std::to_string(b) + " marks a cell outside the grid as occupied");
      for (int n = 0; n < 8; ++n) {
        const int32_t s = f.Slot(i + (n & 1), j + ((n >> 1) & 1), k + (n >> 2));
        // A corner in an unlisted brick is empty space, as it was in the saved field.
        if (s >= 0 && !((masks[size_t(s) / kNerfBrickSlots] >> (s % kNerfBrickSlots)) & 1u))
          ThrowInputError(source,
                          "brick " + std::to_string(b) + " has an occupied cell with a corner that is not stored");
      }
    }
  }
  return f;
}

void SaveNerf(const std::string& path, const NerfField& field) { WriteFileAtomic(path, SerializeNerf(field)); }

NerfField LoadNerf(const std::string& path) { return ParseNerf(ReadFileBytes(path, kNerfMaxFileBytes), path); }

}  // namespace nerfar
