// nerfar env scene.nerf -o env.json [--preview env.exr] [--report FILE|DIR | --no-report] [--truth env.exr]
//            [--preset P] [--set key=value]...
// Estimates the distant environment light that the NeRF does not hold (paper
// §4.2) as SG lobes, writes env.json (render/lighting/env_light.h), an
// equirect preview and the report picture (render/lighting/env_report.h);
// states the fit's residual and, with a true panorama, the irradiance error;
// says when the estimate is negligible against the near field.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "app/cli.h"
#include "app/commands.h"
#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "calib/core/image_io.h"
#include "calib/core/log.h"
#include "calib/core/output_guard.h"
#include "render/lighting/env_estimate.h"
#include "render/lighting/env_light.h"
#include "render/lighting/env_report.h"
#include "render/lighting/seen_radiance.h"
#include "render/nerf/nerf_file.h"
#include "render/sg/sphere.h"

namespace nerfar {
namespace {

// The report picture's path: --report FILE as given; --report DIR (an
// existing folder, or a name ending in '/') or no --report: NAME_report.png
// there or beside the output (env.json -> env_report.png).
std::string ReportPath(const std::string& output, const std::string& report) {
  namespace fs = std::filesystem;
  const std::string name = fs::path(output).stem().string() + "_report.png";
  if (report.empty()) return (fs::path(output).parent_path() / name).string();
  std::error_code error;
  if (report.back() == '/' || fs::is_directory(report, error)) return (fs::path(report) / name).string();
  const std::string extension = fs::path(report).extension().string();
  if (extension != ".png" && extension != ".jpg" && extension != ".jpeg")
    throw InputError("nerfar env: --report " + report + ": not a folder, and not a .png or .jpg file");
  return report;
}

void LogFitResidual(const EnvLight& env) {
  const EnvFitResidual& fit = env.fit;
  char line[400];
  std::snprintf(line, sizeof line,
                "env: fit residual over %lld surface samples: relative RMS %.4f, robust loss %.5f per sample",
                fit.samples, fit.relative_rms, fit.loss);
  std::string text = line;
  if (fit.near_only_fitted) {
    std::snprintf(line, sizeof line, "; near field only: relative RMS %.4f, robust loss %.5f",
                  fit.near_only_relative_rms, fit.near_only_loss);
    text += line;
  }
  LogInfo(text);
}

// --dump-samples: every surface sample with what was observed and modelled there, as CSV.
void WriteSamplesCsv(const std::string& path, const EnvEstimateReport& report) {
  std::string csv =
      "x,y,z,nx,ny,nz,L_r,L_g,L_b,Enerf_r,Enerf_g,Enerf_b,Eenv_r,Eenv_g,Eenv_b,Lmodel_r,Lmodel_g,Lmodel_b\n";
  const EnvSurfaceSamples& s = report.surface;
  const std::vector<Vec3f>& model = report.fit.modelled;
  for (size_t i = 0; i < s.size(); ++i) {
    char row[500];
    std::snprintf(row, sizeof row,
                  "%.5f,%.5f,%.5f,%.4f,%.4f,%.4f,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g\n",
                  s.positions[i].x, s.positions[i].y, s.positions[i].z, s.normals[i].x, s.normals[i].y, s.normals[i].z,
                  s.radiance[i].x, s.radiance[i].y, s.radiance[i].z, s.e_nerf[i].x, s.e_nerf[i].y, s.e_nerf[i].z,
                  report.e_env[i].x, report.e_env[i].y, report.e_env[i].z, model[i].x, model[i].y, model[i].z);
    csv += row;
  }
  WriteFileAtomic(path, csv);
}

// What the estimate found and why it is kept or judged negligible.
void LogEstimate(const EnvLight& env, const EnvEstimateReport& report) {
  char line[512];
  std::snprintf(line, sizeof line,
                "env: %d views rendered, %d kept; %zu surface samples; %d lobes (dictionary %d); fit relative RMS "
                "%.3f, mean albedo %.3f, near-field gain %.2f; times: views %.1fs, rays %.1fs, fit %.1fs",
                report.views.rendered, report.views.accepted, report.samples, report.fit.active_lobes,
                report.fit.dictionary_size, report.fit.relative_rms, report.fit.mean_albedo, report.fit.near_field_gain,
                report.seconds_views, report.seconds_near_field, report.seconds_fit);
  LogInfo(line);
  std::snprintf(line, sizeof line,
                "env: of %ld picked pixels, %ld dropped as not surface-like (fog), %ld without a normal (depth "
                "edges), %ld seen too grazing",
                report.views.pixels_tried, report.views.pixels_not_surface, report.views.pixels_no_normal,
                report.views.pixels_grazing);
  LogInfo(line);
  std::snprintf(line, sizeof line,
                "env: environment / near-field irradiance: %.4f over the surface samples, %.4f at the volume centre",
                env.env_to_near_surface, env.env_to_near_center);
  LogInfo(line);
  if (env.evidence_needed > 0) {
    std::snprintf(line, sizeof line,
                  "env: model selection: the environment's log-likelihood gain over the near field alone %.1f, "
                  "BIC penalty for its %d lobes %.1f: %s",
                  env.evidence, report.fit.active_lobes, env.evidence_needed,
                  report.fit.environment_supported ? "supported by the data" : "not supported by the data");
    LogInfo(line);
  }
  if (env.negligible)
    LogInfo(std::string("env: the estimate is negligible (") +
            (report.fit.environment_supported
                 ? "below " + std::to_string(env.threshold) + " of the near field"
                 : "the near field alone explains the observations as well, up to the environment's parameters") +
            "): all light is inside the NeRF; env.json says so and insertion drops the environment term");
  for (const std::string& source : SourceSupportLines(env.lobes, report.fit.lobe_support)) LogInfo("env: " + source);
  LogFitResidual(env);
}

}  // namespace

int RunEnv(const CommandArgs& args) {
  std::string nerf_path, output, preview, dump, report_option, truth_path, preset = "balanced";
  bool no_report = false;
  std::vector<std::string> sets;
  ArgParser parser("env", "Estimate the distant environment light (32 SGs) of a NeRF by inverse rendering.");
  parser.Positional("NERF", &nerf_path, "trained model (.nerf)");
  parser.Option("-o", &output, "FILE", "output env.json");
  parser.Required("-o");
  parser.Option("--preview", &preview, "FILE", "also write a 256x128 equirect EXR of the estimate");
  parser.Option(
      "--dump-samples", &dump, "FILE",
      "also write the surface samples as CSV (position, normal, observed L, E_nerf, E_env, the fit's modelled L; "
      "diagnostics)");
  parser.Option("--report", &report_option, "FILE|DIR",
                "report picture (PNG): the estimate's panorama with its lobes, the fit's residual over the surface "
                "samples in 4 of the sampled views, the numbers; default NAME_report.png beside -o (a folder: in it)");
  parser.Flag("--no-report", &no_report, "write no report picture (saves rendering 4 views)");
  parser.Option("--truth", &truth_path, "FILE",
                "true environment panorama (equirect EXR, as scenes/*/env.exr): in the report beside the estimate "
                "with their difference, and the irradiance error over the upper hemisphere (eval/metrics.py "
                "irradiance --upper) printed");
  parser.Option("--preset", &preset, "P", "fast | balanced (default) | accurate");
  parser.Option("--set", &sets, "KEY=VALUE", "override one option (repeatable; see below)");
  parser.Epilog("Options (--set): " + EnvEstimateOptions::Preset("balanced").ToJson() +
                "\nBaseline that ignores the NeRF's light and visibility: --set ignore_near_field=true\n"
                "Example: nerfar env window.nerf -o env.json --preview env.exr --truth scenes/window/env.exr");
  if (!parser.Parse(args)) return 0;
  EnvEstimateOptions options = EnvEstimateOptions::Preset(preset);
  for (const std::string& s : sets) options.Set(s);
  {
    const std::vector<std::string> problems = options.Validate();
    if (!problems.empty()) {
      Problems list("nerfar env");
      for (const std::string& p : problems) list.Add("options", p);
      list.ThrowIfAny();
    }
  }
  if (no_report && !report_option.empty())
    throw InputError("nerfar env: --report and --no-report contradict each other");
  const std::string report_path = no_report ? "" : ReportPath(output, report_option);
  CheckOutputsSpareInputs({output, preview, dump, report_path}, {nerf_path, truth_path});
  // The truth is read before the estimate, so that a bad file fails at once.
  const ImageF truth = truth_path.empty() ? ImageF() : ReadTruePanorama(truth_path);
  const NerfField field = LoadNerf(nerf_path);
  LogInfo("env: " + nerf_path + "; preset " + preset + "; options " + options.ToJson() + "; seen radiance " +
          SeenViewsNote(field, SeenOptions(options)));

  // One progress bar (with ETA) per stage.
  std::unique_ptr<Progress> bar;
  std::string stage_now;
  const EnvProgress progress = [&](const std::string& stage, size_t done, size_t total) {
    if (stage != stage_now) {
      if (bar) bar->Finish();
      bar = std::make_unique<Progress>("env " + stage, total);
      stage_now = stage;
    }
    bar->Update(done);
  };
  EnvEstimateReport report;
  report.keep_samples = !dump.empty() || !report_path.empty();
  EnvLight env = EstimateEnvironment(field, options, &report, progress);
  if (bar) bar->Finish();
  bar.reset();
  env.source = nerf_path;
  WriteEnvLight(output, env);
  if (!preview.empty()) WriteEnvPreview(preview, env);
  if (!dump.empty()) WriteSamplesCsv(dump, report);
  LogEstimate(env, report);
  if (!truth.empty()) {
    const ImageF estimate = RenderEquirect(env.lobes, truth.width, truth.height);
    char line[512];
    std::snprintf(line, sizeof line,
                  "env: irradiance error against %s (luminance, relative RMS; eval/metrics.py irradiance): %.4f over "
                  "the 32 upper-hemisphere normals (--upper), %.4f over all 64",
                  truth_path.c_str(), IrradianceError(estimate, truth, true), IrradianceError(estimate, truth, false));
    LogInfo(line);
  }
  if (!report_path.empty()) {
    const auto start = std::chrono::steady_clock::now();
    EnvReportOptions report_options;
    report_options.render = options.render;
    const Image8 picture =
        RenderEnvReport(field, env, report, truth.empty() ? nullptr : &truth, report_options, nullptr, progress);
    if (bar) bar->Finish();
    const std::string folder = std::filesystem::path(report_path).parent_path().string();
    if (!folder.empty()) MakeDirectories(folder);
    WriteImage8(report_path, picture);
    LogInfo("env: wrote the report " + report_path + " (" +
            FormatDuration(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count()) + ")");
  }
  LogInfo("env: wrote " + output + (preview.empty() ? "" : " and " + preview));
  return 0;
}

}  // namespace nerfar
