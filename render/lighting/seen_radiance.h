// Radiance of NeRF surfaces towards directions no capture camera saw.
//
// A trained NeRF's colour is only constrained towards the captures'
// directions. The shared scenes (and hand-held captures of a tabletop) are
// taken from above; seen from below, a surface's colour is whatever the
// optimisation left there. A lamp's bulb seen from the table can be several
// times too dark (its underside was never photographed), so the near
// field E_nerf misses most of the light and an environment estimate makes it
// up. Here the radiance along a near-field ray that meets a surface from
// below the capture hemisphere is replaced by the brightest radiance that
// views from the capture hemisphere, aimed at the same point, see within
// reach_m of it (the same lamp seen from above: its top instead of its
// never-photographed underside). This takes emitters as uniform (the bulb,
// the panel's front) and surfaces as matte where the NeRF cannot say
// otherwise; it brightens a dark surface next to a brighter one within
// reach_m (measured on both shared scenes: docs/BENCHMARKS.md "env").
//
// See-through content (SeenRadianceOptions::see_through, on for the
// incident light's rays): semi-transparent content (glass, fog, floaters)
// is the NeRF's explanation of what the captures saw through it, and its
// colour and opacity hold only along the directions the captures looked.
// The same views from the capture band, aimed at the point where such a
// ray's content lies, tell how much of it is matter: a view that finds its
// surface at the point (within see_through_reach_m) sees matter there; a
// view that passes the point while still more than half transparent sees
// through it (views hidden before they reach it say nothing). The ray's
// opacity is scaled by the share s = surface views / (surface + see-through
// views), its colour (the content's own radiance, already opacity-weighted)
// is kept: a caller blending Ĉ + (1 − Ô)·L_behind then lets the light behind
// the content through by the share the views see through, while a glowing
// halo or a lamp's glass still adds its own light. Fog that every view sees
// through no longer hides what lies behind it; a surface that every view
// meets is kept as it was. (Measured: docs/BENCHMARKS.md "see-through".)
//
// Face views (SeenRadianceOptions::face_views): the views are aimed at the
// face of the surface the ray meets. A point's normal (the NeRF's averaged
// density gradient, turned towards the ray's origin) picks the directions of
// the capture band that see that face (n·u >= face_min_cosine); views along
// them that find their surface within face_reach_m of the point see the
// point itself, and the brightest of them is its seen radiance. Only when no
// view of the band sees the face (a lamp's underside, whose normal points
// below the band) does the whole-band rule above decide. Why: an emitter
// that faces away from the band (a panel tilted towards the table) is seen
// by the captures only from the few low directions in front of it; views
// spread over the whole band mostly meet its dark backing, and a wide reach
// lets the views from above that meet a bulb lend its radiance to the pole
// and stand under it. Measured: docs/BENCHMARKS.md "face views".
//
// The capture's cameras (NerfField::capture_centres, when the model has
// them): the views are aimed from them, along the directions the NeRF was
// trained on, instead of from the band's spiral (whose directions fall
// between the cameras). A trained emitter's radiance is right only towards
// its cameras: its view-dependent colour is fitted along them alone, and
// between them it swings (a small bulb's core by a factor of two either
// way). Face views are the cameras in front of the face (n·u >=
// face_min_cosine), the band's views `views` cameras spread over the list;
// the elevation limits do not apply. Of a long capture, at most as many
// cameras as the band has face candidates (16 per view), spread over the
// capture's order, so that each point costs no more than with the band. A
// field without them: the band.
#pragma once

#include <cstdint>
#include <string>
#include <unordered_map>
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
  // See-through content (above): rays from below the capture band whose
  // opacity exceeds see_through_min_opacity keep the share of their colour
  // and opacity that the views find matter. Off by default (the environment
  // estimate's near field keeps the NeRF's opacity); NerfSceneOptions turns
  // it on for the incident light.
  bool see_through = false;
  // Content fainter than this is left alone (it changes the light by less
  // than this fraction; skipping it saves the views).
  double see_through_min_opacity = 0.05;
  // A view meets matter at the point when its surface lies within this
  // distance of it (2 steps of the live light march on the shared scenes'
  // 5 mm voxels: where two marches place one surface). Farther before it the
  // view is hidden, farther past it (or never half opaque) it sees through.
  double see_through_reach_m = 0.02;
  // Rays whose points fall in one cell of this size (metres, a grid from the
  // field's box corner) share the views aimed at the first one's point:
  // fewer views where rays crowd (a refined direction's 16 sub-rays meet a
  // lamp within a few centimetres). 0: one cell per voxel of the field.
  double group_m = 0.0;
  // Face views (above): aim the views at the face the ray meets. false: the
  // whole band for every point.
  bool face_views = true;
  // A band direction u sees the face of normal n when n·u is at least this
  // (0.1: up to 84° from the normal: captures from above see an upright
  // panel's front at grazing cosines).
  double face_min_cosine = 0.1;
  // A face view sees the point when its surface lies within this distance
  // of it (4 voxels of the shared scenes' 5 mm grids: two live march steps
  // each way). Tighter than reach_m: a view that meets another surface
  // (a bulb 3 cm above the pole point it was aimed at) says nothing here.
  double face_reach_m = 0.02;
  // The seen radiance of a point is the mean of the views that see it
  // (face views, or the whole band's when no face view does) whose
  // luminance is at least this fraction of the brightest's. 1: the
  // brightest alone. Why not the brightest: a
  // trained emitter's radiance varies from view to view around its true
  // value (the field blurs the emitter's edge and the training compensates
  // with a brighter core along some directions), and the maximum of 12 such
  // views is biased high (up to about three times a small bulb's true
  // radiance); a point's
  // views that are far darker than the brightest meet another surface at
  // it (a lamp's dark frame or backing, a pole), and would drag the mean of
  // an emitter down. 0: the plain mean of every view that sees the point.
  double agree_fraction = 0.5;
  bool operator==(const SeenRadianceOptions&) const = default;
};

// Where the views of the field's seen radiance come from, for logs: "views
// from the capture's N cameras" ("from M of ..." where a long capture is
// thinned), or the band's note that the model has none.
std::string SeenViewsNote(const NerfField& field, const SeenRadianceOptions& options);

// The seen radiance of a point from the radiances (per unit opacity) of
// the views that see it: the mean of those whose luminance is at least
// agree_fraction × the brightest's (all of them when every one is darker
// than black, a field's negative colour). False, `out` untouched, when
// there are none.
bool AgreeingRadiance(const std::vector<Vec3f>& radiances, double agree_fraction, Vec3f& out);

// The unit normal at p of the field's surface: unit density gradients
// averaged at p and ±1 voxel along each axis, negated (zero where undefined).
Vec3f AveragedGradientNormal(const NerfField& field, const Vec3f& p);

// The views' answer for one cell of points (ApplySeenRadiance): the
// radiance its views agree on (when reached), and the see-through votes.
struct SeenCellAnswer {
  Vec3f seen;
  bool reached = false;
  int meet = 0, pass = 0;
};

// The cells' answers kept across calls (frames). A dragged object's light
// rays meet the same cells of the scene frame after frame (the lamp, the
// wall): a cell answered before is not looked at again, only the cells the
// rays reach for the first time take views. A cell's answer is that of the
// first point the views were aimed at in it (as within one call), so a call
// with the same rays as an earlier one gives the same results bit for bit.
// The answers hold for one field and one set of options: ApplySeenRadiance
// empties the cache when called with another (the field's arrays or size,
// the options; `key` below). Code that edits a field's values in place calls
// Clear(), as for NerfField::UpdateRenderCopy.
struct SeenRadianceCache {
  // What the answers depend on (ApplySeenRadiance sets it): the field (its
  // address, its arrays' addresses and sizes, whether its render copy is
  // current and where, its grid and box), every option of the views and the
  // render options that change what a view's march finds.
  struct Key {
    const NerfField* field = nullptr;
    const float* density = nullptr;
    size_t density_size = 0;
    const float* color = nullptr;
    size_t color_size = 0;
    const uint64_t* occupancy = nullptr;
    size_t occupancy_size = 0;
    bool render_copy_current = false;
    const uint8_t* render_copy = nullptr;
    float voxel_m = 0;
    Vec3f origin;
    Vec3 aabb_min, aabb_max;
    SeenRadianceOptions options;
    float step_voxels = 0, min_transmittance = 0, min_alpha = 0;  // NerfRenderOptions
    bool use_render_copy = false;                                 // NerfRenderOptions
    bool operator==(const Key&) const = default;
  };
  Key key;
  std::unordered_map<int64_t, SeenCellAnswer> cells;
  // Emptied before a call's new cells would grow it past this many (a long
  // drag through a big scene; ~40 bytes a cell); that call's cells are kept.
  size_t max_cells = size_t(1) << 20;
  uint64_t hits = 0, misses = 0;  // cells answered from the cache / by new views, since construction
  void Clear() {
    key = {};
    cells.clear();
  }
};

// For every ray (origin, dir) with its rendered result whose surface point
// x = o + surface_depth·d is seen from below the capture hemisphere (the
// direction back to the ray's origin, −d, has elevation below
// min_elevation_deg), replaces result.color by the radiance (per unit
// opacity) the views from the capture hemisphere that reach x agree on
// (SeenRadianceOptions::agree_fraction), times
// the ray's opacity, when that is brighter than the ray's own colour; rays
// whose point no view reaches keep their colour. Points are grouped by
// voxel, or by cells of options.group_m, and by whether their opacity
// exceeds min_opacity (one look-up per cell and kind). With options.see_through, rays from below
// the band with opacity above see_through_min_opacity (the point being
// where their transmittance crosses 1/2, or their mean depth when they stay
// under 1/2 opaque) also have their opacity scaled by the share of the
// informative views that meet a surface there (the header's note). With
// options.face_views the seen radiance comes from the views of the point's
// own face when any of them sees it (the header's note). Returns how many
// rays were changed.
// `samples` (optional) is increased by the density samples the views took.
// `cache` (optional): cells answered by an earlier call with the same field
// and options take that answer instead of new views (SeenRadianceCache).
size_t ApplySeenRadiance(const NerfField& field, const std::vector<NerfRay>& rays, std::vector<NerfRayResult>& results,
                         const SeenRadianceOptions& options, const NerfRenderOptions& render = {},
                         uint64_t* samples = nullptr, SeenRadianceCache* cache = nullptr);

}  // namespace nerfar
