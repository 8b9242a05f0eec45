#include "render/insert/drag_hold.h"

#include <algorithm>
#include <limits>

namespace nerfar {

namespace {

// Objects that differ by this much from a common translation are not
// dragged together: a micrometre, far below any length the insertion
// resolves (the finest NeRF voxel is millimetres), and far above the
// rounding of poses composed in double precision.
constexpr double kSameShiftM = 1e-6;

std::vector<Vec3> Positions(const std::vector<InsertObject>& objects) {
  std::vector<Vec3> p;
  p.reserve(objects.size());
  for (const InsertObject& o : objects) p.push_back(o.T_world_object.translation);
  return p;
}

// The objects' common translation from `from` into *shift, false when they
// did not move together.
bool CommonShift(const std::vector<Vec3>& from, const std::vector<Vec3>& to, Vec3* shift) {
  if (from.size() != to.size() || to.empty()) return false;
  *shift = to[0] - from[0];
  for (size_t i = 0; i < to.size(); ++i)
    if (Length(to[i] - from[i] - *shift) > kSameShiftM) return false;
  return true;
}

}  // namespace

DragFrame DragHold::Begin(const std::vector<InsertObject>& objects, const std::vector<WorldSphere>& spheres,
                          bool kappa_through_retakes) {
  const bool dragged = std::any_of(objects.begin(), objects.end(), [](const InsertObject& o) { return o.dragged; });
  std::vector<ObjectShapeKey> shape = dragged ? ObjectShapeKeysOf(objects) : std::vector<ObjectShapeKey>{};
  if (!dragged || shape != shape_) light_.valid = kappa_.valid = false;
  if (!dragged) return {};
  const std::vector<Vec3> positions = Positions(objects);
  float reach = std::numeric_limits<float>::infinity();
  for (const WorldSphere& s : spheres) reach = std::min(reach, s.radius);
  DragFrame frame;
  if (light_.valid && CommonShift(light_.positions, positions, &frame.shift) && Length(frame.shift) <= double(reach)) {
    frame.phase = DragPhase::kHeld;
  } else {
    // The light is taken anew here: the objects as they stand key the hold.
    frame = {};
    frame.phase = DragPhase::kStart;
    light_.valid = false;  // until Take
    light_.positions = positions;
    light_.key = {shape, positions};
  }
  frame.key = &light_.key;
  shape_ = std::move(shape);
  Vec3 kappa_shift;
  if (!kappa_through_retakes || !kappa_.valid || !CommonShift(kappa_.positions, positions, &kappa_shift))
    kappa_.valid = false;  // taken with the light (Take)
  const bool kappa_apart = kappa_.valid && !(kappa_is_light_ && frame.phase == DragPhase::kHeld);
  frame.kappa_shift = kappa_apart ? kappa_shift : frame.shift;
  frame.kappa_key = kappa_apart ? &kappa_.key : &light_.key;
  frame.kappa_apart = kappa_apart;
  if (frame.phase == DragPhase::kStart) kappa_is_light_ = false;
  return frame;
}

void DragHold::Take(const std::vector<SgMixture>& lights, const std::vector<LightParallax>& parallax) {
  light_.lights = lights;
  light_.parallax = parallax;
  light_.valid = true;
  if (kappa_.valid) return;
  kappa_ = light_;
  kappa_is_light_ = true;
}

LightParallax DragHold::Hold::Parallax(size_t i, const Vec3& shift) const {
  LightParallax p = parallax.at(i);
  p.center = p.center + shift;
  return p;
}

}  // namespace nerfar
