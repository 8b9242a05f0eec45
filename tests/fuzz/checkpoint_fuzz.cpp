// Fuzzes the training checkpoint reader (NerfTrainer::LoadCheckpoint) of the
// tiny trainer of tests/support/tiny_trainer.h. An input is a checkpoint's
// training state (its TRAN section; the fields after the identity in a flat
// checkpoint of before sections): the target puts its own trainer's identity
// with it, in a sectioned file and in a flat one, so that mutations reach the
// grid, brick list and arrays; the bytes as a whole file (a checksum
// appended) are tried as well. Any input must be loaded or rejected with
// InputError.
#include <cstdint>
#include <cstring>
#include <string>

#include "calib/core/atomic_file.h"
#include "calib/core/binary_file.h"
#include "calib/core/error.h"
#include "tests/fuzz/fuzz_support.h"
#include "tests/support/sectioned_file.h"
#include "tests/support/tiny_trainer.h"

namespace {

struct Fixture {
  nerfar::NerfTrainData data = nerfar::testing::TinyTrainData();  // the trainer keeps a reference
  nerfar::NerfTrainer trainer{data, nerfar::testing::TinyTrainOptions()};
  std::string path = nerfar::fuzz::ScratchFile("fuzz.ckpt");
  std::string magic;     // of this build's checkpoints
  uint32_t version = 0;  // of this build's checkpoints
  std::string identity;  // this trainer's IDEN section (the identity fields of a flat checkpoint too)
  Fixture() {
    trainer.SaveCheckpoint(path);
    const std::string saved = nerfar::ReadFileBytes(path);
    magic = saved.substr(0, 8);
    std::memcpy(&version, saved.data() + 8, 4);
    identity = nerfar::testing::SectionBytes(saved, "IDEN");
  }
  // A sectioned checkpoint of this trainer's identity and `state`.
  std::string Sectioned(const std::string& state) const {
    const nerfar::BinaryFormat format{"checkpoint", magic, true, version, version, version, ""};
    nerfar::BinaryFileWriter w(format, version);
    w.Section("IDEN").PutBytes(identity);
    w.Section("TRAN").PutBytes(state);
    return std::move(w).Seal();
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  using namespace nerfar;
  static Fixture fixture;
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  for (const std::string& file :
       {fixture.Sectioned(bytes), fuzz::WithLegacyChecksum("NERFCKP2" + fixture.identity + bytes),
        fuzz::WithCrc32(bytes), fuzz::WithLegacyChecksum(bytes)}) {
    if (!fuzz::WriteBytes(fixture.path, file)) return 0;
    fuzz::Expect([&] { fixture.trainer.LoadCheckpoint(fixture.path); });
  }
  return 0;
}
