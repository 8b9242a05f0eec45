// Internal to render/insert: the objects' radiance I_v per covered pixel —
// material (constant or maps at the mesh UVs), self-shadow γ (per vertex,
// interpolated, or one SSDF query per pixel) and render/sg's SG shading.
#pragma once

#include <cstdint>
#include <vector>

#include "render/insert/insert_common.h"
#include "render/insert/light_prep.h"
#include "render/insert/vertex_gamma.h"

namespace nerfar {

// Shades the pixels `covered` (G-buffer indices, scan order) into `object`
// (RGB over g.rect, same layout as the G-buffer). `vertex_gamma` nullptr: γ
// per pixel; else the per-vertex γ with `vertex_normals` (UpdateVertexGamma).
void ShadeObjects(const std::vector<InsertObject>& objects, const std::vector<WorldSphere>& spheres,
                  const std::vector<LightPrep>& preps, const std::vector<VertexGamma>* vertex_gamma,
                  const std::vector<std::vector<Vec3f>>& vertex_normals, const InsertOptions& options,
                  const ObjectGBuffer& g, const std::vector<uint32_t>& covered, const Vec3f& eye, ImageF& object);

}  // namespace nerfar
