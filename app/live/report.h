// The session of a live run and its report. `nerfar live` writes
// SESSION/session.json (options, counters, the last errors the loop went on
// after, one record per processed frame:
// tracking state, pose, true pose where the source knows it, per-stage ms,
// capture-to-display latency; the objects as they were at the end: placed,
// anchor, yaw, scale, material, world pose) and the last views (last_ar.png, ...); the
// report is computed from those and the SCENE's files: calibration RMS,
// tracking jitter and loss (and error against the truth), light-fit error,
// environment energy, SSDF error estimate (field against brute-force ray
// casting), fps and per-stage times, and the per-frame series behind the
// plots (stages, latency, pose jitter, tracking state, light refits).
// Written as SESSION/report.json, a one-page SESSION/report.png (views,
// plots, figures) and the same page as one self-contained report.html.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "app/live/pipeline.h"
#include "calib/core/json.h"

namespace nerfar {

struct SessionInfo {
  std::string scene_dir;             // SCENE ("" for none)
  std::string source;                // the source string
  std::string camera_path;           // camera.json / transforms.json used ("" = the source's own)
  std::vector<std::string> objects;  // object files
  std::string mode;                  // "window" or "headless"
  double wall_s = 0;                 // seconds from start to end
  int threads = 0;
  std::string load;  // /proc/loadavg at the end (others' work inflates times)
  // Frame whose pose placed object 0 by --auto-place (-1: not auto-placed).
  std::int64_t auto_placed_frame = -1;
};

// SESSION/session.json (atomic).
void WriteSession(const std::string& session_dir, const SessionInfo& info, const LivePipeline& pipeline);

// The report of a session folder (with session.json), or of a SCENE folder
// (scene items only, plus its newest sessions/* if any); its "inputs" list
// the files it was computed from. InputError when the folder is neither.
Json BuildReport(const std::string& dir, std::string* report_dir = nullptr);
// Writes report.json, report.png and report.html into report_dir and prints
// the figures.
void WriteReport(const Json& report, const std::string& report_dir);

// Median and 90th percentile of values (NaN for none).
double PercentileOf(std::vector<double> values, double q);

}  // namespace nerfar
