// Radiance of NeRF surfaces towards directions no capture camera saw.
//
// A trained NeRF's colour is only constrained towards the captures'
// directions. The shared scenes (and hand-held captures of a tabletop) are
// taken from above; seen from below, a surface's colour is whatever the
// optimisation left there. On the session-3 lamps NeRF the bulb seen from the
// table is 3-8x too dark (its underside was never photographed), so the near
// field E_nerf misses most of the light and an environment estimate makes it
// up. Here the radiance along a near-field ray that meets a surface from
// below the capture hemisphere is replaced by the brightest radiance that
// views from the capture hemisphere, aimed at the same point, see within
// reach_m of it (the same lamp seen from above: its top instead of its
// never-photographed underside). This takes emitters as uniform (the bulb,
// the panel's front) and surfaces as matte where the NeRF cannot say
// otherwise; it brightens a dark surface next to a brighter one within
// reach_m (measured on both shared scenes: docs/BENCHMARKS.md "env").
#pragma once

#include <cstdint>
#include <vector>

#include "render/nerf/nerf_field.h"

namespace nerfar {

struct SeenRadianceOptions {
  // Capture hemisphere: directions from a surface point towards the camera
  // with elevation in [min_elevation_deg, max_elevation_deg].
  double min_elevation_deg = 10;
  double max_elevation_deg = 70;
  int views = 12;  // rays aimed at each surface point from the capture hemisphere
  // A view counts when its surface lies within this distance (metres) of the
  // point (otherwise something else hides the point from that side).
  double reach_m = 0.05;
  // Only rays whose opacity exceeds this are treated (a surface, not fog).
  double min_opacity = 0.5;
};

// For every ray (origin, dir) with its rendered result whose surface point
// x = o + surface_depth·d is seen from below the capture hemisphere (the
// direction back to the ray's origin, −d, has elevation below
// min_elevation_deg), replaces result.color by the brightest (luminance per
// unit opacity) of the views from the capture hemisphere that reach x, times
// the ray's opacity, when that is brighter than the ray's own colour; rays
// whose point no view reaches keep their colour. Points are grouped by
// voxel (one look-up per voxel). Returns how many rays were changed.
// `samples` (optional) is increased by the density samples the views took.
size_t ApplySeenRadiance(const NerfField& field, const std::vector<NerfRay>& rays, std::vector<NerfRayResult>& results,
                         const SeenRadianceOptions& options, const NerfRenderOptions& render = {},
                         uint64_t* samples = nullptr);

}  // namespace nerfar
