// The environment variables that steer `nerfar bench`, listed once: the
// stages read them through BenchVariable (which refuses a name not listed
// here), `nerfar bench --help` prints the list, and RunBench refuses an unset
// NERFAR_BENCH_* name that is not in it, so a misspelt variable stops the
// bench instead of being ignored. docs/USER_GUIDE.md (section Benchmarks)
// tables the same names with their values and defaults.
#include <cstdlib>
#include <stdexcept>
#include <string>

#include "app/bench.h"
#include "calib/core/error.h"

namespace nerfar {

const std::vector<BenchVariableInfo>& BenchVariables() {
  static const std::vector<BenchVariableInfo> list = {
      {"NERFAR_BENCH_NERF_PRESETS", "nerf", "presets trained on each scene, comma-separated"},
      {"NERFAR_BENCH_NERF_MODELS", "nerf", "SCENE=FILE,...: score these models instead of training"},
      {"NERFAR_BENCH_ENV_MODELS", "env", "SCENE=FILE,...: each shared scene end to end with its trained NeRF"},
      {"NERFAR_BENCH_ENV_PRESET", "env", "preset of the shared-scene runs"},
      {"NERFAR_BENCH_ENV_SET", "env", "key=value;...: options as `nerfar env --set` sets them"},
      {"NERFAR_BENCH_ENV_TRADE", "env", "1 or PxR,...: the pixels x rays cells"},
      {"NERFAR_BENCH_ENV_TRADE_ONLY", "env", "1: only the pixels x rays cells"},
      {"NERFAR_BENCH_INSERT_PRESETS", "insert", "presets timed on the bench frame (none: none)"},
      {"NERFAR_BENCH_INSERT_GT", "insert", "0: skip the quality with ground-truth inputs"},
      {"NERFAR_BENCH_INSERT_KNOBS", "insert", "key=value,...: any `nerfar insert --set` key over the preset"},
      {"NERFAR_BENCH_INSERT_PARALLAX", "insert", "0: near-light parallax off"},
      {"NERFAR_BENCH_INSERT_OFF", "insert", "snap,skip_covered: those kappa savings off"},
      {"NERFAR_BENCH_INSERT_SUN", "insert, live", "sharpness: also a small, very bright sun in the light"},
      {"NERFAR_BENCH_INSERT_HANDHELD_FRAMES", "insert", "hand-held frames (2-1000)"},
      {"NERFAR_BENCH_INSERT_HANDHELD_ONLY", "insert", "1: only the preset's hand-held frames (profiling)"},
      {"NERFAR_BENCH_INSERT_SSDF_CACHE", "insert", "PATH: the object's SSDF read from (or baked to) PATH"},
      {"NERFAR_BENCH_INSERT_NERF", "insert", "MODEL.nerf: also the incident light on this trained NeRF"},
      {"NERFAR_BENCH_INSERT_NERF_POSE", "insert", "pose.json of the object for the trained NeRF's light"},
      {"NERFAR_BENCH_INSERT_NERF_COPY", "insert", "0: march the model's float arrays, not its render copy"},
      {"NERFAR_BENCH_INSERT_LIGHT_PRESETS", "insert", "presets of the trained NeRF's light"},
      {"NERFAR_BENCH_INSERT_LIGHT_RENDER", "insert", "full, live or preview: the light rays' march"},
      {"NERFAR_BENCH_INSERT_LIGHT_DIRECTIONS", "insert", "light directions (as --light-directions)"},
      {"NERFAR_BENCH_INSERT_LIGHT_REFINE", "insert", "sub-rays per refined direction (as --light-refine-rays)"},
      {"NERFAR_BENCH_INSERT_SEE_THROUGH", "insert", "0: semi-transparent content kept whole"},
      {"NERFAR_BENCH_INSERT_SEEN_VIEWS", "insert", "views per point (as --seen-views)"},
      {"NERFAR_BENCH_INSERT_SEEN_GROUP_CM", "insert", "cell of shared views in cm (as --seen-group-cm)"},
      {"NERFAR_BENCH_INSERT_VIEWS_CACHE", "insert", "0 / 1: the views' cache across frames"},
      {"NERFAR_BENCH_INSERT_DRAG_FRAMES", "insert", "frames of the drag (at least 2)"},
      {"NERFAR_BENCH_INSERT_DRAG_MM", "insert", "millimetres the object moves a frame"},
      {"NERFAR_BENCH_LIVE_FRAMES", "live", "frames of each run (20-3000)"},
      {"NERFAR_BENCH_LIVE_RUNS", "live",
       "TEXT: only the runs whose label holds TEXT, e.g. still_balanced_t1 (profiling)"},
  };
  return list;
}

const char* BenchVariable(const char* name) {
  for (const BenchVariableInfo& v : BenchVariables())
    if (std::string(v.name) == name) return std::getenv(name);
  throw std::logic_error(std::string("BenchVariable: ") + name + " is not in BenchVariables() (list it there)");
}

void CheckBenchEnvironment(const char* const* environment) {
  const std::string prefix = "NERFAR_BENCH_";
  std::string unknown;
  for (const char* const* entry = environment; entry != nullptr && *entry != nullptr; ++entry) {
    const std::string text = *entry;
    if (text.rfind(prefix, 0) != 0) continue;
    const std::string name = text.substr(0, text.find('='));
    bool listed = false;
    for (const BenchVariableInfo& v : BenchVariables()) listed |= name == v.name;
    if (!listed) unknown += (unknown.empty() ? "" : ", ") + name;
  }
  if (!unknown.empty())
    throw InputError("nerfar bench: unknown environment variable " + unknown +
                     " (a misspelling? the variables are listed in 'nerfar bench --help'; unset it to run)");
}

}  // namespace nerfar
