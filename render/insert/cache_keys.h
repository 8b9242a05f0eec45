// Internal to render/insert: what each value kept between frames depends on
// — the objects' prepared lights, γ per vertex, κ's lattice and layer, a
// drag's held light — as named structs compared exactly, field by field
// (operator==): a cache is made anew when any field differs. Objects and
// their fields and meshes are compared by address (the caller's loans: the
// same object stays at one address while it is unchanged), numbers exactly.
// World frame, metres.
#pragma once

#include <array>
#include <cstddef>
#include <optional>
#include <vector>

#include "calib/core/math.h"
#include "render/sg/sg.h"

namespace nerfar {

// The keys hold these by address or take them as arguments (inserter.h,
// object_visibility.h, mesh.h, sphere.h, prefiltered.h, incident_light.h).
struct InsertObject;
class ObjectVisibility;
struct TriangleMesh;
struct RadianceSamples;
class DistanceMap;
struct LightParallax;

// A pose's rotation (row-major) and translation, with the object's scale.
struct PoseKey {
  std::array<double, 9> rotation{};
  Vec3 translation;
  double scale = 1.0;
  bool operator==(const PoseKey&) const = default;
};

// An object as its light and shadows see it: its field and mesh, its pose
// and its field's bounding sphere (centre and radius 0 without a field).
struct ObjectKey {
  const ObjectVisibility* visibility = nullptr;
  const TriangleMesh* mesh = nullptr;
  PoseKey pose;
  Vec3 field_center;
  double field_radius = 0.0;
  bool operator==(const ObjectKey&) const = default;
};
ObjectKey ObjectKeyOf(const InsertObject& object);

// What a common translation of the objects leaves unchanged of one of them
// (a drag's hold, drag_hold.h): its mesh, its field's size (the posed field
// itself is made anew per pose), rotation, scale and any light given for it
// with what comes beside that light.
struct ObjectShapeKey {
  const TriangleMesh* mesh = nullptr;
  double field_radius = -1.0;  // -1: no field
  std::array<double, 9> rotation{};
  double scale = 1.0;
  std::optional<SgMixture> light_override;
  const std::vector<double>* light_distances = nullptr;
  const RadianceSamples* light_samples = nullptr;
  const SgMixture* light_compact = nullptr;
  const DistanceMap* light_sample_distances = nullptr;
  bool operator==(const ObjectShapeKey&) const = default;
};
std::vector<ObjectShapeKey> ObjectShapeKeysOf(const std::vector<InsertObject>& objects);

// The objects as a drag's light was taken: their shapes and positions then
// (DragFrame::key).
struct DragObjectsKey {
  std::vector<ObjectShapeKey> shapes;
  std::vector<Vec3> positions;
  bool operator==(const DragObjectsKey&) const = default;
};

// The objects a cache kept in their frame was made for (γ per vertex, κ's
// lattice): their own keys, or through a drag the objects as its light was
// taken (those caches do not change with the objects' common translation).
struct ObjectsKey {
  std::vector<ObjectKey> posed;  // not dragged
  DragObjectsKey held;           // dragged (posed empty)
  bool operator==(const ObjectsKey&) const = default;
};
// `held` when given (a drag), else the keys of the objects whose indices
// `which` lists (every object when `which` is null).
ObjectsKey ObjectsKeyOf(const std::vector<InsertObject>& objects, const DragObjectsKey* held,
                        const std::vector<size_t>* which = nullptr);

// The lobes of a light re-aimed from each receiver as near sources
// (LightParallax without its centre): from which sharpness, and each
// lobe's distance.
struct ReaimedLobesKey {
  double min_sharpness = 0.0;
  std::vector<double> distance;
  bool operator==(const ReaimedLobesKey&) const = default;
};
ReaimedLobesKey ReaimedLobesKeyOf(const LightParallax& parallax);

// One object's prepared light (LightPrepCache): the object, its light
// (every lobe's axis, sharpness and amplitude) and the light's parallax.
struct LightPrepKey {
  ObjectKey object;
  SgMixture light;
  Vec3 parallax_center;
  ReaimedLobesKey lobes;
  bool operator==(const LightPrepKey&) const = default;
};

// One object's γ per vertex (VertexGamma): its mesh, the self-shadow
// options, its light, and the objects whose fields shadow it.
struct VertexGammaKey {
  const TriangleMesh* mesh = nullptr;
  double offset_radii = 0.0;  // InsertOptions::self_shadow_offset_radii
  bool horizon = false;       // InsertOptions::self_shadow_horizon
  SgMixture light;
  ObjectsKey objects;
  bool operator==(const VertexGammaKey&) const = default;
};

// κ's lattice and the κ layer kept for an unchanged camera (KappaCache):
// the options that shape them, the rule that places receivers, the
// casters, and each object's light with its re-aimed lobes.
struct KappaKey {
  double spacing_m = 0.0;            // the lattice's spacing
  double reach_radii = 0.0;          // InsertOptions::shadow_reach_radii
  double epsilon = 0.0;              // InsertOptions::shadow_epsilon
  int step_px = 0;                   // KappaSpacing::step
  size_t coarse_factor = 0;          // KappaSpacing::factor
  double refine_delta = 0.0;         // InsertOptions::kappa_refine_delta
  bool plane_upsampling = false;     // InsertOptions::kappa_plane_upsampling
  bool epsilon_snap = false;         // InsertOptions::shadow_epsilon_snap
  bool skip_covered = false;         // InsertOptions::kappa_skip_covered
  std::vector<float> receiver_rule;  // ReceiverFrame::rule
  ObjectsKey casters;
  std::vector<SgMixture> lights;         // per object
  std::vector<ReaimedLobesKey> reaimed;  // per object
  bool operator==(const KappaKey&) const = default;
};

}  // namespace nerfar
