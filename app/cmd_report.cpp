// nerfar report SCENE_OR_SESSION
// The session report (app/live/report.h) of a `nerfar live` session folder,
// or of a SCENE folder (its scene items and its newest session): calibration
// RMS, tracking jitter and loss, light-fit error, environment energy, SSDF
// error estimate, fps and per-stage times, as report.json, report.png and report.html.
#include <cstdio>
#include <nlohmann/json.hpp>

#include "app/cli.h"
#include "app/commands.h"
#include "app/live/report.h"
#include "calib/core/log.h"
#include "calib/core/output_guard.h"

namespace nerfar {

int RunReport(const CommandArgs& args) {
  std::string dir;
  ArgParser parser("report", "The report of a live session (or of a SCENE and its newest session).");
  parser.Positional("DIR", &dir, "a session folder (with session.json) or a SCENE folder");
  parser.Epilog(
      "writes DIR/report.json, report.png and report.html (for a SCENE: into its newest session, or into SCENE\n"
      "when it has none) and prints the figures.\n"
      "example:\n"
      "  nerfar report demo_out/session\n");
  if (!parser.Parse(args)) return 0;
  std::string report_dir;
  const Json report = BuildReport(dir, &report_dir);
  CheckOutputsSpareInputs(FilesIn(report_dir, {"report.json", "report.png", "report.html"}),
                          report.at("inputs").get<std::vector<std::string>>());
  WriteReport(report, report_dir);
  LogInfo("report: wrote " + report_dir + "/report.json, report.png and report.html");
  return 0;
}

}  // namespace nerfar
