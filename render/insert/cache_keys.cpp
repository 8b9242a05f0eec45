#include "render/insert/cache_keys.h"

#include "render/insert/inserter.h"

namespace nerfar {

ObjectKey ObjectKeyOf(const InsertObject& object) {
  const Pose& pose = object.T_world_object;
  const ObjectVisibility* field = object.visibility;
  return {.visibility = field,
          .mesh = object.mesh,
          .pose = {.rotation = pose.rotation.m, .translation = pose.translation, .scale = object.scale},
          .field_center = field ? field->Center() : Vec3{},
          .field_radius = field ? field->Radius() : 0.0};
}

ObjectsKey ObjectsKeyOf(const std::vector<InsertObject>& objects, const DragObjectsKey* held,
                        const std::vector<size_t>* which) {
  ObjectsKey key;
  if (held) {
    key.held = *held;
  } else if (which) {
    for (size_t i : *which) key.posed.push_back(ObjectKeyOf(objects[i]));
  } else {
    for (const InsertObject& object : objects) key.posed.push_back(ObjectKeyOf(object));
  }
  return key;
}

std::vector<ObjectShapeKey> ObjectShapeKeysOf(const std::vector<InsertObject>& objects) {
  std::vector<ObjectShapeKey> keys;
  keys.reserve(objects.size());
  for (const InsertObject& o : objects) {
    ObjectShapeKey& key = keys.emplace_back();
    key.mesh = o.mesh;
    key.field_radius = o.visibility ? o.visibility->Radius() : -1.0;
    key.rotation = o.T_world_object.rotation.m;
    key.scale = o.scale;
    if (o.light_override) key.light_override = *o.light_override;
    key.light_distances = o.light_distances;
    key.light_samples = o.light_samples;
    key.light_compact = o.light_compact;
    key.light_sample_distances = o.light_sample_distances;
  }
  return keys;
}

ReaimedLobesKey ReaimedLobesKeyOf(const LightParallax& parallax) { return {parallax.min_sharpness, parallax.distance}; }

}  // namespace nerfar
