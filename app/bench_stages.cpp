#include "app/bench.h"

namespace nerfar {

const std::vector<BenchStage>& AllBenchStages() {
  static const std::vector<BenchStage> stages = {
      {"core", "file I/O: EXR read/write, JSON parse", BenchCore},
      {"tracking", "tag detection + pose at 1280x720 per preset; pose error on the shared scenes", BenchTracking},
      {"env", "environment estimation per preset and pixels x rays on a synthetic scene with a known environment",
       BenchEnv},
      {"insert", "per-frame insertion stages at 1280x720 per preset; quality with ground-truth inputs", BenchInsert},
      {"synth", "synthetic scenes: scene build, one view per scene and preset, camera-stream frame, SG accuracy",
       BenchSynth},
      {"ssdf", "SSDF bake time, file size, SSD error per preset, query cost", BenchSsdf},
      {"sg", "SG shading cost, fit time cold/warm and optimisers, fitted-light error vs lobe count", BenchSg},
      {"live",
       "the live pipeline on pre-rendered 1280x720 frames at 30/s: fps, drops, stages, latency per motion, preset and "
       "thread count",
       BenchLive},
      {"nerf", "NeRF training per preset (time, psnr_tm vs insert/bg, depth error, size), query throughput", BenchNerf},
  };
  return stages;
}

}  // namespace nerfar
