#include "app/bench.h"

namespace nerfar {

const std::vector<BenchStage>& AllBenchStages() {
  static const std::vector<BenchStage> stages = {
      {"core", "file I/O: EXR read/write, JSON parse", BenchCore},
  };
  return stages;
}

}  // namespace nerfar
