#include "render/insert/vertex_gamma.h"

#include <algorithm>
#include <limits>

#include "calib/core/parallel.h"
#include "render/insert/shadow_terms.h"

namespace nerfar {

// Unit world normals per vertex: the mesh's own, else area-weighted face normals.
std::vector<Vec3f> WorldVertexNormals(const TriangleMesh& mesh, const Pose& T_world_object) {
  const size_t nv = mesh.positions.size();
  std::vector<Vec3> n(nv);
  if (mesh.normals.size() == nv) {
    for (size_t v = 0; v < nv; ++v) n[v] = Vec3(mesh.normals[v]);
  } else {
    for (const auto& t : mesh.triangles) {
      if (t[0] >= nv || t[1] >= nv || t[2] >= nv) continue;
      const Vec3 face =
          Cross(Vec3(mesh.positions[t[1]] - mesh.positions[t[0]]), Vec3(mesh.positions[t[2]] - mesh.positions[t[0]]));
      if (!(std::isfinite(face.x) && std::isfinite(face.y) && std::isfinite(face.z))) continue;
      for (int c = 0; c < 3; ++c) n[t[c]] = n[t[c]] + face;
    }
  }
  std::vector<Vec3f> out(nv);
  for (size_t v = 0; v < nv; ++v) {
    const Vec3 w = T_world_object.Rotate(n[v]);
    out[v] = Dot(w, w) > 1e-30 ? Vec3f(Normalized(w)) : Vec3f{};
  }
  return out;
}

bool UpdateVertexGamma(const std::vector<InsertObject>& objects, const std::vector<WorldSphere>& spheres,
                       const std::vector<SgMixture>& lights, const std::vector<LightPrep>& preps,
                       const InsertOptions& options, std::vector<VertexGamma>& cache,
                       std::vector<std::vector<Vec3f>>& vertex_normals, const DragObjectsKey* held) {
  const size_t n_objects = objects.size();
  cache.resize(n_objects);
  vertex_normals.assign(n_objects, {});
  bool rebuilt = false;
  for (size_t o = 0; o < n_objects; ++o) {
    if (!preps[o].shader || objects[o].mesh == nullptr) continue;
    const TriangleMesh& mesh = *objects[o].mesh;
    vertex_normals[o] = WorldVertexNormals(mesh, objects[o].T_world_object);
    VertexGammaKey key{.mesh = &mesh,
                       .offset_radii = options.self_shadow_offset_radii,
                       .horizon = options.self_shadow_horizon,
                       .light = lights[o],
                       .objects = ObjectsKeyOf(objects, held)};
    VertexGamma& vg = cache[o];
    if (key == vg.key) continue;
    rebuilt = true;
    vg.key = std::move(key);
    const LightPrep& p = preps[o];
    const size_t m = p.axes.size(), nv = mesh.positions.size();
    vg.gamma.assign(nv * m, 1.0f);
    if (m == 0) continue;
    const float offset = static_cast<float>(options.self_shadow_offset_radii * spheres[o].radius);
    std::vector<Vec3f> points(nv);
    for (size_t v = 0; v < nv; ++v)
      points[v] = Vec3f(objects[o].T_world_object * (Vec3(mesh.positions[v]) * objects[o].scale)) +
                  vertex_normals[o][v] * offset;
    constexpr size_t kVertexChunk = 128;
    ParallelFor((nv + kVertexChunk - 1) / kVertexChunk,
                [&](size_t c) {
                  const size_t begin = c * kVertexChunk, end = std::min(nv, begin + kVertexChunk);
                  std::vector<float> ssd((end - begin) * m),
                      ssd_min((end - begin) * m, std::numeric_limits<float>::infinity());
                  for (size_t j = 0; j < n_objects; ++j) {
                    if (!p.queries[j]) continue;
                    p.queries[j]->Ssd(&points[begin], end - begin, ssd.data());
                    for (size_t q = 0; q < ssd.size(); ++q) ssd_min[q] = std::min(ssd_min[q], ssd[q]);
                  }
                  for (size_t v = begin; v < end; ++v)
                    GammaFromSsd(p.axes, p.gamma_rows, vertex_normals[o][v], &ssd_min[(v - begin) * m],
                                 options.self_shadow_horizon, &vg.gamma[v * m]);
                },
                1);
  }
  return rebuilt;
}

}  // namespace nerfar
