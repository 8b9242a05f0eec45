#include "render/lighting/env_options.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "calib/core/error.h"
#include "calib/core/json.h"
#include "calib/core/option_fields.h"
#include "render/sg/sg.h"

namespace nerfar {
namespace {

// ------------------------------------------------------------------- options
std::vector<OptionField> Fields(EnvEstimateOptions& o) {
  using F = OptionField;
  return {{"views", F::kInt, &o.views},
          {"pixels_per_view", F::kInt, &o.pixels_per_view},
          {"view_width", F::kInt, &o.view_width},
          {"view_height", F::kInt, &o.view_height},
          {"view_fov_deg", F::kDouble, &o.view_fov_deg},
          {"view_distance_scale", F::kDouble, &o.view_distance_scale},
          {"min_view_elevation_deg", F::kDouble, &o.min_view_elevation_deg},
          {"brisque_max", F::kDouble, &o.brisque_max},
          {"max_view_attempts", F::kInt, &o.max_view_attempts},
          {"min_pixel_opacity", F::kDouble, &o.min_pixel_opacity},
          {"min_view_cosine", F::kDouble, &o.min_view_cosine},
          {"max_surface_spread_voxels", F::kDouble, &o.max_surface_spread_voxels},
          {"max_pixel_tries_factor", F::kInt, &o.max_pixel_tries_factor},
          {"surface_step_voxels", F::kFloat, &o.surface_step_voxels},
          {"normal_from_depth", F::kBool, &o.normal_from_depth},
          {"normal_baseline_px", F::kDouble, &o.normal_baseline_px},
          {"normal_scale_voxels", F::kDouble, &o.normal_scale_voxels},
          {"radiance_over_opacity", F::kBool, &o.radiance_over_opacity},
          {"rays_per_point", F::kInt, &o.rays_per_point},
          {"ray_offset_voxels", F::kDouble, &o.ray_offset_voxels},
          {"near_field_pool_m", F::kDouble, &o.near_field_pool_m},
          {"near_field_seen_radiance", F::kBool, &o.near_field_seen_radiance},
          {"seen_radiance_views", F::kInt, &o.seen_radiance_views},
          {"seen_radiance_face_views", F::kBool, &o.seen_radiance_face_views},
          {"seen_radiance_agree_fraction", F::kDouble, &o.seen_radiance_agree_fraction},
          {"step_voxels", F::kFloat, &o.render.step_voxels},
          {"min_transmittance", F::kFloat, &o.render.min_transmittance},
          {"ignore_near_field", F::kBool, &o.ignore_near_field},
          {"lobes", F::kInt, &o.lobes},
          {"dictionary_levels", F::kInt, &o.dictionary_levels},
          {"dictionary_base", F::kInt, &o.dictionary_base},
          {"dictionary_sharpness", F::kDouble, &o.dictionary_sharpness},
          {"iterations", F::kInt, &o.iterations},
          {"albedo_cell_m", F::kDouble, &o.albedo_cell_m},
          {"albedo_prior", F::kDouble, &o.albedo_prior},
          {"albedo_prior_weight", F::kDouble, &o.albedo_prior_weight},
          {"loss_epsilon", F::kDouble, &o.loss_epsilon},
          {"robust_scale", F::kDouble, &o.robust_scale},
          {"normal_balance", F::kDouble, &o.normal_balance},
          {"light_energy_weight", F::kDouble, &o.light_energy_weight},
          {"near_field_gain_max", F::kDouble, &o.near_field_gain_max},
          {"negligible_ratio", F::kDouble, &o.negligible_ratio},
          {"evidence_bic_factor", F::kDouble, &o.evidence_bic_factor},
          {"sources_max", F::kInt, &o.sources_max},
          {"source_candidates", F::kInt, &o.source_candidates},
          {"source_search_samples", F::kInt, &o.source_search_samples},
          {"source_refine_samples", F::kInt, &o.source_refine_samples},
          {"source_bundle_rays", F::kInt, &o.source_bundle_rays},
          {"source_sharpness_min", F::kDouble, &o.source_sharpness_min},
          {"source_sharpness_max", F::kDouble, &o.source_sharpness_max},
          {"source_steps", F::kInt, &o.source_steps},
          {"chroma_steps", F::kInt, &o.chroma_steps},
          {"shadow_step_voxels", F::kFloat, &o.shadow_render.step_voxels},
          {"shadow_min_transmittance", F::kFloat, &o.shadow_render.min_transmittance},
          {"seed", F::kU64, &o.seed}};
}

}  // namespace

SeenRadianceOptions SeenOptions(const EnvEstimateOptions& o) {
  SeenRadianceOptions seen;
  seen.min_elevation_deg = std::max(0.0, o.min_view_elevation_deg);
  seen.views = o.seen_radiance_views;
  seen.face_views = o.seen_radiance_face_views;
  seen.agree_fraction = o.seen_radiance_agree_fraction;
  return seen;
}

EnvEstimateOptions EnvEstimateOptions::Preset(const std::string& name) {
  EnvEstimateOptions o;
  if (name == "balanced") return o;
  if (name == "fast") {
    // Balanced's samples: a sharp source is found from the shadowed samples it
    // explains, and with fewer (2400) the estimate swung between two trainings
    // of one scene (docs/history/env.md, "The fast preset's samples").
    o.rays_per_point = 128;
    o.iterations = 8;
    o.max_view_attempts = 200;
    return o;
  }
  if (name == "accurate") {
    o.pixels_per_view = 128;
    o.rays_per_point = 512;
    o.iterations = 20;
    o.view_width = 160;
    o.view_height = 120;
    return o;
  }
  ThrowInputError("--preset", "is \"" + name + "\" (expected fast, balanced or accurate)");
}

std::vector<std::string> EnvEstimateOptions::Validate() const {
  std::vector<std::string> p;
  auto range = [&p](const char* name, double v, double lo, double hi) {
    if (!(v >= lo && v <= hi))
      p.push_back(std::string(name) + ": is " + std::to_string(v) + " (expected " + std::to_string(lo) + " to " +
                  std::to_string(hi) + ")");
  };
  range("views", views, 1, 10000);
  range("pixels_per_view", pixels_per_view, 1, 100000);
  range("view_width", view_width, 16, 4096);
  range("view_height", view_height, 16, 4096);
  range("view_fov_deg", view_fov_deg, 1, 170);
  range("view_distance_scale", view_distance_scale, 0.1, 100);
  range("min_view_elevation_deg", min_view_elevation_deg, -90, 89);
  range("brisque_max", brisque_max, 0, 1e9);
  range("max_view_attempts", max_view_attempts, views, 1e6);
  range("min_pixel_opacity", min_pixel_opacity, 0, 1);
  range("min_view_cosine", min_view_cosine, 0, 1);
  range("max_surface_spread_voxels", max_surface_spread_voxels, 0.1, 1e6);
  range("surface_step_voxels", surface_step_voxels, 0.05, 10);
  range("max_pixel_tries_factor", max_pixel_tries_factor, 1, 1e6);
  range("normal_baseline_px", normal_baseline_px, 0.25, 64);
  range("normal_scale_voxels", normal_scale_voxels, 0.25, 64);
  range("rays_per_point", rays_per_point, 8, 65536);
  range("ray_offset_voxels", ray_offset_voxels, 0, 100);
  range("near_field_pool_m", near_field_pool_m, 0, 10);
  range("seen_radiance_views", seen_radiance_views, 1, 1024);
  range("seen_radiance_agree_fraction", seen_radiance_agree_fraction, 0, 1);
  range("step_voxels", render.step_voxels, 0.01, 10);
  range("min_transmittance", render.min_transmittance, 0, 1);
  range("lobes", lobes, 1, kMaxSgLobes);
  range("dictionary_levels", dictionary_levels, 1, 5);
  range("dictionary_base", dictionary_base, 4, 4096);
  range("dictionary_sharpness", dictionary_sharpness, 1e-2, 1e3);
  if (dictionary_levels >= 1 && dictionary_base >= 1 &&
      dictionary_base * ((std::pow(4.0, dictionary_levels) - 1) / 3) > 8192)
    p.push_back("dictionary_base: gives more than 8192 dictionary lobes (expected fewer levels or a smaller base)");
  range("iterations", iterations, 1, 1000);
  range("albedo_cell_m", albedo_cell_m, 0, 100);
  range("albedo_prior", albedo_prior, 0.01, 1);
  range("albedo_prior_weight", albedo_prior_weight, 0, 1e6);
  range("loss_epsilon", loss_epsilon, 1e-6, 1e3);
  range("robust_scale", robust_scale, 1e-3, 1e6);
  range("normal_balance", normal_balance, 0, 1);
  range("light_energy_weight", light_energy_weight, 0, 1e3);
  range("near_field_gain_max", near_field_gain_max, 1, 1e3);
  range("negligible_ratio", negligible_ratio, 0, 1);
  range("evidence_bic_factor", evidence_bic_factor, 0, 1e6);
  range("sources_max", sources_max, 0, kMaxSgLobes);
  range("source_candidates", source_candidates, 12, 1e6);
  range("source_search_samples", source_search_samples, 16, 1e7);
  range("source_refine_samples", source_refine_samples, 16, 1e7);
  range("source_bundle_rays", source_bundle_rays, 1, 4096);
  range("source_sharpness_min", source_sharpness_min, 1, 1e5);
  range("source_sharpness_max", source_sharpness_max, source_sharpness_min, 1e4);
  range("source_steps", source_steps, 1, 1000);
  range("chroma_steps", chroma_steps, 1, 1000);
  range("shadow_step_voxels", shadow_render.step_voxels, 0.01, 10);
  range("shadow_min_transmittance", shadow_render.min_transmittance, 0, 0.999);
  if (sources_max > lobes) p.push_back("sources_max: exceeds lobes (expected at most the lobes kept)");
  return p;
}

std::string EnvEstimateOptions::ToJson() const {
  EnvEstimateOptions copy = *this;
  return OptionFieldsJson(Fields(copy));
}

void EnvEstimateOptions::Set(const std::string& key_value) { SetOptionField(Fields(*this), key_value); }

}  // namespace nerfar
