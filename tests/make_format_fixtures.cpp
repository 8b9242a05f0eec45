// Writes the binary-format fixtures of tests/data/formats/ from the inputs of
// tests/nerf/format_fixtures.h and tests/ssdf/format_fixtures.h:
//   field.nerf, field_raw.nerf  a field saved twice (so its bytes repeat on
//                               every later save), deflated and not
//   train.ckpt                  a checkpoint after kFormatFixtureTrainSteps steps
//   tetra.ssdf                  a baked tetrahedron with its material
// The committed files were written before the formats' shared container
// (calib/core/binary_file.h); rewrite them only when a format's version changes.
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
  SaveNerf(dir + "/field.nerf", ParseNerf(SerializeNerf(field), "memory"));
  NerfFileOptions raw;
  raw.compress = false;
  raw.density_bits = 16;
  raw.color_base_bits = 10;
  raw.color_slope_bits = 6;
  SaveNerf(dir + "/field_raw.nerf", ParseNerf(SerializeNerf(field, raw), "memory"), raw);

  const NerfTrainData data = testing::TinyTrainData();
  NerfTrainer trainer(data, testing::TinyTrainOptions());
  for (int n = 0; n < testing::kFormatFixtureTrainSteps; ++n) trainer.Step();
  trainer.SaveCheckpoint(dir + "/train.ckpt");

  WriteSsdf(dir + "/tetra.ssdf", BakeSsdf(testing::FormatFixtureMesh(), testing::FormatFixtureSsdfOptions(),
                                          testing::FormatFixtureMaterial()));
  std::printf("wrote %s/{field.nerf,field_raw.nerf,train.ckpt,tetra.ssdf}\n", dir.c_str());
  return 0;
}
