// Internal to render/insert: the shadow terms from spherical signed
// distances — self-shadow γ per lobe (paper eq. 10) and the shadow ratio κ
// on scene receivers (paper eqs. 8-9) with every caster's SSDF field.
#pragma once

#include <cstddef>
#include <vector>

#include "render/insert/insert_common.h"
#include "render/insert/light_prep.h"
#include "render/sg/sphere.h"
#include "render/sg/visibility.h"

namespace nerfar {

// κ (paper eqs. 8-9) with the half-space visibility of f_h bounded by the
// occluder's size (see shadow_terms.cpp). `ssd` and `cap_radius` per lobe.
// `lobes`: PrepareShadowLobes(cosine_weighted).
double ShadowRatioCapped(const SgMixture& cosine_weighted, const std::vector<PreparedShadowLobe>& lobes,
                         const Vec3& normal, const std::vector<double>& ssd, const std::vector<double>& cap_radius);

// γ_k of every lobe at a surface point with normal n from the union SSD
// there (paper eq. 10; with `horizon`, relative to the part of the lobe above
// the surface's horizon, see InsertOptions::self_shadow_horizon).
void GammaFromSsd(const std::vector<Vec3f>& axes, const std::vector<SgTableRow>& rows, const Vec3f& n,
                  const float* ssd_min, bool horizon, float* gamma);

// κ from the light's radiance samples instead of its SG lobes
// (InsertOptions::kappa_from_samples). The samples are gathered into
// sources, one per bin of a Fibonacci set of directions and per kind: near
// (the sample's direction is ruled by a lobe with a finite distance,
// LightParallax) or distant. A source keeps its energy (luminance × solid
// angle), mean direction and angular radius (√2 × the RMS angle of its
// samples about that direction, the pixels' own size included, at least
// `min_radius`): a compact bulb stays as small as it is, however wide the
// SG lobe fitted to it. Seen from a receiver x, a near source at
// c + d·direction is re-aimed at it, its solid angle and energy scaled by
// (d/d')² and its radius by d/d' (ratio clamped to [1/4, 4], as
// ReaimLight); the SSDF is queried along the source's direction from x and
// the visible part of the source, a disc of that radius cut by the
// half-space the SSD describes, is the circular segment beyond the signed
// distance S (at most the occluder's disc (α/r)² is blocked when its
// bounding sphere looks smaller than the source). Then
//   κ = Σ e'_i max(n·u_i, 0) visible_i / Σ e'_i max(n·u_i, 0).
struct ShadowSource {
  Vec3f direction;     // unit, from the light centre
  float distance = 0;  // metres from the centre (+infinity for distant sources)
  float radius = 0;    // angular radius seen from the centre, radians
  float energy = 0;    // luminance × solid angle seen from the centre
};
struct ShadowSources {
  Vec3f center;
  std::vector<ShadowSource> near, distant;
  float min_radius = 0;
  // Every object's SSDF query along the distant sources' directions
  // (nullptr: no field), and the objects' fields for the near ones.
  std::vector<std::unique_ptr<VisibilityQuery>> distant_queries;
  std::vector<const ObjectVisibility*> visibilities;
  bool empty() const { return near.empty() && distant.empty(); }
};
// Sources of `samples` (directions from `parallax.center`) with the
// distances of `light`'s lobes (`parallax`, empty: all distant): each
// sample takes the distance of the lobe brightest in its direction when
// that lobe is sharp enough to be re-aimed (ReaimLight's rule). `compact`:
// lobes beside the samples (IncidentLight::compact()), each a distant
// source of its integral's energy and radius 2/√λ (√2 × its RMS angle
// √(2/λ)). Sources with less than `energy_cut` of the total energy are
// dropped. `bins` >= 4.
ShadowSources BuildShadowSources(const RadianceSamples& samples, const SgMixture& light, const LightParallax& parallax,
                                 const std::vector<InsertObject>& objects, int bins, double min_radius,
                                 const SgMixture& compact = {}, double energy_cut = 1e-4);
// The visible fraction of a disc of angular radius r whose nearest blocked
// direction lies at signed angular distance s from its centre (the
// half-space model of the SSD): 1 for s ≥ r, 0 for s ≤ −r, the circular
// segment in between.
double DiscVisibleFraction(double s, double r);

// What κ at a receiver needs: the casters (object indices with a field), the
// objects' world spheres, their prepared lights and the lights themselves.
struct KappaContext {
  const std::vector<size_t>* casters = nullptr;
  const std::vector<WorldSphere>* spheres = nullptr;
  const std::vector<LightPrep>* preps = nullptr;  // prepared for every object
  const std::vector<SgMixture>* lights = nullptr;
  float reach = 0;           // InsertOptions::shadow_reach_radii
  double one_minus_eps = 1;  // 1 − InsertOptions::shadow_epsilon
  // Per object, its light as sources (InsertOptions::kappa_from_samples);
  // nullptr or an empty entry: κ from the SG lobes.
  const std::vector<ShadowSources>* sources = nullptr;
};

// Scratch of one κ evaluation (kept per thread to avoid allocations).
struct KappaScratch {
  std::vector<double> s_bound, s_exact, cap;
  std::vector<float> ssd;
  // The cosine-weighted light of the last call and its prepared lobes,
  // reused while the owner's light (same object, no parallax) and the
  // normal (bit for bit) repeat, as at the lattice nodes of one normal
  // cell. cw_light nullptr: nothing kept; reset it whenever the lights
  // may have changed (a new κ pass).
  SgMixture cw;
  std::vector<PreparedShadowLobe> lobes;
  const SgMixture* cw_light = nullptr;
  Vec3f cw_normal;
  // κ from sources: each source as seen from the receiver.
  std::vector<Vec3f> src_dir, near_dirs;
  std::vector<float> src_radius, src_weight, src_ssd, src_alpha, src_best, near_ssd, distant_ssd;
  std::vector<uint32_t> near_index;
};

// κ at world point x with unit normal n under the light of the caster
// nearest in units of its radius: 1 where no caster is within reach or the
// bounding spheres cannot darken it below 1 − ε. *queried (optional) is set
// when the SSDF fields were queried.
float KappaAt(const KappaContext& context, const Vec3f& x, const Vec3f& n, KappaScratch& scratch, bool* queried);

}  // namespace nerfar
