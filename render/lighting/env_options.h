// Options of the environment estimate (render/lighting/env_estimate.h): one
// plain struct with a comment per field, presets, validation, JSON and the
// CLI's key=value overrides.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "render/lighting/seen_radiance.h"
#include "render/nerf/nerf_field.h"

namespace nerfar {

struct EnvEstimateOptions {
  // --- view sampling (paper: 100 views, 64 pixels each)
  int views = 100;           // accepted views to collect
  int pixels_per_view = 64;  // surface samples drawn per accepted view
  int view_width = 128;      // rendering size of a sampled view (BRISQUE and pixel picking)
  int view_height = 96;
  double view_fov_deg = 60;  // horizontal field of view of the sampled views
  // Camera distance from the volume's centre, in units of half the aabb
  // diagonal (1: on the sphere around the box; the paper's "half the grid size").
  double view_distance_scale = 1.0;
  // Views below this elevation (degrees, seen from the centre) are not drawn.
  // Captures are taken from above (the shared scenes: 15 to 70 degrees), so
  // views from below see the untrained underside (fog, wrong normals), which
  // BRISQUE does not reliably reject; −90 draws the whole sphere.
  double min_view_elevation_deg = 10;
  double brisque_max = 50;      // views scoring above are rejected (paper: 50); ≥ 100 disables BRISQUE
  int max_view_attempts = 400;  // views rendered at most; the best-scoring are kept when too few pass
  // A pixel passes through the NeRF when its opacity exceeds this. Trained
  // grids can hold translucent surfaces (a table of opacity 0.1-0.5 seen from
  // above on a black background); surface-likeness is judged by
  // max_surface_spread_voxels instead (at 0.95 such a table gives almost no
  // samples).
  double min_pixel_opacity = 0.2;
  // A pixel's surface x = o + t50·d lies where its accumulated opacity reaches
  // half of the ray's total (not the expected depth, which fog pulls towards
  // the camera). Pixels whose opacity builds up over more than this many
  // voxels between its quarter and three quarters (a layer of fog, not a
  // surface) are dropped.
  // Trained tables can spread their opacity over tens of voxels along the
  // ray with the median still within a few voxels of the top: 20 keeps them
  // and drops deeper fog.
  double max_surface_spread_voxels = 20;
  // At most this many pixels per wanted sample are tried in a view (bounds
  // the marching when most pixels are rejected).
  int max_pixel_tries_factor = 4;
  float surface_step_voxels = 0.5f;  // march step for the surface quartiles
  // Normals from the median-depth map (central differences over
  // normal_baseline_px pixels; depth edges dropped) rather than from the
  // density gradient (smoothed over normal_scale_voxels), which fog turns.
  bool normal_from_depth = true;
  double normal_baseline_px = 2;
  double normal_scale_voxels = 1.5;
  // Observed radiance L_o: the rendered pixel C (false; right on a black
  // background, as the shared scenes' camera rays see) or C / opacity (true).
  bool radiance_over_opacity = false;
  double min_view_cosine = 0.25;  // samples whose normal is seen more grazing than this (n·view) are dropped
  // --- near field
  int rays_per_point = 256;  // R: rays per surface point (near-field irradiance and visibility cache)
  // Rays start this far along the normal (in voxels) to leave the surface and
  // the surface's own fog: on the window NeRF (5 mm voxels) E_nerf on the
  // table fell ~3.5x from 2 to 12 voxels (the rays no longer collect the
  // table's own smeared radiance); 4 is the compromise with thin objects.
  double ray_offset_voxels = 4.0;
  // E_nerf is averaged over samples within this distance (metres) whose normals
  // agree (cos > 0.95): R rays per point see a small bright source only a few
  // times. 0 keeps each point's own estimate.
  double near_field_pool_m = 0.03;
  // Near-field rays that meet a surface from below the capture hemisphere
  // (elevation < min_view_elevation_deg seen from the surface) take the
  // radiance of that surface point seen from the capture hemisphere
  // (render/lighting/seen_radiance.h): a NeRF's emitters and surfaces are
  // untrained towards directions no camera saw.
  bool near_field_seen_radiance = true;
  int seen_radiance_views = 12;  // views from the capture hemisphere per surface point
  // The views aimed at the face each ray meets (SeenRadianceOptions::face_views); false: the whole band.
  bool seen_radiance_face_views = true;
  // The views' agreement (SeenRadianceOptions::agree_fraction); 1: the brightest view alone.
  double seen_radiance_agree_fraction = 0.5;
  NerfRenderOptions render;        // sample spacing etc. of every NeRF ray
  bool ignore_near_field = false;  // baseline: E_nerf = 0 and Ô = 0 (environment explains everything, PhySG-like)
  // --- fit
  int lobes = 32;  // M: lobes in the result (paper: 32)
  // Dictionary levels: level l has dictionary_base·4^l lobes on a Fibonacci
  // sphere with sharpness dictionary_sharpness·4^l (same relative overlap).
  // One level: 24 lobes of λ = 3, as wide as their spacing, span the
  // spherical-harmonic bands 0-2 (9 coefficients) that carry the samples'
  // shading: shading is the light convolved with the clamped cosine, which
  // passes band 2 at a quarter of band 0's gain, band 3 not at all and
  // bands 4 and up under 5 %. Finer levels add only detail shading cannot
  // see, which the fit then places where noise and the few side-facing
  // samples pull it (bright blobs near the horizon that a glossy object
  // reflects). Finer light shows in shadows, which the sharp-source search
  // reads.
  int dictionary_levels = 1;
  int dictionary_base = 24;
  double dictionary_sharpness = 3.0;
  int iterations = 12;                // alternations of the albedo and light solves
  double albedo_cell_m = 0;           // albedo grid cell (metres); 0: 1/8 of the aabb's largest side
  double albedo_prior = 0.5;          // grey-world prior that fixes the scale when the near field does not
  double albedo_prior_weight = 1e-3;  // its weight, per cell, relative to one sample
  double loss_epsilon = 0.05;         // relative loss floor in units of the mean observed luminance
  double robust_scale = 0.3;          // Cauchy scale of the log residual (outliers: emitters, tags, bad normals)
  // Each sample's weight in the data term is (1 / samples whose normal falls
  // in the same of 32 direction bins)^normal_balance, normalised to mean 1:
  // 0 weights every sample alike, 1 gives every occupied normal direction the
  // same total weight. A tabletop gives most samples one normal (up), which
  // tells the light's elevation only through shadows; the objects' sides,
  // few in number, tell it through their shading.
  double normal_balance = 0.75;
  // Minimum-energy prior on the light (relative to the data term): light that
  // no sample sees stays dark. 0 disables it.
  double light_energy_weight = 1e-3;
  // The near field enters the model as g·E_nerf with one gain g in [1, this]
  // fitted with the rest. A trained NeRF's emitters are often much dimmer
  // towards directions no camera saw (the underside of a lamp seen from the
  // table: several times too dark); without g the fit makes
  // up the missing light with a bright environment. Light that E_nerf's
  // pattern cannot explain (a window's shadows and lit sides) still goes to
  // the environment. 1 disables it.
  double near_field_gain_max = 1;
  // The estimate is negligible when E_env / E_nerf (luminance) is below this
  // both over the surface samples and at the volume's centre.
  double negligible_ratio = 0.05;
  // The estimate is also negligible when the environment does not explain
  // the observations better than the near field alone by more than its
  // parameters would explain of noise: its log-likelihood gain (the robust
  // loss as a Cauchy likelihood) must exceed this times the Bayesian
  // information criterion's penalty (k/2)·ln n (EnvFitReport). 1 is the
  // criterion itself; 0 turns the test off.
  double evidence_bic_factor = 1;
  // --- sharp sources (env_sources.cpp): small bright lights found from the
  // shadows and shading they cast, placed continuously (direction, then size),
  // each kept only when the model selection (evidence_bic_factor) supports it.
  int sources_max = 4;               // sources searched for at most (0: the dictionary alone)
  int source_candidates = 1500;      // directions of the coarse search (a Fibonacci sphere)
  int source_search_samples = 1024;  // samples the coarse search scores each direction on
  int source_refine_samples = 3072;  // samples the direction's refinement and the size's choice use
  int source_bundle_rays = 16;       // shadow rays per sample spread over a lobe (its mean visibility)
  double source_sharpness_min = 30, source_sharpness_max = 1e4;  // the sizes tried (a geometric ladder)
  int source_steps = 4;  // alternation steps of the joint fit after a source is added
  NerfRenderOptions shadow_render = NerfRenderOptions::Preset("live");  // shadow rays (transmittance only)
  int chroma_steps = 2;  // alternation steps per lobe when testing its chroma (env_fit.cpp FreeChroma)
  uint64_t seed = 1;     // views, pixels and ray rotations

  // "fast", "balanced" (the defaults), "accurate"; InputError otherwise.
  static EnvEstimateOptions Preset(const std::string& name);
  // Every problem as "field: what is wrong (what was expected)".
  std::vector<std::string> Validate() const;
  std::string ToJson() const;
  // Sets one field from "key=value" (the CLI's --set); InputError if unknown or bad.
  void Set(const std::string& key_value);
};

// The seen-radiance settings that `o` implies (capture band from min_view_elevation_deg).
SeenRadianceOptions SeenOptions(const EnvEstimateOptions& o);

}  // namespace nerfar
