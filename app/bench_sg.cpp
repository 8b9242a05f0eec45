// Bench stage "sg": spherical-Gaussian shading cost, SG fit time cold and warm
// on 2048 directions (one core), the optimisers side by side, and the error of
// the fitted light against the lobe count (8/16/32/64) on the shared panoramas
// (window/env.exr and every insert/*/probe.exr; skipped when absent).
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <random>
#include <string>

#include "app/bench.h"
#include "calib/core/exr.h"
#include "calib/core/metrics.h"
#include "render/sg/brdf.h"
#include "render/sg/fit.h"
#include "render/sg/sphere.h"
#include "render/sg/visibility.h"

namespace nerfar {

namespace {

// A light without the shared scenes: a sky-like broad part plus a bright
// window-like cluster, sampled like a 64 × 32 panorama.
SgMixture SyntheticLight() {
  SgMixture light;
  const std::vector<Vec3> axes = FibonacciSphere(24);
  for (size_t k = 0; k < axes.size(); ++k)
    light.push_back({axes[k], 2.0 + static_cast<double>(k % 5), Vec3(0.2, 0.22, 0.3) * (1.0 + 0.1 * (k % 3))});
  const Vec3 window = Normalized(Vec3(0.6, 0.55, 0.45));
  for (int k = 0; k < 6; ++k) {
    const Vec3 offset(0.05 * std::cos(k), 0.05 * std::sin(k), 0.03 * (k % 2));
    light.push_back({Normalized(window + offset), 300.0, Vec3(35, 32, 27)});
  }
  return light;
}

ImageF SyntheticPanorama() { return RenderEquirect(SyntheticLight(), 256, 128); }

struct LightError {
  double irradiance_rel_rms = 0;
  double psnr_tm = 0;
};

// Lighting error of DESIGN.md (irradiance for 64 normals, relative RMS) and
// psnr_tm of the panorama rendered from the fit.
LightError ErrorOf(const SgMixture& fit, const ImageF& pano) {
  double num = 0.0, den = 0.0;
  for (const Vec3& n : FibonacciSphere(64)) {
    const double a = LuminanceOf(Irradiance(fit, n)), b = LuminanceOf(PanoramaIrradiance(pano, n));
    num += (a - b) * (a - b);
    den += b * b;
  }
  return {den > 0.0 ? std::sqrt(num / den) : 0.0, PsnrTm(RenderEquirect(fit, pano.width, pano.height), pano)};
}

RadianceSamples Rotated(RadianceSamples samples, double angle_rad) {
  const Mat3 r = RotationFromAxisAngle(Vec3(0, 0, 1), angle_rad);
  for (Vec3& d : samples.directions) d = r * d;
  return samples;
}

std::string MapName(const std::string& scenes, const std::string& path) {
  return std::filesystem::relative(path, scenes).string();
}

// How long each timing runs: fewer repeats for --quick.
struct Timing {
  int repeats;
  double min_seconds;
  bool quick;
};

// The panorama the fit timings use: the window scene's env.exr, or a
// synthetic one without the shared scenes.
struct FitPanorama {
  ImageF pano;
  std::string source;
};

FitPanorama PanoramaForFits(const BenchOptions& options) {
  if (!options.scenes_dir.empty() && std::filesystem::exists(options.scenes_dir + "/window/env.exr"))
    return {ReadExrRgb(options.scenes_dir + "/window/env.exr"), "window/env.exr"};
  return {SyntheticPanorama(), "synthetic sky + window"};
}

// Fit time of the default method, cold and warm after a 2° rotation; returns
// the cold fit.
SgMixture AddFitTimes(const RadianceSamples& samples, const std::string& condition, const Timing& timing,
                      std::vector<BenchFigure>& figures) {
  const SgFitOptions fit_options;  // balanced: 32 lobes
  SgMixture cold;
  figures.push_back(
      {"fit_cold_ms",
       MedianMilliseconds([&] { cold = FitSg(samples, fit_options); }, timing.repeats, timing.min_seconds), "ms",
       condition + ", 32 lobes (budget 80)"});
  const RadianceSamples moved = Rotated(samples, 2.0 * kPi / 180.0);
  SgFitReport warm_report;
  figures.push_back({"fit_warm_ms",
                     MedianMilliseconds([&] { FitSg(moved, fit_options, &cold, &warm_report); }, timing.repeats * 3,
                                        timing.min_seconds),
                     "ms", condition + ", 32 lobes, light turned 2 deg (budget 3)"});
  {
    // The fastest of 30 warm fits: on a shared machine the median carries the
    // other processes' load, the minimum is the least disturbed run.
    double best = 1e300;
    for (int r = 0; r < (timing.quick ? 5 : 30); ++r) {
      const double t0 = NowSeconds();
      FitSg(moved, fit_options, &cold);
      best = std::min(best, (NowSeconds() - t0) * 1e3);
    }
    figures.push_back({"fit_warm_ms_best", best, "ms", condition + ", 32 lobes, light turned 2 deg, fastest of 30"});
  }
  SgFitReport moved_cold_report;
  FitSg(moved, fit_options, nullptr, &moved_cold_report);
  figures.push_back({"fit_warm_loss_ratio", warm_report.final_loss / moved_cold_report.final_loss, "",
                     "warm loss / cold loss on the turned light"});
  return cold;
}

// The optimisers side by side (docs/SG.md): time and result of a cold fit.
void AddOptimisers(const RadianceSamples& samples, const ImageF& pano, const std::string& condition,
                   const Timing& timing, std::vector<BenchFigure>& figures) {
  const std::vector<const char*>& names = SgFitMethodNames();
  for (size_t method = 0; method < names.size(); ++method) {
    SgFitOptions o;
    o.method = static_cast<SgFitMethod>(method);
    const std::string name = names[method];
    if (timing.quick) {
      o.cold_iterations = 3;
      o.adam_iterations = 20;
    }
    SgFitReport report;
    SgMixture fit;
    const double ms = MedianMilliseconds([&] { fit = FitSg(samples, o, nullptr, &report); }, 1, 0.0);
    const LightError error = ErrorOf(fit, pano);
    const std::string note = name + ", " + condition + ", 32 lobes";
    figures.push_back({"fit_cold_ms_" + name, ms, "ms", note});
    figures.push_back({"fit_loss_" + name, report.final_loss, "", note});
    figures.push_back({"fit_irradiance_rel_rms_" + name, error.irradiance_rel_rms, "", note});
  }
}

// Random shading inputs: a normal, a view direction and 32 γ per pixel.
struct ShadePixels {
  int count = 4096;
  std::vector<Vec3f> normals, views;
  std::vector<float> gamma;

  ShadePixels() : normals(count), views(count), gamma(32 * count) {
    std::mt19937 rng(1);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    for (int p = 0; p < count; ++p) {
      normals[p] = Normalized(Vec3f(u(rng), u(rng), u(rng) + 0.01f));
      views[p] = Normalized(normals[p] + Vec3f(u(rng), u(rng), u(rng)) * 0.5f);
      for (int k = 0; k < 32; ++k) gamma[32 * p + k] = 0.5f + 0.5f * u(rng);
    }
  }
};

// Shading cost per pixel, 32 lobes (prepared float path), one call per pixel
// and one many-pixel call, for a diffuse and a glossy material.
void AddShadeCost(const SgShader& shader, const ShadePixels& px, const Timing& timing,
                  std::vector<BenchFigure>& figures) {
  const int pixels = px.count;
  for (const auto& [name, material] : {std::pair{"diffuse", SgMaterial{Vec3(0.8, 0.35, 0.2), 0.7, 0.0}},
                                       std::pair{"glossy", SgMaterial{Vec3(0.9, 0.9, 0.9), 0.25, 1.0}}}) {
    float sink = 0.0f;
    const double ms = MedianMilliseconds(
        [&] {
          for (int p = 0; p < pixels; ++p)
            sink += shader.Shade(material, px.normals[p], px.views[p], &px.gamma[32 * p]).x;
        },
        timing.repeats, timing.min_seconds);
    if (!std::isfinite(sink)) figures.push_back({"shade_nonfinite", 1, "", name});
    const std::string suffix = std::string(name) == "diffuse" ? "" : "_glossy";
    figures.push_back({"shade_ns_per_pixel" + suffix, ms * 1e6 / pixels, "ns",
                       std::string(name) + " material, 32 lobes, with gamma, 1 thread, one call per pixel "
                                           "(insertion budget: ~65 ns on 2 cores, 6 ms for 92k pixels)"});
    // The same pixels in one many-pixel call (the fast path).
    const std::vector<SgMaterial> materials(pixels, material);
    std::vector<Vec3f> out(pixels);
    const double batch_ms = MedianMilliseconds(
        [&] {
          shader.Shade(materials.data(), px.normals.data(), px.views.data(), px.gamma.data(), pixels, out.data());
          sink += out[0].x;
        },
        timing.repeats, timing.min_seconds);
    figures.push_back({"shade_batch_ns_per_pixel" + suffix, batch_ms * 1e6 / pixels, "ns",
                       std::string(name) + " material, 32 lobes, with gamma, 1 thread, " + std::to_string(pixels) +
                           " pixels per call (insertion budget: ~130 ns per pixel on one core)"});
  }
}

// γ for 32 lobes per pixel (the SSDF values given).
void AddGammaCost(const SgMixture& light, const ShadePixels& px, const Timing& timing,
                  std::vector<BenchFigure>& figures) {
  std::vector<SgTableRow> rows;
  for (const Sg& sg : light) rows.push_back(PrepareGamma(sg.sharpness));
  float sink = 0.0f;
  const double gamma_ms = MedianMilliseconds(
      [&] {
        for (int p = 0; p < px.count; ++p)
          for (int k = 0; k < 32; ++k) sink += GammaPrepared(rows[k], px.gamma[32 * p + k] - 0.5f);
      },
      timing.repeats, timing.min_seconds);
  figures.push_back({"gamma_ns_per_pixel_32_lobes", gamma_ms * 1e6 / px.count + 0.0 * sink, "ns",
                     "table lookups, SSD given, 1 thread"});
}

// The panoramas the lobe-count errors are taken on: window/env.exr and every
// insert/*/probe.exr of the shared scenes (one with --quick), or a synthetic one.
std::vector<std::pair<std::string, ImageF>> LightMaps(const BenchOptions& options, const ImageF& window_env) {
  std::vector<std::pair<std::string, ImageF>> maps;
  if (!options.scenes_dir.empty()) {
    namespace fs = std::filesystem;
    const std::string env = options.scenes_dir + "/window/env.exr";
    if (fs::exists(env)) maps.emplace_back(MapName(options.scenes_dir, env), window_env);
    std::vector<std::string> probes;
    std::error_code error;
    for (const auto& scene : fs::directory_iterator(options.scenes_dir, error)) {
      const fs::path insert = scene.path() / "insert";
      if (!fs::is_directory(insert, error)) continue;
      for (const auto& object : fs::directory_iterator(insert, error))
        if (fs::exists(object.path() / "probe.exr")) probes.push_back((object.path() / "probe.exr").string());
    }
    std::sort(probes.begin(), probes.end());
    for (const std::string& p : probes) maps.emplace_back(MapName(options.scenes_dir, p), ReadExrRgb(p));
  }
  if (maps.empty()) maps.emplace_back("synthetic", SyntheticPanorama());
  if (options.quick) maps.resize(1);
  return maps;
}

// The error of the fitted light against the lobe count (8/16/32/64).
void AddLobeCountErrors(const std::vector<std::pair<std::string, ImageF>>& maps, bool quick,
                        std::vector<BenchFigure>& figures) {
  for (const auto& [name, map] : maps) {
    const RadianceSamples s = SamplesFromEquirect(map, 64, 32);
    for (int lobes : {8, 16, 32, 64}) {
      SgFitOptions o;
      o.lobes = lobes;
      if (quick) o.cold_iterations = 3;
      const double t0 = NowSeconds();
      const SgMixture fit = FitSg(s, o);
      const double ms = (NowSeconds() - t0) * 1e3;
      const LightError error = ErrorOf(fit, map);
      const std::string note = name + ", cold fit " + std::to_string(static_cast<int>(ms + 0.5)) + " ms";
      figures.push_back({"irradiance_rel_rms_" + std::to_string(lobes) + "_lobes", error.irradiance_rel_rms, "", note});
      figures.push_back({"psnr_tm_" + std::to_string(lobes) + "_lobes", error.psnr_tm, "dB", note});
    }
  }
}

}  // namespace

std::vector<BenchFigure> BenchSg(const BenchOptions& options) {
  std::vector<BenchFigure> figures;
  const Timing timing{options.quick ? 3 : 7, options.quick ? 0.05 : 0.5, options.quick};
  const FitPanorama fit_pano = PanoramaForFits(options);
  const RadianceSamples samples = SamplesFromEquirect(fit_pano.pano, 64, 32);
  const std::string condition = "2048 directions, " + fit_pano.source + ", 1 thread";
  const SgMixture cold = AddFitTimes(samples, condition, timing, figures);
  AddOptimisers(samples, fit_pano.pano, condition, timing, figures);
  {
    const SgMixture light = cold.size() == 32 ? cold : FitSg(samples, SgFitOptions());
    const SgShader shader(light);
    const ShadePixels pixels;
    AddShadeCost(shader, pixels, timing, figures);
    AddGammaCost(light, pixels, timing, figures);
  }
  AddLobeCountErrors(LightMaps(options, fit_pano.pano), options.quick, figures);
  return figures;
}

}  // namespace nerfar
