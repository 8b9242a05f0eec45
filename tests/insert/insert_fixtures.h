// Scene pieces the insertion tests share: a plain table as the scene, one SG
// lobe as the light, and a sphere object with its exact visibility.
#pragma once

#include <cmath>
#include <memory>
#include <optional>

#include "render/insert/inserter.h"
#include "render/insert/object_visibility.h"
#include "render/lighting/scene_field.h"
#include "render/mesh/mesh.h"
#include "tests/support/analytic_scene.h"

namespace nerfar::testing {

// A table alone (no sphere, no medium, no checker), plain radiance.
inline testing::AnalyticSceneParams PlainTable() {
  testing::AnalyticSceneParams p;
  p.has_sphere = false;
  p.has_medium = false;
  p.checker_size_m = 0;
  return p;
}

inline SgMixture OneLobe(const Vec3& axis, double sharpness, double amplitude) {
  Sg sg;
  sg.axis = Normalized(axis);
  sg.sharpness = sharpness;
  sg.amplitude = {amplitude, amplitude, amplitude};
  return {sg};
}

// A sphere of radius r at c, drawn as a UV mesh, shadowing with the exact
// sphere visibility (render/insert's SphereVisibility).
struct SphereObject {
  TriangleMesh mesh = MakeUvSphere(1.0, 48, 24);
  double radius = 0.05;
  Vec3 center{0, 0, 0.05};
  std::unique_ptr<SphereVisibility> visibility;

  SphereObject(const Vec3& c, double r) : radius(r), center(c) {
    visibility = std::make_unique<SphereVisibility>(center, radius);
  }
  InsertObject Object(const SgMixture* light = nullptr) const {
    InsertObject o;
    o.mesh = &mesh;
    o.T_world_object = {Mat3::Identity(), center};
    o.scale = radius;
    o.material.base_color = {0.8, 0.5, 0.3};
    o.material.roughness = 0.6;
    o.visibility = visibility.get();
    o.light_override = light;
    return o;
  }
};

// The plain table's point (z = 0, within |x| <= 0.6, |y| <= 0.4) seen through
// pixel (x, y) of a rendered frame where no object covers the pixel; nullopt
// on object pixels and rays that miss that part of the table. The truth a κ
// pixel is compared with is taken there.
inline std::optional<Vec3> TablePointAt(const InsertLayers& layers, const CameraIntrinsics& camera, const Pose& cam,
                                        int x, int y) {
  const ObjectGBuffer& g = layers.gbuffer;
  if (g.rect.Contains(x, y) && g.object[g.Index(x, y)] >= 0) return std::nullopt;
  const Vec3 d(CameraRayDirection(camera, cam, x, y));
  if (d.z >= 0) return std::nullopt;
  const Vec3 p = cam.translation + d * (-cam.translation.z / d.z);
  if (std::abs(p.x) > 0.6 || std::abs(p.y) > 0.4) return std::nullopt;
  return p;
}

}  // namespace nerfar::testing
