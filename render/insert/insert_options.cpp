#include "render/insert/insert_options.h"

#include <cmath>

#include "calib/core/error.h"

namespace nerfar {

InsertOptions InsertOptions::Preset(const std::string& name) {
  InsertOptions o;
  o.light.fit = SgFitOptions::Preset(name);
  if (name == "fast") {
    o.light.directions = 512;
    o.shadow_reach_radii = 8.0;
    o.shadow_epsilon = 5e-3;
    o.kappa_step = 4;
    o.occlusion_step = 4;
    o.kappa_cache_spacing_radii = 0.15;
    // Coarse κ cells refined only where their corners differ by > 0.04:
    // soft gradients stay interpolated, so fewer receivers are found and
    // marched per frame, at a small cost in the shadow's error near edges
    // (`nerfar bench insert` gives both).
    o.kappa_refine_delta = 0.04;
    o.antialias_edges = false;  // the coverage sub-samples double the raster time
    // The prefiltered specular adds a map look-up per pixel beside the SG
    // diffuse and visibility pass: fast keeps the SG specular to stay within
    // DESIGN.md's shading budget.
    o.prefiltered_specular = false;
    // Re-aiming near lobes prepares the SSDF query per κ evaluation, which
    // multiplies the κ work of a frame whose object or light changed.
    o.light.parallax = false;
    // Refining the incident light's fast-changing directions casts
    // refine_rays more rays for each of them: several times the light's rays.
    o.light.refine_rays = 0;
  } else if (name == "balanced") {
  } else if (name == "accurate") {
    o.light.directions = 2048;
    o.specular_parallax_iterations = 3;
    o.shade_step = 1;
    o.shadow_reach_radii = 20.0;
    o.shadow_epsilon = 5e-4;
    o.kappa_step = 1;
    o.self_shadow_per_vertex = false;
    o.occlusion_step = 1;
    o.kappa_cache_spacing_radii = 0.0;
    o.kappa_plane_upsampling = false;
    o.kappa_receiver_reuse = false;
    o.receiver_normal_per_cell = false;
    o.kappa_coarse_factor = 2;
    o.kappa_refine_delta = 0.01;
  } else {
    ThrowInputError("preset", "unknown preset '" + name + "' (expected fast, balanced or accurate)");
  }
  return o;
}

std::vector<std::string> InsertOptions::Validate() const {
  std::vector<std::string> problems = light.Validate();
  const auto check = [&problems](bool ok, const std::string& what) {
    if (!ok) problems.push_back(what);
  };
  check(std::isfinite(self_shadow_offset_radii) && self_shadow_offset_radii >= 0 && self_shadow_offset_radii <= 1,
        "self_shadow_offset_radii: out of range (expected 0 to 1)");
  check(std::isfinite(shadow_reach_radii) && shadow_reach_radii >= 1 && shadow_reach_radii <= 1000,
        "shadow_reach_radii: out of range (expected 1 to 1000)");
  check(std::isfinite(shadow_epsilon) && shadow_epsilon >= 0 && shadow_epsilon < 1,
        "shadow_epsilon: out of range (expected 0 <= value < 1)");
  check(specular_levels >= 2 && specular_levels <= 64, "specular_levels: out of range (expected 2 to 64)");
  check(specular_parallax_iterations >= 1 && specular_parallax_iterations <= 16,
        "specular_parallax_iterations: out of range (expected 1 to 16)");
  check(shade_step >= 1 && shade_step <= 8, "shade_step: out of range (expected 1 to 8)");
  check(std::isfinite(shade_refine_delta) && shade_refine_delta >= 0,
        "shade_refine_delta: out of range (expected a finite value >= 0)");
  check(std::isfinite(shade_refine_angle_deg) && shade_refine_angle_deg >= 0 && shade_refine_angle_deg <= 90,
        "shade_refine_angle_deg: out of range (expected 0 to 90)");
  check(kappa_sample_bins >= 4 && kappa_sample_bins <= 4096, "kappa_sample_bins: out of range (expected 4 to 4096)");
  check(std::isfinite(kappa_sample_min_radius) && kappa_sample_min_radius >= 0 && kappa_sample_min_radius <= 1,
        "kappa_sample_min_radius: out of range (expected 0 to 1 radians)");
  check(occlusion_step >= 1 && occlusion_step <= 64, "occlusion_step: out of range (expected 1 to 64)");
  check(std::isfinite(occlusion_clear_opacity) && occlusion_clear_opacity >= 0 && occlusion_clear_opacity < 1,
        "occlusion_clear_opacity: out of range (expected 0 <= value < 1)");
  check(std::isfinite(kappa_cache_spacing_radii) && kappa_cache_spacing_radii >= 0 && kappa_cache_spacing_radii <= 10,
        "kappa_cache_spacing_radii: out of range (expected 0 to 10)");
  check(std::isfinite(kappa_reuse_tolerance_radii) && kappa_reuse_tolerance_radii >= 0 &&
            kappa_reuse_tolerance_radii <= 1,
        "kappa_reuse_tolerance_radii: out of range (expected 0 to 1)");
  check(kappa_step >= 1 && kappa_step <= 64, "kappa_step: out of range (expected 1 to 64)");
  check(kappa_coarse_factor >= 1 && kappa_coarse_factor <= 64, "kappa_coarse_factor: out of range (expected 1 to 64)");
  check(kappa_grid_width >= 0 && kappa_grid_width <= 65536, "kappa_grid_width: out of range (expected 0 to 65536)");
  check(std::isfinite(kappa_refine_delta) && kappa_refine_delta >= 0 && kappa_refine_delta <= 1,
        "kappa_refine_delta: out of range (expected 0 to 1)");
  check(std::isfinite(receiver_min_opacity) && receiver_min_opacity >= 0 && receiver_min_opacity <= 1,
        "receiver_min_opacity: out of range (expected 0 to 1)");
  return problems;
}

std::vector<OptionField> InsertOptions::Fields() {
  IncidentLightOptions& l = light;
  SgFitOptions& fit = light.fit;
  return {FieldOf("light_source", &l.source, LightSourceNames()),
          FieldOf("light_directions", &l.directions),
          FieldOf("light_move_threshold_m", &l.move_threshold_m),
          FieldOf("light_parallax", &l.parallax),
          FieldOf("light_parallax_min_sharpness", &l.parallax_min_sharpness),
          FieldOf("light_start_outside_object", &l.start_outside_object),
          FieldOf("light_start_tolerance_m", &l.start_tolerance_m),
          FieldOf("light_refine_rays", &l.refine_rays),
          FieldOf("light_refine_contrast", &l.refine_contrast),
          FieldOf("light_analytic_compact_lobes", &l.analytic_compact_lobes),
          FieldOf("light_lobe_bundle_rays", &l.lobe_bundle_rays),
          FieldOf("sg_lobes", &fit.lobes),
          FieldOf("sg_cold_iterations", &fit.cold_iterations),
          FieldOf("sg_warm_iterations", &fit.warm_iterations),
          FieldOf("sg_hdr_floor", &fit.hdr_floor),
          FieldOf("sg_min_sharpness", &fit.min_sharpness),
          FieldOf("sg_max_sharpness", &fit.max_sharpness),
          FieldOf("sg_tolerance", &fit.tolerance),
          FieldOf("sg_adam_iterations", &fit.adam_iterations),
          FieldOf("sg_adam_step", &fit.adam_step),
          FieldOf("sg_method", &fit.method, SgFitMethodNames()),
          FieldOf("self_shadow", &self_shadow),
          FieldOf("self_shadow_horizon", &self_shadow_horizon),
          FieldOf("self_shadow_offset_radii", &self_shadow_offset_radii),
          FieldOf("self_shadow_per_vertex", &self_shadow_per_vertex),
          FieldOf("prefiltered_specular", &prefiltered_specular),
          FieldOf("specular_levels", &specular_levels),
          FieldOf("specular_parallax", &specular_parallax),
          FieldOf("specular_parallax_iterations", &specular_parallax_iterations),
          FieldOf("shade_step", &shade_step),
          FieldOf("shade_refine_delta", &shade_refine_delta),
          FieldOf("shade_refine_angle_deg", &shade_refine_angle_deg),
          FieldOf("shade_specular_on_grid", &shade_specular_on_grid),
          FieldOf("antialias_edges", &antialias_edges),
          FieldOf("occlusion_step", &occlusion_step),
          FieldOf("occlusion_clear_opacity", &occlusion_clear_opacity),
          FieldOf("shadows", &shadows),
          FieldOf("shadow_reach_radii", &shadow_reach_radii),
          FieldOf("shadow_epsilon", &shadow_epsilon),
          FieldOf("shadow_epsilon_snap", &shadow_epsilon_snap),
          FieldOf("kappa_from_samples", &kappa_from_samples),
          FieldOf("kappa_sample_bins", &kappa_sample_bins),
          FieldOf("kappa_sample_min_radius", &kappa_sample_min_radius),
          FieldOf("kappa_step", &kappa_step),
          FieldOf("kappa_grid_width", &kappa_grid_width),
          FieldOf("kappa_skip_covered", &kappa_skip_covered),
          FieldOf("kappa_coarse_factor", &kappa_coarse_factor),
          FieldOf("kappa_refine_delta", &kappa_refine_delta),
          FieldOf("kappa_plane_upsampling", &kappa_plane_upsampling),
          FieldOf("receiver_min_opacity", &receiver_min_opacity),
          FieldOf("kappa_cache_spacing_radii", &kappa_cache_spacing_radii),
          FieldOf("kappa_receiver_reuse", &kappa_receiver_reuse),
          FieldOf("receiver_normal_per_cell", &receiver_normal_per_cell),
          FieldOf("kappa_reuse_tolerance_radii", &kappa_reuse_tolerance_radii)};
}

void InsertOptions::Set(const std::string& key_value, const std::string& source) {
  SetOptionField(Fields(), key_value, source);
}

std::string InsertOptions::ToJson() const {
  InsertOptions copy = *this;
  return OptionFieldsJson(copy.Fields());
}

}  // namespace nerfar
