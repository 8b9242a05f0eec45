// SSDF field of a virtual object (paper §4.3): the spherical signed distance
// S(d; x) — signed angle in radians from direction d to the object's
// silhouette seen from point x, positive where the ray x + t·d misses the
// object, in [-π, π] — baked on an N³ grid centred at the bounding-sphere
// centre (edge 3× the radius), over an octahedral direction map of R×R texels,
// compressed by PCA across grid points. Everything is in the object's local
// frame (metres): callers move points and directions into it.
//
// Queries: trilinear inside the grid; outside it, the point is projected
// radially onto the grid box and the angles are re-mapped by the change of the
// object's apparent size (see QueryOutside in ssdf_field.cpp; exact for a
// sphere). Grid points inside the object (every ray blocked) take the mean of
// their outside neighbours at bake time, so that near the surface the field
// blends outside views: looking outwards open, inwards blocked (self-shadow);
// deep inside the values are finite and bounded but carry no meaning.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "calib/core/error.h"
#include "calib/core/math.h"
#include "calib/core/option_fields.h"
#include "calib/object.h"
#include "render/mesh/mesh.h"

namespace nerfar {

class Progress;

// ---------------------------------------------------------------- directions
// Octahedral map of the unit sphere onto [0,1]²: texel (i, j) of an R×R map has
// its centre at u = (i + 0.5)/R, v = (j + 0.5)/R. Texel solid angles vary by
// less than a factor of ~2.3 (largest at the poles ±z).
Vec3 OctahedralDirection(double u, double v);
// Inverse of OctahedralDirection; d need not be unit (must not be zero).
std::array<double, 2> OctahedralCoordinates(const Vec3& d);
// Direction of texel (i, j) of an R×R map (unit).
Vec3 OctahedralTexelDirection(int i, int j, int resolution);
// The texel across the map's edge from (i, j), for i or j one step outside
// [0, R): the octahedral map folds each edge onto itself about its midpoint.
std::array<int, 2> OctahedralWrap(int i, int j, int resolution);

// ---------------------------------------------------------------- baking
struct SsdfBakeOptions {
  int grid = 16;             // grid points per axis (paper: 16). Larger: better near the object, N³ cost.
  int dirs = 32;             // octahedral map resolution R (R² directions per point). Sets the angular
                             // detail: texel spacing ≈ 203°/R; the silhouette itself is refined by bisection.
  int components = 32;       // PCA components kept (file size ∝ components). Fewer: smoother, smaller.
  int bisection_steps = 6;   // ray-cast bisections that place each silhouette crossing between two
                             // texels (precision: spacing / 2^steps). 0: crossing at the midpoint.
  double grid_extent = 3.0;  // grid edge / bounding-sphere radius (paper: 3). Must exceed 2 (the box
                             // has to hold the sphere).

  // "fast", "balanced" (the defaults above) or "accurate"; InputError otherwise.
  static SsdfBakeOptions Preset(const std::string& name);
  // Every problem, as "field: what is wrong (expected)"; empty when valid.
  std::vector<std::string> Validate() const;
  // Every field under its own name (`nerfar bake --set`).
  std::vector<OptionField> Fields();
  // Sets one field from "key=value" (`nerfar bake --set`); InputError naming
  // the key when it is unknown or its value is not of the field's kind.
  void Set(const std::string& key_value);
  // The effective options as a one-line JSON object, keys in alphabetical
  // order (logged and stored in the file).
  std::string ToJson() const;
};

// Uncompressed SSD samples: values[p * R² + t] for grid point p (index
// (iz * N + iy) * N + ix, position center - edge/2 + (ix, iy, iz) * edge/(N-1))
// and texel t = j * R + i.
struct SsdSamples {
  int grid = 0, dirs = 0;
  Vec3 center;
  double radius = 0;  // bounding-sphere radius
  double edge = 0;    // grid edge length (grid_extent * radius)
  std::vector<float> values;

  Vec3 GridPoint(int ix, int iy, int iz) const;
};

// What a bake did, for logs and the benchmark.
struct SsdfBakeReport {
  double seconds_rays = 0, seconds_pca = 0;
  uint64_t rays = 0;       // primary + bisection rays
  double pca_rms_rad = 0;  // RMS of (compressed - raw) over all samples
  double pca_max_rad = 0;  // largest |compressed - raw|
  size_t raw_bytes = 0;    // float32 samples before compression
};

// Ray casting (Embree) at every grid point and spherical distance transform.
// The result does not depend on the thread count.
SsdSamples ComputeSsdSamples(const TriangleMesh& mesh, const SsdfBakeOptions& options, Progress* progress = nullptr,
                             uint64_t* ray_count = nullptr);

// ---------------------------------------------------------------- the field
class SsdfField {
 public:
  SsdfField() = default;

  // PCA of the samples (mean + `components` basis maps + per-point coefficients).
  static SsdfField Compress(const SsdSamples& samples, int components);

  int grid() const { return grid_; }
  int dirs() const { return dirs_; }
  int components() const { return components_; }
  const Vec3& center() const { return center_; }
  double radius() const { return radius_; }
  double edge() const { return edge_; }

  // Provenance and the object's description, stored in the file.
  std::string mesh_reference;        // mesh file the field was baked from
  Bounds mesh_bounds;                // local-frame bounds of that mesh
  std::optional<Material> material;  // the object's material, if known
  std::string options_json;          // SsdfBakeOptions::ToJson() of the bake

  // S(d; x) in radians, [-π, π]; x and d in the object frame (d any length > 0).
  float Query(const Vec3f& x, const Vec3f& d) const;
  // The compressed value at grid point (ix, iy, iz) and texel t = j * R + i.
  float SampleAt(int ix, int iy, int iz, int texel) const;

  // Stored arrays (float32): mean[R²], basis[K][R²], coefficients[N³][K].
  const std::vector<float>& mean() const { return mean_; }
  const std::vector<float>& basis() const { return basis_; }
  const std::vector<float>& coefficients() const { return coefficients_; }
  size_t StoredFloats() const { return mean_.size() + basis_.size() + coefficients_.size(); }

  // Every inconsistency (sizes, finiteness, ranges) as "what (expected)".
  std::vector<std::string> Validate() const;

 private:
  friend class SsdfBatch;
  friend SsdfField ParseSsdf(const std::string& bytes, const std::string& source);
  // Mean + basis at a direction (bilinear over the octahedral map) into out[0..K].
  void EvaluateBasis(const Vec3f& d, float* out) const;
  // Coefficients at a point of the grid box by trilinear weights into out[0..K-1].
  void InterpolateCoefficients(const Vec3f& x, float* out) const;
  // Outside the grid: the per-point part (x_b on the grid box and the apparent
  // size change), then per direction d_b and what MapBack needs.
  struct OutsidePoint {
    Vec3f x_b;
    Vec3 u;                    // unit, from x towards the centre
    double far_over_near = 1;  // D_f / D_b
    double alpha_f = 0, alpha_b = 0;
  };
  struct OutsideMap {
    Vec3f d_b;
    float beta_f = 0, h_beta = 0, ratio = 1;  // ratio = D_b / D_f
  };
  // False when x is inside the grid box.
  bool MapPoint(const Vec3f& x, OutsidePoint* point) const;
  static OutsideMap MapDirection(const OutsidePoint& point, const Vec3f& d);
  static float MapBack(const OutsideMap& map, float s_b);

  int grid_ = 0, dirs_ = 0, components_ = 0;
  Vec3 center_;
  double radius_ = 0, edge_ = 0;
  std::vector<float> mean_, basis_, coefficients_;
};

// Bakes a mesh: ComputeSsdSamples + Compress, and records the mesh reference,
// bounds, material (the mesh's own unless `material` is given) and options.
SsdfField BakeSsdf(const TriangleMesh& mesh, const SsdfBakeOptions& options, const std::optional<Material>& material,
                   Progress* progress = nullptr, SsdfBakeReport* report = nullptr);

// The per-frame path: the lobe directions are fixed for a frame, so the PCA
// basis is evaluated at them once (PrepareDirections); then a point inside the
// grid costs one trilinear blend of K coefficients and one K-dot per lobe.
// Points outside the grid re-map their directions and evaluate the basis per
// lobe (about 4K more per lobe). Read-only after PrepareDirections: QueryBatch
// may run on many threads at once.
class SsdfBatch {
 public:
  explicit SsdfBatch(const SsdfField& field) : field_(field) {}
  // Directions in the object frame (any length > 0).
  void PrepareDirections(const std::vector<Vec3f>& directions);
  size_t lobes() const { return directions_.size(); }
  // out[p * lobes() + m] = S(direction m; points[p]) in radians.
  void QueryBatch(const Vec3f* points, size_t count, float* out) const;

 private:
  const SsdfField& field_;
  std::vector<Vec3f> directions_;
  std::vector<float> evaluated_;  // [lobe][1 + K]: mean then basis values
};

// ---------------------------------------------------------------- the file
// Binary, little-endian, in the sectioned container of calib/core/binary_file.h
// (magic "NERFSSDF", version, section table, crc32): sizes, geometry, mesh
// reference, bounds and options; the material if any; the float32 arrays
// (ssdf_io.cpp has the layout). Version 1 files (flat, before sections) are read too.
inline constexpr uint32_t kSsdfFileVersion = 2;

std::string SerializeSsdf(const SsdfField& field);
// InputError "source: what is wrong (expected)" for bad magic, version, sizes,
// checksum, non-finite or out-of-range values, truncation.
SsdfField ParseSsdf(const std::string& bytes, const std::string& source);
void WriteSsdf(const std::string& path, const SsdfField& field);  // atomic
SsdfField ReadSsdf(const std::string& path);

// ---------------------------------------------------------------- reference
// Brute-force S(d; x) from the mesh itself, for benchmarks and checks: exact
// for directions that miss (angular distance to the nearest projected
// triangle); for blocked directions, the nearest unblocked direction is
// searched along `azimuths` great circles (steps of `step_rad`, then bisection
// to 1e-5 rad); an unblocked sliver thinner than a step along every one of
// them is missed. Thread-safe after construction.
class SsdReference {
 public:
  explicit SsdReference(const TriangleMesh& mesh);
  ~SsdReference();
  SsdReference(const SsdReference&) = delete;
  SsdReference& operator=(const SsdReference&) = delete;
  double Ssd(const Vec3& x, const Vec3& d, int azimuths = 180, double step_rad = 0.005) const;
  bool Blocked(const Vec3& x, const Vec3& d) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  const TriangleMesh* mesh_;
};

}  // namespace nerfar
