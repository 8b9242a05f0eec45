// Options of the per-frame insertion (render/insert/inserter.h): plain
// struct, a comment per field, presets fast / balanced / accurate.
#pragma once

#include <string>
#include <vector>

#include "calib/core/option_fields.h"
#include "render/lighting/incident_light.h"

namespace nerfar {

struct InsertOptions {
  IncidentLightOptions light;  // rays from the centre, SG fit, light source (ours or an ablation)

  bool self_shadow = true;  // γ_k from the SSDF fields (paper eq. 10); off: objects never shadow themselves
  // γ_k relative to the part of lobe k above the surface's horizon,
  // f_h(min(S, e))/f_h(e) with e = asin(p_k·n), so that a convex object does
  // not darken the light its cosine already removes; off: the paper's
  // f_h(S)/f_h(π/2).
  bool self_shadow_horizon = true;
  // SSDF queried this far (× bounding radius) off the surface, along n. The
  // 16³ grid's cell is 0.2 radii and trilinear interpolation mixes in grid
  // points inside the mesh (SSD ≈ −π) closer than about a cell, darkening
  // the surface: monkey_diffuse under its true probe measured 23.3 dB at
  // 0.01, 28.7 at 0.1, 29.2 at 0.15 (32² direction maps; 28.3 without γ).
  double self_shadow_offset_radii = 0.15;

  // γ at the mesh vertices (view-independent: cached while the objects and
  // the light stand still), interpolated over each triangle with the
  // rasteriser's barycentrics; false: one SSDF query per pixel.
  bool self_shadow_per_vertex = true;

  // Specular term from the incident-light samples prefiltered by the GGX
  // lobe at specular_levels roughness levels (render/sg/prefiltered.h,
  // split sum; built when the light changes), its self-shadow the SG
  // specular's ratio with and without γ; false: the SG product integral
  // (paper eq. 5), which cannot reflect sources sharper than its lobes.
  bool prefiltered_specular = true;
  int specular_levels = 9;
  // Parallax-corrected reflections of the prefiltered specular: each pixel
  // looks its reflection up towards where its reflected ray from its own
  // surface point meets the scene's distance seen from the light's centre
  // (PrefilteredRadiance::SetParallax; near walls, the table, neighbouring
  // objects), in this many fixed-point steps; false: along the reflected
  // direction, as if everything reflected were distant. A glossy object
  // beside the table sees the table and its neighbours from its own surface,
  // not from its centre. One step (the distance met along the uncorrected
  // direction) is one distance look-up per pixel; more steps each add one,
  // for the fixed point of a surface whose distance changes across the
  // shift (accurate takes 3). Fast keeps the SG specular and so has none.
  bool specular_parallax = true;
  int specular_parallax_iterations = 1;
  // With a prefiltered map: the smooth part of the shading (the diffuse
  // radiance and the specular's self-shadow ratio, both from the SG light
  // with γ) at every shade_step-th pixel of the objects' box, bilinear in
  // between; the map's specular per pixel (but shade_specular_on_grid). A pixel is shaded exactly
  // where its cell's four nodes are not all on its object, a node's normal
  // is more than shade_refine_angle_deg from the pixel's, or the nodes'
  // values differ by more than shade_refine_delta (diffuse: relative to its
  // brightest channel; ratio: absolute). 1: every pixel exactly (objects
  // with a roughness or metallic map always are).
  int shade_step = 2;
  double shade_refine_delta = 0.1;
  double shade_refine_angle_deg = 20.0;
  // On the grid path, the map's specular too (split by F0, so an albedo
  // map still applies per pixel) in the cells where it also agrees to
  // shade_refine_delta and the nodes' mirror directions differ by at most
  // α/3 (GGX α = roughness²: a rough object nearly everywhere, a glossy
  // one only when large on screen); elsewhere looked up per pixel.
  bool shade_specular_on_grid = true;

  // Object edges blended with the background by the fraction of each pixel
  // the objects cover (4×4 sub-samples of the rasteriser), as a camera's
  // pixel integrates its square; false: a pixel is the object or not.
  bool antialias_edges = true;

  // Occlusion first along every occlusion_step-th pixel ray of the object's
  // screen box (each clipped at the farthest object depth around it); blocks
  // whose four corner rays all see opacity below occlusion_clear_opacity take
  // the object unoccluded, the others march every pixel (1: every pixel).
  int occlusion_step = 2;
  double occlusion_clear_opacity = 1e-3;

  bool shadows = true;               // κ on the scene (paper eq. 8)
  double shadow_reach_radii = 12.0;  // κ only within this distance (× bounding radius) of an object's centre
  // Receivers whose κ, bounded from below through each object's bounding
  // sphere, cannot fall under 1 − shadow_epsilon keep κ = 1 (no SSDF query).
  double shadow_epsilon = 2e-3;
  // κ found at or above 1 − shadow_epsilon (by the SSDF, or interpolated
  // between lattice nodes) is taken as 1, as where the bound above clears
  // it: the same rule whichever decided, and the background is multiplied
  // only where κ < 1 − ε (the bound's sphere is loose for broad lobes, so
  // receivers across the whole reach had κ a hair under 1); false: κ kept
  // as computed.
  bool shadow_epsilon_snap = true;
  // κ from the light's radiance samples gathered into sources (compact ones
  // keep their true size; near ones re-aimed at each receiver with their
  // lobe's distance; ShadowSources in shadow_terms.h) instead of from the SG
  // lobes; false (every preset): the SG lobes (paper eqs. 8-9). Off: the
  // sources follow the light's samples, so with a NeRF's light they carry
  // its radiance errors into κ that the SG fit smooths, and κ's cost grows
  // with the number of distinct sources (a sky of many distant ones).
  bool kappa_from_samples = false;
  int kappa_sample_bins = 128;            // Fibonacci bins the samples are gathered into (per kind: near, distant)
  double kappa_sample_min_radius = 0.03;  // radians: no source narrower (the SSDF's own resolution)
  int kappa_step = 2;                     // κ at every kappa_step-th pixel, bilinear in between (1: every pixel)
  // The frame width kappa_step and the coarse spacing (kappa_step ×
  // kappa_coarse_factor) are given for: a frame of another width scales both
  // spacings by its width over this one (rounded; the step at least 1 px,
  // the coarse spacing at least the step), so that κ resolves the same share
  // of the view, and costs about the same share of the frame, at every
  // resolution (a small frame in its own pixels would blur sharp shadow
  // edges over several of the view's grid cells). 1280: DESIGN.md's
  // budgets' frame. 0: spacings in the frame's own pixels.
  int kappa_grid_width = 1280;
  // κ grid nodes whose surrounding grid cells hold only object pixels (no
  // background pixel is multiplied by them) are neither found nor
  // evaluated, and hold κ = 1 in the κ layer (only cells wholly under the
  // objects read them). The composite is unchanged; false: κ at every node,
  // under the objects too.
  bool kappa_skip_covered = true;
  // κ first at every kappa_coarse_factor-th node of that grid; a coarse cell
  // whose corners differ by more than kappa_refine_delta is refined by
  // halves: it gets the nodes that halve it (edge midpoints, centre), and
  // each half is tested again with its own corners, down to neighbouring
  // nodes (a smooth gradient stops at the first half it passes; an edge is
  // followed to every node); cells that pass are interpolated (1: every node
  // of the grid).
  int kappa_coarse_factor = 4;
  double kappa_refine_delta = 0.02;
  // Refined nodes inside a coarse cell whose four receivers lie on one plane
  // take their receiver where their ray meets that plane (no NeRF march, no
  // normal query); false: every refined node is marched.
  bool kappa_plane_upsampling = true;
  double receiver_min_opacity = 0.5;  // pixels whose scene opacity is below this have no surface: κ = 1
  // κ depends on the receiver point, its normal, the objects and the light,
  // not on the view: it is kept at the nodes of a world lattice of this
  // spacing (× the smallest caster's bounding radius), one value per node and
  // receiver-normal cell (32×32 octahedral cells), computed when a receiver
  // first needs it and reused, trilinearly, until an object or a light
  // changes. 0: κ evaluated exactly at every receiver, every frame. The
  // trilinear error grows with the spacing relative to the casters' size,
  // the nodes a moving camera needs anew shrink with it; 0.15 radii keeps κ
  // within the shadow metric's noise.
  double kappa_cache_spacing_radii = 0.15;
  // With the lattice (spacing > 0) and NeRF receivers: a grid node's receiver
  // is first sought among the last frame's receivers instead of marching its
  // ray. The last grid's cell at the node's pixel gives a plane (through its
  // four receivers, normal from the diagonals; none of the four farther than
  // kappa_reuse_tolerance_radii × the smallest caster's bounding radius from
  // it); the ray meets it, and the point is taken when its projection into
  // the last view falls in that same cell (else once more with the cell it
  // fell in), with the NeRF normal of the nearest of the four (so the κ
  // lattice's normal cell is kept). A cell of four "no surface" nodes stays
  // no surface when the eye moved by less than the tolerance and the ray by
  // less than a grid step. Anything else is marched. The receivers do not
  // depend on objects or light and survive their changes. false: every
  // receiver marched.
  bool kappa_receiver_reuse = true;
  // With the lattice and NeRF receivers: one receiver normal per lattice
  // cell, the NeRF normal at the first receiver found in the cell (any view),
  // so that a receiver's normal, its κ lattice normal cell and κ do not change
  // with the view (the NeRF's normals scatter with the point's exact
  // position); false: the NeRF normal at every receiver.
  bool receiver_normal_per_cell = true;
  double kappa_reuse_tolerance_radii = 0.02;

  // "fast", "balanced" (the defaults) or "accurate"; InputError otherwise.
  static InsertOptions Preset(const std::string& name);
  // Every problem as "field: what is wrong (what was expected)".
  std::vector<std::string> Validate() const;
  // Every field under the name `--set` and ToJson give it (the light's
  // fields prefixed light_, its SG fit's sg_); the two enums as named
  // choices: light_source full|near|env, sg_method block|dense|adam.
  std::vector<OptionField> Fields();
  // Sets one field from "key=value" (`nerfar insert --set`, `nerfar live
  // --set`, NERFAR_BENCH_INSERT_KNOBS: SOURCE names which); InputError naming
  // the key when it is unknown or its value is not of the field's kind.
  void Set(const std::string& key_value, const std::string& source = "--set");
  // The effective options as one compact JSON object, keys in alphabetical
  // order (logged by every job, OUT/options.json): Fields().
  std::string ToJson() const;
};

}  // namespace nerfar
