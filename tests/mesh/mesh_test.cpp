// render/mesh: reading OBJ / PLY / glTF / GLB (fixtures in tests/data/mesh and
// the shared objects), rejecting bad files, procedural shapes checked against
// analytic volumes and watertightness, bounds, bounding spheres, transforms.
#include "render/mesh/mesh.h"

#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <tuple>

#include "calib/core/json.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

using testing::TempDir;
using testing::TestDataPath;

// Signed volume by the divergence theorem: positive iff the faces point out.
double SignedVolume(const TriangleMesh& mesh) {
  double v = 0;
  for (const auto& t : mesh.triangles) {
    const Vec3 a(mesh.positions[t[0]]), b(mesh.positions[t[1]]), c(mesh.positions[t[2]]);
    v += Dot(a, Cross(b, c)) / 6.0;
  }
  return v;
}

// Every edge, keyed by its end positions, must be used exactly once in each
// direction (a closed, consistently oriented surface). Seams duplicate
// vertices, so positions, not indices, are compared.
bool IsClosedAndOriented(const TriangleMesh& mesh, std::string* why) {
  using Key = std::tuple<float, float, float, float, float, float>;
  std::map<Key, int> directed;
  for (const auto& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) {
      const Vec3f a = mesh.positions[t[k]], b = mesh.positions[t[(k + 1) % 3]];
      if (a == b) continue;  // degenerate pole edge of a UV sphere
      ++directed[{a.x, a.y, a.z, b.x, b.y, b.z}];
    }
  }
  for (const auto& [key, count] : directed) {
    const auto& [ax, ay, az, bx, by, bz] = key;
    const auto reverse = directed.find({bx, by, bz, ax, ay, az});
    if (count != 1 || reverse == directed.end() || reverse->second != 1) {
      *why = "edge (" + std::to_string(ax) + "," + std::to_string(ay) + "," + std::to_string(az) + ")->(" +
             std::to_string(bx) + "," + std::to_string(by) + "," + std::to_string(bz) + ") used " +
             std::to_string(count) + " times forward, " +
             std::to_string(reverse == directed.end() ? 0 : reverse->second) + " backward";
      return false;
    }
  }
  return true;
}

// Vertex normals must agree with the faces that use them: cos(angle) to each
// face normal above `min_cos`. Smooth normals of a finely tessellated shape
// deviate from a face by a fraction of a facet angle (min_cos 0.5, i.e. < 60°);
// at a sharp corner (tetrahedron, the monkey's ears) they may be up to 90° off
// a face but never point into it (min_cos 0, up to float rounding).
void ExpectNormalsAgreeWithFaces(const TriangleMesh& mesh, double min_cos = 0.5) {
  ASSERT_EQ(mesh.normals.size(), mesh.positions.size());
  for (const auto& t : mesh.triangles) {
    const Vec3 a(mesh.positions[t[0]]), b(mesh.positions[t[1]]), c(mesh.positions[t[2]]);
    const Vec3 face = Normalized(Cross(b - a, c - a));
    if (Length(face) == 0) continue;  // degenerate triangle at a pole
    for (uint32_t i : t) {
      EXPECT_NEAR(Length(Vec3(mesh.normals[i])), 1.0, 1e-5);
      // Smooth normals deviate from a face by at most half a facet angle (< 60 deg here).
      EXPECT_GT(Dot(face, Vec3(mesh.normals[i])), min_cos);
    }
  }
}

void ExpectInputErrorNaming(const std::string& path, const std::string& fragment = "") {
  try {
    ReadMesh(path);
    ADD_FAILURE() << "no error for " << path;
  } catch (const InputError& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find(path), std::string::npos) << message;
    if (!fragment.empty()) {
      EXPECT_NE(message.find(fragment), std::string::npos) << message;
    }
  }
}

void ExpectTetrahedron(const TriangleMesh& mesh, const Vec3& offset) {
  EXPECT_EQ(mesh.TriangleCount(), 4u);
  EXPECT_EQ(mesh.VertexCount(), 4u);  // identical corners joined
  // Exact in float: corners are small integers (+0.5).
  EXPECT_NEAR(SignedVolume(mesh), 1.0 / 6.0 + 0.0, 1e-6) << "outward orientation";
  const Bounds b = ComputeBounds(mesh);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(b.min[k], offset[k]);
    EXPECT_EQ(b.max[k], offset[k] + 1.0);
  }
  std::string why;
  EXPECT_TRUE(IsClosedAndOriented(mesh, &why)) << why;
  ExpectNormalsAgreeWithFaces(mesh, -1e-6);
}

TEST(ReadMesh, TetrahedronObj) {
  const TriangleMesh mesh = ReadMesh(TestDataPath("mesh/tetra.obj"));
  ExpectTetrahedron(mesh, {0, 0, 0});
  EXPECT_EQ(mesh.source, TestDataPath("mesh/tetra.obj"));
  EXPECT_FALSE(mesh.material.has_value()) << "an OBJ without MTL has no material";
}

TEST(ReadMesh, TetrahedronPly) { ExpectTetrahedron(ReadMesh(TestDataPath("mesh/tetra.ply")), {0, 0, 0}); }

TEST(ReadMesh, TetrahedronGltfWithNodeTransformAndMaterial) {
  const std::string path = TestDataPath("mesh/tetra.gltf");
  const TriangleMesh mesh = ReadMesh(path);
  ExpectTetrahedron(mesh, {0.5, 0, 0});  // the node's translation is applied
  ASSERT_TRUE(mesh.material.has_value());
  const Material& m = *mesh.material;
  // The factors are stored as float in the file: compare at float precision.
  EXPECT_NEAR(m.albedo.x, 0.25, 1e-7);
  EXPECT_NEAR(m.albedo.y, 0.5, 1e-7);
  EXPECT_NEAR(m.albedo.z, 0.75, 1e-7);
  EXPECT_NEAR(m.metallic, 0.3, 1e-7);
  EXPECT_NEAR(m.roughness, 0.6, 1e-7);
  const std::string folder = std::filesystem::path(path).parent_path().string();
  EXPECT_EQ(m.albedo_texture, folder + "/textures/tetra_albedo.png");
  EXPECT_EQ(m.roughness_texture, folder + "/textures/tetra_mr.png");
  EXPECT_EQ(m.metallic_texture, folder + "/textures/tetra_mr.png");
  EXPECT_EQ(m.mesh, path);
}

// A binary glTF built here byte by byte from the spec (header, JSON chunk,
// BIN chunk), independent of the reader.
std::string BuildTetraGlb() {
  const float positions[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  const uint16_t indices[12] = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};
  std::string bin(sizeof positions + sizeof indices, '\0');
  std::memcpy(bin.data(), positions, sizeof positions);
  std::memcpy(bin.data() + sizeof positions, indices, sizeof indices);
  std::string json =
      R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],)"
      R"("meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1,"material":0}]}],)"
      R"("materials":[{"pbrMetallicRoughness":{"baseColorFactor":[1,0,0,1],"metallicFactor":1,)"
      R"("roughnessFactor":0.125}}],"buffers":[{"byteLength":72}],)"
      R"("bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":48},{"buffer":0,"byteOffset":48,"byteLength":24}],)"
      R"("accessors":[{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,1]},)"
      R"({"bufferView":1,"componentType":5123,"count":12,"type":"SCALAR"}]})";
  while (json.size() % 4) json += ' ';
  const auto u32 = [](uint32_t v) { return std::string(reinterpret_cast<const char*>(&v), 4); };
  const uint32_t total = 12 + 8 + static_cast<uint32_t>(json.size()) + 8 + static_cast<uint32_t>(bin.size());
  return u32(0x46546C67) + u32(2) + u32(total) + u32(static_cast<uint32_t>(json.size())) + u32(0x4E4F534A) + json +
         u32(static_cast<uint32_t>(bin.size())) + u32(0x004E4942) + bin;
}

TEST(ReadMesh, TetrahedronGlb) {
  TempDir dir;
  const std::string path = dir.File("tetra.glb");
  testing::WriteText(path, BuildTetraGlb());
  const TriangleMesh mesh = ReadMesh(path);
  ExpectTetrahedron(mesh, {0, 0, 0});
  ASSERT_TRUE(mesh.material.has_value());
  EXPECT_EQ(mesh.material->albedo, Vec3(1, 0, 0));
  EXPECT_EQ(mesh.material->metallic, 1.0);
  EXPECT_EQ(mesh.material->roughness, 0.125);  // exact in float

  // Truncated GLB: rejected, file named.
  const std::string cut = dir.File("cut.glb");
  testing::WriteTruncatedCopy(path, cut, 100);
  ExpectInputErrorNaming(cut);
}

TEST(ReadMesh, SharedObjectsMatchTheirJson) {
  NERFAR_REQUIRE_SHARED_SCENES(scenes);
  int checked = 0;
  for (const auto& entry : std::filesystem::directory_iterator(scenes + "/objects")) {
    if (entry.path().extension() != ".json") continue;
    const nlohmann::json info = ReadJsonFile(entry.path().string());
    const std::string obj = (entry.path().parent_path() / info.at("mesh").get<std::string>()).string();
    SCOPED_TRACE(obj);
    const TriangleMesh mesh = ReadMesh(obj);
    EXPECT_EQ(mesh.TriangleCount(), info.at("n_triangles").get<size_t>());
    // Vertices with the same position and normal are joined; the file's own
    // vertex list is exactly that set, so the counts agree.
    EXPECT_EQ(mesh.VertexCount(), info.at("n_vertices").get<size_t>());
    const Bounds b = ComputeBounds(mesh);
    for (int k = 0; k < 3; ++k) {
      // The OBJ prints 6 decimals; the JSON holds the exact floats: 1e-6 m + rounding.
      EXPECT_NEAR(b.min[k], info.at("bbox_min")[k].get<double>(), 2e-6);
      EXPECT_NEAR(b.max[k], info.at("bbox_max")[k].get<double>(), 2e-6);
    }
    EXPECT_GT(SignedVolume(mesh), 0) << "faces point outwards";
    ExpectNormalsAgreeWithFaces(mesh, 0.0);
    ++checked;
  }
  EXPECT_GE(checked, 2);
}

TEST(ReadMesh, BadFilesAreInputErrorsNamingTheFile) {
  ExpectInputErrorNaming(TestDataPath("mesh/does_not_exist.obj"), "no such mesh file");
  ExpectInputErrorNaming(TestDataPath("mesh/bad_index.obj"));
  ExpectInputErrorNaming(TestDataPath("mesh/nan_vertex.obj"));
  ExpectInputErrorNaming(TestDataPath("mesh/no_triangles.obj"));
  ExpectInputErrorNaming(TestDataPath("mesh/absurd_count.ply"), "4000000000 vertex elements");
  ExpectInputErrorNaming(TestDataPath("mesh/truncated.gltf"));
  TempDir dir;
  testing::WriteText(dir.File("empty.obj"), "");
  ExpectInputErrorNaming(dir.File("empty.obj"), "empty");
  testing::WriteText(dir.File("mesh.stl"), "solid x\nendsolid x\n");
  ExpectInputErrorNaming(dir.File("mesh.stl"), "extension");
  testing::WriteText(dir.File("garbage.ply"), "ply\nthis is not a header\n");
  ExpectInputErrorNaming(dir.File("garbage.ply"));
  std::filesystem::create_directory(dir.File("folder.obj"));
  ExpectInputErrorNaming(dir.File("folder.obj"));
}

// PLY headers outside the grammar are refused by our check, before assimp:
// the fuzzer's input (a header that never ends, with a property line of four
// words) kept assimp 5.2 busy for minutes.
TEST(ReadMesh, PlyHeadersOutsideTheGrammarAndBadFaceIndicesAreRefused) {
  ExpectInputErrorNaming(testing::TestDataPath("../fuzz/regressions/mesh/ply_without_end_header.ply"), "line 7");
  TempDir dir;
  const std::string good = testing::ReadText(TestDataPath("mesh/tetra.ply"));
  const std::string header_end = "end_header\n";
  ASSERT_NE(good.find(header_end), std::string::npos);
  testing::WriteText(dir.File("no_end.ply"), good.substr(0, good.find(header_end)));
  ExpectInputErrorNaming(dir.File("no_end.ply"), "without end_header");
  testing::WriteText(dir.File("type.ply"), "ply\nformat ascii 1.0\nelement vertex 1\nproperty real x\nend_header\n0\n");
  ExpectInputErrorNaming(dir.File("type.ply"), "line 4");
  testing::WriteText(dir.File("orphan.ply"), "ply\nformat ascii 1.0\nproperty float x\nend_header\n");
  ExpectInputErrorNaming(dir.File("orphan.ply"), "after an element");
  testing::WriteText(dir.File("format.ply"), "ply\nformat utf8 1.0\nend_header\n");
  ExpectInputErrorNaming(dir.File("format.ply"), "line 2");
  // A binary PLY whose first face lists no vertex (and others past the four
  // it has): refused before assimp's post-processing, which aborted on it.
  ExpectInputErrorNaming(testing::TestDataPath("../fuzz/regressions/mesh/binary_ply_bad_faces.ply"), "face 0");
  // A valid header with comments passes on to the importer.
  const std::string commented =
      "ply\nformat ascii 1.0\ncomment made by hand\nobj_info x" + good.substr(good.find("\nelement"));
  testing::WriteText(dir.File("commented.ply"), commented);
  EXPECT_EQ(ReadMesh(dir.File("commented.ply")).triangles.size(), 4u);
}

TEST(ValidateMesh, ListsEveryProblem) {
  TriangleMesh mesh = MakeBox({1, 1, 1});
  EXPECT_TRUE(ValidateMesh(mesh, "box").empty());
  mesh.triangles[3][1] = 1000;
  mesh.positions[2].y = std::numeric_limits<float>::quiet_NaN();
  mesh.positions[5].z = std::numeric_limits<float>::infinity();
  mesh.normals.pop_back();
  const Problems problems = ValidateMesh(mesh, "box");
  EXPECT_EQ(problems.items().size(), 4u);
  TriangleMesh empty;
  EXPECT_FALSE(ValidateMesh(empty, "empty").empty());
}

struct ShapeCase {
  const char* name;
  TriangleMesh mesh;
  double volume;     // analytic volume of the smooth shape
  double tolerance;  // relative: the polygon's deficit, see below
};

TEST(Procedural, ClosedOrientedAndOfTheRightVolume) {
  const double r = 0.5, R = 1.0, h = 0.75;
  // Relative volume deficits of inscribed polygons: a circle of n segments
  // loses 1 - sin(2π/n)/(2π/n) ≈ (2π/n)²/6; two such factors for the torus and sphere.
  const ShapeCase cases[] = {
      {"sphere", MakeUvSphere(r, 64, 32), 4.0 / 3.0 * kPi * r * r * r, 0.01},
      {"box", MakeBox({0.5, 1.0, 1.5}), 8 * 0.5 * 1.0 * 1.5, 1e-6},
      {"torus", MakeTorus(R, r, 48, 24), 2 * kPi * kPi * R * r * r, 0.02},
      {"cylinder", MakeCylinder(r, h, 48), kPi * r * r * 2 * h, 0.005},
  };
  for (const ShapeCase& c : cases) {
    SCOPED_TRACE(c.name);
    EXPECT_TRUE(ValidateMesh(c.mesh, c.name).empty());
    const double v = SignedVolume(c.mesh);
    EXPECT_GT(v, 0);
    EXPECT_LE(v, c.volume * (1 + 1e-6)) << "inscribed polygons are smaller than the smooth shape";
    EXPECT_NEAR(v / c.volume, 1.0, c.tolerance);
    std::string why;
    EXPECT_TRUE(IsClosedAndOriented(c.mesh, &why)) << why;
    ExpectNormalsAgreeWithFaces(c.mesh);
    EXPECT_EQ(c.mesh.uvs.size(), c.mesh.positions.size());
  }
}

TEST(Bounds, BoundingSphereHoldsEveryVertexAndIsTightForSymmetricShapes) {
  const TriangleMesh sphere = MakeUvSphere(0.3, 32, 16);
  const BoundingSphere s = ComputeBoundingSphere(sphere);
  EXPECT_NEAR(Length(s.center), 0, 1e-6);  // float positions
  EXPECT_NEAR(s.radius, 0.3, 1e-6);
  const TriangleMesh box = MakeBox({1, 2, 3});
  const BoundingSphere b = ComputeBoundingSphere(box);
  EXPECT_NEAR(b.radius, std::sqrt(14.0), 1e-6);
  // An off-centre cluster: every vertex inside, radius within the Ritter bound
  // (at most ~5% above the minimum for such a set; the minimum here is 1).
  TriangleMesh skew = MakeUvSphere(1.0, 16, 8);
  for (Vec3f& p : skew.positions) p = p + Vec3f(5, -3, 2);
  const BoundingSphere k = ComputeBoundingSphere(skew);
  for (const Vec3f& p : skew.positions) EXPECT_LE(Length(Vec3(p) - k.center), k.radius * (1 + 1e-12));
  EXPECT_LE(k.radius, 1.05);
  EXPECT_TRUE(ComputeBounds(TriangleMesh{}).Empty());
}

TEST(Transform, PoseAndScaleMoveBoundsAndRotateNormals) {
  const TriangleMesh box = MakeBox({1, 2, 3});
  Pose T;
  T.rotation = RotationFromAxisAngle({0, 0, 1}, kPi / 2);  // x -> y, y -> -x
  T.translation = {10, 20, 30};
  const TriangleMesh moved = TransformMesh(box, T, 2.0);
  const Bounds b = ComputeBounds(moved);
  // Scaled half extents (2, 4, 6), rotated: x extent 4, y extent 2. float: 1e-5.
  EXPECT_NEAR(b.min.x, 10 - 4, 1e-5);
  EXPECT_NEAR(b.max.x, 10 + 4, 1e-5);
  EXPECT_NEAR(b.min.y, 20 - 2, 1e-5);
  EXPECT_NEAR(b.max.y, 20 + 2, 1e-5);
  EXPECT_NEAR(b.min.z, 30 - 6, 1e-5);
  EXPECT_NEAR(b.max.z, 30 + 6, 1e-5);
  EXPECT_NEAR(SignedVolume(moved), 8 * SignedVolume(box), 1e-3);
  ExpectNormalsAgreeWithFaces(moved);
}

TEST(WriteMeshObj, RoundTrip) {
  TempDir dir;
  const TriangleMesh torus = MakeTorus(1.0, 0.25, 12, 8);
  WriteMeshObj(dir.File("torus.obj"), torus);
  const TriangleMesh back = ReadMesh(dir.File("torus.obj"));
  EXPECT_EQ(back.TriangleCount(), torus.TriangleCount());
  // 9 significant digits: float positions survive to ~1e-7.
  EXPECT_NEAR(SignedVolume(back), SignedVolume(torus), 1e-6);
  const Bounds a = ComputeBounds(torus), b = ComputeBounds(back);
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(a.min[k], b.min[k], 1e-7);
    EXPECT_NEAR(a.max[k], b.max[k], 1e-7);
  }
  ExpectNormalsAgreeWithFaces(back);
}

}  // namespace
}  // namespace nerfar
