#include "render/insert/drag_hold.h"

#include <algorithm>
#include <cstdint>
#include <limits>

#include "render/insert/cache_keys.h"

namespace nerfar {

namespace {

// Objects that differ by this much from a common translation are not
// dragged together: a micrometre, far below any length the insertion
// resolves (the finest NeRF voxel is millimetres), and far above the
// rounding of poses composed in double precision.
constexpr double kSameShiftM = 1e-6;

// What a translation leaves unchanged: each object's mesh and field (its
// size; the posed field itself is made anew per pose), rotation, scale and
// any light given for it (with its samples).
std::vector<double> ShapeKey(const std::vector<InsertObject>& objects) {
  std::vector<double> key = {double(objects.size())};
  for (const InsertObject& o : objects) {
    key.push_back(double(reinterpret_cast<uintptr_t>(o.mesh)));
    key.push_back(o.visibility ? o.visibility->Radius() : -1.0);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) key.push_back(o.T_world_object.rotation(r, c));
    key.push_back(o.scale);
    if (o.light_override)
      AppendLightKey(*o.light_override, key);
    else
      key.push_back(-1.0);
    for (const void* given :
         {static_cast<const void*>(o.light_distances), static_cast<const void*>(o.light_samples),
          static_cast<const void*>(o.light_compact), static_cast<const void*>(o.light_sample_distances)})
      key.push_back(double(reinterpret_cast<uintptr_t>(given)));
  }
  return key;
}

std::vector<Vec3> Positions(const std::vector<InsertObject>& objects) {
  std::vector<Vec3> p;
  p.reserve(objects.size());
  for (const InsertObject& o : objects) p.push_back(o.T_world_object.translation);
  return p;
}

}  // namespace

DragFrame DragHold::Begin(const std::vector<InsertObject>& objects, const std::vector<WorldSphere>& spheres) {
  const bool dragged = std::any_of(objects.begin(), objects.end(), [](const InsertObject& o) { return o.dragged; });
  if (!dragged) {
    holding_ = false;
    return {};
  }
  std::vector<double> shape = ShapeKey(objects);
  std::vector<Vec3> positions = Positions(objects);
  if (holding_ && shape == hold_shape_) {
    const Vec3 shift = positions[0] - hold_positions_[0];
    bool together = true;
    float reach = std::numeric_limits<float>::infinity();
    for (size_t i = 0; i < positions.size(); ++i) {
      together = together && Length(positions[i] - hold_positions_[i] - shift) <= kSameShiftM;
      reach = std::min(reach, spheres[i].radius);
    }
    if (together && Length(shift) <= double(reach)) return {DragPhase::kHeld, shift, &key_};
  }
  // The light is taken anew here: the objects as they stand key the hold.
  holding_ = false;  // until Take
  hold_shape_ = shape;
  hold_positions_ = positions;
  key_ = std::move(shape);
  for (const Vec3& p : positions) key_.insert(key_.end(), {p.x, p.y, p.z});
  return {DragPhase::kStart, Vec3{}, &key_};
}

void DragHold::Take(const std::vector<SgMixture>& lights, const std::vector<LightParallax>& parallax) {
  lights_ = lights;
  parallax_ = parallax;
  holding_ = true;
}

LightParallax DragHold::Parallax(size_t i, const Vec3& shift) const {
  LightParallax p = parallax_.at(i);
  p.center = p.center + shift;
  return p;
}

}  // namespace nerfar
