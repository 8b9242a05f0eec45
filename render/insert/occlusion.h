// Internal to render/insert: occlusion of the objects by the scene and the
// composite on object pixels (paper eq. 7): NeRF opacity and colour over
// [min(d, t_n), min(d, t_f)] per pixel, I_α·I_c + (1 − I_α)·I_v, and the
// edge pixels an object covers only in part.
#pragma once

#include <cstdint>
#include <vector>

#include "render/insert/inserter.h"

namespace nerfar {

// Composites layers.object into `frame` on the pixels `covered` (G-buffer
// indices of layers.gbuffer, scan order); writes layers.alpha and counts
// non-finite scene samples into layers.nonfinite_fixed.
void OccludeAndComposite(const SceneField& scene, const InsertOptions& options, const CameraIntrinsics& camera,
                         const Pose& T_world_camera, const std::vector<uint32_t>& covered,
                         const ReceiverOverride& receivers, ImageF& frame, InsertLayers& layers);

// Pixels partly covered by an object whose centre misses it (edge coverage
// on): the composite of the nearest covered neighbour over the covered part.
void CompositeEdges(const ReceiverOverride& receivers, ImageF& frame, const InsertLayers& layers);

}  // namespace nerfar
