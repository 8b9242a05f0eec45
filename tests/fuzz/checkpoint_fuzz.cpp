// Fuzzes the training checkpoint reader (NerfTrainer::LoadCheckpoint) of the
// tiny trainer of tests/support/tiny_trainer.h. An input is the part of a checkpoint
// after its magic and identity strings, without the checksum: the target
// puts its own trainer's identity in front and the checksum after, so that
// mutations reach the grid, brick list and arrays; the bytes as a whole file
// (checksum appended) are tried as well. Any input must be loaded or
// rejected with InputError.
#include <cstdint>
#include <string>

#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "tests/fuzz/fuzz_support.h"
#include "tests/support/tiny_trainer.h"

namespace {

struct Fixture {
  nerfar::NerfTrainData data = nerfar::testing::TinyTrainData();  // the trainer keeps a reference
  nerfar::NerfTrainer trainer{data, nerfar::testing::TinyTrainOptions()};
  std::string path = nerfar::fuzz::ScratchFile("fuzz.ckpt");
  std::string identity;  // magic and identity strings of this trainer's checkpoints
  Fixture() {
    trainer.SaveCheckpoint(path);
    const std::string saved = nerfar::ReadFileBytes(path);
    identity = saved.substr(0, nerfar::fuzz::CheckpointIdentityBytes(saved));
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  using namespace nerfar;
  static Fixture fixture;
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  for (const std::string& file : {fixture.identity + bytes, bytes}) {
    if (!fuzz::WriteBytes(fixture.path, fuzz::WithChecksum(file))) return 0;
    fuzz::Expect([&] { fixture.trainer.LoadCheckpoint(fixture.path); });
  }
  return 0;
}
