// `nerfar insert` with what users bring: an object as a mesh or an object
// JSON (its field baked in memory), a GLB whose base colour is an embedded
// texture (the rendered object shows the texture's colours where its UVs
// put them), on a tiny scene: an opaque slab NeRF whose top is the plane
// z = 0, a grey light from above, a 64 × 48 dataset looking down at it.
// Camera paths: the orbit's geometry, the camera_path.json reader (its
// cameras, and each kind of bad input named), and a short orbit to PNG
// frames and an MP4 (ffmpeg; skipped, saying so, where it is absent).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "app/camera_path.h"
#include "app/live/scene.h"
#include "app/video.h"
#include "calib/camera.h"
#include "calib/core/atomic_file.h"
#include "calib/core/exr.h"
#include "calib/core/image_io.h"
#include "calib/core/json.h"
#include "calib/dataset.h"
#include "render/mesh/mesh.h"
#include "tests/support/nerfar_command.h"
#include "tests/support/slab_scene.h"
#include "tests/support/support.h"

namespace nerfar {
namespace {

namespace fs = std::filesystem;
using Result = testing::CommandResult;
using testing::RunNerfar;

constexpr int kWidth = 64, kHeight = 48;
constexpr double kHalfSide = 0.05;  // the textured quad's half side, metres

// The camera of the one test view: above the slab, looking down at the origin.
Pose ViewPose() { return LookAt({0.0, -0.12, 0.35}, {0, 0, 0}); }

CameraIntrinsics ViewCamera() {
  CameraIntrinsics camera;
  camera.width = kWidth;
  camera.height = kHeight;
  camera.fx = camera.fy = 70;
  camera.cx = kWidth / 2.0;
  camera.cy = kHeight / 2.0;
  return camera;
}

// DIR/transforms_test.json with one grey EXR frame, the slab NeRF, a light
// from above (grey: the object's colour is its albedo's) and an identity pose.
void WriteScene(const testing::TempDir& dir) {
  Dataset dataset;
  dataset.dir = dir.File("ds");
  dataset.camera = ViewCamera();
  dataset.aabb = Aabb{{-0.3, -0.3, -0.05}, {0.3, 0.3, 0.2}};
  MakeDirectories(dir.File("ds/test"));
  DatasetFrame frame;
  frame.file_path = "test/r_000.exr";
  frame.image_path = dir.File("ds/") + frame.file_path;
  frame.T_world_camera = ViewPose();
  WriteExrRgb(frame.image_path, ImageF(kWidth, kHeight, 3, 0.3f));
  dataset.frames.push_back(frame);
  WriteDataset(dir.File("ds/transforms_test.json"), dataset);
  testing::WriteSlabNerf(dir.File("slab.nerf"), Aabb{{-0.3, -0.3, -0.04}, {0.3, 0.3, 0.0}});
  testing::WriteOverheadEnv(dir.File("env.json"));
  testing::WriteText(dir.File("pose.json"), R"({"object_to_world": [[1,0,0,0],[0,1,0,0],[0,0,1,0.01],[0,0,0,1]]})");
}

void Append(std::string& bytes, const void* data, size_t size) {
  bytes.append(static_cast<const char*>(data), size);
  while (bytes.size() % 4 != 0) bytes.push_back('\0');
}

void AppendU32(std::string& out, uint32_t value) { out.append(reinterpret_cast<const char*>(&value), 4); }

// A GLB (glTF 2.0 binary) of one quad in the plane z = 0, facing +z, its
// base colour the embedded PNG `png`: glTF's UV (0, 0) is the image's top
// left, so the image's top rows land on the quad's +y side.
void WriteTexturedQuadGlb(const std::string& path, const std::string& png) {
  const float a = static_cast<float>(kHalfSide);
  const float positions[12] = {-a, -a, 0, a, -a, 0, a, a, 0, -a, a, 0};
  const float normals[12] = {0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1};
  const float uvs[8] = {0, 1, 1, 1, 1, 0, 0, 0};  // y = −a at the image's bottom (v = 1), +a at its top
  const uint16_t indices[6] = {0, 1, 2, 0, 2, 3};
  std::string bin;
  size_t offsets[6];
  offsets[0] = bin.size(), Append(bin, positions, sizeof positions);
  offsets[1] = bin.size(), Append(bin, normals, sizeof normals);
  offsets[2] = bin.size(), Append(bin, uvs, sizeof uvs);
  offsets[3] = bin.size(), Append(bin, indices, sizeof indices);
  offsets[4] = bin.size(), Append(bin, png.data(), png.size());
  offsets[5] = bin.size();
  const size_t lengths[5] = {sizeof positions, sizeof normals, sizeof uvs, sizeof indices, png.size()};
  nlohmann::json views = nlohmann::json::array();
  for (int v = 0; v < 5; ++v) views.push_back({{"buffer", 0}, {"byteOffset", offsets[v]}, {"byteLength", lengths[v]}});
  const nlohmann::json gltf = {
      {"asset", {{"version", "2.0"}}},
      {"scene", 0},
      {"scenes", {{{"nodes", {0}}}}},
      {"nodes", {{{"mesh", 0}}}},
      {"meshes",
       {{{"primitives",
          {{{"attributes", {{"POSITION", 0}, {"NORMAL", 1}, {"TEXCOORD_0", 2}}}, {"indices", 3}, {"material", 0}}}}}}},
      {"materials",
       {{{"name", "textured"},
         {"pbrMetallicRoughness",
          {{"baseColorTexture", {{"index", 0}}},
           {"baseColorFactor", {1, 1, 1, 1}},
           {"metallicFactor", 0},
           {"roughnessFactor", 1}}}}}},
      {"textures", {{{"source", 0}}}},
      {"images", {{{"bufferView", 4}, {"mimeType", "image/png"}}}},
      {"accessors",
       {{{"bufferView", 0},
         {"componentType", 5126},
         {"count", 4},
         {"type", "VEC3"},
         {"min", {-a, -a, 0}},
         {"max", {a, a, 0}}},
        {{"bufferView", 1}, {"componentType", 5126}, {"count", 4}, {"type", "VEC3"}},
        {{"bufferView", 2}, {"componentType", 5126}, {"count", 4}, {"type", "VEC2"}},
        {{"bufferView", 3}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}}}},
      {"bufferViews", views},
      {"buffers", {{{"byteLength", bin.size()}}}}};
  std::string json = gltf.dump();
  while (json.size() % 4 != 0) json.push_back(' ');
  std::string glb = "glTF";
  AppendU32(glb, 2);
  AppendU32(glb, static_cast<uint32_t>(12 + 8 + json.size() + 8 + bin.size()));
  AppendU32(glb, static_cast<uint32_t>(json.size()));
  glb += "JSON" + json;
  AppendU32(glb, static_cast<uint32_t>(bin.size()));
  glb += std::string("BIN\0", 4) + bin;
  WriteFileAtomic(path, glb);
}

// DIR/quad.glb, its texture 8 × 8 pixels: the top four rows red, the bottom
// four green (sRGB 230 / 30).
void WriteTwoColourQuad(const testing::TempDir& dir) {
  Image8 texture(8, 8, 3);
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x) {
      uint8_t* p = texture.Pixel(x, y);
      p[0] = y < 4 ? 230 : 30, p[1] = y < 4 ? 30 : 230, p[2] = 30;
    }
  WriteImage8(dir.File("texture.png"), texture);
  WriteTexturedQuadGlb(dir.File("quad.glb"), ReadFileBytes(dir.File("texture.png")));
}

// The rendered object's chromaticity (each channel's share of the sum) at a
// world point of the quad, from the object layer (I_v) of the view.
Vec3 ChromaticityAt(const ImageF& object, const Vec3& world) {
  Vec2 pixel;
  EXPECT_TRUE(Project(ViewCamera(), ViewPose().Inverse() * world, pixel));
  const int x = static_cast<int>(pixel.x), y = static_cast<int>(pixel.y);
  const Vec3 rgb(object.at(x, y, 0), object.at(x, y, 1), object.at(x, y, 2));
  const double sum = rgb.x + rgb.y + rgb.z;
  EXPECT_GT(sum, 0.0) << "no object at pixel " << x << "," << y;
  return rgb / sum;
}

TEST(InsertMedia, AGlbsEmbeddedTextureColoursTheObjectWhereItsUvsPutIt) {
  testing::TempDir dir;
  WriteScene(dir);
  WriteTwoColourQuad(dir);
  const Result r = RunNerfar("insert --nerf " + dir.File("slab.nerf") + " --env " + dir.File("env.json") +
                             " --object " + dir.File("quad.glb") + " --pose " + dir.File("pose.json") + " --dataset " +
                             dir.File("ds") + " -o " + dir.File("out") + " --preset fast --threads 2");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("baking the field of " + dir.File("quad.glb")), std::string::npos) << r.output;
  const ImageF object = ReadExrRgb(dir.File("out/r_000_object.exr"));
  // The texture's colours, linear: 230 -> 0.79, 30 -> 0.013; chromaticity 0.96 / 0.016.
  const double strong = SrgbToLinear(230 / 255.0f), weak = SrgbToLinear(30 / 255.0f);
  const Vec3 red(strong, weak, weak), green(weak, strong, weak);
  // The light is grey (a grey lobe and a grey slab), so the diffuse colour
  // is the albedo's; the dielectric specular (F0 = 0.02, roughness 1) adds
  // grey of a few per cent of it: 0.05 of chromaticity holds it, while a
  // flipped or missing texture is off by 0.3 or more.
  const Vec3 top = ChromaticityAt(object, {0, kHalfSide / 2, 0.01});
  const Vec3 bottom = ChromaticityAt(object, {0, -kHalfSide / 2, 0.01});
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(top[c], red[c] / (red.x + red.y + red.z), 0.05) << "channel " << c << " of the +y half";
    EXPECT_NEAR(bottom[c], green[c] / (green.x + green.y + green.z), 0.05) << "channel " << c << " of the -y half";
  }
  // Baked to an .ssdf from its own folder, the texture is "quad.glb#0":
  // used from another folder, it is found beside the field, as the mesh is.
  Result baked = testing::RunCommand("cd " + dir.path() + " && " + std::string(NERFAR_BINARY) +
                                     " bake quad.glb -o quad.ssdf --preset fast");
  ASSERT_EQ(baked.exit_code, 0) << baked.output;
  baked = RunNerfar("insert --nerf " + dir.File("slab.nerf") + " --env " + dir.File("env.json") + " --object " +
                    dir.File("quad.ssdf") + " --pose " + dir.File("pose.json") + " --dataset " + dir.File("ds") +
                    " -o " + dir.File("from_ssdf") + " --preset fast --threads 2");
  ASSERT_EQ(baked.exit_code, 0) << baked.output;
  EXPECT_EQ(ReadExrRgb(dir.File("from_ssdf/r_000_object.exr")).pixels, object.pixels);
}

// `live` loads the same maps: row 0 is v = 0 of the mesh's UVs (the
// image's bottom row, green), linear values (sRGB 230 -> 0.79), times the
// glTF factor 1.
TEST(InsertMedia, LiveLoadsAGlbsTextureAsTheInserterSamplesIt) {
  testing::TempDir dir;
  WriteTwoColourQuad(dir);
  const LiveObjectAsset asset = LoadLiveObject(dir.File("quad.glb"));
  ASSERT_TRUE(asset.maps.albedo.has_value());
  const ImageF& albedo = *asset.maps.albedo;
  ASSERT_EQ(albedo.width, 8);
  ASSERT_EQ(albedo.height, 8);
  // 1e-6: the same float conversion of an 8-bit value.
  EXPECT_NEAR(albedo.at(3, 0, 1), SrgbToLinear(230 / 255.0f), 1e-6);
  EXPECT_NEAR(albedo.at(3, 0, 0), SrgbToLinear(30 / 255.0f), 1e-6);
  EXPECT_NEAR(albedo.at(3, 7, 0), SrgbToLinear(230 / 255.0f), 1e-6);
  EXPECT_FALSE(asset.maps.roughness.has_value());
}

TEST(InsertMedia, AnObjectJsonIsBakedInMemoryAsBakeWritesIt) {
  testing::TempDir dir;
  WriteScene(dir);
  WriteMeshObj(dir.File("box.obj"), MakeBox({0.03, 0.03, 0.03}));
  testing::WriteText(dir.File("box.json"),
                     R"({"mesh": "box.obj", "albedo": [0.7, 0.5, 0.3], "roughness": 0.6, "metallic": 0.0})");
  const std::string common = " --pose " + dir.File("pose.json") + " --nerf " + dir.File("slab.nerf") + " --env " +
                             dir.File("env.json") + " --dataset " + dir.File("ds") + " --preset fast --threads 2";
  Result r = RunNerfar("insert --object " + dir.File("box.json") + common + " -o " + dir.File("memory"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunNerfar("bake " + dir.File("box.json") + " -o " + dir.File("box.ssdf") + " --preset fast");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = RunNerfar("insert --object " + dir.File("box.ssdf") + common + " -o " + dir.File("file"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // The same field and material either way: the composites agree bit for bit.
  const ImageF memory = ReadExrRgb(dir.File("memory/r_000.exr")), file = ReadExrRgb(dir.File("file/r_000.exr"));
  EXPECT_EQ(memory.pixels, file.pixels);
  // The box casts a shadow on the slab (its field is used, not skipped).
  const ImageF kappa = ReadExrChannel(dir.File("memory/r_000_kappa.exr"));
  size_t shadowed = 0;
  for (float k : kappa.pixels) shadowed += k < 0.9f;
  EXPECT_GT(shadowed, 20u);
  // A JSON naming no mesh is named in the error.
  testing::WriteText(dir.File("nomesh.json"), R"({"albedo": [0.7, 0.5, 0.3], "roughness": 0.6, "metallic": 0.0})");
  r = RunNerfar("insert --object " + dir.File("nomesh.json") + common + " -o " + dir.File("bad"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find(dir.File("nomesh.json")), std::string::npos) << r.output;
}

// The text after "(expected one of: " in an unknown-key error: the keys a
// command's --set knows.
std::string KnownKeys(const std::string& output) {
  const std::string marker = "(expected one of: ";
  const size_t begin = output.find(marker);
  if (begin == std::string::npos) return "";
  const size_t end = output.find(')', begin);
  return output.substr(begin + marker.size(), end - begin - marker.size());
}

// insert with WriteScene's object, NeRF and dataset, into DIR/out.
std::string InsertOf(const testing::TempDir& dir) {
  return "insert --object " + dir.File("box.ssdf") + " --pose " + dir.File("pose.json") + " --nerf " +
         dir.File("slab.nerf") + " --dataset " + dir.File("ds") + " -o " + dir.File("out");
}

// insert, live and bake take --set KEY=VALUE through the one parser: an
// unknown key stops each with exit code 2 naming it before anything runs.
TEST(Knobs, AnUnknownSetKeyExitsTwoNamingIt) {
  testing::TempDir dir;
  WriteScene(dir);
  const std::string insert = InsertOf(dir);
  for (const std::string& command : {insert, "live --source synthetic --scene " + dir.path() + " --headless --frames 1",
                                     "bake " + dir.File("box.obj") + " -o " + dir.File("box.ssdf")}) {
    const Result r = RunNerfar(command + " --set kapa_step=3");
    EXPECT_EQ(r.exit_code, 2) << command << ": " << r.output;
    EXPECT_NE(r.output.find("--set kapa_step=3: unknown option 'kapa_step'"), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(dir.File("box.ssdf"))) << "bake wrote its field: " << r.output;
  }
  const Result bad = RunNerfar(insert + " --set kappa_step=two");
  EXPECT_EQ(bad.exit_code, 2) << bad.output;
  EXPECT_NE(bad.output.find("'two' is not a valid value of kappa_step"), std::string::npos) << bad.output;
}

// live's --set takes insert's keys, the NeRF scene's among them, but for
// support_plane (insert's alone: live takes no support plane): the keys
// each names when refusing an unknown one.
TEST(Knobs, LiveSetTakesInsertsKeys) {
  testing::TempDir dir;
  WriteScene(dir);
  const Result insert = RunNerfar(InsertOf(dir) + " --set x=1");
  const Result live = RunNerfar("live --source synthetic --scene " + dir.path() + " --headless --frames 1 --set x=1");
  EXPECT_EQ(live.exit_code, 2) << live.output;
  const std::string keys = KnownKeys(insert.output), live_keys = KnownKeys(live.output);
  ASSERT_FALSE(live_keys.empty()) << live.output;
  EXPECT_EQ(live_keys + ", support_plane", keys) << insert.output << "\n" << live.output;
  for (const char* key : {"kappa_step", "light_source", "seen_group_m", "seen_cache_views", "normal_probe_voxels"})
    EXPECT_NE(live_keys.find(key), std::string::npos) << key << " missing from " << live_keys;
}

// The bench's NERFAR_BENCH_INSERT_KNOBS and insert's --set are one list of
// insertion knobs: the keys the bench names when refusing an unknown one are
// the first insert names, which include fields beyond the bench's former
// hand list of twelve and both named choices; insert's list goes on with the
// NeRF scene's knobs (its synthetic scene has no NeRF for the bench to set).
TEST(Knobs, BenchInsertKnobsAreInsertSetsInsertionKnobs) {
  const Result insert = RunNerfar("insert --object a.ssdf --pose p.json --nerf n.nerf --dataset d -o o --set x=1");
  const Result bench =
      testing::RunCommand("NERFAR_BENCH_INSERT_KNOBS=x=1 " + std::string(NERFAR_BINARY) + " bench insert --quick");
  EXPECT_EQ(bench.exit_code, 2) << bench.output;
  const std::string keys = KnownKeys(insert.output), bench_keys = KnownKeys(bench.output);
  ASSERT_FALSE(bench_keys.empty()) << bench.output;
  EXPECT_EQ(keys.substr(0, bench_keys.size() + 2), bench_keys + ", ") << insert.output << "\n" << bench.output;
  for (const char* key :
       {"kappa_step", "light_parallax", "antialias_edges", "sg_lobes", "kappa_grid_width", "light_source", "sg_method"})
    EXPECT_NE(bench_keys.find(key), std::string::npos) << key << " missing from " << bench_keys;
  for (const char* key : {"seen_views", "seen_group_m", "surface_depth", "normal_probe_voxels", "support_plane"}) {
    EXPECT_NE(keys.find(key, bench_keys.size()), std::string::npos) << key << " missing from " << keys;
    EXPECT_EQ(bench_keys.find(key), std::string::npos) << key << " in the bench's " << bench_keys;
  }
}

// A named choice refuses any other name, naming the allowed ones, whether
// given by --set (insert, live) or by its named flag.
TEST(Knobs, ABadChoiceIsRefusedNamingTheAllowedOnes) {
  testing::TempDir dir;
  WriteScene(dir);
  const std::string insert = InsertOf(dir);
  struct Case {
    std::string command, expected;
  };
  for (const Case& c :
       {Case{insert + " --set sg_method=newton",
             "--set sg_method=newton: 'newton' is not a valid value of sg_method "
             "(expected block, dense or adam)"},
        Case{insert + " --light-source sun",
             "--light-source light_source=sun: 'sun' is not a valid value of "
             "light_source (expected full, near or env)"},
        Case{"live --source synthetic --scene " + dir.path() + " --headless --frames 1 --set light_source=sun",
             "(expected full, near or env)"}}) {
    const Result r = RunNerfar(c.command);
    EXPECT_EQ(r.exit_code, 2) << c.command << ": " << r.output;
    EXPECT_NE(r.output.find(c.expected), std::string::npos) << c.command << ": " << r.output;
  }
  EXPECT_FALSE(fs::exists(dir.File("out/options.json"))) << "refused before anything ran";
}

// A key set changes the effective options, read back from what the command
// writes: insert's OUT/options.json, bake's logged options. --set applies
// after the named flag of the same field (both given: --set holds), a key no
// named flag has (kappa_grid_width) takes effect too, and so do the NeRF
// scene's knobs, by --set or by their named flags (the same fields).
TEST(Knobs, SetChangesTheEffectiveOptionsAfterTheNamedFlags) {
  testing::TempDir dir;
  WriteScene(dir);
  WriteMeshObj(dir.File("box.obj"), MakeBox({0.03, 0.03, 0.03}));
  Result r = RunNerfar("bake " + dir.File("box.obj") + " -o " + dir.File("box.ssdf") +
                       " --preset fast --grid 12 --set grid=9 --set components=8");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find(R"("components":8,)"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(R"("grid":9,)"), std::string::npos) << r.output;
  r = RunNerfar(
      "insert --object " + dir.File("box.ssdf") + " --pose " + dir.File("pose.json") + " --nerf " +
      dir.File("slab.nerf") + " --env " + dir.File("env.json") + " --dataset " + dir.File("ds") +
      " --preset fast --threads 2 -o " + dir.File("out") +
      " --kappa-step 5 --set kappa_step=3 --set light_source=near --set kappa_grid_width=0" +
      " --seen-views 5 --set seen_views=7 --seen-group-cm 3 --set normal_probe_voxels=1.5 --no-support-plane");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json options = nlohmann::json::parse(testing::ReadText(dir.File("out/options.json")));
  EXPECT_EQ(options.at("kappa_step"), 3);
  EXPECT_EQ(options.at("light_source"), "near");
  EXPECT_EQ(options.at("kappa_grid_width"), 0);
  EXPECT_EQ(options.at("occlusion_step"), 4) << "the fast preset's, untouched";
  EXPECT_EQ(options.at("seen_views"), 7);
  EXPECT_EQ(options.at("seen_group_m"), 0.03) << "--seen-group-cm 3 in metres, exactly 3 / 100";
  EXPECT_EQ(options.at("normal_probe_voxels"), 1.5);
  EXPECT_EQ(options.at("support_plane"), false);
  EXPECT_EQ(options.at("seen_cache_views"), true) << "the fast preset's, untouched";
  EXPECT_EQ(options.at("sg_method"), "block") << "the presets' method";
}

TEST(CameraPath, AnOrbitCirclesItsCentreAtItsRadiusAndElevationLookingAtIt) {
  const Orbit orbit{{0.1, -0.2, 0.05}, 0.6, 30.0 * kPi / 180.0, 0.25, 8};
  const std::vector<Pose> poses = OrbitPoses(orbit);
  ASSERT_EQ(poses.size(), 8u);
  for (size_t i = 0; i < poses.size(); ++i) {
    SCOPED_TRACE(i);
    const Vec3 offset = poses[i].translation - orbit.centre;
    // Closed forms; 1e-9 is rounding in doubles.
    EXPECT_NEAR(Length(offset), 0.6, 1e-9);
    EXPECT_NEAR(std::asin(offset.z / Length(offset)), 30.0 * kPi / 180.0, 1e-9);
    const double azimuth = std::atan2(offset.y, offset.x);
    EXPECT_NEAR(std::remainder(azimuth - (0.25 + 2 * kPi * i / 8), 2 * kPi), 0.0, 1e-9);
    // OpenCV axes: the camera's +z looks at the centre, its +y (image down) points down in the world.
    const Vec3 forward = poses[i].Rotate({0, 0, 1}), down = poses[i].Rotate({0, 1, 0});
    EXPECT_NEAR(Dot(forward, Normalized(-offset)), 1.0, 1e-9);
    EXPECT_LT(down.z, 0.0);
  }
  // The capture's orbit: cameras at 0.5, 0.6 and 0.9 m, 10, 20 and 60 degrees up: the medians.
  std::vector<Pose> capture;
  const double distances[3] = {0.5, 0.9, 0.6}, elevations[3] = {20, 60, 10};
  for (int k = 0; k < 3; ++k) {
    const double e = elevations[k] * kPi / 180.0, az = 1.0 + k;
    capture.push_back(
        LookAt(Vec3(std::cos(e) * std::cos(az), std::cos(e) * std::sin(az), std::sin(e)) * distances[k], {0, 0, 0}));
  }
  const Orbit suggested = OrbitOfCapture(capture, {0, 0, 0}, 12);
  EXPECT_NEAR(suggested.radius_m, 0.6, 1e-9);
  EXPECT_NEAR(suggested.elevation_rad, 20.0 * kPi / 180.0, 1e-9);
  EXPECT_NEAR(suggested.start_azimuth_rad, 1.0, 1e-9);
  EXPECT_EQ(suggested.frames, 12);
}

// nerfstudio's camera_path.json as its viewer writes it (keys nerfar does not read included).
std::string CameraPathJson(const std::string& first_matrix, const std::string& fov = "60") {
  return R"({"default_fov": 75, "default_transition_sec": 2, "keyframes": [], "camera_type": "perspective",
    "render_height": 240, "render_width": 320, "fps": 30, "seconds": 1, "is_cycle": false, "smoothness_value": 0.5,
    "camera_path": [
      {"camera_to_world": )" +
         first_matrix + R"(, "fov": )" + fov + R"(, "aspect": 1.333},
      {"camera_to_world": [1,0,0,0, 0,1,0,0, 0,0,1,2, 0,0,0,1], "fov": 30, "aspect": 1.333}]})";
}

TEST(CameraPath, ReadsNerfstudiosCameraPathJson) {
  testing::TempDir dir;
  testing::WriteText(dir.File("path.json"), CameraPathJson("[1,0,0,0.5, 0,1,0,0, 0,0,1,1, 0,0,0,1]"));
  const CameraPath path = ReadCameraPath(dir.File("path.json"));
  ASSERT_EQ(path.views.size(), 2u);
  EXPECT_EQ(path.fps, 30);
  const CameraIntrinsics& camera = path.views[0].camera;
  EXPECT_EQ(camera.width, 320);
  EXPECT_EQ(camera.height, 240);
  // Vertical field of view 60°: f = (240 / 2) / tan(30°) = 207.85 px.
  EXPECT_NEAR(camera.fy, 120.0 / std::tan(kPi / 6), 1e-9);
  EXPECT_NEAR(path.views[1].camera.fy, 120.0 / std::tan(kPi / 12), 1e-9);
  EXPECT_NEAR(camera.cx, 160.0, 1e-12);
  // An OpenGL camera at (0.5, 0, 1) with identity rotation looks along −z:
  // as OpenCV axes its +z is world −z and its +y (image down) world −y.
  const Pose& pose = path.views[0].T_world_camera;
  EXPECT_NEAR(Length(pose.translation - Vec3(0.5, 0, 1)), 0.0, 1e-12);
  EXPECT_NEAR(pose.Rotate({0, 0, 1}).z, -1.0, 1e-12);
  EXPECT_NEAR(pose.Rotate({0, 1, 0}).y, -1.0, 1e-12);
}

TEST(CameraPath, BadInputIsNamedWithWhatIsWrong) {
  testing::TempDir dir;
  struct Case {
    std::string text, expected;
  };
  const std::string rigid = "[1,0,0,0, 0,1,0,0, 0,0,1,1, 0,0,0,1]";
  const Case cases[] = {
      {"{not json", "line 1"},
      {CameraPathJson("[1,0,0,0, 0,2,0,0, 0,0,1,1, 0,0,0,1]"), "not a rotation"},
      {CameraPathJson("[1,0,0,0, 0,1,0,0]"), "camera_to_world"},
      {CameraPathJson(rigid, "0"), "/camera_path/0/fov"},
      {CameraPathJson(rigid, "\"wide\""), "/camera_path/0/fov"},
      {R"({"render_width": 320, "render_height": 240, "camera_path": []})", "is empty"},
      {R"({"render_width": 320, "camera_path": [{"camera_to_world": )" + rigid + R"(, "fov": 50}]})", "render_height"},
      {R"({"camera_type": "fisheye", "render_width": 320, "render_height": 240, "camera_path": [{"camera_to_world": )" +
           rigid + R"(, "fov": 50}]})",
       "fisheye"},
  };
  for (const Case& c : cases) {
    testing::WriteText(dir.File("bad.json"), c.text);
    try {
      ReadCameraPath(dir.File("bad.json"));
      ADD_FAILURE() << "accepted: " << c.text;
    } catch (const InputError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(dir.File("bad.json")), std::string::npos) << what;
      EXPECT_NE(what.find(c.expected), std::string::npos) << "expected '" << c.expected << "' in: " << what;
    }
  }
}

// The video runs: the textured quad's scene, an orbit of `frames` views at
// 48 pixels across (36 high: the dataset's 4:3).
std::string OrbitCommand(const testing::TempDir& dir, int frames) {
  return "insert --nerf " + dir.File("slab.nerf") + " --env " + dir.File("env.json") + " --object " +
         dir.File("box.obj") + " --pose " + dir.File("pose.json") + " --dataset " + dir.File("ds") + " -o " +
         dir.File("video") + " --orbit --orbit-frames " + std::to_string(frames) +
         " --video-width 48 --preset fast --threads 2";
}

TEST(InsertVideo, FlagsThatDoNotGoWithAPathExitTwoNamingTheFlag) {
  const std::string common = "insert --nerf n.nerf --object o.obj --pose p.json --dataset d -o out ";
  const std::pair<std::string, std::string> cases[] = {
      {"--orbit --camera-path path.json", "--camera-path"},
      {"--orbit --frames frames", "--frames"},
      {"--orbit --truth truth", "--truth"},
      {"--orbit --orbit-frames 0", "--orbit-frames"},
      {"--orbit --orbit-elevation 95", "--orbit-elevation"},
      {"--orbit --video-width 1", "--video-width"},
      {"--orbit --fps 0", "--fps"},
      {"--orbit --orbit-radius -2", "--orbit-radius"},
  };
  for (const auto& [flags, named] : cases) {
    const Result r = RunNerfar(common + flags);
    EXPECT_EQ(r.exit_code, 2) << flags << "\n" << r.output;
    EXPECT_NE(r.output.find(named), std::string::npos) << flags << "\n" << r.output;
  }
}

TEST(InsertVideo, AnOrbitWritesItsFramesAndADecodableMp4OfTheStatedSize) {
  if (!FindOnPath("ffmpeg") || !FindOnPath("ffprobe"))
    GTEST_SKIP() << "ffmpeg / ffprobe not on PATH (setup.sh installs them)";
  testing::TempDir dir;
  WriteScene(dir);
  WriteMeshObj(dir.File("box.obj"), MakeBox({0.03, 0.03, 0.03}));
  const Result r = RunNerfar(OrbitCommand(dir, 6) + " --fps 12");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (int i = 0; i < 6; ++i) {
    const Image8 frame = ReadImage8(dir.File("video/frame_000" + std::to_string(i) + ".png"));
    EXPECT_EQ(frame.width, 48);
    EXPECT_EQ(frame.height, 36);
  }
  EXPECT_FALSE(fs::exists(dir.File("video/frame_0006.png")));
  // ffprobe decodes every frame (-count_frames) and states the stream's size.
  const Result probe = testing::RunCommand(
      "ffprobe -v error -count_frames -select_streams v:0 -show_entries stream=width,height,nb_read_frames,codec_name "
      "-of default=noprint_wrappers=1 " +
      dir.File("video/video.mp4"));
  ASSERT_EQ(probe.exit_code, 0) << probe.output;
  EXPECT_NE(probe.output.find("codec_name=h264"), std::string::npos) << probe.output;
  EXPECT_NE(probe.output.find("width=48"), std::string::npos) << probe.output;
  EXPECT_NE(probe.output.find("height=36"), std::string::npos) << probe.output;
  EXPECT_NE(probe.output.find("nb_read_frames=6"), std::string::npos) << probe.output;
  // Progress: the last frame's count.
  EXPECT_NE(r.output.find("(6/6)"), std::string::npos) << r.output;
}

TEST(InsertVideo, WithoutFfmpegTheFramesAreKeptAndTheErrorSaysHowToEncodeThem) {
  testing::TempDir dir;
  WriteScene(dir);
  WriteMeshObj(dir.File("box.obj"), MakeBox({0.03, 0.03, 0.03}));
  const Result r = testing::RunCommand("/usr/bin/env PATH=" + dir.File("empty") + " " + std::string(NERFAR_BINARY) +
                                       " " + OrbitCommand(dir, 2));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("ffmpeg not found"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("ffmpeg -hide_banner"), std::string::npos) << "no command to run by hand:\n" << r.output;
  EXPECT_TRUE(fs::is_regular_file(dir.File("video/frame_0000.png")));
  EXPECT_TRUE(fs::is_regular_file(dir.File("video/frame_0001.png")));
  EXPECT_FALSE(fs::exists(dir.File("video/video.mp4")));
}

TEST(InsertVideo, ACameraPathsViewsAreRenderedAtItsSizeScaledToTheVideoWidth) {
  testing::TempDir dir;
  WriteScene(dir);
  WriteMeshObj(dir.File("box.obj"), MakeBox({0.03, 0.03, 0.03}));
  // Two views from 0.4 m above, looking straight down (OpenGL: −z forward), the second 5 cm along +x.
  testing::WriteText(dir.File("path.json"), R"({"camera_type": "perspective", "render_width": 320,
    "render_height": 240, "fps": 10, "camera_path": [
      {"camera_to_world": [1,0,0,0, 0,1,0,0, 0,0,1,0.4, 0,0,0,1], "fov": 40},
      {"camera_to_world": [1,0,0,0.05, 0,1,0,0, 0,0,1,0.4, 0,0,0,1], "fov": 40}]})");
  // Without ffmpeg on PATH (the frames are what is checked here).
  const Result r = testing::RunCommand("/usr/bin/env PATH=" + dir.File("empty") + " " + std::string(NERFAR_BINARY) +
                                       " insert --nerf " + dir.File("slab.nerf") + " --env " + dir.File("env.json") +
                                       " --object " + dir.File("box.obj") + " --pose " + dir.File("pose.json") +
                                       " --dataset " + dir.File("ds") + " -o " + dir.File("video") + " --camera-path " +
                                       dir.File("path.json") + " --video-width 32 --preset fast --threads 2");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  const Image8 first = ReadImage8(dir.File("video/frame_0000.png")),
               second = ReadImage8(dir.File("video/frame_0001.png"));
  EXPECT_EQ(first.width, 32);
  EXPECT_EQ(first.height, 24);
  EXPECT_FALSE(fs::exists(dir.File("video/frame_0002.png")));
  // The box seen from straight above sits in the middle of the first view;
  // the second, 5 cm to the side, sees it off centre: the views differ.
  EXPECT_NE(first.pixels, second.pixels);
  // The frame rate the file states is the one the command to encode them by hand uses.
  EXPECT_NE(r.output.find("-framerate 10"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace nerfar
