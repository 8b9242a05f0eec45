#include "render/lighting/env_estimate.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "calib/core/error.h"
#include "render/lighting/env_internal.h"

namespace nerfar {

using env_internal::ToD;
using env_internal::Y;

EnvLight EstimateEnvironment(const NerfField& field, const EnvEstimateOptions& options, EnvEstimateReport* report,
                             const EnvProgress& progress) {
  const std::vector<std::string> problems = options.Validate();
  if (!problems.empty()) {
    Problems list("env options");
    for (const std::string& p : problems) list.Add("", p);
    list.ThrowIfAny();
  }
  EnvEstimateReport local;
  local.keep_samples = report != nullptr && report->keep_samples;
  const auto clock_start = std::chrono::steady_clock::now();
  const auto elapsed = [&clock_start] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - clock_start).count();
  };
  double t0 = elapsed();
  EnvSurfaceSamples samples = SampleSurfaces(field, options, &local.views, progress);
  local.seconds_views = elapsed() - t0;
  local.samples = samples.size();
  t0 = elapsed();
  ComputeNearField(field, options, samples, progress);
  local.seconds_near_field = elapsed() - t0;
  t0 = elapsed();
  EnvLight env;
  // Shadow rays through the NeRF; the baseline that ignores the NeRF's
  // visibility (ignore_near_field) fits the dictionary alone, as before.
  const EnvShadowRays shadow =
      options.ignore_near_field ? nullptr : NerfShadowRays(field, options.shadow_render, samples.fog_density);
  env.lobes = FitEnvironment(samples, field.aabb, options, &local.fit, progress, shadow);
  if (std::any_of(local.fit.lobe_distance_m.begin(), local.fit.lobe_distance_m.end(), [](double d) { return d > 0; }))
    env.distance_m = local.fit.lobe_distance_m;
  local.seconds_fit = elapsed() - t0;

  const std::vector<Vec3> e_env =
      EnvironmentIrradiance(samples, env.lobes, shadow, options.source_bundle_rays, options.seed, env.distance_m);
  double sum_env = 0, sum_nerf = 0;
  for (size_t i = 0; i < samples.size(); ++i) {
    sum_env += Y(e_env[i]);
    sum_nerf += Y(ToD(samples.e_nerf[i]));
  }
  env.env_to_near_surface = sum_nerf > 0 ? sum_env / sum_nerf : (sum_env > 0 ? 1e30 : 0.0);
  const SeenRadianceOptions seen = SeenOptions(options);
  const double centre_ratio = EnvToNearRatioAt(field, env.lobes, (field.aabb.min + field.aabb.max) * 0.5, 1024, 64,
                                               options.render, options.near_field_seen_radiance ? &seen : nullptr);
  env.env_to_near_center = std::isfinite(centre_ratio) ? std::min(centre_ratio, 1e30) : 1e30;
  env.threshold = options.negligible_ratio;
  env.evidence = local.fit.evidence;
  env.evidence_needed = local.fit.evidence_needed;
  env.fit = {.samples = static_cast<long long>(samples.size()),
             .relative_rms = local.fit.relative_rms,
             .loss = local.fit.final_loss,
             .near_only_fitted = local.fit.near_only_loss > 0,  // 0: the fit without environment did not run
             .near_only_relative_rms = local.fit.near_only_relative_rms,
             .near_only_loss = local.fit.near_only_loss};
  env.negligible = (env.env_to_near_surface < env.threshold && env.env_to_near_center < env.threshold) ||
                   !local.fit.environment_supported;
  env.options_json = options.ToJson();
  if (local.keep_samples) {
    local.surface = std::move(samples);
    local.e_env = e_env;
  }
  if (report) *report = std::move(local);
  return env;
}

double RelativeIrradianceRms(const std::vector<Vec3>& estimate, const std::vector<Vec3>& reference) {
  NERFAR_CHECK_EQ(estimate.size(), reference.size());
  double err = 0, ref = 0;
  for (size_t i = 0; i < estimate.size(); ++i) {
    err += std::pow(Y(estimate[i]) - Y(reference[i]), 2);
    ref += std::pow(Y(reference[i]), 2);
  }
  return ref > 0 ? std::sqrt(err / ref) : (err > 0 ? std::numeric_limits<double>::infinity() : 0.0);
}

}  // namespace nerfar
