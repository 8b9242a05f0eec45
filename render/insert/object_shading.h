// Internal to render/insert: the objects' radiance I_v per covered pixel —
// material (constant or maps at the mesh UVs), self-shadow γ (per vertex,
// interpolated, or one SSDF query per pixel) and render/sg's SG shading.
#pragma once

#include <cstdint>
#include <vector>

#include "render/insert/insert_common.h"
#include "render/insert/light_prep.h"
#include "render/insert/vertex_gamma.h"
#include "render/sg/prefiltered.h"

namespace nerfar {

// Shades the pixels `covered` (G-buffer indices, scan order) into `object`
// (RGB over g.rect, same layout as the G-buffer). `vertex_gamma` nullptr: γ
// per pixel; else the per-vertex γ with `vertex_normals` (UpdateVertexGamma).
// `specular` (one per object, or empty): an object with a non-empty map
// takes its specular term from it (PrefilteredRadiance::ShadeSpecular) times
// the SG specular's self-shadow ratio (with γ over without: the SG light
// knows where the lobes are shadowed, the map what they reflect) and its
// diffuse term from the SG light; the others shade with SGs alone. A map
// with a distance field (SetParallax) looks each pixel's reflection up from
// its world point.
void ShadeObjects(const std::vector<InsertObject>& objects, const std::vector<WorldSphere>& spheres,
                  const std::vector<LightPrep>& preps, const std::vector<VertexGamma>* vertex_gamma,
                  const std::vector<std::vector<Vec3f>>& vertex_normals, const InsertOptions& options,
                  const ObjectGBuffer& g, const std::vector<uint32_t>& covered, const Vec3f& eye, ImageF& object,
                  const std::vector<PrefilteredRadiance>& specular = {});

}  // namespace nerfar
