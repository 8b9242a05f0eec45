#include "render/insert/cache_keys.h"

#include <cstdint>

namespace nerfar {

void AppendPoseKey(const Pose& pose, double scale, std::vector<double>& key) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) key.push_back(pose.rotation(r, c));
  for (int c = 0; c < 3; ++c) key.push_back(pose.translation[c]);
  key.push_back(scale);
}
void AppendObjectKey(const InsertObject& object, std::vector<double>& key) {
  key.push_back(double(reinterpret_cast<uintptr_t>(object.visibility)));
  key.push_back(double(reinterpret_cast<uintptr_t>(object.mesh)));
  AppendPoseKey(object.T_world_object, object.scale, key);
  if (object.visibility) {
    const Vec3 c = object.visibility->Center();
    key.insert(key.end(), {c.x, c.y, c.z, object.visibility->Radius()});
  }
}
void AppendLightKey(const SgMixture& light, std::vector<double>& key) {
  key.push_back(double(light.size()));
  for (const Sg& lobe : light)
    key.insert(key.end(), {lobe.axis.x, lobe.axis.y, lobe.axis.z, lobe.sharpness, lobe.amplitude.x, lobe.amplitude.y,
                           lobe.amplitude.z});
}

}  // namespace nerfar
