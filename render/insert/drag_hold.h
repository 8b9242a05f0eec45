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
// up to a radius away from it); κ keeps the light the drag began with
// through those retakes (its lattice stays valid, so a retake costs the
// light and γ, not every κ node again: κ at a reduced rate), and the first
// frame no object is dragged takes the full-quality path (the light
// refitted where they are, γ and κ anew). World frame, metres.
#pragma once

#include <vector>

#include "render/insert/cache_keys.h"
#include "render/insert/insert_common.h"
#include "render/insert/inserter.h"
#include "render/lighting/incident_light.h"

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
  // The objects as the light was taken: stands for their own keys in the
  // caches kept in their frame (γ per vertex, κ's lattice) while phase != kNone.
  const DragObjectsKey* key = nullptr;
  // κ's light, held from the drag's start through the light's retakes: the
  // objects' translation since then and their key then (the same as shift
  // and key until the first retake); kappa_apart: κ's light is no longer
  // this frame's (DragHold::kappa_light).
  Vec3 kappa_shift;
  const DragObjectsKey* kappa_key = nullptr;
  bool kappa_apart = false;
  bool dragged() const { return phase != DragPhase::kNone; }
};

class DragHold {
 public:
  // This frame's phase from the objects' drag flags and poses against
  // those the light was taken at; no object dragged: kNone (the holds
  // dropped). `kappa_through_retakes` false: κ's light is retaken with the
  // light (κ from the light's samples, InsertOptions::kappa_from_samples,
  // needs the two to be one).
  DragFrame Begin(const std::vector<InsertObject>& objects, const std::vector<WorldSphere>& spheres,
                  bool kappa_through_retakes);
  // At kStart: the lights just taken and their parallax, held from now on
  // (and for κ too when its hold starts with them).
  void Take(const std::vector<SgMixture>& lights, const std::vector<LightParallax>& parallax);
  // At kHeld: object i's held light, and its parallax re-centred by `shift`;
  // κ's held light likewise (with DragFrame::kappa_shift).
  const SgMixture& light(size_t i) const { return light_.lights.at(i); }
  LightParallax Parallax(size_t i, const Vec3& shift) const { return light_.Parallax(i, shift); }
  const SgMixture& kappa_light(size_t i) const { return kappa_.lights.at(i); }
  LightParallax KappaParallax(size_t i, const Vec3& shift) const { return kappa_.Parallax(i, shift); }

 private:
  // A light held with the objects' positions and key as it was taken.
  struct Hold {
    bool valid = false;
    std::vector<Vec3> positions;
    DragObjectsKey key;  // DragFrame::key
    std::vector<SgMixture> lights;
    std::vector<LightParallax> parallax;
    LightParallax Parallax(size_t i, const Vec3& shift) const;
  };
  std::vector<ObjectShapeKey> shape_;  // the objects without their positions, as both holds took them
  Hold light_, kappa_;
  bool kappa_is_light_ = false;  // κ's hold was taken with the current light's
};

}  // namespace nerfar
