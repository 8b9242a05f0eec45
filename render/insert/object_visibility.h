// What insertion asks of a virtual object's visibility field (paper §4.3):
// the spherical signed distance S(d; x), in radians, from world points x in
// world directions d; positive where the ray x + t·d misses the object. The
// object's pose is applied by the implementation. Several objects act as one
// occluder through UnionSsd (the smaller signed distance, DESIGN.md).
#pragma once

#include <cstddef>
#include <memory>
#include <vector>

#include "calib/core/math.h"

namespace nerfar {

// S for one frame's fixed directions (the light lobes' axes) at many points.
class VisibilityQuery {
 public:
  virtual ~VisibilityQuery() = default;
  virtual int direction_count() const = 0;
  // ssd[i * direction_count() + k] = S(dir k; points[i]). Thread-safe (const).
  virtual void Ssd(const Vec3f* points, size_t count, float* ssd) const = 0;
};

class ObjectVisibility {
 public:
  virtual ~ObjectVisibility() = default;
  // World bounding sphere of the object (the occluder lies inside it).
  virtual Vec3 Center() const = 0;
  virtual double Radius() const = 0;
  // Prepares the per-frame work for these world directions (any length > 0).
  virtual std::unique_ptr<VisibilityQuery> Prepare(const std::vector<Vec3f>& directions) const = 0;
};

// An exact sphere occluder: S(d; x) = ∠(d, c − x) − asin(r/|c − x|), and
// −π/2 inside it (every direction blocked; f_h clamps S to [−π/2, π/2]).
// The reference for tests, and the exact field of a spherical object.
class SphereVisibility final : public ObjectVisibility {
 public:
  SphereVisibility(const Vec3& center, double radius) : center_(center), radius_(radius) {}
  Vec3 Center() const override { return center_; }
  double Radius() const override { return radius_; }
  std::unique_ptr<VisibilityQuery> Prepare(const std::vector<Vec3f>& directions) const override;
  static float SsdAt(const Vec3& center, double radius, const Vec3& x, const Vec3& d);

 private:
  Vec3 center_;
  double radius_;
};

// Lower bound of S over every object inside the ball (c, r), from the angle
// to its centre: ∠(d, c − x) − asin(r/|c − x|) (−π/2 inside the ball). A ray
// that misses the ball misses the object, and one that hits the object is
// nearer the ball's silhouette than the object's, so S_object ≥ this. Used to
// skip work where nothing can be in the way.
float BallSsdLowerBound(const Vec3f& center, float radius, const Vec3f& x, const Vec3f& d);

}  // namespace nerfar
