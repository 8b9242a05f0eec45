// Internal to render/insert: scene receivers for κ — the last frame's NeRF
// receivers at its κ grid nodes, reused for a new view where they can stand
// for marching (InsertOptions::kappa_receiver_reuse).
#pragma once

#include <cstddef>
#include <cstdint>
#include <unordered_map>
#include <vector>

#include "calib/camera.h"
#include "calib/core/math.h"
#include "render/lighting/scene_field.h"

namespace nerfar {

// The last frame's NeRF receivers at its κ grid nodes.
struct ReceiverFrame {
  bool valid = false;
  // How they were found (receiver_min_opacity, the support plane):
  // receivers found another way are not reused.
  std::vector<float> rule;
  CameraIntrinsics camera;
  Pose T_world_camera, T_camera_world;
  std::vector<int> xs, ys;     // the grid's pixel columns and rows
  std::vector<size_t> cx, cy;  // its coarse nodes (indices into xs, ys)
  size_t factor = 1;
  int step = 1;
  std::vector<uint8_t> state;  // per node: 0 unknown, 1 surface, 2 no surface
  std::vector<Vec3f> point, normal;
  float nearest = 0;  // the nearest surface receiver's distance from the eye (m)
};

// The last frame's receiver for a new grid node's ray (eye, d) at pixel
// (x, y), if its receivers can give it: 1 with `point`/`normal`, 2 for no
// surface, 0 to march (the rule: InsertOptions::kappa_receiver_reuse).
int ReuseReceiver(const ReceiverFrame& r, const Vec3f& eye, const Vec3f& d, int x, int y, float tolerance, Vec3f& point,
                  Vec3f& normal);

// Receivers onto a known plane where their ray ends on it. A trained field
// holds a flat table as a layer of fog some millimetres to centimetres deep
// (and uneven), so where a ray's transmittance crosses any one level is off
// the table by up to that depth, and the shadow moves by that error times
// the light's slope; the plane is exact. Ray i (from `eye` along dirs[i],
// entering the scene's box at t_near[i], its transmittance 1/2 at t[i])
// ends on the plane when the plane lies within the central part of its
// termination: no nearer than where its transmittance was 1 − q
// (q = kSupportTerminationShare) and no farther past t[i] than that point
// lies before it (a layer's termination about its median). Then t[i] is the
// plane's distance and on_plane[i] = 1. Rays that end on something else (an
// object's face or top, which stops the ray short of the plane, hollow
// inside or not) stay.
inline constexpr float kSupportTerminationShare = 0.1f;
void ReceiversOnPlane(const SceneField& scene, const SupportPlane& plane, const Vec3f& eye,
                      const std::vector<Vec3f>& dirs, const std::vector<float>& t_near, std::vector<float>& t,
                      std::vector<uint8_t>& on_plane);

// A receiver found at κ grid node `node` with its own normal (not yet unit).
struct CellCandidate {
  size_t node = 0;
  Vec3f point, normal;
};

// One receiver normal per world cell of the κ lattice
// (InsertOptions::receiver_normal_per_cell), so that a receiver's normal, its
// lattice normal cell and κ do not change with the view. A cell's normal is
// kept from the first pass that found a receiver in it; within that pass it
// is the mean of its receivers' unit normals, summed in the order of their
// values (point, then normal), so it does not depend on the order in which
// threads found the receivers.
class CellNormals {
 public:
  // Replaces every candidate's normal by its cell's (cells of `spacing`
  // metres; a new spacing drops the kept normals). Candidates whose normal
  // is not usable (non-finite or shorter than 0.5) are not picked but take
  // their cell's normal if it has one.
  void Resolve(double spacing, std::vector<CellCandidate>& candidates);
  size_t size() const { return normals_.size(); }

 private:
  double spacing_ = 0;
  std::unordered_map<uint64_t, Vec3f> normals_;
};

}  // namespace nerfar
