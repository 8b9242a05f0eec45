// The inputs of the .ssdf fixture in tests/data/formats/ (written by
// tests/make_format_fixtures.cpp; the test reads that file to show that files
// written by earlier builds still read): a tetrahedron with a material,
// baked on a small grid.
#pragma once

#include "calib/object.h"
#include "render/mesh/mesh.h"
#include "render/ssdf/ssdf.h"

namespace nerfar::testing {

inline TriangleMesh FormatFixtureMesh() {
  TriangleMesh mesh;
  mesh.positions = {{0.1f, 0.0f, 0.0f}, {-0.05f, 0.087f, 0.0f}, {-0.05f, -0.087f, 0.0f}, {0.0f, 0.0f, 0.15f}};
  mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {2, 0, 3}};
  mesh.source = "fixture/tetra.obj";
  return mesh;
}

inline Material FormatFixtureMaterial() {
  Material m;
  m.albedo = {0.6, 0.3, 0.1};
  m.roughness = 0.4;
  m.metallic = 0.25;
  m.f0 = 0.04;
  m.mesh = "fixture/tetra.obj";
  m.albedo_texture = "fixture/albedo.png";
  return m;
}

inline SsdfBakeOptions FormatFixtureSsdfOptions() {
  SsdfBakeOptions o;
  o.grid = 4;
  o.dirs = 8;
  o.components = 4;
  return o;
}

}  // namespace nerfar::testing
