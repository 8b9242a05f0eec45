// The .nerf file: a versioned, checksummed, sparse half-float form of a
// NerfField. Only the vertices that some occupied cell needs are stored (the
// rest of an allocated brick reads as empty space), so a saved and reloaded
// field renders exactly like the saved one up to half-float rounding of the
// stored values, and saving a loaded field reproduces the file byte for byte.
//
// Layout (little endian): "NERFARF1" magic, u32 version, u32 colour model,
// f32 aabb[6], f32 origin[3], f32 voxel_m, f32 occupancy_sigma, i32 res[3],
// u32 brick_count, u64 stored_vertex_count; per brick i32 coords[3] + u64 mask
// of stored vertices; per stored vertex f16 density + 12 x f16 colour; u64
// FNV-1a checksum of everything before it.
#pragma once

#include <string>

#include "render/nerf/nerf_field.h"

namespace nerfar {

inline constexpr uint32_t kNerfFileVersion = 1;
// Largest file the reader accepts (a wrong path to a huge file fails fast).
inline constexpr size_t kNerfMaxFileBytes = size_t{1} << 31;

std::string SerializeNerf(const NerfField& field);
// InputError "source: what is wrong (what was expected)" for anything bad.
NerfField ParseNerf(const std::string& bytes, const std::string& source);

void SaveNerf(const std::string& path, const NerfField& field);  // atomic
NerfField LoadNerf(const std::string& path);

}  // namespace nerfar
