// Internal to render/insert: self-shadow γ per mesh vertex and lobe
// (InsertOptions::self_shadow_per_vertex). γ does not depend on the view, so
// it is kept per object while the objects and the light stand still, and
// interpolated over each triangle with the rasteriser's barycentrics.
#pragma once

#include <vector>

#include "render/insert/cache_keys.h"
#include "render/insert/insert_common.h"
#include "render/insert/light_prep.h"

namespace nerfar {

// γ of one object's vertices, with what it was computed for.
struct VertexGamma {
  VertexGammaKey key;
  std::vector<float> gamma;  // vertex-major, lobes per vertex
};

// Unit world normals per vertex: the mesh's own, else area-weighted face normals.
std::vector<Vec3f> WorldVertexNormals(const TriangleMesh& mesh, const Pose& T_world_object);

// For every object with a prepared light (preps[o].shader set) and a mesh:
// its world vertex normals into vertex_normals[o], and cache[o] rebuilt when
// what it depends on changed (SSD of every field at the vertices pushed off
// along the normal by self_shadow_offset_radii, γ from their minimum).
// Returns true when any object's γ was rebuilt. `held` (optional) stands
// for the objects' own keys (a drag: DragFrame::key, the objects as its
// light was taken; γ does not change with their common translation).
bool UpdateVertexGamma(const std::vector<InsertObject>& objects, const std::vector<WorldSphere>& spheres,
                       const std::vector<SgMixture>& lights, const std::vector<LightPrep>& preps,
                       const InsertOptions& options, std::vector<VertexGamma>& cache,
                       std::vector<std::vector<Vec3f>>& vertex_normals, const DragObjectsKey* held = nullptr);

}  // namespace nerfar
