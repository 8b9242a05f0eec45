// The smallest scene `nerfar insert` runs on, for the command-line tests: a
// table slab of the given box as an opaque grey NeRF and a distant light of
// one broad lobe from above, written as .nerf and env.json.
#pragma once

#include <cmath>
#include <string>

#include "calib/core/math.h"
#include "render/lighting/env_light.h"
#include "render/nerf/nerf_field.h"
#include "render/nerf/nerf_file.h"

namespace nerfar::testing {

// A slab of density 5000/m (opaque within a voxel) and dark grey radiance filling `box`, voxels of 2 cm.
inline void WriteSlabNerf(const std::string& path, const Aabb& box) {
  NerfField slab = NerfField::Dense(box, 0.02, std::log(5000.0f), {-1.0f, -1.0f, -1.0f});
  slab.UpdateOccupancy(1.0f);
  SaveNerf(path, slab);
}

// One grey lobe of sharpness 8 from near the zenith.
inline void WriteOverheadEnv(const std::string& path) {
  EnvLight env;
  env.lobes.push_back(Sg{Normalized(Vec3(0.2, 0.1, 1.0)), 8.0, {6.0, 6.0, 6.0}});
  WriteEnvLight(path, env);
}

}  // namespace nerfar::testing
