// Bench stage "env": environment estimation (paper §4.2) on a synthetic NeRF
// grid whose radiance is computed here from a known environment (a Lambertian
// floor and a floating ball, analytic visibility, albedo 0.5): time and the
// relative RMS irradiance error over upper-hemisphere normals, for each preset
// and for the pixels x rays trade (paper figure rays_pixels).
// End to end on the shared scenes, with NeRFs trained beforehand and named in
// $NERFAR_BENCH_ENV_MODELS ("window=/tmp/w.nerf,lamps=/tmp/l.nerf"; preset
// $NERFAR_BENCH_ENV_PRESET, default balanced): the estimate against env.exr
// (window) and against the near field (lamps), the total irradiance at each
// object centre against probe.exr for the estimate and the two baselines
// (near field alone; environment fitted ignoring the near field and NeRF
// visibility, PhySG-like) and for env.exr itself seen through the NeRF (what
// the NeRF alone limits). $NERFAR_BENCH_ENV_TRADE=1 adds the pixels x rays
// table on each scene (or "16x64,64x256": those cells only), and
// $NERFAR_BENCH_ENV_TRADE_ONLY=1 skips everything else. $NERFAR_BENCH_ENV_SET="key=value;..." overrides
// options as `nerfar env --set` does (the PhySG-like baseline takes them too).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <map>
#include <sstream>
#include <string>

#include "app/bench.h"
#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "calib/core/log.h"
#include "calib/object.h"
#include "render/lighting/env_estimate.h"
#include "render/nerf/nerf_file.h"
#include "render/sg/sphere.h"
#include "render/sg/visibility.h"

namespace nerfar {
namespace {

const Vec3 kBall{0.1, -0.05, 0.45};
constexpr double kBallRadius = 0.25;

bool Blocked(const Vec3& x, const Vec3& d) {
  const Vec3 oc = x - kBall;
  const double b = Dot(oc, d), c = Dot(oc, oc) - kBallRadius * kBallRadius, disc = b * b - c;
  if (disc > 0 && -b - std::sqrt(disc) > 1e-9) return true;
  if (d.z < 0 && x.z > 1e-9) {
    const Vec3 hit = x + d * (-x.z / d.z);
    if (std::fabs(hit.x) <= 1 && std::fabs(hit.y) <= 1) return true;
  }
  return false;
}

SgMixture TrueEnvironment() {
  const double el = 35 * kPi / 180, az = 40 * kPi / 180;
  return {Sg{{0, 0, 1}, 1.5, {0.3, 0.35, 0.45}},
          Sg{{std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)}, 20.0, {8, 7, 6}}};
}

NerfField SyntheticScene(double voxel) {
  const Aabb box{{-1, -1, -0.2}, {1, 1, 1.0}};
  const SgMixture env = TrueEnvironment();
  const std::vector<Vec3> dirs = FibonacciSphere(4096);
  auto radiance = [&](const Vec3& x, const Vec3& n) {
    Vec3 e;
    for (const Vec3& d : dirs)
      if (Dot(n, d) > 0 && !Blocked(x + n * 1e-6, d)) e += Evaluate(env, d) * Dot(n, d);
    return e * (4 * kPi / dirs.size() * 0.5 / kPi);
  };
  NerfField field = NerfField::Dense(box, voxel, kNerfEmptyDensityRaw, Vec3f{-20, -20, -20});
  std::map<std::pair<int, int>, Vec3> floor;
  for (int k = 0; k < field.res[2]; ++k)
    for (int j = 0; j < field.res[1]; ++j)
      for (int i = 0; i < field.res[0]; ++i) {
        const int32_t slot = field.Slot(i, j, k);
        const Vec3 p = Vec3(field.origin) + Vec3{double(i), double(j), double(k)} * double(field.voxel_m);
        const double ball = Length(p - kBall) - kBallRadius, sd = std::min(p.z, ball);
        field.density[slot] = static_cast<float>(std::clamp(3.0 - 10.0 * sd / voxel, -30.0, 8.0));
        if (std::fabs(sd) > 3 * voxel) continue;
        Vec3 l;
        if (p.z < ball) {
          auto it = floor.find({i, j});
          if (it == floor.end()) it = floor.emplace(std::make_pair(i, j), radiance({p.x, p.y, 0}, {0, 0, 1})).first;
          l = it->second;
        } else {
          const Vec3 n = Normalized(p - kBall);
          l = radiance(kBall + n * kBallRadius, n);
        }
        for (int c = 0; c < 3; ++c) {
          field.color[slot * kNerfColorCoeffs + c * 4] = static_cast<float>(std::log(std::max(l[c], 1e-9)));
          for (int b = 1; b < 4; ++b) field.color[slot * kNerfColorCoeffs + c * 4 + b] = 0;
        }
      }
  field.UpdateOccupancy(1.0f);
  return field;
}

double IrradianceError(const SgMixture& estimate) {
  std::vector<Vec3> a, b;
  for (const Vec3& n : FibonacciSphere(128))
    if (n.z > 0) {
      a.push_back(Irradiance(estimate, n));
      b.push_back(Irradiance(TrueEnvironment(), n));
    }
  return RelativeIrradianceRms(a, b);
}

// Nearest-pixel radiance of an equirect panorama (scenes/README.md convention).
Vec3 PanoramaLookup(const ImageF& pano, const Vec3& d) {
  double u = 0, v = 0;
  EquirectCoordinates(d, &u, &v);
  const int x = std::clamp(static_cast<int>(u * pano.width), 0, pano.width - 1);
  const int y = std::clamp(static_cast<int>(v * pano.height), 0, pano.height - 1);
  return {pano.at(x, y, 0), pano.at(x, y, 1), pano.at(x, y, 2)};
}

std::map<std::string, std::string> ModelsFromEnvironment() {
  std::map<std::string, std::string> models;
  const char* list = BenchVariable("NERFAR_BENCH_ENV_MODELS");
  if (list == nullptr) return models;
  std::stringstream in(list);
  std::string item;
  while (std::getline(in, item, ',')) {
    const size_t eq = item.find('=');
    if (eq != std::string::npos) models[item.substr(0, eq)] = item.substr(eq + 1);
  }
  return models;
}

// The estimate, the baselines and the figures at the object centres (see the file comment).
void MainFigures(const std::filesystem::path& dir, const std::string& scene, const NerfField& field,
                 EnvEstimateOptions o, const std::string& note, const ImageF& truth_env, const std::vector<Vec3>& upper,
                 const std::vector<Vec3>& e_true, double true_energy, std::vector<BenchFigure>& figures) {
  namespace fs = std::filesystem;
  double t0 = NowSeconds();
  const std::clock_t cpu0 = std::clock();
  EnvEstimateReport report;
  const EnvLight est = EstimateEnvironment(field, o, &report);
  figures.push_back({"env_" + scene + "_s", NowSeconds() - t0, "s", note});
  figures.push_back({"env_" + scene + "_cpu_s", static_cast<double>(std::clock() - cpu0) / CLOCKS_PER_SEC, "s",
                     note + ", CPU time (all threads)"});
  figures.push_back({"env_" + scene + "_samples", static_cast<double>(report.samples), "", note});
  figures.push_back({"env_" + scene + "_near_field_gain", report.fit.near_field_gain, "", note});
  figures.push_back({"env_" + scene + "_fit_rel_rms", report.fit.relative_rms, "", note});
  o.ignore_near_field = true;
  t0 = NowSeconds();
  const EnvLight physg = EstimateEnvironment(field, o);
  figures.push_back({"env_" + scene + "_physg_s", NowSeconds() - t0, "s", note + ", PhySG-like baseline"});
  figures.push_back({"env_" + scene + "_negligible", est.negligible ? 1.0 : 0.0, "", note});
  figures.push_back({"env_" + scene + "_env_to_near_surface", est.env_to_near_surface, "", note});
  figures.push_back({"env_" + scene + "_env_to_near_center", est.env_to_near_center, "", note});
  figures.push_back(
      {"env_" + scene + "_evidence", est.evidence, "", note + "; log-likelihood gain of the environment"});
  figures.push_back({"env_" + scene + "_evidence_needed", est.evidence_needed, "", note + "; BIC penalty"});

  const std::vector<Vec3> all = FibonacciSphere(128);
  // The distant light alone (unoccluded) over upper-hemisphere normals.
  std::vector<Vec3> e_est, e_physg, e_none(upper.size());
  for (const Vec3& n : upper) {
    e_est.push_back(Irradiance(est.lobes, n));
    e_physg.push_back(Irradiance(physg.lobes, n));
  }
  if (true_energy > 0) {
    figures.push_back({"env_" + scene + "_env_rel_rms", RelativeIrradianceRms(e_est, e_true), "",
                       note + "; irradiance of the estimate vs env.exr, 64 upper normals"});
    // The same after the best single scale factor (shape only, not the overall brightness).
    double ab = 0, bb = 0;
    for (size_t i = 0; i < e_est.size(); ++i) {
      ab += LuminanceOf(e_est[i]) * LuminanceOf(e_true[i]);
      bb += LuminanceOf(e_est[i]) * LuminanceOf(e_est[i]);
    }
    const double best = bb > 0 ? ab / bb : 0;
    std::vector<Vec3> e_scaled;
    for (const Vec3& e : e_est) e_scaled.push_back(e * best);
    figures.push_back({"env_" + scene + "_env_rel_rms_best_scale", RelativeIrradianceRms(e_scaled, e_true), "",
                       note + "; the estimate times the best single factor vs env.exr (shape alone)"});
    figures.push_back({"env_" + scene + "_env_best_scale", best, "", note + "; that factor"});
    figures.push_back({"env_" + scene + "_physg_env_rel_rms", RelativeIrradianceRms(e_physg, e_true), "",
                       note + "; PhySG-like baseline vs env.exr"});
    figures.push_back({"env_" + scene + "_nearonly_env_rel_rms", RelativeIrradianceRms(e_none, e_true), "",
                       note + "; near field alone (no environment) vs env.exr"});
  }
  // Total irradiance at each object centre (all 128 normals) against probe.exr.
  for (const char* object : {"sphere_glossy", "monkey_diffuse"}) {
    const fs::path obj_dir = dir / "insert" / object;
    if (!fs::exists(obj_dir / "pose.json")) continue;
    const ObjectPlacement placement = ReadObjectPlacement((obj_dir / "pose.json").string());
    const Vec3 centre = placement.center_world ? *placement.center_world : placement.T_world_object.translation;
    const ImageF probe = ReadExrRgb((obj_dir / "probe.exr").string());
    // The near field as the estimate sees it (seen-radiance correction when on).
    const SeenRadianceOptions seen = SeenOptions(o);
    const NerfIncident in = NerfIncidentAt(field, centre, 4096, o.render, o.near_field_seen_radiance ? &seen : nullptr);
    const auto sg_light = [](const SgMixture& m) { return [&m](const Vec3& d) { return Evaluate(m, d); }; };
    const auto pano_light = [&truth_env](const Vec3& d) { return PanoramaLookup(truth_env, d); };
    std::vector<Vec3> truth, with_est, near_only, with_physg, oracle;
    double env_sum = 0, physg_sum = 0, near_sum = 0;
    for (const Vec3& n : all) {
      truth.push_back(PanoramaIrradiance(probe, n));
      const Vec3 near = in.NearIrradiance(n), env = in.DistantIrradiance(sg_light(est.lobes), n);
      near_only.push_back(near);
      with_est.push_back(near + env);
      with_physg.push_back(Irradiance(physg.lobes, n));
      oracle.push_back(near + in.DistantIrradiance(pano_light, n));
      env_sum += LuminanceOf(env);
      physg_sum += LuminanceOf(in.DistantIrradiance(sg_light(physg.lobes), n));
      near_sum += LuminanceOf(near);
    }
    const std::string at = "env_" + scene + "_" + object + "_";
    const std::string on = note + "; at the " + std::string(object) + " centre, 128 normals vs probe.exr";
    figures.push_back({at + "total_rel_rms", RelativeIrradianceRms(with_est, truth), "", on + ", E_nerf + E_env"});
    figures.push_back({at + "nearonly_total_rel_rms", RelativeIrradianceRms(near_only, truth), "", on});
    figures.push_back({at + "physg_total_rel_rms", RelativeIrradianceRms(with_physg, truth), "", on});
    figures.push_back({at + "oracle_total_rel_rms", RelativeIrradianceRms(oracle, truth), "",
                       on + ", E_nerf + env.exr through NeRF visibility (the NeRF's share of the error)"});
    figures.push_back({at + "env_to_near", near_sum > 0 ? env_sum / near_sum : 0.0, "", note + ", E_env/E_nerf"});
    // As insertion uses it: a negligible environment is dropped (E_env = 0).
    figures.push_back({at + "env_to_near_used", est.negligible || !(near_sum > 0) ? 0.0 : env_sum / near_sum, "",
                       note + ", E_env/E_nerf as insertion uses it (0 when negligible)"});
    figures.push_back({at + "used_total_rel_rms", RelativeIrradianceRms(est.negligible ? near_only : with_est, truth),
                       "", on + ", what insertion uses (near field alone when negligible)"});
    figures.push_back(
        {at + "physg_env_to_near", near_sum > 0 ? physg_sum / near_sum : 0.0, "", note + ", PhySG-like E_env/E_nerf"});
  }
}

// One shared scene end to end (see the file comment).
void SharedScene(const std::string& scenes_dir, const std::string& scene, const std::string& model,
                 const std::string& preset, std::vector<BenchFigure>& figures) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::path(scenes_dir) / scene;
  const NerfField field = LoadNerf(model);
  EnvEstimateOptions o = EnvEstimateOptions::Preset(preset);
  // $NERFAR_BENCH_ENV_SET: "key=value;key=value" overrides (as `nerfar env --set`).
  const char* sets = BenchVariable("NERFAR_BENCH_ENV_SET");
  if (sets != nullptr) {
    std::stringstream in(sets);
    std::string kv;
    while (std::getline(in, kv, ';'))
      if (!kv.empty()) o.Set(kv);
  }
  const std::string note =
      scene + ", " + model + ", preset " + preset + (sets != nullptr && *sets != 0 ? ", " + std::string(sets) : "");
  const ImageF truth_env = ReadExrRgb((dir / "env.exr").string());
  std::vector<Vec3> upper, all = FibonacciSphere(128);
  for (const Vec3& n : all)
    if (n.z > 0) upper.push_back(n);
  std::vector<Vec3> e_true;
  for (const Vec3& n : upper) e_true.push_back(PanoramaIrradiance(truth_env, n));
  double true_energy = 0;
  for (const Vec3& e : e_true) true_energy += LuminanceOf(e);
  const char* trade_only = BenchVariable("NERFAR_BENCH_ENV_TRADE_ONLY");
  if (trade_only == nullptr || std::string(trade_only) != "1")
    MainFigures(dir, scene, field, o, note, truth_env, upper, e_true, true_energy, figures);
  const char* trade = BenchVariable("NERFAR_BENCH_ENV_TRADE");
  if (trade != nullptr) {
    // "1": the cells 16/64 px x 64/256 rays other than the run above (64 x
    // 256 with the balanced preset); else a list "PxR,PxR,...".
    std::vector<std::pair<int, int>> cells;
    if (std::string(trade) == "1") {
      cells = {{16, 64}, {16, 256}, {64, 64}};
    } else {
      std::stringstream list(trade);
      std::string cell;
      while (std::getline(list, cell, ',')) {
        int p = 0, r = 0;
        if (std::sscanf(cell.c_str(), "%dx%d", &p, &r) != 2 || p < 1 || r < 8)
          throw InputError("NERFAR_BENCH_ENV_TRADE: cell \"" + cell + "\" (expected PIXELSxRAYS, e.g. 16x64)");
        cells.push_back({p, r});
      }
    }
    for (const auto& [pixels, rays] : cells) {
      EnvEstimateOptions t = o;
      t.ignore_near_field = false;
      t.pixels_per_view = pixels;
      t.rays_per_point = rays;
      const double start = NowSeconds();
      const std::clock_t cpu_start = std::clock();
      const EnvLight env = EstimateEnvironment(field, t);
      const std::string label = "env_" + scene + "_px" + std::to_string(pixels) + "_rays" + std::to_string(rays);
      const std::string tn = note + "; " + std::to_string(pixels) + " px/view, " + std::to_string(rays) + " rays";
      figures.push_back({label + "_s", NowSeconds() - start, "s", tn});
      figures.push_back(
          {label + "_cpu_s", static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC, "s", tn + ", CPU time"});
      if (true_energy > 0) {
        std::vector<Vec3> e;
        for (const Vec3& n : upper) e.push_back(Irradiance(env.lobes, n));
        figures.push_back({label + "_env_rel_rms", RelativeIrradianceRms(e, e_true), "", tn});
      }
      figures.push_back({label + "_env_to_near_center", env.env_to_near_center, "", tn});
      figures.push_back({label + "_negligible", env.negligible ? 1.0 : 0.0, "", tn});
    }
  }
}

}  // namespace

std::vector<BenchFigure> BenchEnv(const BenchOptions& options) {
  std::vector<BenchFigure> figures;
  const std::map<std::string, std::string> models = ModelsFromEnvironment();
  if (!models.empty() && !options.scenes_dir.empty()) {
    const char* preset = BenchVariable("NERFAR_BENCH_ENV_PRESET");
    for (const auto& [scene, model] : models)
      SharedScene(options.scenes_dir, scene, model, preset != nullptr ? preset : "balanced", figures);
    return figures;
  }
  const NerfField field = SyntheticScene(options.quick ? 0.05 : 0.025);
  const std::string scene = "synthetic floor+ball, known env";
  auto run = [&](const std::string& label, EnvEstimateOptions o) {
    o.brisque_max = 100;  // synthetic flat renders are not natural images
    o.min_view_elevation_deg = 5;
    if (options.quick) {
      o.views = 10;
      o.rays_per_point = std::min(o.rays_per_point, 64);
    }
    const double t0 = NowSeconds();
    EnvEstimateReport report;
    const EnvLight env = EstimateEnvironment(field, o, &report);
    const double seconds = NowSeconds() - t0;
    const std::string note = scene + "; " + std::to_string(o.views) + " views x " + std::to_string(o.pixels_per_view) +
                             " px, " + std::to_string(o.rays_per_point) + " rays";
    figures.push_back({"env_" + label + "_s", seconds, "s", note});
    figures.push_back({"env_" + label + "_irradiance_rel_rms", IrradianceError(env.lobes), "", note});
  };
  for (const char* preset : {"fast", "balanced", "accurate"}) {
    if (options.quick && std::string(preset) != "fast") continue;
    run(preset, EnvEstimateOptions::Preset(preset));
  }
  if (!options.quick)
    for (int pixels : {16, 64})
      for (int rays : {64, 256}) {
        EnvEstimateOptions o = EnvEstimateOptions::Preset("balanced");
        o.pixels_per_view = pixels;
        o.rays_per_point = rays;
        run("px" + std::to_string(pixels) + "_rays" + std::to_string(rays), o);
      }
  return figures;
}

}  // namespace nerfar
