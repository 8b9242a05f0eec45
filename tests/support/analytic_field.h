// Dense NeRF grids built from an analytic shape and a radiance function that
// a test computes itself (independently of the code under test): the
// synthetic scenes of the lighting and insertion tests. World frame, metres,
// linear RGB radiance.
#pragma once

#include <array>
#include <functional>

#include "calib/core/math.h"
#include "calib/dataset.h"
#include "render/nerf/nerf_field.h"

namespace nerfar::testing {

// A signed distance (negative inside) and, for each point, the nearest
// surface point and its unit outward normal.
struct Shape {
  std::function<double(const Vec3&)> sd;
  std::function<void(const Vec3&, Vec3*, Vec3*)> project;
};

// Fills a dense grid from a shape: raw log-density ramps from 8 inside to −30
// outside across a third of a voxel around the surface (so the rendered
// surface lies within a fraction of a voxel of sd = 0); colour constant per
// vertex (Lambertian: no view dependence) from radiance(x_surf, n) of the
// nearest surface point, only within 3 voxels of the surface. With
// `log_slope`, the vertex's log radiance also varies with the ray's direction
// d as log_slope(x_surf, n)·d (the field's own view-dependence model,
// a + b·d per channel).
NerfField MakeField(const Aabb& aabb, double voxel, const Shape& shape,
                    const std::function<Vec3(const Vec3&, const Vec3&)>& radiance,
                    const std::function<Vec3(const Vec3&, const Vec3&)>& log_slope = nullptr);

// A box centred at c with half sizes half[k] along the orthonormal axes[k].
Shape OrientedBox(const Vec3& c, const std::array<Vec3, 3>& axes, const Vec3& half);
// An axis-aligned box.
Shape BoxShape(const Aabb& box);
Shape SphereShape(const Vec3& centre, double radius);

}  // namespace nerfar::testing
