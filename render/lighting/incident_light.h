// Incident light at a virtual object's centre (paper eq. 1 and §4.4): rays
// leave the centre in N Fibonacci directions through the scene field, and
// L_i(d) = Ĉ(d) + (1 − Ô(d))·L_env(d), where Ĉ = Ô·L_nerf is the field's
// opacity-weighted colour (so this is the paper's (1 − Ô)L_env + Ô·L_nerf).
// The samples are fitted with SGs (render/sg FitSg), warm-started from the
// previous fit, and the result is kept while the centre does not move.
// Environment lobes sharper than the N directions resolve (a sun) skip the
// sampling and the fit: they join the fitted lobes as they are, times the
// scene's transmittance towards them (CompactSharpness, LobeTransmittance).
// World frame, metres, linear RGB radiance.
#pragma once

#include <string>
#include <vector>

#include "calib/core/image.h"
#include "render/lighting/scene_field.h"
#include "render/mesh/mesh.h"
#include "render/sg/compact_sources.h"
#include "render/sg/fit.h"
#include "render/sg/sg.h"
#include "render/sg/sphere.h"

namespace nerfar {

// Which light the object sees: ours, or the paper's two ablations.
enum class LightSource {
  kFull,             // NeRF near field blended with the environment by NeRF opacity
  kNearFieldOnly,    // Ĉ only (no environment light)
  kEnvironmentOnly,  // the environment SGs only (no NeRF rays, no fit)
};
// The sources' names in the enum's order ("full", "near", "env"): `--set
// light_source=NAME` (InsertOptions::Fields) and the reports.
const std::vector<const char*>& LightSourceNames();
const char* LightSourceName(LightSource source);

struct IncidentLightOptions {
  int directions = 1024;           // N rays from the centre: more is smoother and slower (linear cost)
  double move_threshold_m = 1e-4;  // the light is recomputed once the centre moved farther than this
  LightSource source = LightSource::kFull;
  SgFitOptions fit;  // lobe count and iterations of the SG fit (render/sg presets)
  // Parallax of near light (LightParallax below): each lobe gets a distance
  // from the scene's depth along the directions it covers, and shadows (κ at
  // a receiver) re-aim it from there. false: the light is the same at every
  // point, as taken at the centre (the paper). Off in the fast preset: each
  // κ evaluation then prepares its own SSDF query (~2-3× the κ work when
  // the lattice is rebuilt).
  bool parallax = true;
  // Lobes at least this sharp are treated as compact sources that can be
  // re-aimed (a lobe of sharpness λ is ~1/√λ rad wide: 10 is ~18°); broader
  // ones (walls, the table, the sky) stay as they are, fully re-aimed from
  // twice this sharpness, blended in between.
  double parallax_min_sharpness = 10.0;
  // Rays leave from where they exit the object's own volume (its mesh, as
  // posed) rather than from its centre: whatever the scene holds inside the
  // object (a NeRF's fog or floaters there) is replaced by the object, so it
  // neither lights it nor hides the light behind it. false: from the centre
  // (the paper).
  bool start_outside_object = true;
  // A turned object keeps its light while no ray's start moved farther than
  // this (a ball turned about its centre: only its facets move). 1 mm is a
  // fifth of the finest NeRF voxel (5 mm), below what the scene can resolve.
  double start_tolerance_m = 1e-3;
  // Supersampling where the light changes faster than the N directions
  // resolve (a lamp a few directions wide, a window's edge): a direction
  // whose radiance differs by more than refine_contrast× from a neighbour's,
  // the brighter of the two above the mean, takes the mean of refine_rays
  // rays spread over its own cell (solid angle 4π/N) instead of its centre
  // ray's alone, so that each sample carries its cell's light (flux) rather
  // than a point value that hits or misses a small source. 0: no refinement.
  int refine_rays = 16;  // fast preset: 0
  double refine_contrast = 2.0;
  // Environment lobes sharper than the N directions resolve (a sun, a lamp
  // a few degrees wide: CompactSharpness) pass to the light analytically:
  // each keeps its axis, sharpness and radiance, times the scene's
  // transmittance towards it (LobeTransmittance over `lobe_bundle_rays`
  // rays spread as the lobe); the directions and the SG fit carry the near
  // field and the broad environment, with the lobes left of the budget.
  // false: every lobe through the directions and the fit, as before.
  bool analytic_compact_lobes = true;
  // Rays of one compact lobe's transmittance bundle: its visible share is
  // resolved in steps of 1/rays (16: 6 %, below the SG fit's own error).
  int lobe_bundle_rays = 16;
  // Every problem as "field: what is wrong (what was expected)".
  std::vector<std::string> Validate() const;
};

// Radiance arriving at `center` from each unit direction (solid angle 4π/N
// each), per `source`. `opacity` (optional) receives Ô per direction and
// `depth` (optional) the scene's hit distance from the centre (0 where
// Ô = 0). `start` (optional, one per direction): ray i integrates the scene
// from max(start[i], box entry) on (ObjectExitDistances).
// `refine_rays` > 0: the directions whose light changes fast take the mean
// over their cells (IncidentLightOptions::refine_rays, refine_contrast; the
// directions must then be an even set such as FibonacciSphere's); `refined`
// (optional) receives how many did. A refined direction's opacity is its
// cell's mean, its depth the centre ray's, and its sub-rays start at the
// centre ray's start. `beside` (optional): lobes that reach the centre
// apart from the directions (the compact ones passed analytically); their
// mean radiance counts in the refinement's "above the mean" as if sampled.
RadianceSamples SampleIncidentLight(const SceneField& scene, const SgMixture& environment, const Vec3& center,
                                    const std::vector<Vec3>& directions, LightSource source,
                                    std::vector<float>* opacity = nullptr, std::vector<float>* depth = nullptr,
                                    const std::vector<float>* start = nullptr, int refine_rays = 0,
                                    double refine_contrast = 2.0, size_t* refined = nullptr,
                                    const SgMixture* beside = nullptr);

// The object whose light is taken: its mesh as posed in the world (a loan).
struct LightObjectVolume {
  const TriangleMesh* mesh = nullptr;
  Pose T_world_object;
  double scale = 1.0;
};

// The environment split into the lobes the directions carry (`broad`) and
// the compact ones (sharper than CompactSharpness(directions)) passed on
// analytically; at most `max_compact` of those, the most energetic (by
// luminance integral): the rest stay broad. Order kept within each part.
// `compact_index` (optional) receives each compact lobe's index in `environment`.
void SplitCompactLobes(const SgMixture& environment, int directions, int max_compact, SgMixture* broad,
                       SgMixture* compact, std::vector<size_t>* compact_index = nullptr);

// The scene's transmittance (1 − Ô, mean over `rays` directions spread as
// the lobe, SgQuadrature) from
// `center` towards each lobe, the rays starting where they leave `volume`
// (optional, ObjectExitDistances) as the light's other rays do. In [0, 1].
std::vector<double> LobeTransmittance(const SceneField& scene, const Vec3& center, const SgMixture& lobes, int rays,
                                      const LightObjectVolume* volume = nullptr);

// Per direction d, the distance t at which the ray center + t·d leaves the
// object's mesh for the last time (its farthest crossing of a triangle);
// 0 where it crosses none (e.g. the centre outside the mesh, looking away).
std::vector<float> ObjectExitDistances(const LightObjectVolume& volume, const Vec3& center,
                                       const std::vector<Vec3>& directions);

// The light taken at `center` with a distance per lobe: lobe k stands for a
// source at center + distance[k]·axis_k (infinity: distant light, the
// environment). Seen from another point p the source lies along
// s_k − p at |s_k − p|; a compact source keeps its radiance (the amplitude)
// while its solid angle scales with 1/distance², so its sharpness scales
// with distance² (width ~ 1/√λ). This is what makes the shadows of near
// lamps point the right way from each receiver.
struct LightParallax {
  Vec3 center;
  std::vector<double> distance;  // per lobe, metres; +infinity for distant light (empty: no parallax)
  double min_sharpness = 10.0;   // IncidentLightOptions::parallax_min_sharpness
  // Whether any lobe would move (a finite distance on a sharp enough lobe).
  bool Active(const SgMixture& light) const;
};

// Each lobe's distance from the samples taken at the centre: the inverse
// distance averaged over the directions with the lobe's own value as the
// weight, where a direction that meets a surface (opacity ≥ 1/2, as κ's
// receivers) contributes s/depth and any other 1/∞ = 0 (distant light, or
// thin fog in front of it); s is the share of the light there that the
// scene's own radiance `near_radiance` (Ĉ) explains, min(1, Y(Ĉ)/Y(light)),
// so that a bright distant source seen past a dark near surface stays
// distant (all 1 when near_radiance is empty). Lobes whose directions meet
// no near light get +infinity.
std::vector<double> LobeDistances(const SgMixture& light, const std::vector<Vec3>& directions,
                                  const std::vector<float>& opacity, const std::vector<float>& depth,
                                  const std::vector<Vec3>& near_radiance = {});

// LobeDistances' rule per direction (also the reflections' distances,
// ReflectionDistances): the inverse distance s / depth where the ray met a
// surface (opacity ≥ 1/2 at a finite positive depth, as κ's receivers),
// else 0; s = min(1, Y(near_radiance) / Y(light)), 1 when `light` is empty
// or near_radiance has fewer entries than the directions.
std::vector<double> NearInverseDistances(const SgMixture& light, const std::vector<Vec3>& directions,
                                         const std::vector<float>& opacity, const std::vector<float>& depth,
                                         const std::vector<Vec3>& near_radiance = {});

// The light of `parallax` as seen from point p (see LightParallax). The
// ratio of new to old distance is clamped to [1/4, 4] so that a point next
// to a source does not turn it into a spike. Lobes without a finite distance,
// or broader than the minimum sharpness, are returned unchanged.
// With `receiver_normal` (unit; p a surface point facing that way), a
// re-aimed lobe whose source lies at or below p's tangent plane is dark,
// one whose source stands less than its own extent (d/√λ) above it dims
// linearly: the source cannot light that side of the surface. An SG lobe
// would still reach above the horizon with half its tail (a patch of the
// table under a receiver on the table), light that the surface never
// receives and that the object's shadow on it could not hide.
SgMixture ReaimLight(const SgMixture& light, const LightParallax& parallax, const Vec3& p,
                     const Vec3* receiver_normal = nullptr);

// The environment as seen from p: a lobe whose light `nerfar env` placed
// `distance_m[k]` > 0 metres from the origin along its axis (EnvLight's
// distance_m) turns towards that point and sharpens or widens with the
// distance as ReaimLight re-aims a near lobe (at any sharpness: the fit
// placed it as a source); distant lobes, or all with `distance_m` not one
// per lobe, are returned unchanged.
// `distance_from_p` (optional) receives, per lobe, how far its light is
// from p (+infinity for distant light).
SgMixture EnvironmentSeenFrom(const SgMixture& environment, const std::vector<double>& distance_m, const Vec3& p,
                              std::vector<double>* distance_from_p = nullptr);

// One object's incident light, refreshed per frame.
class IncidentLight {
 public:
  struct Update {
    bool recomputed = false;  // false: the cached fit was reused
    double sample_ms = 0;     // ray marching from the centre
    double fit_ms = 0;        // SG fit (0 when reused or for the environment-only source)
    SgFitReport report;
  };

  // Recomputes the light if the centre moved (or the options changed, or on
  // the first call); warm-starts the fit from the last one. Never throws on
  // scene content: non-finite radiance is replaced by 0.
  // `volume` (optional): the object itself, whose inside the rays skip
  // (IncidentLightOptions::start_outside_object); a new pose refits when it
  // moves a ray's start by more than start_tolerance_m.
  // `environment_at_origin`: the environment's lobes, with `environment_distance_m`
  // (EnvLight::distance_m: one per lobe, or empty) for its lights at a
  // distance: the centre sees them turned and fallen off
  // (EnvironmentSeenFrom), and the environment's lobes that reach the light
  // as they are (the compact ones, the environment-only light) keep their
  // distance from the centre for the shadows' parallax.
  Update Refresh(const SceneField& scene, const SgMixture& environment_at_origin, const Vec3& center,
                 const IncidentLightOptions& options, const LightObjectVolume* volume = nullptr,
                 const std::vector<double>& environment_distance_m = {});
  // Forget the cache (the next Refresh fits from scratch).
  void Reset();

  bool valid() const { return valid_; }
  const SgMixture& light() const { return light_; }
  // The directions' radiance: without the compact lobes (compact()) when
  // those pass analytically.
  const RadianceSamples& samples() const { return samples_; }
  // The environment's compact lobes as they reach the centre (attenuated by
  // the scene's transmittance; part of light()); empty without any.
  const SgMixture& compact() const { return compact_; }
  const Vec3& center() const { return center_; }
  // The fitted lobes' distances (LobeDistances; empty without parallax).
  const std::vector<double>& lobe_distances() const { return distances_; }
  // The scene's opacity Ô and hit distance per direction of samples() (0 where Ô = 0).
  const std::vector<float>& opacity() const { return opacity_; }
  const std::vector<float>& depth() const { return depth_; }
  // How many directions the last sampling refined (IncidentLightOptions::refine_rays).
  size_t refined() const { return refined_; }

  // For a light given from elsewhere (a probe): the scene is sampled from
  // `center` for opacity and depth only, and `light`'s lobes get their
  // distances from it; kept while the centre, the light and the options
  // hold. Empty without parallax.
  const std::vector<double>& DistancesFor(const SceneField& scene, const SgMixture& light, const Vec3& center,
                                          const IncidentLightOptions& options,
                                          const LightObjectVolume* volume = nullptr);

 private:
  // The ray starts for `volume` at `center` (empty without one or with
  // start_outside_object off), cached while the mesh, pose and centre hold.
  const std::vector<float>* Starts(const Vec3& center, const IncidentLightOptions& options,
                                   const LightObjectVolume* volume);
  std::vector<float> starts_;
  const TriangleMesh* starts_mesh_ = nullptr;
  Pose starts_pose_;
  double starts_scale_ = 0.0;
  Vec3 starts_center_;
  int starts_directions_ = 0;
  // The starts the fitted light was sampled from (empty: from the centre).
  std::vector<float> fitted_starts_;

  bool valid_ = false;
  Vec3 center_;
  int directions_ = 0;
  LightSource source_ = LightSource::kFull;
  int lobes_ = 0;
  int refine_rays_ = 0;
  double refine_contrast_ = 0.0;
  size_t refined_ = 0;
  std::vector<Vec3> dirs_;
  RadianceSamples samples_;
  std::vector<float> opacity_, depth_;
  SgMixture light_;
  SgMixture fitted_;   // the fitted part of light_ (the warm start)
  SgMixture compact_;  // the analytic part of light_ (compact environment lobes)
  bool analytic_ = false;
  int bundle_rays_ = 0;
  std::vector<double> distances_;
  // DistancesFor's cache: the light and centre it was computed for.
  SgMixture given_light_;
  Vec3 given_center_;
  int given_directions_ = 0;
  bool given_valid_ = false;
};

// ---- Diagnostics (nerfar insert --truth): where on the sphere the light differs ----

// The raw samples (before the SG fit) as a width × height panorama in the
// scenes' equirect convention: each pixel takes the radiance of the sample
// direction nearest to its centre (3 channels). Empty samples: all zero.
ImageF SamplesPanorama(const RadianceSamples& samples, int width, int height);

// A part of the sphere: the directions with elevation (asin z, degrees) in
// [elevation_min_deg, elevation_max_deg) and azimuth (atan2(y, x), degrees,
// in [-180, 180)) in [azimuth_min_deg, azimuth_max_deg); or, with
// `mask` non-empty, the panorama pixels where mask is non-zero.
struct SphereRegion {
  std::string name;
  double elevation_min_deg = -90.0, elevation_max_deg = 90.0;
  double azimuth_min_deg = -180.0, azimuth_max_deg = 180.0;
  std::vector<unsigned char> mask;  // width × height of the panoramas measured (row-major)
  bool Contains(const Vec3& direction) const;
};

// The regions a light report lists: the sphere split into three bands
// (above 15° elevation, the horizon band within ±15°, below −15°), the 2D
// table of 6 elevation bands of 30° × 4 azimuth quadrants, and "sources":
// the directions within `source_margin_deg` of a pixel of `truth` brighter
// than `source_factor` × its mean luminance (lamps, a window: wherever the
// truth's compact sources are; empty when there is none).
std::vector<SphereRegion> LightReportRegions(const ImageF& truth, double source_factor = 10.0,
                                             double source_margin_deg = 5.0);

// Luminance flux ∫_region Y(L) dω (radiance × sr) of an equirect panorama,
// by summation over its pixels (their centres decide membership).
double RegionFlux(const ImageF& panorama, const SphereRegion& region);

}  // namespace nerfar
