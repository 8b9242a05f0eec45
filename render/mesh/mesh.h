// Triangle meshes of virtual objects: a plain indexed mesh (float positions in
// the object's local frame, metres; unit per-vertex normals; optional UVs;
// uint32 triangles, counter-clockwise seen from outside), its bounds and
// bounding sphere, rigid+scale transforms, ReadMesh for OBJ / PLY / glTF 2.0
// (.gltf, .glb; metallic-roughness materials), a tiny OBJ writer, and
// procedural shapes (UV sphere, box, torus, cylinder) for tests and synth.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "calib/core/error.h"
#include "calib/core/image.h"
#include "calib/core/math.h"
#include "calib/object.h"

namespace nerfar {

struct TriangleMesh {
  std::vector<Vec3f> positions;                    // metres, object frame
  std::vector<Vec3f> normals;                      // empty, or one unit normal per position
  std::vector<std::array<float, 2>> uvs;           // empty, or one (u, v) per position
  std::vector<std::array<uint32_t, 3>> triangles;  // indices into positions
  std::optional<Material> material;                // from the mesh file (glTF / MTL), if it has one
  std::string source;                              // file it was read from ("" if built in code)

  size_t VertexCount() const { return positions.size(); }
  size_t TriangleCount() const { return triangles.size(); }
};

// Axis-aligned box; min > max (componentwise) when empty.
struct Bounds {
  Vec3 min{1, 1, 1}, max{-1, -1, -1};
  bool Empty() const { return min.x > max.x || min.y > max.y || min.z > max.z; }
  Vec3 Center() const { return (min + max) * 0.5; }
  Vec3 Size() const { return max - min; }
};

struct BoundingSphere {
  Vec3 center;
  double radius = 0;
};

// Limits a mesh file may not exceed (a wrong path to a huge scan fails fast).
inline constexpr size_t kMaxMeshVertices = size_t{20} << 20;
inline constexpr size_t kMaxMeshTriangles = size_t{40} << 20;

Bounds ComputeBounds(const TriangleMesh& mesh);
// A sphere holding every vertex: the smaller of the box-centred sphere and a
// Ritter sphere (grown until it holds all points). Exact for symmetric shapes
// such as a UV sphere centred on its box; never smaller than the true minimum.
BoundingSphere ComputeBoundingSphere(const TriangleMesh& mesh);

// Every problem of the mesh (no triangles, index out of range, non-finite
// position or normal, normal count mismatch, absurd counts), `source` prefixed.
Problems ValidateMesh(const TriangleMesh& mesh, const std::string& source);

// p' = T_world_object * (scale * p); normals rotated (scale > 0 keeps them unit).
TriangleMesh TransformMesh(const TriangleMesh& mesh, const Pose& T_world_object, double scale = 1.0);

// Recomputes smooth per-vertex normals (area-weighted face normals).
void ComputeVertexNormals(TriangleMesh& mesh);

// Reads OBJ, PLY, glTF 2.0 (.gltf with its buffers, .glb). Node transforms are
// applied, all meshes of the file are merged into one, polygons triangulated,
// identical vertices joined; missing normals are computed. The material of the
// largest part is kept: base colour factor, roughness and metallic factors and
// texture file references (resolved against the mesh's folder; an embedded
// glTF texture is referenced as "<mesh path>#<index>"). Throws InputError
// "path: what is wrong (what was expected)" for missing, unreadable, empty or
// invalid files.
TriangleMesh ReadMesh(const std::string& path);

// The image a material's texture reference names: a PNG or JPEG file, or
// "<mesh path>#<index>" for a texture embedded in a GLB (as ReadMesh writes
// them). Row 0 is the image's top row; the mesh's UVs have v = 0 at its
// bottom row (OBJ's convention, and glTF's as assimp flips it), so v maps to
// row (1 − v) × height. InputError naming the reference when unreadable.
Image8 ReadMeshTexture(const std::string& reference);

// Writes positions, normals (and UVs) as OBJ, atomically. Material not written.
void WriteMeshObj(const std::string& path, const TriangleMesh& mesh);

// Procedural shapes centred at the origin, outward normals, +z the axis.
// UV sphere: `segments` around z (>= 3), `rings` from pole to pole (>= 2).
TriangleMesh MakeUvSphere(double radius, int segments = 64, int rings = 32);
// Box with the given half extents; flat faces (4 vertices each).
TriangleMesh MakeBox(const Vec3& half_extents);
// Torus around z: ring radius `major`, tube radius `minor` < major.
TriangleMesh MakeTorus(double major, double minor, int major_segments = 48, int minor_segments = 24);
// Closed cylinder along z from -half_height to +half_height, flat caps.
TriangleMesh MakeCylinder(double radius, double half_height, int segments = 48);

}  // namespace nerfar
