#include "app/bench.h"

namespace nerfar {

const std::vector<BenchStage>& AllBenchStages() {
  static const std::vector<BenchStage> stages = {
      {"core", "file I/O: EXR read/write, JSON parse", BenchCore},
      {"ssdf", "SSDF bake time, file size, SSD error per preset, query cost", BenchSsdf},
  };
  return stages;
}

}  // namespace nerfar
