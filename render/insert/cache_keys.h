// Internal to render/insert: what a cached value (light, γ per vertex, κ
// lattice, κ layer) depends on, as a list of numbers compared exactly.
#pragma once

#include <vector>

#include "calib/core/math.h"
#include "render/insert/inserter.h"
#include "render/sg/sg.h"

namespace nerfar {

// The pose's rotation (row-major), translation and the scale: 13 numbers.
void AppendPoseKey(const Pose& pose, double scale, std::vector<double>& key);
// The object's field and mesh (addresses), pose and bounding sphere.
void AppendObjectKey(const InsertObject& object, std::vector<double>& key);
// Every lobe's axis, sharpness and amplitude.
void AppendLightKey(const SgMixture& light, std::vector<double>& key);

}  // namespace nerfar
