// The simplified Disney BRDF as SGs and SG shading (paper eq. 5). Material:
// base colour a (linear RGB in [0, 1]), roughness r in [0, 1] (GGX alpha =
// r², clamped to ≥ 0.02² so the lobe stays finite), metallic m in [0, 1];
// F0 = mix(0.02, a, m), diffuse (1 − m)·a/π with Burley's retro-reflection.
// Directions are unit vectors in one frame (world); n the surface normal, v
// towards the viewer, l towards the light. Radiance linear RGB.
#pragma once

#include <string>
#include <vector>

#include "render/sg/sg.h"
#include "render/sg/visibility.h"

namespace nerfar {

struct SgMaterial {
  Vec3 base_color{0.8, 0.8, 0.8};  // albedo a, linear RGB in [0, 1]
  double roughness = 0.5;          // r in [0, 1]; GGX alpha = r²
  double metallic = 0.0;           // m in [0, 1]: 1 = metal (no diffuse, F0 = a)
  // Every problem as "field: what is wrong (what was expected)"; empty if valid.
  std::vector<std::string> Validate() const;
};

inline constexpr double kDielectricF0 = 0.02;
inline constexpr double kMinAlpha = 0.02 * 0.02;

// The reference BRDF the scenes were rendered with (Burley diffuse + GGX with
// separable Smith shadowing + Schlick Fresnel), f_r(l, v) in 1/sr; 0 when l or
// v is below the horizon. For tests and error figures, not the live path.
Vec3 DisneyBrdf(const SgMaterial& material, const Vec3& n, const Vec3& v, const Vec3& l);

// The specular lobe for one view: the GGX distribution as an SG in the half
// vector, D(h) ≈ exp((2/α²)(h·n − 1))/(πα²), warped to the mirror direction
// r = 2(n·v)n − v with sharpness (2/α²)/(4 n·v), times F·G/(4 n·v) taken at r.
// Its inner product with a light lobe is that lobe's specular radiance.
Sg SpecularLobe(const SgMaterial& material, const Vec3& n, const Vec3& v);

// Burley's diffuse factor (1 + (F90 − 1)(1 − n·l)⁵)(1 + (F90 − 1)(1 − n·v)⁵),
// F90 = 0.5 + 2 r (l·h)², with the cosines clamped to [0, 1].
double BurleyFactor(double roughness, const Vec3& n, const Vec3& v, const Vec3& l);

// Outgoing radiance L_o(v) at a point with normal n under an SG light (paper
// eq. 5): Σ_k γ_k [(1 − m) a/π · Burley(l = p_k) · μ_k E_k(n) + μ_k ⟨G_k, spec⟩],
// E_k the exact clamped-cosine irradiance of lobe k (visibility.h). `gamma`
// holds one self-shadow factor per lobe (1 = unshadowed) or is empty.
Vec3 ShadeSg(const SgMixture& light, const SgMaterial& material, const Vec3& n, const Vec3& v,
             const std::vector<double>& gamma = {});

// The same for many pixels: the light prepared once (per-lobe table rows,
// float structure of arrays), then Shade per pixel. At most kMaxSgLobes lobes.
// Agrees with ShadeSg to float precision (differential test).
class SgShader {
 public:
  explicit SgShader(const SgMixture& light);
  int lobe_count() const { return count_; }
  // gamma: lobe_count() factors or nullptr (all 1). Returns linear RGB.
  Vec3f Shade(const SgMaterial& material, const Vec3f& n, const Vec3f& v, const float* gamma = nullptr) const;

 private:
  int count_ = 0;
  float px_[kMaxSgLobes], py_[kMaxSgLobes], pz_[kMaxSgLobes];  // axes
  float lambda_[kMaxSgLobes];                                  // sharpness
  float mr_[kMaxSgLobes], mg_[kMaxSgLobes], mb_[kMaxSgLobes];  // amplitudes
  SgTableRow irradiance_[kMaxSgLobes];
};

}  // namespace nerfar
