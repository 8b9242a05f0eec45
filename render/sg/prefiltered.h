// Specular shading from the incident-light samples themselves (split sum):
// the radiance prefiltered by the GGX lobe at a few roughness levels (maps
// over the sphere, built once per light) times an environment-BRDF term
// F0·A(n·v, r) + B(n·v, r) that holds the BRDF's integral under white light.
// An SG light of a few dozen lobes cannot carry reflections of compact
// sources sharper than its lobes; the samples can, up to their spacing.
// Directions are world unit vectors; radiance linear RGB; materials as in brdf.h.
#pragma once

#include <vector>

#include "render/sg/brdf.h"
#include "render/sg/sphere.h"

namespace nerfar {

// Brute-force outgoing radiance Σ_i f(l_i, v) L_i max(n·l_i, 0) Δω_i over
// the samples, with f the whole BRDF or its specular part only. The
// reference the prefiltered shading is tested against (slow: every sample
// per call).
Vec3 ShadeSamplesBruteForce(const RadianceSamples& samples, const SgMaterial& material, const Vec3& n, const Vec3& v,
                            bool specular_only);

// The split-sum environment BRDF: ∫ f_spec(l, v) max(n·l, 0) dω under unit
// radiance = F0·A + B (Schlick: F = F0 + (1 − F0)(1 − v·h)⁵), tabulated over
// n·v and roughness by importance-sampled integration once per process and
// read bilinearly (table accuracy in tests/insert/shading_test.cpp).
struct EnvironmentBrdfTerms {
  float scale = 0;  // A: multiplies F0
  float bias = 0;   // B: added (per channel, times 1)
};
EnvironmentBrdfTerms EnvironmentBrdf(float n_dot_v, float roughness);

// The distance from the point the light was taken at (its centre) to what
// each direction sees: an octahedral map (prefiltered.cpp's layout) of the
// inverse distance, nearest given direction per texel, bilinear between
// texels (inverse: distant light is 0, and a silhouette between a near
// surface and the sky blends towards the sky). For parallax-corrected
// reflections (PrefilteredRadiance::SetParallax).
class DistanceMap {
 public:
  DistanceMap() = default;
  // `distance[i]` (metres) is what direction `directions[i]` meets; a
  // non-finite or non-positive one: nothing near (distant light). The map
  // has n × n texels, n = clamp(⌈√count⌉, 8, 128) (about a texel per given
  // direction). No directions: empty().
  DistanceMap(const std::vector<Vec3>& directions, const std::vector<float>& distance);
  bool empty() const { return size_ == 0; }
  // 1 / distance around direction d (any length, non-zero); 0: distant.
  float InverseAt(const Vec3f& d) const;

 private:
  int size_ = 0;
  float fsize_ = 0;
  std::vector<float> inverse_;  // (n + 2)² texels with the folded border, as the level maps
};

// GGX-prefiltered radiance at `levels` roughness levels r_k = k/(levels − 1):
// map k holds, per direction R, Σ_i w_i L_i / Σ_i w_i with
// w_i = D_α(h_i)·max(R·l_i, 0)·Δω_i, h_i the half vector of R and l_i (the
// lobe with n = v = R). The filter's α is widened to √(α² + (Δ/2)²), Δ the
// samples' mean spacing (√ of their mean solid angle): a map cannot hold a
// reflection finer than the samples it is made of. Each level is an
// octahedral map (the sphere projected onto |x| + |y| + |z| = 1, the lower
// half folded out; a direction's texel by abs and one division) n × n with
// n = 1.5 × clamp(⌈π/α⌉, 8, the samples' resolution); the GGX tail beyond tan θ_h = 6α (under 3 % of the lobe's
// projected energy) is left out of the sums.
class PrefilteredRadiance {
 public:
  PrefilteredRadiance() = default;
  // Runs over ParallelFor. Samples with a non-finite or negative value or
  // solid angle count as black; no samples or levels < 2: empty().
  // `compact`: lobes sharper than the samples resolve, given apart (a sun
  // passed analytically, render/insert): each filtered through 64
  // directions of equal share (SgQuadrature) with the BRDF's own α widened
  // by the map's texel only, not by the samples' spacing; the levels are
  // then made fine enough for the sharpest lobe's reflection (texels a
  // third of its width, at most 384 a side), the samples' part read
  // bilinearly from their own map.
  PrefilteredRadiance(const RadianceSamples& samples, int levels, const SgMixture& compact = {});
  bool empty() const { return levels_.empty(); }
  int level_count() const { return static_cast<int>(levels_.size()); }
  // Prefiltered radiance around unit direction d for roughness r in [0, 1]:
  // bilinear in each map, linear between the two nearest levels.
  Vec3f Lookup(const Vec3f& d, float roughness) const;
  // The specular radiance of a pixel: Lookup(mirror of v about n) times the
  // environment BRDF with F0 = mix(0.02, a, m); 0 viewed from behind.
  Vec3f ShadeSpecular(const SgMaterial& material, const Vec3f& n, const Vec3f& v) const;
  // The same for count pixels (out[i] = ShadeSpecular(materials[i], n[i],
  // v[i])); what depends on roughness alone (levels and blend, the lobe's
  // shift, the environment BRDF's row) is worked out once per run of pixels
  // with one roughness (an object's whole material without a roughness map).
  void ShadeSpecular(const SgMaterial* materials, const Vec3f* n, const Vec3f* v, size_t count, Vec3f* out) const;

  // ShadeSpecular split by the material's F0 = mix(0.02, a, m): specular =
  // F0 ⊙ scaled[i] + biased[i], with scaled = L·A and biased = L·B (L the
  // look-up, A and B the environment BRDF at the pixel's n·v). Nothing of
  // the material but its roughness enters: the parts may be interpolated
  // between pixels whose base colour differs (an albedo map) and F0 applied
  // per pixel. `points` as below (nullptr: uncorrected).
  void ShadeSpecularParts(const SgMaterial* materials, const Vec3f* n, const Vec3f* v, const Vec3f* points,
                          size_t count, Vec3f* scaled, Vec3f* biased) const;
  // The specular of a material from its parts: F0 ⊙ scaled + biased, with
  // F0 = mix(0.02, base colour, metallic) per channel.
  static Vec3f SpecularFromParts(const SgMaterial& material, const Vec3f& scaled, const Vec3f& biased);

  // Parallax-corrected reflections: the samples were taken at `center` and
  // `distances` says how far each direction's light comes from. A pixel at
  // world point p then looks its reflection up not along its reflected
  // direction R but towards where the ray p + t·R meets that distance
  // field, found by `iterations` fixed-point steps from R: with the
  // direction d_k, D_k = distance(d_k), t_k solves |p − center + t·R| = D_k
  // (D_k at least |p − center|, so a point beyond the field's surface looks
  // from where it stands) and d_{k+1} = p − center + t_k·R. A distant
  // direction (inverse distance 0) gives d = R: with no near surface the
  // look-up is the uncorrected one. Empty `distances`: no correction.
  void SetParallax(const Vec3& center, DistanceMap distances, int iterations = 3);
  bool has_parallax() const { return !distances_.empty(); }
  // As ShadeSpecular above with each pixel's world point `points[i]`
  // (nullptr, or no parallax set: uncorrected).
  void ShadeSpecular(const SgMaterial* materials, const Vec3f* n, const Vec3f* v, const Vec3f* points, size_t count,
                     Vec3f* out) const;
  // The corrected look-up direction (any length) of a reflected ray from
  // world point p along direction r (any length, non-zero): r itself, as
  // given, without parallax or where the first step finds nothing near.
  Vec3f ParallaxDirection(const Vec3f& p, const Vec3f& r) const;

 private:
  struct Level {
    int size = 0;     // n: the octahedral map is n × n texels
    float fsize = 0;  // n as a float
    // (n + 2)² texels, row-major, 3 floats each: the map with a one-texel
    // border copied from across the square's folded edges.
    std::vector<float> rgb;
  };
  struct Prepared;  // the constants of one roughness (prefiltered.cpp)
  Prepared Prepare(float roughness) const;
  Vec3f Lookup(const Vec3f& d, const Prepared& p) const;
  Vec3f Shade(const Prepared& p, const SgMaterial& material, const Vec3f& n, const Vec3f& v,
              const Vec3f* point = nullptr) const;
  // The look-up and the environment BRDF's A and B at n·v (0 from behind).
  void ShadeParts(const Prepared& p, const Vec3f& n, const Vec3f& v, const Vec3f* point, Vec3f* scaled,
                  Vec3f* biased) const;
  // per_pixel(p, i) for i in [0, count), p prepared for materials[i]'s
  // roughness (again only where it changes; prefiltered.cpp).
  template <class PerPixel>
  void EachPrepared(const SgMaterial* materials, size_t count, PerPixel&& per_pixel) const;
  std::vector<Level> levels_;
  Vec3f center_;
  DistanceMap distances_;
  int iterations_ = 3;
};

}  // namespace nerfar
