// The simplified Disney BRDF as SGs and SG shading (paper eq. 5). Material:
// base colour a (linear RGB in [0, 1]), roughness r in [0, 1] (GGX alpha =
// r², clamped to ≥ 0.02² so the lobe stays finite), metallic m in [0, 1];
// F0 = mix(0.02, a, m), diffuse (1 − m)·a/π with Burley's retro-reflection.
// Directions are unit vectors in one frame (world); n the surface normal, v
// towards the viewer, l towards the light. Radiance linear RGB.
#pragma once

#include <array>
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
// Its specular part alone (GGX, Smith, Schlick; DisneyBrdf minus Burley's
// diffuse), 1/sr; 0 below either horizon.
Vec3 DisneySpecularBrdf(const SgMaterial& material, const Vec3& n, const Vec3& v, const Vec3& l);

// The GGX distribution as two SGs in the half vector (the NDF's core and its
// tail): D(h) ≈ Σ_j c_j/(πα²) · exp((b_j/α²)(h·n − 1)). GGX is
// (1 + t²)^{−2}/(πα²) in t = θ_h/α for small α; (c_j, b_j) are the least-
// squares fit of that profile over the plane (measure t dt): relative L2 error
// 2 %, energy 0.459 of GGX's 0.5 (the rest is in the t⁻⁴ tail beyond t ≈ 4).
// One SG with b = 2 (peak and energy of GGX) keeps all of the energy in the
// core: up to 32 % too bright where a light lobe is about as wide as the
// highlight; two SGs: ≤ 8 % (docs/SG.md "Glossy accuracy").
inline constexpr int kNdfLobes = 2;
inline constexpr double kNdfWeight[kNdfLobes] = {0.76493, 0.20441};
inline constexpr double kNdfSharpness[kNdfLobes] = {3.98723, 0.76465};

// The specular lobes for one view: each NDF SG warped to the mirror direction
// r = 2(n·v)n − v with sharpness (b_j/α²)/(4 n·v), times F·G/(4 n·v) taken at
// r (h = n there, so n·l = v·h = n·v). Their inner products with a light lobe
// sum to that lobe's specular radiance. Viewed from behind: zero amplitudes.
std::array<Sg, kNdfLobes> SpecularLobes(const SgMaterial& material, const Vec3& n, const Vec3& v);

// Burley's diffuse factor (1 + (F90 − 1)(1 − n·l)⁵)(1 + (F90 − 1)(1 − n·v)⁵),
// F90 = 0.5 + 2 r (l·h)², with the cosines clamped to [0, 1].
double BurleyFactor(double roughness, const Vec3& n, const Vec3& v, const Vec3& l);

// Outgoing radiance L_o(v) at a point with normal n under an SG light (paper
// eq. 5): Σ_k γ_k [(1 − m) a/π · Burley(l = p_k) · μ_k E_k(n) + μ_k ⟨G_k, spec⟩],
// E_k the exact clamped-cosine irradiance of lobe k (visibility.h). `gamma`
// holds one self-shadow factor per lobe (1 = unshadowed) or is empty.
Vec3 ShadeSg(const SgMixture& light, const SgMaterial& material, const Vec3& n, const Vec3& v,
             const std::vector<double>& gamma = {});

// The same in float for many pixels: the light prepared once per frame
// (structure of arrays padded to a multiple of kSgLanes lobes, each lobe's
// irradiance table row blended for its sharpness), then Shade for a span of
// pixels (fast: lanes are pixels) or for one pixel (lanes are lobes). Both
// are branch-free loops (FastExp, selects) compiled for AVX-512, AVX2 + FMA
// and SSE2 and picked at run time. At most kMaxSgLobes lobes. Both agree
// with ShadeSg to ~1e-4 relative (differential tests). docs/SG.md "Shading
// cost" counts their FLOPs and instructions.
inline constexpr int kSgLanes = 16;
// Which part of eq. 5 SgShader::Shade (many pixels) returns.
// kSpecularVisibility: not radiance but the specular's self-shadow sums,
// x = Σ_k γ_k Y(μ_k) Σ_j c_j⟨G_k, S_j⟩ and y = the same with every γ = 1 (Y
// luminance); x/y is the fraction of the SG specular that γ lets through.
// kDiffuseAndVisibility: the diffuse radiance in `out` and those sums in
// `visibility`, in one pass over the lobes.
enum class SgTerms { kAll, kDiffuse, kSpecular, kSpecularVisibility, kDiffuseAndVisibility };
class SgShader {
 public:
  explicit SgShader(const SgMixture& light);
  int lobe_count() const { return count_; }
  // One pixel. gamma: lobe_count() factors or nullptr (all 1). Returns
  // linear RGB. Prefer the many-pixel call below where pixels come in spans.
  Vec3f Shade(const SgMaterial& material, const Vec3f& n, const Vec3f& v, const float* gamma = nullptr) const;
  // The same for `count` pixels at once: the fast path (~2× the per-pixel
  // call's speed for 32 lobes; lanes are pixels, so the per-pixel set-up and
  // the sums vectorise too; docs/SG.md "Shading cost"). materials, normals,
  // views, out: count entries each; gamma: count × lobe_count() factors,
  // pixel after pixel (gamma[p · lobe_count() + k]), or nullptr (all 1).
  // terms: both, or one of the two parts (their sum is the whole): kDiffuse
  // is (1 − m) a/π Σ_k μ_k γ_k E_k Burley_k, which depends on v only through
  // Burley's retro-reflection factor; kSpecular is the rest (all of v).
  // visibility: count entries, written only with kDiffuseAndVisibility.
  void Shade(const SgMaterial* materials, const Vec3f* normals, const Vec3f* views, const float* gamma, int count,
             Vec3f* out, SgTerms terms = SgTerms::kAll, Vec3f* visibility = nullptr) const;

 private:
  int count_ = 0;
  int padded_ = 0;  // count_ rounded up to kSgLanes; padded lobes have zero amplitude
  alignas(64) float px_[kMaxSgLobes], py_[kMaxSgLobes], pz_[kMaxSgLobes];  // axes
  alignas(64) float lambda_[kMaxSgLobes];                                  // sharpness
  alignas(64) float mr_[kMaxSgLobes], mg_[kMaxSgLobes], mb_[kMaxSgLobes];  // amplitudes
  // Irradiance E(c) of lobe k at c = p·n: below(|c|) + max(c, 0)·slope, with
  // below = scale · exp(row value interpolated at |c|·inv_width).
  alignas(64) float inv_width_[kMaxSgLobes], scale_[kMaxSgLobes], slope_[kMaxSgLobes];
  std::vector<float> rows_;  // padded_ × kIrradianceTableColumns log values (BlendedIrradianceRow)
};

}  // namespace nerfar
