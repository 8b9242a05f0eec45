#include "render/mesh/mesh.h"

#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <assimp/texture.h>

#include <algorithm>
#include <assimp/Importer.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>
#include <vector>

#include "calib/core/atomic_file.h"
#include "calib/core/image_io.h"

namespace nerfar {

namespace {

// Largest mesh file we open at all (assimp reads it whole).
constexpr uintmax_t kMaxMeshFileBytes = uintmax_t{2} << 30;

}  // namespace

Bounds ComputeBounds(const TriangleMesh& mesh) {
  Bounds bounds;
  for (size_t i = 0; i < mesh.positions.size(); ++i) {
    const Vec3 p(mesh.positions[i]);
    if (i == 0) {
      bounds.min = bounds.max = p;
      continue;
    }
    for (int k = 0; k < 3; ++k) {
      bounds.min[k] = std::min(bounds.min[k], p[k]);
      bounds.max[k] = std::max(bounds.max[k], p[k]);
    }
  }
  return bounds;
}

BoundingSphere ComputeBoundingSphere(const TriangleMesh& mesh) {
  if (mesh.positions.empty()) return {};
  const auto radius_about = [&mesh](const Vec3& c) {
    double r2 = 0;
    for (const Vec3f& pf : mesh.positions) {
      const Vec3 d = Vec3(pf) - c;
      r2 = std::max(r2, Dot(d, d));
    }
    return std::sqrt(r2);
  };
  const Vec3 box_center = ComputeBounds(mesh).Center();
  BoundingSphere box{box_center, radius_about(box_center)};

  // Ritter: start from the farthest pair along a sweep, grow to hold every point.
  const Vec3 p0(mesh.positions[0]);
  Vec3 a = p0, b = p0;
  double best = -1;
  for (const Vec3f& pf : mesh.positions) {
    const double d = Length(Vec3(pf) - p0);
    if (d > best) best = d, a = Vec3(pf);
  }
  best = -1;
  for (const Vec3f& pf : mesh.positions) {
    const double d = Length(Vec3(pf) - a);
    if (d > best) best = d, b = Vec3(pf);
  }
  Vec3 c = (a + b) * 0.5;
  double r = 0.5 * Length(b - a);
  for (const Vec3f& pf : mesh.positions) {
    const Vec3 p(pf);
    const double d = Length(p - c);
    if (d > r) {
      const double new_r = 0.5 * (r + d);
      c = c + (p - c) * ((new_r - r) / d);
      r = new_r;
    }
  }
  BoundingSphere ritter{c, radius_about(c)};  // re-measure: no rounding can leave a point outside
  return ritter.radius < box.radius ? ritter : box;
}

Problems ValidateMesh(const TriangleMesh& mesh, const std::string& source) {
  Problems problems(source);
  if (mesh.triangles.empty()) problems.Add("", "mesh has no triangles (expected at least one)");
  if (mesh.positions.size() > kMaxMeshVertices)
    problems.Add("", std::to_string(mesh.positions.size()) + " vertices (expected at most " +
                         std::to_string(kMaxMeshVertices) + ")");
  if (mesh.triangles.size() > kMaxMeshTriangles)
    problems.Add("", std::to_string(mesh.triangles.size()) + " triangles (expected at most " +
                         std::to_string(kMaxMeshTriangles) + ")");
  if (!mesh.normals.empty() && mesh.normals.size() != mesh.positions.size())
    problems.Add("", std::to_string(mesh.normals.size()) + " normals for " + std::to_string(mesh.positions.size()) +
                         " vertices (expected one per vertex)");
  if (!mesh.uvs.empty() && mesh.uvs.size() != mesh.positions.size())
    problems.Add("", std::to_string(mesh.uvs.size()) + " texture coordinates for " +
                         std::to_string(mesh.positions.size()) + " vertices (expected one per vertex)");
  size_t reported = 0;
  const auto add_limited = [&](const std::string& where, const std::string& what) {
    if (reported++ < 5) problems.Add(where, what);
  };
  for (size_t i = 0; i < mesh.positions.size(); ++i)
    if (!Finite(mesh.positions[i]))
      add_limited("vertex " + std::to_string(i), "position is NaN or infinite (expected finite)");
  for (size_t i = 0; i < mesh.normals.size(); ++i)
    if (!Finite(mesh.normals[i]))
      add_limited("vertex " + std::to_string(i), "normal is NaN or infinite (expected finite)");
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    for (uint32_t index : mesh.triangles[t])
      if (index >= mesh.positions.size())
        add_limited("triangle " + std::to_string(t), "vertex index " + std::to_string(index) +
                                                         " out of range (expected < " +
                                                         std::to_string(mesh.positions.size()) + ")");
  if (reported > 5) problems.Add("", std::to_string(reported - 5) + " more bad vertices or triangles not listed");
  return problems;
}

TriangleMesh TransformMesh(const TriangleMesh& mesh, const Pose& T_world_object, double scale) {
  TriangleMesh out = mesh;
  for (Vec3f& p : out.positions) p = Vec3f(T_world_object * (Vec3(p) * scale));
  for (Vec3f& n : out.normals) n = Vec3f(Normalized(T_world_object.Rotate(Vec3(n))));
  return out;
}

void ComputeVertexNormals(TriangleMesh& mesh) {
  std::vector<Vec3> sum(mesh.positions.size());
  for (const auto& t : mesh.triangles) {
    const Vec3 a(mesh.positions[t[0]]), b(mesh.positions[t[1]]), c(mesh.positions[t[2]]);
    const Vec3 n = Cross(b - a, c - a);  // length = twice the area: area weighting
    for (uint32_t i : t) sum[i] += n;
  }
  mesh.normals.resize(mesh.positions.size());
  for (size_t i = 0; i < sum.size(); ++i) {
    const Vec3 n = Normalized(sum[i]);
    mesh.normals[i] = Length(n) > 0 ? Vec3f(n) : Vec3f(0, 0, 1);  // isolated vertex: any unit vector
  }
}

namespace {

// A texture reference of an assimp material, resolved against the mesh folder.
std::string TextureReference(const aiMaterial& material, aiTextureType type, const std::string& mesh_path) {
  aiString name;
  if (material.GetTextureCount(type) == 0 || material.GetTexture(type, 0, &name) != AI_SUCCESS) return "";
  const std::string reference = name.C_Str();
  if (reference.empty()) return "";
  if (reference[0] == '*') return mesh_path + "#" + reference.substr(1);  // embedded (glb)
  const std::filesystem::path p(reference);
  if (p.is_absolute()) return reference;
  return (std::filesystem::path(mesh_path).parent_path() / p).lexically_normal().string();
}

std::optional<Material> ConvertMaterial(const aiMaterial& in, const std::string& path) {
  aiString name;
  in.Get(AI_MATKEY_NAME, name);
  if (std::string(name.C_Str()) == AI_DEFAULT_MATERIAL_NAME) return std::nullopt;  // the file had none
  Material m;
  aiColor4D colour;
  if (in.Get(AI_MATKEY_BASE_COLOR, colour) == AI_SUCCESS || in.Get(AI_MATKEY_COLOR_DIFFUSE, colour) == AI_SUCCESS)
    m.albedo = {colour.r, colour.g, colour.b};
  float value = 0;
  if (in.Get(AI_MATKEY_ROUGHNESS_FACTOR, value) == AI_SUCCESS) m.roughness = value;
  if (in.Get(AI_MATKEY_METALLIC_FACTOR, value) == AI_SUCCESS) m.metallic = value;
  m.mesh = path;
  m.albedo_texture = TextureReference(in, aiTextureType_BASE_COLOR, path);
  if (m.albedo_texture.empty()) m.albedo_texture = TextureReference(in, aiTextureType_DIFFUSE, path);
  // glTF packs roughness (G) and metallic (B) into one image, which assimp
  // files as AI_MATKEY_GLTF_PBRMETALLICROUGHNESS_METALLICROUGHNESS_TEXTURE (UNKNOWN, 0).
  const std::string packed = TextureReference(in, aiTextureType_UNKNOWN, path);
  m.roughness_texture = TextureReference(in, aiTextureType_DIFFUSE_ROUGHNESS, path);
  m.metallic_texture = TextureReference(in, aiTextureType_METALNESS, path);
  if (m.roughness_texture.empty()) m.roughness_texture = packed;
  if (m.metallic_texture.empty()) m.metallic_texture = packed;
  return m;
}

bool PlyType(const std::string& type) {
  static const char* const kTypes[] = {"char", "uchar", "short", "ushort", "int",   "uint",   "float",   "double",
                                       "int8", "uint8", "int16", "uint16", "int32", "uint32", "float32", "float64"};
  return std::find(std::begin(kTypes), std::end(kTypes), type) != std::end(kTypes);
}

// One line of a PLY header checked against the header's grammar (an importer
// that meets anything else may misread or never finish: a fuzzed header sent
// assimp into an endless loop). Returns false for end_header.
bool CheckPlyHeaderLine(const std::string& path, int number, const std::string& line, bool& ascii, bool& in_element,
                        uintmax_t file_bytes) {
  std::istringstream words(line);
  std::string keyword;
  words >> keyword;
  std::vector<std::string> rest;
  for (std::string word; words >> word;) rest.push_back(word);
  const auto bad = [&](const std::string& expected) {
    ThrowInputError(
        path, "line " + std::to_string(number + 1) + " of the PLY header, '" + line + "' (expected " + expected + ")");
  };
  if (number == 0) {
    if (line != "ply") bad("'ply'");
  } else if (keyword == "format") {
    const bool known =
        rest.size() == 2 && (rest[0] == "ascii" || rest[0] == "binary_little_endian" || rest[0] == "binary_big_endian");
    if (!known || number != 1) bad("'format ascii|binary_little_endian|binary_big_endian 1.0' as the second line");
    ascii = rest[0] == "ascii";
  } else if (keyword == "comment" || keyword == "obj_info") {
  } else if (keyword == "element") {
    long double count = -1;
    if (rest.size() != 2 || !(std::istringstream(rest[1]) >> count) || count < 0) bad("'element NAME COUNT'");
    const size_t limit = rest[0] == "face" ? kMaxMeshTriangles : kMaxMeshVertices;
    // Each element takes at least 1 byte in binary and 2 ('0\n') in ASCII:
    // absurd counts are refused before the importer allocates for them.
    if (count > static_cast<long double>(limit) || count * (ascii ? 2 : 1) > static_cast<long double>(file_bytes))
      ThrowInputError(path, "PLY header announces " + std::to_string(static_cast<unsigned long long>(count)) + " " +
                                rest[0] + " elements in a " + std::to_string(file_bytes) +
                                "-byte file (expected at most " + std::to_string(limit) +
                                " and a file large enough to hold them)");
    in_element = true;
  } else if (keyword == "property") {
    const bool scalar = rest.size() == 2 && PlyType(rest[0]);
    const bool list = rest.size() == 4 && rest[0] == "list" && PlyType(rest[1]) && PlyType(rest[2]);
    if (!in_element || !(scalar || list))
      bad("'property TYPE NAME' or 'property list TYPE TYPE NAME' after an element");
  } else if (keyword == "end_header" && rest.empty()) {
    return false;
  } else {
    bad("format, comment, element, property or end_header");
  }
  return true;
}

// A binary glTF (GLB: "glTF", version, total length, then chunks of length,
// type and data): the lengths it states must fit the file. assimp allocates
// a chunk by its stated length before reading it, so a corrupt length in a
// small file asked for gigabytes.
void CheckGlbHeader(const std::string& path, uintmax_t file_bytes) {
  std::ifstream file(path, std::ios::binary);
  const auto read_u32 = [&file](uint32_t& value) {
    unsigned char b[4];
    if (!file.read(reinterpret_cast<char*>(b), 4)) return false;
    value = uint32_t(b[0]) | uint32_t(b[1]) << 8 | uint32_t(b[2]) << 16 | uint32_t(b[3]) << 24;
    return true;
  };
  uint32_t magic = 0, version = 0, total = 0;
  if (!read_u32(magic) || magic != 0x46546c67u) return;  // not a GLB ("glTF" little-endian)
  if (!read_u32(version) || !read_u32(total)) ThrowInputError(path, "GLB header is truncated (the file is corrupt)");
  if (total != file_bytes)
    ThrowInputError(path, "GLB header states " + std::to_string(total) + " bytes, the file has " +
                              std::to_string(file_bytes) + " (the file is corrupt)");
  uintmax_t at = 12;
  while (at < file_bytes) {
    uint32_t length = 0, type = 0;
    if (!read_u32(length) || !read_u32(type))
      ThrowInputError(path, "GLB chunk header at byte " + std::to_string(at) + " is truncated (the file is corrupt)");
    if (length > file_bytes - at - 8)
      ThrowInputError(path, "GLB chunk at byte " + std::to_string(at) + " states " + std::to_string(length) +
                                " bytes, past the end of the file (the file is corrupt)");
    at += 8 + uintmax_t(length);
    file.seekg(std::streamoff(at));
  }
}

// The header of a PLY file, line by line, up to end_header.
void CheckPlyHeader(const std::string& path, uintmax_t file_bytes) {
  std::ifstream in(path, std::ios::binary);
  std::string line;
  bool ascii = false, in_element = false;
  constexpr int kMaxHeaderLines = 1000;
  for (int number = 0; number < kMaxHeaderLines && std::getline(in, line); ++number) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (!CheckPlyHeaderLine(path, number, line, ascii, in_element, file_bytes)) return;
  }
  ThrowInputError(path, "PLY header without end_header in its first " + std::to_string(kMaxHeaderLines) +
                            " lines (expected a header ending with the line 'end_header')");
}

// What assimp's importers made, checked before its post-processing steps run
// on it: they take the scene as valid, and abort the process on face indices
// past the vertices or nodes naming meshes that are not there (a fuzzed
// binary PLY did).
void CheckImportedScene(const aiScene& scene, const std::string& path) {
  const auto bad = [&](const std::string& what) {
    ThrowInputError(path, "cannot read the mesh: " + what + " (expected a valid OBJ, PLY or glTF 2.0 file)");
  };
  for (unsigned m = 0; m < scene.mNumMeshes; ++m) {
    const aiMesh* mesh = scene.mMeshes[m];
    if (mesh == nullptr || (mesh->mNumVertices > 0 && mesh->mVertices == nullptr)) bad("a mesh without vertices");
    if (mesh->mNumFaces > 0 && mesh->mFaces == nullptr) bad("a mesh without its faces");
    if (scene.mNumMaterials > 0 && mesh->mMaterialIndex >= scene.mNumMaterials) bad("a material index out of range");
    for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
      const aiFace& face = mesh->mFaces[f];
      if (face.mNumIndices == 0 || face.mIndices == nullptr) bad("face " + std::to_string(f) + " has no vertices");
      for (unsigned k = 0; k < face.mNumIndices; ++k)
        if (face.mIndices[k] >= mesh->mNumVertices)
          bad("face " + std::to_string(f) + " names vertex " + std::to_string(face.mIndices[k]) + " of " +
              std::to_string(mesh->mNumVertices));
    }
  }
  // The node tree (PreTransformVertices walks it), without recursion: depth is the file's to choose.
  std::vector<const aiNode*> nodes = {scene.mRootNode};
  for (size_t visited = 0; !nodes.empty(); ++visited) {
    const aiNode* node = nodes.back();
    nodes.pop_back();
    if (node == nullptr || visited > kMaxMeshTriangles) bad("a broken node tree");
    for (unsigned i = 0; i < node->mNumMeshes; ++i)
      if (node->mMeshes[i] >= scene.mNumMeshes) bad("a node names mesh " + std::to_string(node->mMeshes[i]));
    for (unsigned i = 0; i < node->mNumChildren; ++i) nodes.push_back(node->mChildren[i]);
  }
}

// The file through assimp: imported as it is, checked, then post-processed
// into triangles with shared vertices and the node transforms applied.
const aiScene* ImportScene(Assimp::Importer& importer, const std::string& path) {
  const auto failed = [&] {
    std::string why = importer.GetErrorString();
    if (why.empty()) why = "unknown reason";
    ThrowInputError(path, "cannot read the mesh: " + why + " (expected a valid OBJ, PLY or glTF 2.0 file)");
  };
  const aiScene* imported = importer.ReadFile(path, 0);
  if (imported == nullptr) failed();
  CheckImportedScene(*imported, path);
  // Drop lines and points so that Triangulate leaves triangles only.
  importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE, aiPrimitiveType_LINE | aiPrimitiveType_POINT);
  const aiScene* scene = importer.ApplyPostProcessing(aiProcess_ValidateDataStructure | aiProcess_Triangulate |
                                                      aiProcess_JoinIdenticalVertices | aiProcess_PreTransformVertices |
                                                      aiProcess_SortByPType);
  if (scene == nullptr) failed();
  return scene;
}

}  // namespace

TriangleMesh ReadMesh(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    ThrowInputError(path, "no such mesh file (expected OBJ, PLY, glTF or GLB)");
  const uintmax_t bytes = std::filesystem::file_size(path, ec);
  if (ec) ThrowInputError(path, "cannot read the file size (" + ec.message() + ")");
  if (bytes == 0) ThrowInputError(path, "file is empty (expected a mesh)");
  if (bytes > kMaxMeshFileBytes)
    ThrowInputError(path, "file is " + std::to_string(bytes) + " bytes (expected at most 2 GiB)");
  std::string extension = std::filesystem::path(path).extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  if (extension != ".obj" && extension != ".ply" && extension != ".gltf" && extension != ".glb")
    ThrowInputError(path, "unknown mesh extension '" + extension + "' (expected .obj, .ply, .gltf or .glb)");

  if (extension == ".ply") CheckPlyHeader(path, bytes);
  CheckGlbHeader(path, bytes);  // by content: assimp reads a GLB whatever its extension

  Assimp::Importer importer;
  const aiScene* scene = ImportScene(importer, path);
  if (scene->mNumMeshes == 0) ThrowInputError(path, "the file holds no mesh (expected at least one triangle)");

  size_t total_vertices = 0, total_faces = 0;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    total_vertices += scene->mMeshes[m]->mNumVertices;
    total_faces += scene->mMeshes[m]->mNumFaces;
  }
  if (total_vertices > kMaxMeshVertices || total_faces > kMaxMeshTriangles)
    ThrowInputError(path, std::to_string(total_vertices) + " vertices and " + std::to_string(total_faces) +
                              " faces (expected at most " + std::to_string(kMaxMeshVertices) + " and " +
                              std::to_string(kMaxMeshTriangles) + ")");

  TriangleMesh mesh;
  mesh.source = path;
  mesh.positions.reserve(total_vertices);
  mesh.triangles.reserve(total_faces);
  bool all_normals = true, all_uvs = true;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh& part = *scene->mMeshes[m];
    if (!(part.mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) continue;
    all_normals = all_normals && part.HasNormals();
    all_uvs = all_uvs && part.HasTextureCoords(0);
  }
  unsigned largest = 0, largest_faces = 0;
  Problems problems(path);
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh& part = *scene->mMeshes[m];
    if (!(part.mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) continue;
    const auto base = static_cast<uint32_t>(mesh.positions.size());
    for (unsigned v = 0; v < part.mNumVertices; ++v) {
      const aiVector3D& p = part.mVertices[v];
      mesh.positions.emplace_back(p.x, p.y, p.z);
      if (all_normals) mesh.normals.emplace_back(part.mNormals[v].x, part.mNormals[v].y, part.mNormals[v].z);
      if (all_uvs) mesh.uvs.push_back({part.mTextureCoords[0][v].x, part.mTextureCoords[0][v].y});
    }
    unsigned faces = 0;
    for (unsigned f = 0; f < part.mNumFaces; ++f) {
      const aiFace& face = part.mFaces[f];
      if (face.mNumIndices != 3) continue;  // points and lines of a mixed part
      mesh.triangles.push_back({base + face.mIndices[0], base + face.mIndices[1], base + face.mIndices[2]});
      ++faces;
    }
    if (faces > largest_faces) largest_faces = faces, largest = m;
  }
  if (!mesh.triangles.empty() && scene->mMeshes[largest]->mMaterialIndex < scene->mNumMaterials)
    mesh.material = ConvertMaterial(*scene->mMaterials[scene->mMeshes[largest]->mMaterialIndex], path);

  // Normals: recompute where missing or degenerate (zero-area corners give NaN).
  bool normals_ok = !mesh.normals.empty();
  for (const Vec3f& n : mesh.normals) normals_ok = normals_ok && Finite(n) && Length(n) > 0.5f;
  Problems checked = ValidateMesh(mesh, path);
  checked.ThrowIfAny();
  if (!normals_ok) ComputeVertexNormals(mesh);
  for (Vec3f& n : mesh.normals) n = Normalized(n);
  return mesh;
}

Image8 ReadMeshTexture(const std::string& reference) {
  const size_t hash = reference.rfind('#');
  if (hash == std::string::npos) return ReadImage8(reference);
  const std::string mesh_path = reference.substr(0, hash), index_text = reference.substr(hash + 1);
  if (index_text.empty() || index_text.find_first_not_of("0123456789") != std::string::npos)
    return ReadImage8(reference);  // a file name with a '#' in it
  std::error_code ec;
  if (!std::filesystem::is_regular_file(mesh_path, ec))
    ThrowInputError(reference, "no such mesh file (expected the GLB the texture is embedded in)");
  CheckGlbHeader(mesh_path, std::filesystem::file_size(mesh_path, ec));
  Assimp::Importer importer;
  const aiScene* scene = importer.ReadFile(mesh_path, 0);
  if (scene == nullptr) ThrowInputError(mesh_path, std::string("cannot read the mesh: ") + importer.GetErrorString());
  const unsigned long index = std::stoul(index_text);
  if (index >= scene->mNumTextures)
    ThrowInputError(reference, "no embedded texture " + index_text + " (the file holds " +
                                   std::to_string(scene->mNumTextures) + ")");
  const aiTexture& texture = *scene->mTextures[index];
  // glTF embeds images as the bytes of their PNG or JPEG files (assimp: mHeight 0, mWidth bytes).
  if (texture.mHeight != 0)
    ThrowInputError(reference, "an embedded texture of raw texels (expected PNG or JPEG bytes)");
  return DecodeImage8(std::string_view(reinterpret_cast<const char*>(texture.pcData), texture.mWidth), reference);
}

void WriteMeshObj(const std::string& path, const TriangleMesh& mesh) {
  ValidateMesh(mesh, path).ThrowIfAny();
  std::ostringstream out;
  out.imbue(std::locale::classic());
  out.precision(9);
  out << "# nerfar mesh: " << mesh.positions.size() << " vertices, " << mesh.triangles.size() << " triangles\n";
  for (const Vec3f& p : mesh.positions) out << "v " << p.x << ' ' << p.y << ' ' << p.z << '\n';
  for (const Vec3f& n : mesh.normals) out << "vn " << n.x << ' ' << n.y << ' ' << n.z << '\n';
  for (const auto& uv : mesh.uvs) out << "vt " << uv[0] << ' ' << uv[1] << '\n';
  const bool n = !mesh.normals.empty(), t = !mesh.uvs.empty();
  for (const auto& tri : mesh.triangles) {
    out << 'f';
    for (uint32_t i : tri) {
      const uint32_t k = i + 1;
      out << ' ' << k;
      if (t) out << '/' << k;
      if (n) out << (t ? "/" : "//") << k;
    }
    out << '\n';
  }
  WriteFileAtomic(path, out.str());
}

// ------------------------------------------------------------ procedural shapes

TriangleMesh MakeUvSphere(double radius, int segments, int rings) {
  NERFAR_CHECK(radius > 0);
  NERFAR_CHECK_GE(segments, 3);
  NERFAR_CHECK_GE(rings, 2);
  TriangleMesh mesh;
  // (segments + 1) columns so that the seam has its own UVs; poles repeated per column.
  for (int j = 0; j <= rings; ++j) {
    // Poles and the seam column get bit-identical positions (a watertight surface).
    const double theta = kPi * j / rings;
    const double sin_theta = (j == 0 || j == rings) ? 0.0 : std::sin(theta);
    const double cos_theta = j == 0 ? 1.0 : (j == rings ? -1.0 : std::cos(theta));
    for (int i = 0; i <= segments; ++i) {
      const double phi = 2 * kPi * (i % segments) / segments;
      const Vec3 n(sin_theta * std::cos(phi), sin_theta * std::sin(phi), cos_theta);
      mesh.positions.push_back(Vec3f(n * radius));
      mesh.normals.push_back(Vec3f(n));
      mesh.uvs.push_back({static_cast<float>(i) / segments, 1.0f - static_cast<float>(j) / rings});
    }
  }
  const auto index = [segments](int i, int j) { return static_cast<uint32_t>(j * (segments + 1) + i); };
  for (int j = 0; j < rings; ++j) {
    for (int i = 0; i < segments; ++i) {
      const uint32_t a = index(i, j), b = index(i + 1, j), c = index(i + 1, j + 1), d = index(i, j + 1);
      // Outward (counter-clockwise seen from outside): theta grows downwards, phi eastwards.
      if (j != 0) mesh.triangles.push_back({a, d, b});
      if (j != rings - 1) mesh.triangles.push_back({b, d, c});
    }
  }
  return mesh;
}

TriangleMesh MakeBox(const Vec3& h) {
  NERFAR_CHECK(h.x > 0 && h.y > 0 && h.z > 0);
  TriangleMesh mesh;
  for (int axis = 0; axis < 3; ++axis) {
    for (int sign = -1; sign <= 1; sign += 2) {
      Vec3 n;
      n[axis] = sign;
      // u, v span the face with u x v = n.
      Vec3 u, v;
      u[(axis + 1) % 3] = 1;
      v[(axis + 2) % 3] = 1;
      if (sign < 0) std::swap(u, v);
      const auto base = static_cast<uint32_t>(mesh.positions.size());
      const double corners[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
      for (const auto& c : corners) {
        const Vec3 p = n + u * c[0] + v * c[1];
        mesh.positions.push_back(Vec3f(p * h));
        mesh.normals.push_back(Vec3f(n));
        mesh.uvs.push_back({static_cast<float>(0.5 * (c[0] + 1)), static_cast<float>(0.5 * (c[1] + 1))});
      }
      mesh.triangles.push_back({base, base + 1, base + 2});
      mesh.triangles.push_back({base, base + 2, base + 3});
    }
  }
  return mesh;
}

TriangleMesh MakeTorus(double major, double minor, int major_segments, int minor_segments) {
  NERFAR_CHECK(minor > 0 && major > minor);
  NERFAR_CHECK_GE(major_segments, 3);
  NERFAR_CHECK_GE(minor_segments, 3);
  TriangleMesh mesh;
  for (int i = 0; i <= major_segments; ++i) {
    const double u = 2 * kPi * (i % major_segments) / major_segments;  // seams bit-identical
    const Vec3 radial(std::cos(u), std::sin(u), 0);
    for (int j = 0; j <= minor_segments; ++j) {
      const double v = 2 * kPi * (j % minor_segments) / minor_segments;
      const Vec3 n = radial * std::cos(v) + Vec3(0, 0, std::sin(v));
      mesh.positions.push_back(Vec3f(radial * major + n * minor));
      mesh.normals.push_back(Vec3f(n));
      mesh.uvs.push_back({static_cast<float>(i) / major_segments, static_cast<float>(j) / minor_segments});
    }
  }
  const auto index = [minor_segments](int i, int j) { return static_cast<uint32_t>(i * (minor_segments + 1) + j); };
  for (int i = 0; i < major_segments; ++i) {
    for (int j = 0; j < minor_segments; ++j) {
      const uint32_t a = index(i, j), b = index(i + 1, j), c = index(i + 1, j + 1), d = index(i, j + 1);
      mesh.triangles.push_back({a, b, c});
      mesh.triangles.push_back({a, c, d});
    }
  }
  return mesh;
}

TriangleMesh MakeCylinder(double radius, double half_height, int segments) {
  NERFAR_CHECK(radius > 0 && half_height > 0);
  NERFAR_CHECK_GE(segments, 3);
  TriangleMesh mesh;
  const auto add = [&mesh](const Vec3& p, const Vec3& n, float u, float v) {
    mesh.positions.push_back(Vec3f(p));
    mesh.normals.push_back(Vec3f(n));
    mesh.uvs.push_back({u, v});
    return static_cast<uint32_t>(mesh.positions.size() - 1);
  };
  // Side: two rings with radial normals.
  std::vector<uint32_t> bottom, top;
  for (int i = 0; i <= segments; ++i) {
    const double phi = 2 * kPi * (i % segments) / segments;  // seam bit-identical
    const Vec3 n(std::cos(phi), std::sin(phi), 0);
    const float u = static_cast<float>(i) / segments;
    bottom.push_back(add(n * radius + Vec3(0, 0, -half_height), n, u, 0));
    top.push_back(add(n * radius + Vec3(0, 0, half_height), n, u, 1));
  }
  for (int i = 0; i < segments; ++i) {
    mesh.triangles.push_back({bottom[i], bottom[i + 1], top[i + 1]});
    mesh.triangles.push_back({bottom[i], top[i + 1], top[i]});
  }
  // Caps: a centre vertex and a fan, flat normals.
  for (int sign = -1; sign <= 1; sign += 2) {
    const Vec3 n(0, 0, sign);
    const uint32_t centre = add(Vec3(0, 0, sign * half_height), n, 0.5f, 0.5f);
    std::vector<uint32_t> rim;
    for (int i = 0; i < segments; ++i) {
      const double phi = 2 * kPi * i / segments;
      rim.push_back(add(Vec3(radius * std::cos(phi), radius * std::sin(phi), sign * half_height), n,
                        static_cast<float>(0.5 + 0.5 * std::cos(phi)), static_cast<float>(0.5 + 0.5 * std::sin(phi))));
    }
    for (int i = 0; i < segments; ++i) {
      const uint32_t a = rim[i], b = rim[(i + 1) % segments];
      if (sign > 0)
        mesh.triangles.push_back({centre, a, b});
      else
        mesh.triangles.push_back({centre, b, a});
    }
  }
  return mesh;
}

}  // namespace nerfar
