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

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "calib/camera.h"
#include "calib/core/image.h"
#include "calib/core/math.h"
#include "render/insert/insert_options.h"
#include "render/insert/object_visibility.h"
#include "render/insert/rasterizer.h"
#include "render/lighting/incident_light.h"
#include "render/lighting/scene_field.h"
#include "render/mesh/mesh.h"
#include "render/sg/brdf.h"
#include "render/sg/prefiltered.h"

namespace nerfar {

struct VertexGamma;
struct KappaCache;
struct DragFrame;
class DragHold;
struct LightPrepCache;
struct LightPrep;
struct WorldSphere;

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
  // With light_override: its lobes' distances from the light centre
  // (LightParallax; +infinity = distant); nullptr: taken from the scene.
  const std::vector<double>* light_distances = nullptr;
  // With light_override: the radiance samples it stands for (e.g. the probe's
  // pixels), for the prefiltered specular term; nullptr: SG specular.
  const RadianceSamples* light_samples = nullptr;
  // With light_samples: lobes given beside them (compact sources taken out
  // of a probe, SplitCompactSources), which the prefiltered map filters as
  // lobes; nullptr: none.
  const SgMixture* light_compact = nullptr;
  // With light_samples: how far each direction's light comes from, seen
  // from the light centre (parallax-corrected reflections,
  // InsertOptions::specular_parallax); nullptr: none.
  const DistanceMap* light_sample_distances = nullptr;
  std::optional<Vec3> light_center;  // world point the incident light is taken at (default: bounding-sphere centre)
  // Being moved by the user (a drag): while every object keeps one common
  // translation from where the light was taken, the light is held and γ
  // and κ reused (drag_hold.h). false on every object: the plain path.
  bool dragged = false;
};

// The distance map of parallax-corrected reflections (DistanceMap) from the
// scene seen from a light's centre, by LobeDistances' rule per direction:
// the inverse distance is s / depth where the scene's opacity reaches a
// surface's (≥ 1/2, as κ's receivers take it), else 0 (thin fog, the
// environment), with s = min(1, Y(near_radiance) / Y(light)) the share of
// the light there that the scene's own radiance explains (a bright distant
// window seen past dim near fog stays distant); s = 1 without
// near_radiance or light (NearInverseDistances). Defined with the shading
// (object_shading.cpp).
DistanceMap ReflectionDistances(const std::vector<Vec3>& directions, const std::vector<float>& opacity,
                                const std::vector<float>& depth, const std::vector<Vec3>& near_radiance = {},
                                const SgMixture* light = nullptr);

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
  int lights_held = 0;         // objects lit by the light held through a drag (InsertObject::dragged)
  size_t kappa_evaluated = 0;  // κ values computed this frame (cache misses, or every receiver without the cache)
  size_t kappa_marched = 0;    // receiver rays marched through the scene for κ this frame
  size_t kappa_reused = 0;     // receivers taken from the last frame's instead of marching (kappa_receiver_reuse)
  // Parts of kappa_ms: finding the receivers (reuse, marches, cell normals),
  // κ at them (lattice look-ups or exact), multiplying the background.
  double kappa_receivers_ms = 0, kappa_lookup_ms = 0, kappa_multiply_ms = 0;
  size_t kappa_receivers = 0;     // receivers whose κ was taken (grid nodes found or placed on a plane)
  size_t kappa_lookups = 0;       // shared-lattice look-ups (past each thread's memo)
  size_t kappa_multiplied = 0;    // pixels the κ multiply passed (grid cells not all κ = 1)
  size_t kappa_hidden = 0;        // κ grid nodes under the objects that no background pixel needs (kappa_skip_covered)
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
  // Edge pixels whose centre an object covers but only part of whose area
  // it covers (coverage < 1): G-buffer index and the background's share
  // (1 − coverage) × frame in the composite, which the shadow darkens later
  // (CompositeEdges); empty without edge coverage.
  struct EdgeShare {
    uint32_t index = 0;
    float rgb[3] = {0, 0, 0};
  };
  std::vector<EdgeShare> edge_background;
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
  // `environment` may be empty (no distant light). `environment_distance_m`
  // (EnvLight::distance_m: one per lobe, or empty): lobes whose light stands
  // at a distance, each object seeing them from its centre
  // (EnvironmentSeenFrom). The scene is a loan that must outlive the Inserter.
  Inserter(const SceneField& scene, SgMixture environment, InsertOptions options,
           std::vector<double> environment_distance_m = {});

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
  const SgMixture& environment() const { return environment_; }
  const std::vector<double>& environment_distance_m() const { return environment_distance_m_; }
  // A plane the scene is known to hold (the tag board's), onto which shadow
  // receivers that end on it are taken (ReceiversOnPlane); nullopt: none.
  void set_support_plane(const std::optional<SupportPlane>& plane) { support_ = plane; }

 private:
  // Render's first steps: each object's incident light refreshed (or its
  // override taken, or held through a drag) with its lobes' distances;
  // every object's light prepared, again only when a light, its parallax or
  // an object changed.
  std::vector<LightParallax> UpdateLights(const std::vector<InsertObject>& objects,
                                          const std::vector<WorldSphere>& spheres, const DragFrame& drag,
                                          InsertTimings& times);
  std::vector<LightPrep>& PrepareLights(const std::vector<InsertObject>& objects,
                                        const std::vector<LightParallax>& parallax, const DragFrame& drag);
  // κ's lights held from the drag's start (DragFrame::kappa_apart), prepared.
  void HeldKappaLights(const std::vector<InsertObject>& objects, const DragFrame& drag, std::vector<SgMixture>& lights,
                       std::vector<LightPrep>& preps) const;

  const SceneField& scene_;
  SgMixture environment_;
  std::vector<double> environment_distance_m_;
  InsertOptions options_;
  std::optional<SupportPlane> support_;
  std::vector<IncidentLight> lights_;
  std::vector<SgMixture> used_lights_;
  std::vector<VertexGamma> vertex_gamma_;    // γ per mesh vertex and lobe for each object (vertex_gamma.h)
  std::unique_ptr<KappaCache> kappa_cache_;  // what the shadow pass keeps between frames (shadow_pass.h)
  // Every object's prepared light (SG shader, γ table rows, SSDF queries),
  // kept while the lights, their parallax and the objects are unchanged.
  std::unique_ptr<LightPrepCache> preps_;
  std::unique_ptr<DragHold> drag_;  // the light held through a drag (InsertObject::dragged)

 public:
  ~Inserter();
  Inserter(Inserter&&) noexcept;
};

}  // namespace nerfar
