// Internal to render/insert: what a drag may keep (InsertObject::dragged).
// While the user moves the objects (any flagged dragged) and they keep one
// common translation from where their light was taken (an object dragged
// along the table), that light is held and carried with them: each
// object's fitted SGs and its lobes' distances, re-centred on the object's
// centre. Given the same light, the objects' self-shadows γ and the shadows
// κ at a receiver relative to the objects do not change with the
// translation (re-aimed near lobes move with the centre too), so γ per
// vertex is kept and κ's lattice is kept in the objects' frame, shifted
// with them: a drag evaluates κ only at nodes it has not met yet instead of
// at every node anew. The light is taken again once the objects have moved
// farther than the smallest one's bounding radius from where it was taken
// (the light at the centre already stands for every point of the object,
// up to a radius away from it), and the first frame no object is dragged
// takes the full-quality path (the light refitted where they are, γ and κ
// anew). World frame, metres.
#pragma once

#include <vector>

#include "render/insert/incident_light.h"
#include "render/insert/insert_common.h"
#include "render/insert/inserter.h"

namespace nerfar {

enum class DragPhase {
  kNone,   // not dragged: every cache keyed by the objects' poses
  kStart,  // dragged, the light taken anew this frame (then DragHold::Take)
  kHeld,   // dragged within reach of where the light was taken: the held light, shifted
};

// This frame's part in a drag.
struct DragFrame {
  DragPhase phase = DragPhase::kNone;
  Vec3 shift;  // the objects' translation since the light was taken (kHeld; 0 at kStart)
  // The objects as the light was taken (meshes, fields' sizes, rotations,
  // scales, positions then): stands for their pose keys in the caches kept
  // in their frame (γ per vertex, κ's lattice) while phase != kNone.
  const std::vector<double>* key = nullptr;
  bool dragged() const { return phase != DragPhase::kNone; }
};

class DragHold {
 public:
  // This frame's phase from the objects' drag flags and poses against
  // those the light was taken at; no object dragged: kNone (the hold dropped).
  DragFrame Begin(const std::vector<InsertObject>& objects, const std::vector<WorldSphere>& spheres);
  // At kStart: the lights just taken and their parallax, held from now on.
  void Take(const std::vector<SgMixture>& lights, const std::vector<LightParallax>& parallax);
  // At kHeld: object i's held light, and its parallax re-centred by `shift`.
  const SgMixture& light(size_t i) const { return lights_.at(i); }
  LightParallax Parallax(size_t i, const Vec3& shift) const;

 private:
  bool holding_ = false;
  std::vector<double> hold_shape_;  // the objects without their positions (ShapeKey) as the light was taken
  std::vector<Vec3> hold_positions_;
  std::vector<double> key_;  // DragFrame::key
  std::vector<SgMixture> lights_;
  std::vector<LightParallax> parallax_;
};

}  // namespace nerfar
