// A baked SSDF field (render/ssdf) posed in the world as an ObjectVisibility:
// world points and directions are moved into the object frame
// (p_object = R^T(p_world − t)/scale, d_object = R^T d_world), and the
// per-frame batch path of the field evaluates the PCA basis once per lobe.
#pragma once

#include "calib/core/math.h"
#include "render/insert/object_visibility.h"
#include "render/ssdf/ssdf.h"

namespace nerfar {

class SsdfVisibility final : public ObjectVisibility {
 public:
  // `field` is a loan that must outlive this object and its queries.
  SsdfVisibility(const SsdfField& field, const Pose& T_world_object, double scale = 1.0);
  Vec3 Center() const override;
  double Radius() const override;
  std::unique_ptr<VisibilityQuery> Prepare(const std::vector<Vec3f>& directions) const override;

 private:
  const SsdfField& field_;
  Pose T_world_object_;
  double scale_;
};

}  // namespace nerfar
