#include "render/nerf/nerf_file.h"

#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "calib/core/atomic_file.h"
#include "calib/core/binary_file.h"
#include "calib/core/error.h"

namespace nerfar {
namespace {

// Versions 1 and 2 are flat (read only); 3 has the sections HEAD (the header and the payload's
// coding), BRIK (the stored payload) and, when known, CAMS (the capture's camera centres).
constexpr BinaryFormat kFormat{"nerfar NeRF file", "NERFARF1", true, 1, kNerfFileVersion, 3, ""};
constexpr uint32_t kColorModelLogLinear = 1;            // log L = a + b·d per channel
constexpr int kValuesPerVertex = 1 + kNerfColorCoeffs;  // channels: density, colour 0..11
constexpr uint8_t kCompressionNone = 0, kCompressionZlib = 1;
// Largest payload the reader inflates (a corrupt size field fails fast).
constexpr uint64_t kMaxPayloadBytes = uint64_t{1} << 33;
// Deflate packs at most about 1032:1 (zlib's technical notes): a stated payload
// larger than that over the stored bytes is a corrupt size, refused before it
// is allocated.
constexpr uint64_t kDeflateMaxRatio = 1032;
// Bytes of a version-2 brick besides its codes: coordinates, stored-vertex mask
// and occupancy (28), then per channel a quantiser (i8 exponent, i32 base).
constexpr uint64_t kBrickBytes = 28 + kValuesPerVertex * 5;

// IEEE 754 binary16 to float, exactly (in plain arithmetic: not every
// compiler has a half type on every target).
float FromHalfBits(uint16_t bits) {
  const int exponent = (bits >> 10) & 0x1f;
  const int mantissa = bits & 0x3ff;
  float magnitude;
  if (exponent == 0)
    magnitude = std::ldexp(static_cast<float>(mantissa), -24);  // zero and subnormals: m · 2^-24
  else if (exponent == 31)
    magnitude = mantissa != 0 ? std::numeric_limits<float>::quiet_NaN() : std::numeric_limits<float>::infinity();
  else
    magnitude = std::ldexp(static_cast<float>(mantissa | 0x400), exponent - 25);  // (1 + m/1024) · 2^(e-15)
  return (bits & 0x8000) != 0 ? -magnitude : magnitude;
}

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

// Per brick and channel: values are (base + q)·2^exponent, q in [0, 2^bits - 1].
struct Quantiser {
  int exponent = 0;
  int32_t base = 0;
};

// The smallest exponent e whose 2^bits - 1 levels span [lo, hi] and keeps
// |value| / 2^e <= 2^23 (so (base + q)·2^e is exact in float).
Quantiser ChooseQuantiser(float lo, float hi, int bits) {
  const double levels = double((int64_t{1} << bits) - 1);
  const double magnitude = std::max(std::fabs(double(lo)), std::fabs(double(hi)));
  int e = magnitude > 0 ? std::ilogb(magnitude) - 24 : -60;
  e = std::max(e, -60);
  while (std::ldexp(magnitude, -e) > 8388608.0 ||
         std::ceil(std::ldexp(double(hi), -e)) - std::floor(std::ldexp(double(lo), -e)) > levels)
    ++e;
  return {e, int32_t(std::floor(std::ldexp(double(lo), -e)))};
}

uint32_t Quantise(float v, const Quantiser& q, int bits) {
  const int64_t code = std::llround(std::ldexp(double(v), -q.exponent)) - q.base;
  return uint32_t(std::clamp<int64_t>(code, 0, (int64_t{1} << bits) - 1));
}

// (base + code)·2^exponent; scale = 2^exponent (a normal float for exponents -60..40, so the product is
// the correctly rounded value ldexp gives, at a multiply's cost).
float Dequantise(uint32_t code, const Quantiser& q, float scale) { return float(int64_t(q.base) + code) * scale; }

class BitPacker {
 public:
  explicit BitPacker(std::string& out) : out_(out) {}
  void Put(uint32_t v, int bits) {
    acc_ |= uint64_t(v) << fill_;
    fill_ += bits;
    while (fill_ >= 8) {
      out_.push_back(char(acc_ & 0xffu));
      acc_ >>= 8;
      fill_ -= 8;
    }
  }
  void Flush() {
    if (fill_ > 0) out_.push_back(char(acc_ & 0xffu));
    acc_ = 0, fill_ = 0;
  }

 private:
  std::string& out_;
  uint64_t acc_ = 0;
  int fill_ = 0;
};

int ChannelBits(const NerfFileOptions& o, int channel) {
  if (channel == 0) return o.density_bits;
  return (channel - 1) % 4 == 0 ? o.color_base_bits : o.color_slope_bits;
}

float& ChannelValue(NerfField& f, size_t slot, int channel) {
  return channel == 0 ? f.density[slot] : f.color[slot * kNerfColorCoeffs + size_t(channel - 1)];
}
float ChannelValue(const NerfField& f, size_t slot, int channel) {
  return channel == 0 ? f.density[slot] : f.color[slot * kNerfColorCoeffs + size_t(channel - 1)];
}

// The common header after the version (up to the stored vertex count), as both versions have it.
struct Header {
  uint32_t brick_count = 0;
  uint64_t vertex_count = 0;
};

// How the payload is stored (versions 2 and 3): bits per channel, compression, its inflated size.
struct PayloadCoding {
  uint8_t bits[kValuesPerVertex] = {};
  uint8_t compression = kCompressionNone;
  uint64_t payload_size = 0;
};

void PutCoding(ByteWriter& w, const NerfFileOptions& options, uint64_t payload_size) {
  for (int ch = 0; ch < kValuesPerVertex; ++ch) w.Put(uint8_t(ChannelBits(options, ch)));
  w.Put(options.compress ? kCompressionZlib : kCompressionNone);
  w.Put(uint16_t{0});
  w.Put(payload_size);
}

PayloadCoding ReadCoding(ByteReader& r) {
  PayloadCoding c;
  for (uint8_t& b : c.bits) b = r.Get<uint8_t>("bits per value");
  c.compression = r.Get<uint8_t>("compression");
  r.Get<uint16_t>("padding");
  c.payload_size = r.Get<uint64_t>("payload size");
  return c;
}

void PutHeader(ByteWriter& w, const NerfField& f, uint32_t brick_count, uint64_t stored) {
  w.Put(kColorModelLogLinear);
  for (int a = 0; a < 3; ++a) w.Put(float(f.aabb.min[a]));
  for (int a = 0; a < 3; ++a) w.Put(float(f.aabb.max[a]));
  for (int a = 0; a < 3; ++a) w.Put(f.origin[a]);
  w.Put(f.voxel_m);
  w.Put(f.occupancy_sigma);
  for (int a = 0; a < 3; ++a) w.Put(int32_t(f.res[a]));
  w.Put(brick_count);
  w.Put(stored);
}

Header ReadHeader(ByteReader& r, const std::string& source, NerfField& f) {
  Header h;
  const uint32_t model = r.Get<uint32_t>("colour model");
  if (model != kColorModelLogLinear)
    ThrowInputError(
        source, "colour model " + std::to_string(model) + " (expected " + std::to_string(kColorModelLogLinear) + ")");
  float box[6], origin[3];
  for (float& v : box) v = r.Get<float>("aabb");
  for (float& v : origin) v = r.Get<float>("origin");
  f.voxel_m = r.Get<float>("voxel size");
  f.occupancy_sigma = r.Get<float>("occupancy threshold");
  for (int& v : f.res) v = r.Get<int32_t>("resolution");
  h.brick_count = r.Get<uint32_t>("brick count");
  h.vertex_count = r.Get<uint64_t>("stored vertex count");
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
  if (table > kNerfMaxBrickTable)
    ThrowInputError(source, "resolution " + std::to_string(f.res[0]) + "x" + std::to_string(f.res[1]) + "x" +
                                std::to_string(f.res[2]) + " needs a brick table of " + std::to_string(table) +
                                " entries (expected at most " + std::to_string(kNerfMaxBrickTable) + ")");
  if (h.brick_count > table)
    ThrowInputError(source, std::to_string(h.brick_count) + " bricks (expected at most " + std::to_string(table) + ")");
  if (h.vertex_count > uint64_t(h.brick_count) * kNerfBrickSlots)
    ThrowInputError(source, std::to_string(h.vertex_count) + " stored vertices for " + std::to_string(h.brick_count) +
                                " bricks (expected at most 64 each)");
  return h;
}

// Reads the brick list (coordinates, stored-vertex mask, occupancy) and allocates the bricks.
std::vector<uint64_t> ReadBricks(ByteReader& r, const std::string& source, const Header& h, NerfField& f) {
  f.brick_table.assign(size_t(f.bricks[0]) * f.bricks[1] * f.bricks[2], -1);
  std::vector<uint64_t> masks(h.brick_count);
  uint64_t mask_total = 0;
  for (uint32_t b = 0; b < h.brick_count; ++b) {
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
  if (mask_total != h.vertex_count)
    ThrowInputError(source, "brick masks hold " + std::to_string(mask_total) + " vertices (header says " +
                                std::to_string(h.vertex_count) + ")");
  return masks;
}

void CheckValue(const std::string& source, uint32_t brick, int channel, float v) {
  if (channel == 0) {
    if (!std::isfinite(v) || v < kNerfDensityRawMin || v > kNerfDensityRawMax)
      ThrowInputError(source, "density of brick " + std::to_string(brick) + " is " + std::to_string(v) +
                                  " (expected a finite value in [-30, 14])");
  } else if (!std::isfinite(v) || std::fabs(v) > 1000.0f) {
    ThrowInputError(source, "colour of brick " + std::to_string(brick) + " is " + std::to_string(v) +
                                " (expected a finite log radiance)");
  }
}

void ReadValuesV1(ByteReader& r, const std::string& source, const std::vector<uint64_t>& masks, NerfField& f) {
  for (uint32_t b = 0; b < masks.size(); ++b)
    for (int v = 0; v < kNerfBrickSlots; ++v) {
      if (!((masks[b] >> v) & 1u)) continue;
      const size_t s = size_t(b) * kNerfBrickSlots + v;
      for (int ch = 0; ch < kValuesPerVertex; ++ch) {
        const float x = FromHalfBits(r.Get<uint16_t>(ch == 0 ? "density" : "colour"));
        CheckValue(source, b, ch, x);
        ChannelValue(f, s, ch) = x;
      }
    }
}

void ReadValuesV2(ByteReader& r, const std::string& source, const std::vector<uint64_t>& masks, const uint8_t bits[],
                  NerfField& f) {
  for (uint32_t b = 0; b < masks.size(); ++b) {
    const int count = __builtin_popcountll(masks[b]);
    for (int ch = 0; ch < kValuesPerVertex; ++ch) {
      Quantiser q;
      q.exponent = r.Get<int8_t>("quantiser exponent");
      q.base = r.Get<int32_t>("quantiser base");
      const int nbits = bits[ch];
      if (q.exponent < -60 || q.exponent > 40 || std::abs(int64_t(q.base)) > (int64_t{1} << 24))
        ThrowInputError(source, "brick " + std::to_string(b) + " has a quantiser out of range (exponent " +
                                    std::to_string(q.exponent) + ", base " + std::to_string(q.base) + ")");
      const uint8_t* p =
          reinterpret_cast<const uint8_t*>(r.Take((size_t(count) * nbits + 7) / 8, "quantised values").data());
      uint64_t acc = 0;
      int fill = 0;
      int v = -1;
      const uint32_t mask_bits = uint32_t((uint64_t{1} << nbits) - 1);
      const float scale = std::ldexp(1.0f, q.exponent);
      for (int n = 0; n < count; ++n) {
        while (fill < nbits) {
          acc |= uint64_t(*p++) << fill;
          fill += 8;
        }
        const uint32_t code = uint32_t(acc) & mask_bits;
        acc >>= nbits;
        fill -= nbits;
        do ++v;
        while (!((masks[b] >> v) & 1u));
        const float x = Dequantise(code, q, scale);
        CheckValue(source, b, ch, x);
        ChannelValue(f, size_t(b) * kNerfBrickSlots + size_t(v), ch) = x;
      }
    }
  }
}

// The bricks and values of a payload of versions 2 and 3 (`stored` as the file holds it).
std::vector<uint64_t> ReadPayload(std::string_view stored, const PayloadCoding& c, const Header& h,
                                  const std::string& source, NerfField& f) {
  for (int ch = 0; ch < kValuesPerVertex; ++ch)
    if (c.bits[ch] < 4 || c.bits[ch] > 16)
      ThrowInputError(source, "channel " + std::to_string(ch) + " has " + std::to_string(c.bits[ch]) +
                                  " bits per value (expected 4..16)");
  if (c.compression != kCompressionNone && c.compression != kCompressionZlib)
    ThrowInputError(source, "compression " + std::to_string(c.compression) + " (expected 0 none or 1 zlib)");
  if (c.payload_size > kMaxPayloadBytes || (c.compression == kCompressionNone && c.payload_size != stored.size()))
    ThrowInputError(source, "payload size " + std::to_string(c.payload_size) + " does not match the file");
  // The bricks' codes: the header's vertices at their bits, padded to a byte per brick and channel.
  uint64_t bits_per_vertex = 0;
  for (const uint8_t b : c.bits) bits_per_vertex += b;
  const uint64_t least = uint64_t(h.brick_count) * kBrickBytes + h.vertex_count * bits_per_vertex / 8;
  const uint64_t most = least + uint64_t(h.brick_count) * kValuesPerVertex + 1;
  if (c.payload_size < least || c.payload_size > most ||
      (c.compression == kCompressionZlib && c.payload_size > kDeflateMaxRatio * stored.size() + 64))
    ThrowInputError(source, "payload size " + std::to_string(c.payload_size) + " does not fit " +
                                std::to_string(h.brick_count) + " bricks of " + std::to_string(h.vertex_count) +
                                " stored vertices in " + std::to_string(stored.size()) +
                                " stored bytes (the file is corrupt)");
  std::string inflated;
  if (c.compression == kCompressionZlib) {
    inflated.resize(c.payload_size);
    uLongf size = uLongf(c.payload_size);
    const int status = uncompress(reinterpret_cast<Bytef*>(inflated.data()), &size,
                                  reinterpret_cast<const Bytef*>(stored.data()), uLong(stored.size()));
    if (status != Z_OK || size != c.payload_size)
      ThrowInputError(source, "compressed payload does not inflate to its stated " + std::to_string(c.payload_size) +
                                  " bytes (the file is corrupt)");
  } else {
    inflated = std::string(stored);
  }
  ByteReader p(inflated, source + " (payload)");
  std::vector<uint64_t> masks = ReadBricks(p, source, h, f);
  ReadValuesV2(p, source, masks, c.bits, f);
  if (p.remaining() != 0)
    ThrowInputError(source, "payload has " + std::to_string(p.remaining()) + " bytes of trailing data");
  return masks;
}

// A flat version-2 body: the coding, the stored payload's size, the payload.
std::vector<uint64_t> ReadVersion2Body(ByteReader& r, const Header& h, size_t file_size, NerfField& f) {
  const PayloadCoding coding = ReadCoding(r);
  const uint64_t stored_size = r.Get<uint64_t>("stored payload size");
  if (r.remaining() != stored_size)
    r.Fail("file has " + std::to_string(file_size) + " bytes (expected " +
           std::to_string(file_size - r.remaining() + stored_size) + "; truncated or trailing data)");
  return ReadPayload(r.Take(stored_size, "payload"), coding, h, r.source(), f);
}

// A version-1 body: the brick list, then every stored vertex's values as half floats.
std::vector<uint64_t> ReadVersion1Body(ByteReader& r, const Header& h, size_t file_size, NerfField& f) {
  const uint64_t body = uint64_t(h.brick_count) * 28 + h.vertex_count * kValuesPerVertex * 2;
  if (r.remaining() != body)
    r.Fail("file has " + std::to_string(file_size) + " bytes (expected " +
           std::to_string(file_size - r.remaining() + body) + " for " + std::to_string(h.brick_count) +
           " bricks; truncated or trailing data)");
  std::vector<uint64_t> masks = ReadBricks(r, r.source(), h, f);
  ReadValuesV1(r, r.source(), masks, f);
  return masks;
}

// Every corner of an occupied cell that lies in a listed brick must be stored
// (else the reader would invent an empty corner where the field had a value).
void CheckOccupiedCornersStored(const std::vector<uint64_t>& masks, const std::string& source, const NerfField& f) {
  for (uint32_t b = 0; b < masks.size(); ++b) {
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
}

// CAMS: u32 count, then count x f32 xyz (metres, world).
void PutCaptureCentres(ByteWriter& w, const std::vector<Vec3f>& centres) {
  w.Put(uint32_t(centres.size()));
  for (const Vec3f& c : centres) w.Put(c.x), w.Put(c.y), w.Put(c.z);
}

std::vector<Vec3f> ReadCaptureCentres(ByteReader r) {
  const uint32_t count = r.Get<uint32_t>("capture camera count");
  const std::vector<float> xyz = r.GetArray<float>(uint64_t{3} * count, "capture camera centres");
  r.ExpectEnd("the capture camera centres");
  std::vector<Vec3f> centres;
  for (size_t i = 0; i < xyz.size(); i += 3) {
    centres.emplace_back(xyz[i], xyz[i + 1], xyz[i + 2]);
    if (!Finite(centres.back())) r.Fail("capture camera " + std::to_string(i / 3) + "'s centre is not finite");
  }
  return centres;
}

}  // namespace

std::vector<std::string> NerfFileOptions::Validate() const {
  std::vector<std::string> problems;
  if (density_bits < 8 || density_bits > 16)
    problems.push_back("density_bits " + std::to_string(density_bits) + " (expected 8..16)");
  if (color_base_bits < 4 || color_base_bits > 16)
    problems.push_back("color_base_bits " + std::to_string(color_base_bits) + " (expected 4..16)");
  if (color_slope_bits < 4 || color_slope_bits > 16)
    problems.push_back("color_slope_bits " + std::to_string(color_slope_bits) + " (expected 4..16)");
  return problems;
}

std::string SerializeNerf(const NerfField& f, const NerfFileOptions& options) {
  NERFAR_CHECK(f.Validate().empty());
  NERFAR_CHECK(options.Validate().empty());
  const std::vector<uint64_t> masks = NeededMasks(f);
  // Bricks in table order (canonical), only those with stored vertices.
  std::vector<int32_t> order;
  uint64_t stored = 0;
  for (int32_t b : f.brick_table)
    if (b >= 0 && masks[b] != 0) {
      order.push_back(b);
      stored += uint64_t(__builtin_popcountll(masks[b]));
    }
  ByteWriter payload;
  for (int32_t b : order) {
    for (int a = 0; a < 3; ++a) payload.Put(int32_t(f.brick_coords[3 * size_t(b) + a]));
    payload.Put(masks[b]);
    payload.Put(f.occupancy[b]);
  }
  for (int32_t b : order)
    for (int ch = 0; ch < kValuesPerVertex; ++ch) {
      const int bits = ChannelBits(options, ch);
      float lo = std::numeric_limits<float>::max(), hi = -lo;
      for (int v = 0; v < kNerfBrickSlots; ++v)
        if ((masks[b] >> v) & 1u) {
          const float x = ChannelValue(f, size_t(b) * kNerfBrickSlots + v, ch);
          lo = std::min(lo, x), hi = std::max(hi, x);
        }
      const Quantiser q = ChooseQuantiser(lo, hi, bits);
      payload.Put(int8_t(q.exponent));
      payload.Put(q.base);
      BitPacker packer(payload.bytes());
      for (int v = 0; v < kNerfBrickSlots; ++v)
        if ((masks[b] >> v) & 1u)
          packer.Put(Quantise(ChannelValue(f, size_t(b) * kNerfBrickSlots + v, ch), q, bits), bits);
      packer.Flush();
    }
  std::string body = std::move(payload.bytes());
  const uint64_t payload_size = body.size();
  if (options.compress) {
    uLongf size = compressBound(uLong(body.size()));
    std::string packed(size, '\0');
    NERFAR_CHECK(compress2(reinterpret_cast<Bytef*>(packed.data()), &size, reinterpret_cast<const Bytef*>(body.data()),
                           uLong(body.size()), 6) == Z_OK);
    packed.resize(size);
    body = std::move(packed);
  }
  BinaryFileWriter w(kFormat, kNerfFileVersion);
  ByteWriter& head = w.Section("HEAD");
  PutHeader(head, f, uint32_t(order.size()), stored);
  PutCoding(head, options, payload_size);
  w.Section("BRIK").PutBytes(body);
  if (!f.capture_centres.empty()) PutCaptureCentres(w.Section("CAMS"), f.capture_centres);
  return std::move(w).Seal();
}

NerfField ParseNerf(const std::string& bytes, const std::string& source) {
  const BinaryFile file = OpenBinaryFile(bytes, source, kFormat);
  NerfField f;
  std::vector<uint64_t> masks;
  if (file.sectioned()) {
    ByteReader head = file.Section("HEAD");
    const Header h = ReadHeader(head, source, f);
    const PayloadCoding coding = ReadCoding(head);
    head.ExpectEnd("the header");
    ByteReader stored = file.Section("BRIK");
    masks = ReadPayload(stored.Take(stored.remaining(), "payload"), coding, h, source, f);
    if (file.HasSection("CAMS")) f.capture_centres = ReadCaptureCentres(file.Section("CAMS"));
  } else {
    ByteReader r = file.fields;
    const Header h = ReadHeader(r, source, f);
    masks = file.version == 1 ? ReadVersion1Body(r, h, bytes.size(), f) : ReadVersion2Body(r, h, bytes.size(), f);
  }
  CheckOccupiedCornersStored(masks, source, f);
  f.UpdateSkipGrid();
  return f;
}

void SaveNerf(const std::string& path, const NerfField& field, const NerfFileOptions& options) {
  WriteFileAtomic(path, SerializeNerf(field, options));
}

NerfField LoadNerf(const std::string& path) { return ParseNerf(ReadFileBytes(path, kNerfMaxFileBytes), path); }

}  // namespace nerfar
