// Writes the binary-format fixtures of tests/data/formats/ from the inputs of
// tests/nerf/format_fixtures.h and tests/ssdf/format_fixtures.h:
//   field_vN.nerf, field_raw_vN.nerf  a field saved twice (so its bytes repeat on
//                                     every later save), deflated and not
//   train_vN.ckpt                     a checkpoint after kFormatFixtureTrainSteps steps
//   tetra_vN.ssdf                     a baked tetrahedron with its material
// N is the version this build writes. Each version's files stay committed (the
// tests read every one: old files must still read); write them when a format's
// version changes and commit the new ones beside the old.
//   cmake --build build --target make_format_fixtures && build/tests/make_format_fixtures tests/data/formats
#include <cstdio>
#include <string>

#include "calib/core/atomic_file.h"
#include "render/nerf/nerf_file.h"
#include "render/ssdf/ssdf.h"
#include "tests/nerf/format_fixtures.h"
#include "tests/ssdf/format_fixtures.h"

int main(int argc, char** argv) {
  using namespace nerfar;
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_format_fixtures DIR\n");
    return 2;
  }
  const std::string dir = argv[1];
  const NerfField field = testing::FormatFixtureField();
  const std::string nerf = "_v" + std::to_string(kNerfFileVersion) + ".nerf";
  SaveNerf(dir + "/field" + nerf, ParseNerf(SerializeNerf(field), "memory"));
  NerfFileOptions raw;
  raw.compress = false;
  raw.density_bits = 16;
  raw.color_base_bits = 10;
  raw.color_slope_bits = 6;
  SaveNerf(dir + "/field_raw" + nerf, ParseNerf(SerializeNerf(field, raw), "memory"), raw);

  const NerfTrainData data = testing::TinyTrainData();
  NerfTrainer trainer(data, testing::TinyTrainOptions());
  for (int n = 0; n < testing::kFormatFixtureTrainSteps; ++n) trainer.Step();
  trainer.SaveCheckpoint(dir + "/train_v" + std::to_string(kNerfCheckpointVersion) + ".ckpt");

  WriteSsdf(
      dir + "/tetra_v" + std::to_string(kSsdfFileVersion) + ".ssdf",
      BakeSsdf(testing::FormatFixtureMesh(), testing::FormatFixtureSsdfOptions(), testing::FormatFixtureMaterial()));
  std::printf("wrote the fixtures of this version to %s\n", dir.c_str());
  return 0;
}
