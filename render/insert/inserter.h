// Per-frame insertion of virtual objects (paper §4.4): for each object the
// incident light at its centre (fitted SGs, cached while it stands still),
// rasterised and SG-shaded with self-shadows γ_k from the SSDF fields of all
// objects (a union occludes by the smaller signed distance), occluded by the
// scene (NeRF colour and opacity over [min(d, t_n), min(d, t_f)], composite
// I_α·I_c + (1 − I_α)·I_v), and shadows κ (paper eqs. 8-9) multiplied into
// the background only where an object can shadow. The background is a camera
// frame (AR) or a NeRF rendering, composited in place. World frame, metres,
// OpenCV camera axes, linear HDR RGB.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "calib/camera.h"
#include "calib/core/image.h"
#include "calib/core/math.h"
#include "render/insert/incident_light.h"
#include "render/insert/object_visibility.h"
#include "render/insert/rasterizer.h"
#include "render/insert/scene_field.h"
#include "render/mesh/mesh.h"
#include "render/sg/brdf.h"

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
  int kappa_step = 2;  // κ at every kappa_step-th pixel, bilinear in between (1: every pixel)
  // κ first at every kappa_coarse_factor-th node of that grid; a coarse cell
  // whose corners differ by more than kappa_refine_delta gets all its nodes,
  // the others are interpolated (1: every node of the grid).
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
  // changes. 0: κ evaluated exactly at every receiver, every frame.
  double kappa_cache_spacing_radii = 0.1;
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
  // The effective options as JSON text (logged by every job).
  std::string ToJson() const;
};

// One virtual object in this frame. Pointers are loans for the call.
struct InsertObject {
  const TriangleMesh* mesh = nullptr;  // local frame, metres
  Pose T_world_object;
  double scale = 1.0;
  SgMaterial material;                           // constant material (maps below override per pixel)
  const ImageF* albedo_map = nullptr;            // optional, linear RGB, sampled at the mesh UVs (v = 0 at the top row)
  const ImageF* roughness_map = nullptr;         // optional, 1 channel (first channel used)
  const ImageF* metallic_map = nullptr;          // optional, 1 channel (first channel used)
  const ObjectVisibility* visibility = nullptr;  // its SSDF field, posed; nullptr: casts no shadow at all
  const SgMixture* light_override = nullptr;     // use this light instead of computing it (tests, ground truth)
  std::optional<Vec3> light_center;  // world point the incident light is taken at (default: bounding-sphere centre)
};

// Wall time of each stage of one frame, milliseconds.
struct InsertTimings {
  double light_ms = 0;      // rays from the object centres (0 when the cached light was reused)
  double fit_ms = 0;        // SG fits
  double raster_ms = 0;     // G-buffer
  double shade_ms = 0;      // SG shading with self-shadows
  double occlusion_ms = 0;  // NeRF over the clipped range on object pixels + composite
  double kappa_ms = 0;      // receivers + κ + multiplying the background
  double total_ms = 0;
  int lights_recomputed = 0;
  size_t kappa_evaluated = 0;     // κ values computed this frame (cache misses, or every receiver without the cache)
  size_t kappa_marched = 0;       // receiver rays marched through the scene for κ this frame
  size_t kappa_reused = 0;        // receivers taken from the last frame's instead of marching (kappa_receiver_reuse)
  bool gamma_recomputed = false;  // the per-vertex self-shadow cache was (re)built this frame
};

// Per-frame outputs beside the composite: layers over the screen boxes where
// they can differ from their neutral value.
struct InsertLayers {
  ObjectGBuffer gbuffer;       // object ids, depth, positions, normals over gbuffer.rect
  ImageF object;               // I_v over gbuffer.rect (RGB; 0 where no object)
  ImageF alpha;                // the object's weight (1 − I_α) over gbuffer.rect (1 channel; 0 where no object)
  PixelRect kappa_rect;        // where κ was evaluated
  ImageF kappa;                // κ over kappa_rect (1 channel; 1 elsewhere)
  size_t kappa_queries = 0;    // receivers that needed the SSDF (the rest were bounded to 1)
  size_t nonfinite_fixed = 0;  // non-finite output pixels replaced by the background (should stay 0)
};

// A layer over `rect` as a full width × height image, `fill` outside it.
ImageF ExpandLayer(const ImageF& layer, const PixelRect& rect, int width, int height, float fill);

// Optional per-pixel scene geometry that replaces marching the field for
// receivers: ray distance to the surface (1 channel, ≤ 0 = no surface) and
// world normals (3 channels). Both full-frame.
struct ReceiverOverride {
  const ImageF* distance = nullptr;
  const ImageF* normal = nullptr;
  // Optional: `distance` also decides occlusion of the objects (ground-truth
  // inputs without a NeRF): an object pixel whose distance there is nearer
  // than the object by more than 1% keeps the frame's pixel.
  bool occlude_with_distance = false;
};

// Receiver geometry from a depth map along the viewing axis (the scenes'
// depth_XXX.exr convention, 0 = nothing): ray distances (1 channel) and world
// normals (3 channels) from the back-projected neighbours, taking on each axis
// the side with the smaller depth jump so that edges do not bend normals.
void ReceiversFromDepth(const ImageF& depth_z, const CameraIntrinsics& camera, const Pose& T_world_camera,
                        ImageF& distance, ImageF& normal);

class Inserter {
 public:
  // `environment` may be empty (no distant light). The scene is a loan that
  // must outlive the Inserter.
  Inserter(const SceneField& scene, SgMixture environment, InsertOptions options);

  // Composites the objects into `frame` (linear RGB, camera size: the camera
  // frame, or a NeRF rendering from RenderBackground). Never throws on scene
  // content or poses; InputError on a frame of the wrong size.
  InsertTimings Render(const CameraIntrinsics& camera, const Pose& T_world_camera,
                       const std::vector<InsertObject>& objects, ImageF& frame, InsertLayers* layers = nullptr,
                       const ReceiverOverride& receivers = {});

  // The whole view rendered from the scene field (the "alongside" background).
  ImageF RenderBackground(const CameraIntrinsics& camera, const Pose& T_world_camera) const;

  // Light used for object i in the last frame (its fitted SGs).
  const SgMixture& Light(size_t object) const;
  const IncidentLight& LightCache(size_t object) const { return lights_.at(object); }
  const InsertOptions& options() const { return options_; }
  void set_options(const InsertOptions& options) { options_ = options; }
  const SgMixture& environment() const { return environment_; }

 private:
  const SceneField& scene_;
  SgMixture environment_;
  InsertOptions options_;
  std::vector<IncidentLight> lights_;
  std::vector<SgMixture> used_lights_;
  // γ per mesh vertex and lobe for each object, with what it was computed for.
  struct VertexGamma {
    std::vector<double> key;
    std::vector<float> gamma;  // vertex-major, lobes per vertex
  };
  std::vector<VertexGamma> vertex_gamma_;
  struct KappaCache;  // world lattice of κ (inserter.cpp)
  std::unique_ptr<KappaCache> kappa_cache_;

 public:
  ~Inserter();
  Inserter(Inserter&&) noexcept;
};

}  // namespace nerfar
