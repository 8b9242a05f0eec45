// Writes the binary seeds of the fuzz corpora with the project's own writers
// (build target fuzz_make_seeds; run it from the source tree's root after a
// format changes): tests/fuzz/corpus/{nerf,ssdf,checkpoint,image,mesh}/ and
// corpus/dataset/camera.json. Binary files with a checksum are stored
// without it (the targets append it); of checkpoints only the training state
// (TRAN) is stored (checkpoint_fuzz.cpp puts its trainer's identity with it).
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "calib/camera_file.h"
#include "calib/core/atomic_file.h"
#include "calib/core/image_io.h"
#include "render/mesh/mesh.h"
#include "render/nerf/nerf_file.h"
#include "render/ssdf/ssdf.h"
#include "tests/fuzz/fuzz_support.h"
#include "tests/support/sectioned_file.h"
#include "tests/support/tiny_trainer.h"

namespace {

using namespace nerfar;
namespace fs = std::filesystem;

const std::string kCorpus = "tests/fuzz/corpus/";

void Write(const std::string& name, const std::string& bytes) {
  fs::create_directories(fs::path(kCorpus + name).parent_path());
  WriteFileAtomic(kCorpus + name, bytes);
  std::printf("%-40s %6zu bytes\n", name.c_str(), bytes.size());
}

// A sectioned file without its crc32.
std::string WithoutChecksum(const std::string& bytes) { return bytes.substr(0, bytes.size() - 4); }

// A 12 cm slab with a 4 cm block on it at 2 cm voxels: a few bricks, some cells occupied.
NerfField SmallField() {
  NerfField field =
      NerfField::Dense({{-0.06, -0.06, -0.02}, {0.06, 0.06, 0.04}}, 0.02, std::log(50.0f), Vec3f{-1.0f, -0.5f, 0.2f});
  for (size_t i = 0; i < field.density.size(); i += 3) field.density[i] = -4.0f;  // some empty space
  field.UpdateOccupancy(1.0f);
  return field;
}

template <typename T>
void Put(std::string& out, const T& value) {
  out.append(reinterpret_cast<const char*>(&value), sizeof value);
}

// Version 1 (read only) by its stated layout (nerf_file.h): every vertex of
// every brick stored, as half floats (all 0 here: the layout is what counts).
std::string Version1(const NerfField& f) {
  std::string v1 = "NERFARF1";
  Put(v1, uint32_t{1});
  Put(v1, uint32_t{1});
  for (int a = 0; a < 3; ++a) Put(v1, float(f.aabb.min[a]));
  for (int a = 0; a < 3; ++a) Put(v1, float(f.aabb.max[a]));
  for (int a = 0; a < 3; ++a) Put(v1, f.origin[a]);
  Put(v1, f.voxel_m);
  Put(v1, f.occupancy_sigma);
  for (int a = 0; a < 3; ++a) Put(v1, int32_t(f.res[a]));
  Put(v1, uint32_t(f.BrickCount()));
  Put(v1, uint64_t(f.SlotCount()));
  for (size_t b = 0; b < f.BrickCount(); ++b) {
    for (int a = 0; a < 3; ++a) Put(v1, int32_t(f.brick_coords[3 * b + a]));
    Put(v1, ~uint64_t{0});
    Put(v1, f.occupancy[b]);
  }
  v1.append(f.SlotCount() * (1 + kNerfColorCoeffs) * 2, '\0');
  return v1;
}

void NerfSeeds() {
  const NerfField field = SmallField();
  Write("nerf/small_v1.bin", Version1(field));
  NerfFileOptions raw;
  raw.compress = false;
  Write("nerf/small_raw.bin", WithoutChecksum(SerializeNerf(field, raw)));
  Write("nerf/small_zlib.bin", WithoutChecksum(SerializeNerf(field)));
  raw.density_bits = 16;
  raw.color_base_bits = 4;
  Write("nerf/small_raw_bits.bin", WithoutChecksum(SerializeNerf(field, raw)));
  NerfField with_cameras = field;
  with_cameras.capture_centres = {Vec3f(0.5f, -1.0f, 0.8f), Vec3f(-0.7f, 0.2f, 0.6f)};
  Write("nerf/small_cams.bin", WithoutChecksum(SerializeNerf(with_cameras)));
}

void SsdfSeeds() {
  SsdfBakeOptions options = SsdfBakeOptions::Preset("fast");
  options.grid = 2;
  options.dirs = 4;
  options.components = 2;
  options.bisection_steps = 1;
  SsdfField field = BakeSsdf(MakeBox({0.03, 0.03, 0.03}), options, std::nullopt);
  Write("ssdf/box.bin", WithoutChecksum(SerializeSsdf(field)));
  Material material;
  material.albedo = {0.8, 0.2, 0.1};
  material.roughness = 0.4;
  material.mesh = "box.obj";
  field = BakeSsdf(MakeBox({0.03, 0.03, 0.03}), options, material);
  Write("ssdf/box_material.bin", WithoutChecksum(SerializeSsdf(field)));
}

void CheckpointSeeds() {
  const NerfTrainData data = testing::TinyTrainData();  // the trainer keeps a reference
  NerfTrainer trainer(data, testing::TinyTrainOptions());
  const std::string path = (fs::temp_directory_path() / "nerfar_make_seeds.ckpt").string();
  for (int steps : {0, 2}) {
    while (trainer.step() < steps) trainer.Step();
    trainer.SaveCheckpoint(path);
    const std::string saved = ReadFileBytes(path);
    Write("checkpoint/step" + std::to_string(steps) + ".bin", testing::SectionBytes(saved, "TRAN"));
  }
  fs::remove(path);
}

void ImageSeeds() {
  Image8 rgb(5, 4, 3), grey(3, 2, 1), rgba(2, 2, 4);
  for (size_t i = 0; i < rgb.pixels.size(); ++i) rgb.pixels[i] = static_cast<uint8_t>(i * 37);
  for (size_t i = 0; i < grey.pixels.size(); ++i) grey.pixels[i] = static_cast<uint8_t>(i * 51);
  for (size_t i = 0; i < rgba.pixels.size(); ++i) rgba.pixels[i] = static_cast<uint8_t>(255 - i * 15);
  std::vector<std::pair<std::string, Image8>> images = {
      {"rgb.png", rgb}, {"grey.png", grey}, {"rgba.png", rgba}, {"rgb.jpg", rgb}, {"grey.jpg", grey}};
  const std::string scratch = (fs::temp_directory_path() / "nerfar_make_seeds").string();
  fs::create_directories(scratch);
  for (const auto& [name, image] : images) {
    WriteImage8(scratch + "/" + name, image);
    Write("image/" + name, ReadFileBytes(scratch + "/" + name));
  }
  cv::Mat deep(3, 3, CV_16UC3, cv::Scalar(1000, 30000, 65535));
  cv::imwrite(scratch + "/deep.png", deep);
  Write("image/rgb16.png", ReadFileBytes(scratch + "/deep.png"));
  fs::remove_all(scratch);
}

// A tetrahedron: PLY in binary and a GLB (glTF's binary container).
struct Tetra {
  float positions[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  uint16_t indices[12] = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};
};

void MeshSeeds() {
  for (const char* name : {"tetra.obj", "tetra.ply", "tetra.gltf", "absurd_count.ply", "truncated.gltf"})
    Write(std::string("mesh/") + name, ReadFileBytes(std::string("tests/data/mesh/") + name));
  const Tetra t;
  std::string ply =
      "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
      "property float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n";
  ply.append(reinterpret_cast<const char*>(t.positions), sizeof t.positions);
  for (int f = 0; f < 4; ++f) {
    ply.push_back(3);
    for (int k = 0; k < 3; ++k) {
      const int32_t index = t.indices[3 * f + k];
      ply.append(reinterpret_cast<const char*>(&index), 4);
    }
  }
  Write("mesh/tetra_binary.ply", ply);

  std::string json =
      R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],)"
      R"("meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],)"
      R"("accessors":[{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,1]},)"
      R"({"bufferView":1,"componentType":5123,"count":12,"type":"SCALAR"}],)"
      R"("bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":48},{"buffer":0,"byteOffset":48,"byteLength":24}],)"
      R"("buffers":[{"byteLength":72}]})";
  while (json.size() % 4 != 0) json.push_back(' ');
  std::string bin(reinterpret_cast<const char*>(t.positions), sizeof t.positions);
  bin.append(reinterpret_cast<const char*>(t.indices), sizeof t.indices);
  const auto u32 = [](uint32_t v) { return std::string(reinterpret_cast<const char*>(&v), 4); };
  const std::string glb_body = u32(json.size()) + u32(0x4E4F534A) + json + u32(bin.size()) + u32(0x004E4942) + bin;
  Write("mesh/tetra.glb", "glTF" + u32(2) + u32(12 + glb_body.size()) + glb_body);
}

void CameraSeed() {
  CameraFile file;
  file.camera.width = 640;
  file.camera.height = 480;
  file.camera.fx = file.camera.fy = 500;
  file.camera.cx = 320;
  file.camera.cy = 240;
  file.camera.k1 = -0.1;
  CalibrationRecord record;
  record.rms_px = 0.3;
  record.views_used = 20;
  file.calibration = record;
  const std::string path = (fs::temp_directory_path() / "nerfar_make_seeds_camera.json").string();
  WriteCameraFile(path, file);
  Write("dataset/camera.json", ReadFileBytes(path));
  fs::remove(path);
}

}  // namespace

int main() {
  if (!fs::is_directory(kCorpus)) {
    std::fprintf(stderr, "run from the source tree's root (no %s here)\n", kCorpus.c_str());
    return 2;
  }
  NerfSeeds();
  SsdfSeeds();
  CheckpointSeeds();
  ImageSeeds();
  MeshSeeds();
  CameraSeed();
  return 0;
}
