// Internal to render/insert: the shadow terms from spherical signed
// distances — self-shadow γ per lobe (paper eq. 10) and the shadow ratio κ
// on scene receivers (paper eqs. 8-9) with every caster's SSDF field.
#pragma once

#include <cstddef>
#include <vector>

#include "render/insert/insert_common.h"
#include "render/insert/light_prep.h"
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

// What κ at a receiver needs: the casters (object indices with a field), the
// objects' world spheres, their prepared lights and the lights themselves.
struct KappaContext {
  const std::vector<size_t>* casters = nullptr;
  const std::vector<WorldSphere>* spheres = nullptr;
  const std::vector<LightPrep>* preps = nullptr;  // prepared for every object
  const std::vector<SgMixture>* lights = nullptr;
  float reach = 0;           // InsertOptions::shadow_reach_radii
  double one_minus_eps = 1;  // 1 − InsertOptions::shadow_epsilon
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
};

// κ at world point x with unit normal n under the light of the caster
// nearest in units of its radius: 1 where no caster is within reach or the
// bounding spheres cannot darken it below 1 − ε. *queried (optional) is set
// when the SSDF fields were queried.
float KappaAt(const KappaContext& context, const Vec3f& x, const Vec3f& n, KappaScratch& scratch, bool* queried);

}  // namespace nerfar
