// Surface samples for the environment estimate (paper §4.2): views around
// the NeRF's centre, BRISQUE rejection, surface points from the median depth,
// normals and observed radiance (env_views.cpp); the near-field irradiance
// and visibility cache are filled by render/lighting/env_near_field.h.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "calib/core/math.h"
#include "render/lighting/env_options.h"
#include "render/nerf/nerf_field.h"

namespace nerfar {

// The surface samples and their near-field cache.
struct EnvSurfaceSamples {
  std::vector<Vec3f> positions;  // x_surf, world
  std::vector<Vec3f> normals;    // unit
  std::vector<Vec3f> radiance;   // observed L_o (linear RGB)
  // Trained surfaces are translucent layers centimetres thick (a table of
  // σ ~ 20-60/m over 4 cm), which every ray leaving a sample would cross:
  // dimming it (a lit table 0.6-0.8 open straight up) and lending it the
  // layer's glow. layer_m: the height (metres, along the normal) of the top of
  // the sample's own layer above x_surf, from the camera ray that found it
  // (where its opacity reached 5 % of its total). Empty: no layer.
  std::vector<float> layer_m;
  // Filled by ComputeNearField:
  std::vector<Vec3f> e_nerf;  // near-field irradiance
  int rays_per_point = 0;     // R
  float ray_offset_m = 0;     // rays start where they have risen this far above the surface (SurfaceRay)
  // Rays leaving a sample pass density up to this (1/m) as empty while they
  // cross its own layer (EnvSurfaceRay): the median σ at their start points,
  // the layer's own density there. Occluders and emitters are denser.
  float fog_density = 0;
  std::vector<Vec3f> ray_dirs;  // R per point (world, unit, cosine-distributed about the normal)
  std::vector<float> opacity;   // R per point: Ô towards ray_dirs
  size_t size() const { return positions.size(); }
};

struct EnvViewReport {
  int rendered = 0, accepted = 0;
  std::vector<double> scores;  // BRISQUE score per rendered view (−1: BRISQUE disabled)
  std::vector<bool> kept;      // per rendered view
  // The views' camera (shared by all) and poses T_world_camera (OpenCV axes), per rendered view.
  CameraIntrinsics camera;
  std::vector<Pose> poses;
  // Picked pixels of the kept views: tried, and dropped as not surface-like,
  // without a usable normal, or seen too grazing.
  long pixels_tried = 0, pixels_not_surface = 0, pixels_no_normal = 0, pixels_grazing = 0;
};

// Progress: stage name, done, total (called from the calling thread).
using EnvProgress = std::function<void(const std::string& stage, size_t done, size_t total)>;

// Views, BRISQUE rejection, surface points, normals and observed radiance.
EnvSurfaceSamples SampleSurfaces(const NerfField& field, const EnvEstimateOptions& options,
                                 EnvViewReport* report = nullptr, const EnvProgress& progress = nullptr);

}  // namespace nerfar
