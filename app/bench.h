// `nerfar bench`: the one benchmark entry every stage plugs into. A stage
// returns named figures (time and error, e.g. fit_warm_ms, ssd_err_p95_deg);
// the command prints them as a table with machine, threads and date, and
// writes the same figures as JSON. Stages are listed in bench_stages.cpp.
#pragma once

#include <string>
#include <vector>

#include "render/sg/sg.h"

namespace nerfar {

class NerfField;
struct NerfSceneOptions;
struct TriangleMesh;

struct BenchFigure {
  std::string name;  // snake_case with its unit as suffix: fit_warm_ms, psnr_tm_db
  double value = 0;
  std::string unit;  // "ms", "dB", "MB", "M/s", ...
  std::string note;  // preset, size or condition the figure was taken under
};

struct BenchOptions {
  bool quick = false;      // smaller sizes and fewer repeats (for smoke tests)
  std::string scenes_dir;  // ../shared/scenes or empty when absent
};

struct BenchStage {
  const char* name;
  const char* summary;
  std::vector<BenchFigure> (*run)(const BenchOptions& options);
};

const std::vector<BenchStage>& AllBenchStages();

// The environment variables that steer the stages (bench_variables.cpp): a
// stage reads one through BenchVariable (nullptr when unset; a name not in
// the list is a programming error, std::logic_error). CheckBenchEnvironment
// throws InputError naming every NERFAR_BENCH_* variable of `environment`
// (NAME=VALUE entries, null-terminated, as environ) that is not listed.
struct BenchVariableInfo {
  const char* name;
  const char* stages;  // the stages that read it
  const char* what;    // its value and effect, one line
};
const std::vector<BenchVariableInfo>& BenchVariables();
const char* BenchVariable(const char* name);
void CheckBenchEnvironment(const char* const* environment);

// Runs `body` repeatedly for at least min_seconds (and at least min_repeats
// times) and returns the median time of one call in milliseconds.
template <typename Body>
double MedianMilliseconds(Body&& body, int min_repeats = 5, double min_seconds = 0.2);
double MedianOf(std::vector<double> values);
double NowSeconds();

template <typename Body>
double MedianMilliseconds(Body&& body, int min_repeats, double min_seconds) {
  std::vector<double> times;
  const double start = NowSeconds();
  while (static_cast<int>(times.size()) < min_repeats || NowSeconds() - start < min_seconds) {
    const double t0 = NowSeconds();
    body();
    times.push_back((NowSeconds() - t0) * 1e3);
    if (times.size() >= 1000) break;
  }
  return MedianOf(times);
}

// The insertion benches' scene (bench_insert.cpp), shared by bench live:
// the shared scenes' box holding a 4 cm table slab (top at z = 0) and a
// sphere as a 1 cm NeRF grid; the object; the distant light.
NerfField BenchTabletopNerf();
TriangleMesh BenchObjectMesh(const std::string& scenes_dir, std::string* name);
SgMixture BenchEnvironment();
// The insertion benches' NeRF scene options: the preset's
// (NerfSceneOptions::Preset) with the NERFAR_BENCH_INSERT_* overrides of the
// light's march and views (bench_insert_light.cpp); InputError for a value
// out of range.
NerfSceneOptions BenchInsertSceneOptions(const std::string& preset);

// Stage entry points (one bench_NAME.cpp each).
std::vector<BenchFigure> BenchCore(const BenchOptions& options);
std::vector<BenchFigure> BenchTracking(const BenchOptions& options);
std::vector<BenchFigure> BenchEnv(const BenchOptions& options);
std::vector<BenchFigure> BenchInsert(const BenchOptions& options);
std::vector<BenchFigure> BenchSsdf(const BenchOptions& options);
std::vector<BenchFigure> BenchSynth(const BenchOptions& options);
std::vector<BenchFigure> BenchSg(const BenchOptions& options);
std::vector<BenchFigure> BenchNerf(const BenchOptions& options);
std::vector<BenchFigure> BenchLive(const BenchOptions& options);

}  // namespace nerfar
