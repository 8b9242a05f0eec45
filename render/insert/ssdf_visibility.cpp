#include "render/insert/ssdf_visibility.h"

#include <cmath>

namespace nerfar {

namespace {

class SsdfQuery final : public VisibilityQuery {
 public:
  SsdfQuery(const SsdfField& field, const Pose& T_object_world, double inv_scale, const std::vector<Vec3f>& dirs)
      : batch_(field), T_object_world_(T_object_world), inv_scale_(inv_scale) {
    std::vector<Vec3f> local;
    local.reserve(dirs.size());
    for (const Vec3f& d : dirs) {
      Vec3 l = T_object_world.Rotate(Vec3(d));
      if (!(Length(l) > 0.0)) l = {0, 0, 1};
      local.push_back(Vec3f(l));
    }
    batch_.PrepareDirections(local);
  }
  int direction_count() const override { return static_cast<int>(batch_.lobes()); }
  void Ssd(const Vec3f* points, size_t count, float* ssd) const override {
    constexpr size_t kChunk = 64;
    Vec3f local[kChunk];
    for (size_t begin = 0; begin < count; begin += kChunk) {
      const size_t n = std::min(kChunk, count - begin);
      for (size_t i = 0; i < n; ++i) local[i] = Vec3f((T_object_world_ * Vec3(points[begin + i])) * inv_scale_);
      batch_.QueryBatch(local, n, ssd + begin * batch_.lobes());
    }
  }

 private:
  SsdfBatch batch_;
  Pose T_object_world_;
  double inv_scale_;
};

}  // namespace

SsdfVisibility::SsdfVisibility(const SsdfField& field, const Pose& T_world_object, double scale)
    : field_(field), T_world_object_(T_world_object), scale_(scale > 0 && std::isfinite(scale) ? scale : 1.0) {}

Vec3 SsdfVisibility::Center() const { return T_world_object_ * (field_.center() * scale_); }
double SsdfVisibility::Radius() const { return field_.radius() * scale_; }

std::unique_ptr<VisibilityQuery> SsdfVisibility::Prepare(const std::vector<Vec3f>& directions) const {
  return std::make_unique<SsdfQuery>(field_, T_world_object_.Inverse(), 1.0 / scale_, directions);
}

}  // namespace nerfar
