#include "render/lighting/scene_field.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "calib/core/error.h"

namespace nerfar {

std::optional<std::pair<double, double>> IntersectBox(const Aabb& box, const Vec3& origin, const Vec3& direction) {
  double t0 = 0.0, t1 = std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    const double o = origin[a], d = direction[a];
    if (!std::isfinite(o) || !std::isfinite(d)) return std::nullopt;
    if (d == 0.0) {
      if (o < box.min[a] || o > box.max[a]) return std::nullopt;
      continue;
    }
    double ta = (box.min[a] - o) / d, tb = (box.max[a] - o) / d;
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    if (t0 > t1) return std::nullopt;
  }
  if (!std::isfinite(t1)) return std::nullopt;
  return std::make_pair(t0, t1);
}

SupportPlane PlaneOfBoard(const Board& board, const Vec3& viewer) {
  if (board.tags.empty()) ThrowInputError("board", "no tags (expected the tags whose plane the objects stand on)");
  // The tags lie on one flat sheet: the plane through their corners' mean,
  // its normal the sum of each tag's diagonals' cross product.
  Vec3 centre{}, normal{};
  for (const BoardTag& tag : board.tags) {
    for (const Vec3& c : tag.corners) centre += c;
    normal += Cross(tag.corners[2] - tag.corners[0], tag.corners[3] - tag.corners[1]);
  }
  centre = centre * (1.0 / (4.0 * static_cast<double>(board.tags.size())));
  normal = Normalized(normal);
  if (Dot(viewer - centre, normal) < 0.0) normal = -normal;
  return {Vec3f(centre), Vec3f(normal)};
}

void SceneRays::Reserve(size_t n) {
  origins.reserve(n);
  directions.reserve(n);
  t_near.reserve(n);
  t_far.reserve(n);
}

void SceneRays::Add(const Vec3f& origin, const Vec3f& direction, float t0, float t1) {
  origins.push_back(origin);
  directions.push_back(direction);
  t_near.push_back(t0);
  t_far.push_back(t1);
}

void SceneRays::Clear() {
  origins.clear();
  directions.clear();
  t_near.clear();
  t_far.clear();
}

void SceneSamples::Resize(size_t n) {
  colour.assign(n, Vec3f{});
  opacity.assign(n, 0.0f);
  depth.assign(n, 0.0f);
}

void SceneField::TransmittanceDepths(const SceneRays& rays, const std::vector<float>& transmittance,
                                     std::vector<float>& depth) const {
  NERFAR_CHECK_EQ(transmittance.size(), rays.size());
  SceneSamples samples;
  RenderRays(rays, samples);
  depth.resize(rays.size());
  for (size_t i = 0; i < rays.size(); ++i)
    depth[i] = samples.opacity[i] >= 1.0f - transmittance[i] ? samples.depth[i] : rays.t_far[i];
}

}  // namespace nerfar
