// The .nerf file: a versioned, checksummed, sparse and quantised form of a
// NerfField. Only the vertices that some occupied cell needs are stored (the
// rest of an allocated brick reads as empty space).
//
// Version 3 (written): the sectioned container of calib/core/binary_file.h
// ("NERFARF1" magic, version, section table, crc32) with two or three sections.
// HEAD: u32 colour model, f32 aabb[6], f32 origin[3], f32 voxel_m, f32
// occupancy_sigma, i32 res[3], u32 brick_count, u64 stored_vertex_count, u8
// bits[13] (bits per stored value: density, then the 12 colour coefficients),
// u8 compression (0 none, 1 zlib), u16 0, u64 payload bytes. BRIK: the payload
// (zlib deflated when compression is 1). CAMS (only when the field has them):
// u32 count, then count x f32 xyz, NerfField::capture_centres. Payload: per brick i32 coords[3] + u64 mask of
// stored vertices + u64 cell occupancy; then per brick and per channel (density, colour 0..11) an i8 exponent e, an i32
// base b and the brick's stored vertices' codes q (bits[channel] bits each, little-endian bit order, padded to a byte):
// the value is (b + q)·2^e. The writer picks per brick and channel the smallest e whose 2^bits - 1 levels span the
// brick's values (and keeps |value|/2^e <= 2^23), so the error of a value is at most 2^(e-1) < max((brick max - brick
// min) / (2^bits - 3), 2^-23 · brick max |value|).
// Loading a loaded field's file again gives exactly the loaded values, and
// from the second save on the bytes repeat.
// Version 2 (read only): flat, "NERFARF1", u32 version, HEAD's fields, u64
// stored payload bytes, the payload, u64 FNV checksum (binary_file.h's legacy one).
// Version 1 (read only): flat, the same header up to stored_vertex_count, then per
// brick i32 coords[3] + u64 mask + u64 occupancy, per stored vertex f16
// density + 12 x f16 colour, u64 FNV checksum.
#pragma once

#include <string>
#include <vector>

#include "render/nerf/nerf_field.h"

namespace nerfar {

inline constexpr uint32_t kNerfFileVersion = 3;
// Largest file the reader accepts (a wrong path to a huge file fails fast).
inline constexpr size_t kNerfMaxFileBytes = size_t{1} << 31;

// How the writer quantises and compresses (the reader takes whatever the file says).
struct NerfFileOptions {
  // The defaults store a balanced model in about a third of the bytes of
  // float storage, psnr_tm and depth unchanged to 0.01 dB / 0.01 mm.
  // Bits per stored raw log-density (8..16). At 12 the error is < 1/4093 of
  // the brick's log-density span (< 0.011 over the full -30..14 range: σ within 1.1 %).
  int density_bits = 12;
  // Bits per stored colour base a_c (log radiance; 4..16): error < span / (2^bits - 3).
  int color_base_bits = 8;
  // Bits per stored colour slope b_c (view dependence; 4..16).
  int color_slope_bits = 4;
  // Deflate the payload (zlib): lossless.
  bool compress = true;
  // Every problem with the options; empty when valid.
  std::vector<std::string> Validate() const;
};

std::string SerializeNerf(const NerfField& field, const NerfFileOptions& options = {});
// InputError "source: what is wrong (what was expected)" for anything bad.
NerfField ParseNerf(const std::string& bytes, const std::string& source);

void SaveNerf(const std::string& path, const NerfField& field, const NerfFileOptions& options = {});  // atomic
NerfField LoadNerf(const std::string& path);

}  // namespace nerfar
