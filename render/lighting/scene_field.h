// What per-frame insertion asks of the captured scene: volume rendering of
// rays over a given [t_near, t_far] each (colour, opacity, depth), and the
// surface normal at a point. The HDR NeRF implements it (render/insert's
// nerf_scene.h); the tests' analytic stand-in (tests/support/analytic_scene.h)
// gives exact answers. World frame, metres; directions are unit;
// colour is linear HDR radiance already weighted by opacity (Ĉ = Σ T α c, so
// a half-transparent ray returns half the colour it would behind glass).
#pragma once

#include <cstddef>
#include <optional>
#include <vector>

#include "calib/board.h"
#include "calib/core/math.h"
#include "calib/dataset.h"

namespace nerfar {

// Entry and exit distances of the ray o + t·d (d need not be unit; t in units
// of |d|) through the box, clipped to t >= 0. Nothing when the ray misses it
// (or only touches it behind the origin). (The NeRF module has the float twin
// for its own rays; this one serves scene fields of every kind.)
std::optional<std::pair<double, double>> IntersectBox(const Aabb& box, const Vec3& origin, const Vec3& direction);

// A batch of rays for one RenderRays call. Sizes are equal; directions unit.
struct SceneRays {
  std::vector<Vec3f> origins;
  std::vector<Vec3f> directions;
  std::vector<float> t_near, t_far;  // integration range per ray, t_near <= t_far (empty range: equal)

  size_t size() const { return origins.size(); }
  void Reserve(size_t n);
  void Add(const Vec3f& origin, const Vec3f& direction, float t0, float t1);
  void Clear();
};

// Results of RenderRays, one entry per ray.
struct SceneSamples {
  std::vector<Vec3f> colour;   // Ĉ = Σ T_k α_k c_k over the range (opacity-weighted radiance)
  std::vector<float> opacity;  // Ô = Σ T_k α_k in [0, 1]
  std::vector<float> depth;    // Σ T_k α_k t_k / Ô: expected hit distance along the ray (0 where Ô = 0);
                               // the paper's unnormalised D̂ is Ô·depth (the NeRF's convention too). A
                               // field may instead give where the transmittance crosses 1/2 on rays that
                               // get that opaque (NerfSceneOptions::surface_depth)

  void Resize(size_t n);
};

// A plane the scene is known to hold besides what its field shows (the tag
// board's: the surface the board and the objects lie on). World frame,
// metres; `normal` unit, pointing to the side the cameras see.
struct SupportPlane {
  Vec3f point, normal;
};

// The plane of a tag board's tags (through their corners' mean), its normal
// towards `viewer` (a camera centre: cameras see the printed side).
// InputError for a board without tags.
SupportPlane PlaneOfBoard(const Board& board, const Vec3& viewer);

class SceneField {
 public:
  virtual ~SceneField() = default;
  // The box holding everything of the scene.
  virtual Aabb Box() const = 0;
  // Volume renders every ray over its own [t_near, t_far]; out is resized.
  // Must be callable from several threads at once (const, no shared scratch).
  virtual void RenderRays(const SceneRays& rays, SceneSamples& out) const = 0;
  // The same for rays that gather the light arriving at a virtual object
  // (incident light): a field may correct radiance towards directions its
  // captures never saw (a NeRF: nerf_scene.h). Default: RenderRays.
  virtual void RenderLightRays(const SceneRays& rays, SceneSamples& out) const { RenderRays(rays, out); }
  // Whether RenderLightRays splits its batch over the threads itself (then
  // callers hand it every ray at once); false: callers split the batch.
  virtual bool ParallelLightRays() const { return false; }
  // Unit outward normal of the scene surface at each point (the direction of
  // −∇σ for a NeRF); the zero vector where it is undefined (empty space).
  virtual void Normals(const std::vector<Vec3f>& points, std::vector<Vec3f>& normals) const = 0;
  // Where each ray's transmittance, counted from its own t_near, first falls
  // to transmittance[i] (in (0, 1]): the distance along the ray, or t_far
  // where it stays above within [t_near, t_far]. `depth` is resized. The
  // default serves fields of opaque surfaces, where every level is crossed at
  // the first hit: RenderRays's depth where the ray gets that opaque.
  virtual void TransmittanceDepths(const SceneRays& rays, const std::vector<float>& transmittance,
                                   std::vector<float>& depth) const;
};

// Nothing at all: every ray is empty (opacity 0). For inserting into images
// whose geometry comes from elsewhere (ground-truth depth, tests).
class EmptyScene final : public SceneField {
 public:
  explicit EmptyScene(Aabb box) : box_(box) {}
  Aabb Box() const override { return box_; }
  void RenderRays(const SceneRays& rays, SceneSamples& out) const override { out.Resize(rays.size()); }
  void Normals(const std::vector<Vec3f>& points, std::vector<Vec3f>& normals) const override {
    normals.assign(points.size(), Vec3f{});
  }

 private:
  Aabb box_;
};

}  // namespace nerfar
