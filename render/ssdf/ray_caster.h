// Internal to render/ssdf: occlusion rays against a triangle mesh (Embree
// behind a pimpl, so no Embree type leaves ray_caster.cpp). Rays start at the
// origin (tnear 0) and are blocked by any triangle, front or back face.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>

#include "calib/core/math.h"
#include "render/mesh/mesh.h"

namespace nerfar::ssdf_internal {

class RayCaster {
 public:
  // Validates the mesh (InputError naming mesh.source) and builds the BVH.
  explicit RayCaster(const TriangleMesh& mesh);
  ~RayCaster();
  RayCaster(const RayCaster&) = delete;
  RayCaster& operator=(const RayCaster&) = delete;

  // True when the ray origin + t·dir, t > 0, hits the mesh. Thread-safe.
  bool Occluded(const Vec3f& origin, const Vec3f& dir) const;
  // blocked[i] = Occluded(origin, dirs[i]) for i < count, in packets. Thread-safe.
  void OccludedMany(const Vec3f& origin, const Vec3f* dirs, size_t count, uint8_t* blocked) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace nerfar::ssdf_internal
