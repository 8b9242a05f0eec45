// nerfar bench [STAGE...] [--json FILE] [--quick]
#include <sys/utsname.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <thread>

#include "app/bench.h"
#include "app/cli.h"
#include "app/commands.h"
#include "app/scenes.h"
#include "calib/core/error.h"
#include "calib/core/json.h"
#include "calib/core/log.h"
#include "calib/core/parallel.h"

namespace nerfar {

double NowSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

double MedianOf(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const size_t n = values.size();
  return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

namespace {

std::string CpuModel() {
  std::ifstream cpuinfo("/proc/cpuinfo");
  std::string line;
  while (std::getline(cpuinfo, line)) {
    if (line.rfind("model name", 0) == 0) {
      const size_t colon = line.find(':');
      if (colon != std::string::npos) return line.substr(colon + 2);
    }
  }
  utsname name{};
  return ::uname(&name) == 0 ? name.machine : "unknown";
}

std::string IsoDate() {
  const std::time_t now = std::time(nullptr);
  char buffer[32];
  std::strftime(buffer, sizeof buffer, "%Y-%m-%d %H:%M:%S UTC", std::gmtime(&now));
  return buffer;
}

}  // namespace

int RunBench(const CommandArgs& args) {
  std::vector<std::string> stage_names;
  std::string json_path;
  BenchOptions options;
  ArgParser parser("bench", "Measure each stage's speed and accuracy (all stages if none is named).");
  parser.Positionals("STAGE", &stage_names, "stages to run");
  parser.Option("--json", &json_path, "FILE", "also write the figures as JSON");
  parser.Flag("--quick", &options.quick, "small sizes and few repeats (a smoke test, not for the record)");
  std::string stage_list;
  for (const BenchStage& stage : AllBenchStages())
    stage_list += std::string("  ") + stage.name + ": " + stage.summary + "\n";
  std::string variable_list;
  for (const BenchVariableInfo& v : BenchVariables())
    variable_list += std::string("  ") + v.name + " (" + v.stages + "): " + v.what + "\n";
  parser.Epilog("stages:\n" + stage_list +
                "\nenvironment variables (any other NERFAR_BENCH_* is an error; docs/USER_GUIDE.md tables their "
                "defaults):\n" +
                variable_list);
  if (!parser.Parse(args)) return 0;
  CheckBenchEnvironment(environ);
  options.scenes_dir = FindSharedScenes();

  std::vector<const BenchStage*> selected;
  for (const std::string& name : stage_names) {
    const BenchStage* found = nullptr;
    for (const BenchStage& stage : AllBenchStages())
      if (name == stage.name) found = &stage;
    if (found == nullptr) throw InputError("nerfar bench: unknown stage '" + name + "' (see 'nerfar bench --help')");
    selected.push_back(found);
  }
  if (selected.empty())
    for (const BenchStage& stage : AllBenchStages()) selected.push_back(&stage);

  const std::string machine = CpuModel() + ", " + std::to_string(std::thread::hardware_concurrency()) + " cores";
  const std::string date = IsoDate();
  std::printf("nerfar bench  %s  threads %d  %s%s\n", machine.c_str(), ThreadCount(), date.c_str(),
              options.quick ? "  (quick)" : "");
  std::printf("%-10s %-34s %14s %-6s %s\n", "stage", "figure", "value", "unit", "condition");

  Json report = {{"machine", machine}, {"threads", ThreadCount()}, {"date", date}, {"quick", options.quick}};
  Json stages = Json::object();
  for (const BenchStage* stage : selected) {
    LogInfo(std::string("bench: running ") + stage->name + "...");
    const double start = NowSeconds();
    const std::vector<BenchFigure> figures = stage->run(options);
    Json list = Json::array();
    for (const BenchFigure& f : figures) {
      std::printf("%-10s %-34s %14.4g %-6s %s\n", stage->name, f.name.c_str(), f.value, f.unit.c_str(), f.note.c_str());
      list.push_back({{"name", f.name}, {"value", f.value}, {"unit", f.unit}, {"note", f.note}});
    }
    stages[stage->name] = {{"figures", list}, {"seconds", NowSeconds() - start}};
  }
  std::fflush(stdout);
  report["stages"] = stages;
  if (!json_path.empty()) {
    WriteJsonFile(json_path, report);
    LogInfo("bench: wrote " + json_path);
  }
  return 0;
}

}  // namespace nerfar
