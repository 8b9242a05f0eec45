// Baking: octahedral directions, ray casting at every grid point, the
// spherical distance transform, PCA compression; and the brute-force reference.
#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <random>
#include <sstream>

#include "calib/core/log.h"
#include "calib/core/parallel.h"
#include "render/ssdf/ray_caster.h"
#include "render/ssdf/ssdf.h"

namespace nerfar {

using ssdf_internal::RayCaster;

// ---------------------------------------------------------------- directions

Vec3 OctahedralDirection(double u, double v) {
  double px = 2 * u - 1, py = 2 * v - 1;
  const double pz = 1 - std::abs(px) - std::abs(py);
  if (pz < 0) {  // lower hemisphere: unfold the corner triangles
    const double fx = (1 - std::abs(py)) * (px >= 0 ? 1 : -1);
    const double fy = (1 - std::abs(px)) * (py >= 0 ? 1 : -1);
    px = fx;
    py = fy;
  }
  return Normalized(Vec3(px, py, pz));
}

std::array<double, 2> OctahedralCoordinates(const Vec3& d) {
  const double l1 = std::abs(d.x) + std::abs(d.y) + std::abs(d.z);
  double px = d.x / l1, py = d.y / l1;
  if (d.z < 0) {
    const double fx = (1 - std::abs(py)) * (px >= 0 ? 1 : -1);
    const double fy = (1 - std::abs(px)) * (py >= 0 ? 1 : -1);
    px = fx;
    py = fy;
  }
  return {0.5 * (px + 1), 0.5 * (py + 1)};
}

Vec3 OctahedralTexelDirection(int i, int j, int resolution) {
  return OctahedralDirection((i + 0.5) / resolution, (j + 0.5) / resolution);
}

std::array<int, 2> OctahedralWrap(int i, int j, int resolution) {
  const int r = resolution;
  if (i < 0) i = 0, j = r - 1 - j;
  if (i >= r) i = r - 1, j = r - 1 - j;
  if (j < 0) j = 0, i = r - 1 - i;
  if (j >= r) j = r - 1, i = r - 1 - i;
  return {i, j};
}

// ---------------------------------------------------------------- options

SsdfBakeOptions SsdfBakeOptions::Preset(const std::string& name) {
  SsdfBakeOptions o;
  if (name == "fast") {
    o.dirs = 24;
    o.components = 16;
    o.bisection_steps = 4;
  } else if (name == "balanced") {
    // the defaults
  } else if (name == "accurate") {
    o.dirs = 64;
    o.components = 64;
    o.bisection_steps = 8;
  } else {
    ThrowInputError("--preset", "unknown preset '" + name + "' (expected fast, balanced or accurate)");
  }
  return o;
}

std::vector<std::string> SsdfBakeOptions::Validate() const {
  std::vector<std::string> problems;
  if (grid < 2 || grid > 128) problems.push_back("grid: " + std::to_string(grid) + " (expected 2 to 128)");
  if (dirs < 4 || dirs > 512) problems.push_back("dirs: " + std::to_string(dirs) + " (expected 4 to 512)");
  if (components < 1 || components > 1024)
    problems.push_back("components: " + std::to_string(components) + " (expected 1 to 1024)");
  if (grid >= 2 && grid <= 128 && dirs >= 4 && dirs <= 512) {
    const long long most = std::min<long long>(static_cast<long long>(grid) * grid * grid, 1LL * dirs * dirs);
    if (components > most)
      problems.push_back("components: " + std::to_string(components) +
                         " (expected at most min(grid³, dirs²) = " + std::to_string(most) + ")");
  }
  if (bisection_steps < 0 || bisection_steps > 20)
    problems.push_back("bisection_steps: " + std::to_string(bisection_steps) + " (expected 0 to 20)");
  if (!(grid_extent > 2.0 && grid_extent <= 100.0))
    problems.push_back("grid_extent: " + std::to_string(grid_extent) + " (expected above 2, at most 100)");
  return problems;
}

std::vector<OptionField> SsdfBakeOptions::Fields() {
  return {FieldOf("grid", &grid), FieldOf("dirs", &dirs), FieldOf("components", &components),
          FieldOf("bisection_steps", &bisection_steps), FieldOf("grid_extent", &grid_extent)};
}

void SsdfBakeOptions::Set(const std::string& key_value) { SetOptionField(Fields(), key_value); }

std::string SsdfBakeOptions::ToJson() const {
  SsdfBakeOptions copy = *this;
  return OptionFieldsJson(copy.Fields());
}

Vec3 SsdSamples::GridPoint(int ix, int iy, int iz) const {
  const double step = edge / (grid - 1);
  return center - Vec3(1, 1, 1) * (edge / 2) + Vec3(ix, iy, iz) * step;
}

// ---------------------------------------------------------------- samples

namespace {

double SecondsNow() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// The SSD map at one point: binary visibility per texel, silhouette crossings
// between differing neighbours placed by bisection, then for every texel the
// angle to the nearest crossing, signed by the texel's own visibility.
class PointBaker {
 public:
  PointBaker(const RayCaster& caster, const std::vector<Vec3f>& dirs, int resolution, int bisection_steps)
      : caster_(caster), dirs_(dirs), r_(resolution), steps_(bisection_steps) {}

  // Writes R² values; returns the number of rays cast. *enclosed: every ray blocked.
  uint64_t Bake(const Vec3f& origin, float* out, bool* enclosed) {
    const size_t n = dirs_.size();
    blocked_.resize(n);
    caster_.OccludedMany(origin, dirs_.data(), n, blocked_.data());
    uint64_t rays = n;
    size_t count = 0;
    for (uint8_t b : blocked_) count += b;
    *enclosed = count == n;
    if (count == 0 || count == n) {  // nothing seen, or inside: no silhouette
      std::fill(out, out + n, count == 0 ? static_cast<float>(kPi) : -static_cast<float>(kPi));
      return rays;
    }
    bx_.clear();
    by_.clear();
    bz_.clear();
    const auto edge = [&](int ia, int ja, int ib, int jb) {
      const size_t a = static_cast<size_t>(ja) * r_ + ia, b = static_cast<size_t>(jb) * r_ + ib;
      if (blocked_[a] == blocked_[b]) return;
      rays += AddCrossing(origin, dirs_[a], blocked_[a], dirs_[b]);
    };
    for (int j = 0; j < r_; ++j) {
      for (int i = 0; i < r_; ++i) {
        if (i + 1 < r_) edge(i, j, i + 1, j);
        if (j + 1 < r_) edge(i, j, i, j + 1);
        if (i + 1 < r_ && j + 1 < r_) {
          // Diagonals double the crossings along the silhouette: the worst
          // texel-to-crossing gap falls from ~0.7 to ~0.25 texel spacings
          // (sphere, R 24: max error 6.0° -> < 2°).
          edge(i, j, i + 1, j + 1);
          edge(i + 1, j, i, j + 1);
        }
      }
    }
    // Across the folded map edges: (0, j) touches (0, R-1-j), and so on.
    for (int k = 0; k < r_ / 2; ++k) {
      const int m = r_ - 1 - k;
      edge(0, k, 0, m);
      edge(r_ - 1, k, r_ - 1, m);
      edge(k, 0, m, 0);
      edge(k, r_ - 1, m, r_ - 1);
    }
    DistanceTransform(out);
    return rays;
  }

 private:
  uint64_t AddCrossing(const Vec3f& origin, Vec3f a, uint8_t state_a, Vec3f b) {
    for (int s = 0; s < steps_; ++s) {
      const Vec3f m = Normalized(a + b);
      if (caster_.Occluded(origin, m) == (state_a != 0))
        a = m;
      else
        b = m;
    }
    const Vec3f c = Normalized(a + b);
    bx_.push_back(c.x);
    by_.push_back(c.y);
    bz_.push_back(c.z);
    return static_cast<uint64_t>(steps_);
  }

  // Nearest crossing per texel: max of the dot product, texels in the inner
  // loop so that it vectorises (an element-wise max, no reduction).
  void DistanceTransform(float* out) {
    const size_t n = dirs_.size();
    best_.assign(n, -2.0f);
    tx_.resize(n);
    ty_.resize(n);
    tz_.resize(n);
    for (size_t t = 0; t < n; ++t) tx_[t] = dirs_[t].x, ty_[t] = dirs_[t].y, tz_[t] = dirs_[t].z;
    float* best = best_.data();
    const float *tx = tx_.data(), *ty = ty_.data(), *tz = tz_.data();
    for (size_t k = 0; k < bx_.size(); ++k) {
      const float cx = bx_[k], cy = by_[k], cz = bz_[k];
      for (size_t t = 0; t < n; ++t) {
        const float dot = tx[t] * cx + ty[t] * cy + tz[t] * cz;
        best[t] = best[t] > dot ? best[t] : dot;
      }
    }
    for (size_t t = 0; t < n; ++t) {
      const float angle = std::acos(std::clamp(best[t], -1.0f, 1.0f));
      out[t] = blocked_[t] ? -angle : angle;
    }
  }

  const RayCaster& caster_;
  const std::vector<Vec3f>& dirs_;
  int r_, steps_;
  std::vector<uint8_t> blocked_;
  std::vector<float> bx_, by_, bz_, best_, tx_, ty_, tz_;
};

// Grid points inside the object see it everywhere (S = -π). Left so, they
// would drag every trilinear blend near the surface towards "blocked", and a
// surface point (self-shadow) would read as fully shadowed. Instead each one
// takes the mean map of its 6-neighbours outside, layer by layer inwards, so
// that queries near the surface are blends of outside views (outwards open,
// inwards blocked). Each layer reads only the previous layers: the result does
// not depend on the visiting order. With no point outside, they stay -π.
void FillEnclosedPoints(std::vector<uint8_t> enclosed, SsdSamples* samples) {
  const int n = samples->grid;
  const size_t texels = static_cast<size_t>(samples->dirs) * samples->dirs;
  if (std::all_of(enclosed.begin(), enclosed.end(), [](uint8_t e) { return e != 0; })) return;
  std::vector<double> sum(texels);
  for (bool changed = true; changed;) {
    changed = false;
    std::vector<uint8_t> next = enclosed;
    for (int iz = 0; iz < n; ++iz)
      for (int iy = 0; iy < n; ++iy)
        for (int ix = 0; ix < n; ++ix) {
          const size_t p = (static_cast<size_t>(iz) * n + iy) * n + ix;
          if (!enclosed[p]) continue;
          std::fill(sum.begin(), sum.end(), 0.0);
          int found = 0;
          const int steps[6][3] = {{-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}, {0, 0, -1}, {0, 0, 1}};
          for (const auto& s : steps) {
            const int jx = ix + s[0], jy = iy + s[1], jz = iz + s[2];
            if (jx < 0 || jy < 0 || jz < 0 || jx >= n || jy >= n || jz >= n) continue;
            const size_t q = (static_cast<size_t>(jz) * n + jy) * n + jx;
            if (enclosed[q]) continue;
            const float* v = samples->values.data() + q * texels;
            for (size_t t = 0; t < texels; ++t) sum[t] += v[t];
            ++found;
          }
          if (found == 0) continue;
          float* out = samples->values.data() + p * texels;
          for (size_t t = 0; t < texels; ++t) out[t] = static_cast<float>(sum[t] / found);
          next[p] = 0;
          changed = true;
        }
    enclosed.swap(next);
  }
}

}  // namespace

SsdSamples ComputeSsdSamples(const TriangleMesh& mesh, const SsdfBakeOptions& options, Progress* progress,
                             uint64_t* ray_count) {
  const std::vector<std::string> problems = options.Validate();
  if (!problems.empty()) {
    Problems list("ssdf bake options");
    for (const std::string& p : problems) list.Add("", p);
    list.ThrowIfAny();
  }
  const RayCaster caster(mesh);
  const BoundingSphere sphere = ComputeBoundingSphere(mesh);
  if (!(sphere.radius > 0))
    ThrowInputError(mesh.source.empty() ? "mesh" : mesh.source, "all vertices coincide (expected a mesh with extent)");

  SsdSamples samples;
  samples.grid = options.grid;
  samples.dirs = options.dirs;
  samples.center = sphere.center;
  samples.radius = sphere.radius;
  samples.edge = options.grid_extent * sphere.radius;
  const int n = options.grid, r = options.dirs;
  const size_t texels = static_cast<size_t>(r) * r;
  samples.values.resize(static_cast<size_t>(n) * n * n * texels);

  std::vector<Vec3f> dirs(texels);
  for (int j = 0; j < r; ++j)
    for (int i = 0; i < r; ++i) dirs[static_cast<size_t>(j) * r + i] = Vec3f(OctahedralTexelDirection(i, j, r));

  std::atomic<uint64_t> rays{0};
  std::vector<uint8_t> enclosed(static_cast<size_t>(n) * n * n);
  // One z slice at a time so that progress is reported from this thread.
  const size_t slice = static_cast<size_t>(n) * n;
  for (int iz = 0; iz < n; ++iz) {
    ParallelForChunks(slice, 4, [&](size_t begin, size_t end) {
      PointBaker baker(caster, dirs, r, options.bisection_steps);
      uint64_t local = 0;
      for (size_t k = begin; k < end; ++k) {
        const int ix = static_cast<int>(k % n), iy = static_cast<int>(k / n);
        const size_t point = static_cast<size_t>(iz) * slice + k;
        bool inside = false;
        local += baker.Bake(Vec3f(samples.GridPoint(ix, iy, iz)), samples.values.data() + point * texels, &inside);
        enclosed[point] = inside;
      }
      rays += local;
    });
    if (progress) progress->Update(static_cast<size_t>(iz + 1) * slice);
  }
  if (ray_count) *ray_count = rays.load();
  FillEnclosedPoints(enclosed, &samples);
  return samples;
}

// ---------------------------------------------------------------- PCA

SsdfField SsdfField::Compress(const SsdSamples& samples, int components) {
  const size_t points = static_cast<size_t>(samples.grid) * samples.grid * samples.grid;
  const size_t d = static_cast<size_t>(samples.dirs) * samples.dirs;
  NERFAR_CHECK_EQ(samples.values.size(), points * d);
  NERFAR_CHECK_GE(components, 1);
  NERFAR_CHECK_LE(static_cast<size_t>(components), std::min(points, d));

  using Matrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  Eigen::Map<const Matrix> raw(samples.values.data(), static_cast<Eigen::Index>(points), static_cast<Eigen::Index>(d));
  const Eigen::RowVectorXf mean = raw.colwise().mean();
  const Matrix centred = raw.rowwise() - mean;

  // Randomised SVD (range finder with power iterations, fixed seed): the top
  // `components` right singular vectors of the centred samples.
  const auto k = static_cast<Eigen::Index>(components);
  const Eigen::Index l = std::min<Eigen::Index>(k + 10, std::min<Eigen::Index>(points, d));
  std::mt19937 rng(12345);
  std::normal_distribution<float> normal(0.0f, 1.0f);
  Eigen::MatrixXf omega(static_cast<Eigen::Index>(d), l);
  for (Eigen::Index c = 0; c < l; ++c)
    for (Eigen::Index row = 0; row < omega.rows(); ++row) omega(row, c) = normal(rng);
  const auto orthonormal = [](const Eigen::MatrixXf& m) -> Eigen::MatrixXf {
    Eigen::HouseholderQR<Eigen::MatrixXf> qr(m);
    return qr.householderQ() * Eigen::MatrixXf::Identity(m.rows(), m.cols());
  };
  Eigen::MatrixXf q = orthonormal(centred * omega);
  for (int iteration = 0; iteration < 3; ++iteration) {
    const Eigen::MatrixXf z = orthonormal(centred.transpose() * q);
    q = orthonormal(centred * z);
  }
  const Eigen::MatrixXf b = q.transpose() * centred;  // l × d
  Eigen::BDCSVD<Eigen::MatrixXf> svd(b, Eigen::ComputeThinV);
  const Eigen::MatrixXf v = svd.matrixV().leftCols(k);  // d × k, orthonormal columns
  const Eigen::MatrixXf coefficients = centred * v;     // points × k

  SsdfField field;
  field.grid_ = samples.grid;
  field.dirs_ = samples.dirs;
  field.components_ = components;
  field.center_ = samples.center;
  field.radius_ = samples.radius;
  field.edge_ = samples.edge;
  field.mean_.assign(mean.data(), mean.data() + d);
  field.basis_.resize(d * components);  // texel-major: basis[t * K + k]
  for (size_t t = 0; t < d; ++t)
    for (Eigen::Index c = 0; c < k; ++c) field.basis_[t * components + c] = v(static_cast<Eigen::Index>(t), c);
  field.coefficients_.resize(points * components);
  for (size_t p = 0; p < points; ++p)
    for (Eigen::Index c = 0; c < k; ++c)
      field.coefficients_[p * components + c] = coefficients(static_cast<Eigen::Index>(p), c);
  return field;
}

SsdfField BakeSsdf(const TriangleMesh& mesh, const SsdfBakeOptions& options, const std::optional<Material>& material,
                   Progress* progress, SsdfBakeReport* report) {
  const double t0 = SecondsNow();
  uint64_t rays = 0;
  const SsdSamples samples = ComputeSsdSamples(mesh, options, progress, &rays);
  const double t1 = SecondsNow();
  SsdfField field = SsdfField::Compress(samples, options.components);
  const double t2 = SecondsNow();
  field.mesh_reference = mesh.source;
  field.mesh_bounds = ComputeBounds(mesh);
  field.material = material ? material : mesh.material;
  field.options_json = options.ToJson();
  if (report) {
    report->seconds_rays = t1 - t0;
    report->seconds_pca = t2 - t1;
    report->rays = rays;
    report->raw_bytes = samples.values.size() * sizeof(float);
    // Compression error over every stored sample, summed in a fixed order.
    const size_t texels = static_cast<size_t>(samples.dirs) * samples.dirs;
    const int n = samples.grid;
    std::vector<double> sum_sq(static_cast<size_t>(n) * n * n), max_abs(sum_sq.size());
    ParallelFor(sum_sq.size(), [&](size_t p) {
      const int ix = static_cast<int>(p % n), iy = static_cast<int>((p / n) % n), iz = static_cast<int>(p / n / n);
      for (size_t t = 0; t < texels; ++t) {
        const double e = field.SampleAt(ix, iy, iz, static_cast<int>(t)) - samples.values[p * texels + t];
        sum_sq[p] += e * e;
        max_abs[p] = std::max(max_abs[p], std::abs(e));
      }
    });
    double total = 0;
    for (size_t p = 0; p < sum_sq.size(); ++p) {
      total += sum_sq[p];
      report->pca_max_rad = std::max(report->pca_max_rad, max_abs[p]);
    }
    report->pca_rms_rad = std::sqrt(total / static_cast<double>(samples.values.size()));
  }
  return field;
}

// ---------------------------------------------------------------- reference

struct SsdReference::Impl {
  explicit Impl(const TriangleMesh& mesh) : caster(mesh) {}
  RayCaster caster;
};

SsdReference::SsdReference(const TriangleMesh& mesh) : impl_(std::make_unique<Impl>(mesh)), mesh_(&mesh) {}
SsdReference::~SsdReference() = default;

bool SsdReference::Blocked(const Vec3& x, const Vec3& d) const {
  return impl_->caster.Occluded(Vec3f(x), Vec3f(Normalized(d)));
}

namespace {

double AngleBetween(const Vec3& a, const Vec3& b) { return std::atan2(Length(Cross(a, b)), Dot(a, b)); }

// Angular distance from unit d to the great-circle arc from unit a to unit b (< π).
double ArcDistance(const Vec3& d, const Vec3& a, const Vec3& b) {
  const double end = std::min(AngleBetween(d, a), AngleBetween(d, b));
  Vec3 n = Cross(a, b);
  const double len = Length(n);
  if (len < 1e-12) return end;
  n = n / len;
  const Vec3 p = d - n * Dot(d, n);
  if (Length(p) < 1e-12) return end;  // d is a pole of the arc's circle: all points at π/2
  if (Dot(Cross(a, p), n) >= 0 && Dot(Cross(p, b), n) >= 0)
    return std::min(end, std::asin(std::min(1.0, std::abs(Dot(d, n)))));
  return end;
}

}  // namespace

double SsdReference::Ssd(const Vec3& x, const Vec3& d_in, int azimuths, double step_rad) const {
  const Vec3 d = Normalized(d_in);
  if (!Blocked(x, d)) {
    // Exact: the blocked set is the union of the projected triangles.
    double best = kPi;
    for (const auto& t : mesh_->triangles) {
      const Vec3 a = Normalized(Vec3(mesh_->positions[t[0]]) - x), b = Normalized(Vec3(mesh_->positions[t[1]]) - x),
                 c = Normalized(Vec3(mesh_->positions[t[2]]) - x);
      best = std::min({best, ArcDistance(d, a, b), ArcDistance(d, b, c), ArcDistance(d, c, a)});
    }
    return best;
  }
  // Blocked: march along great circles leaving d until a ray gets through.
  const Vec3 helper = std::abs(d.x) < 0.9 ? Vec3(1, 0, 0) : Vec3(0, 1, 0);
  const Vec3 w1 = Normalized(Cross(d, helper)), w2 = Cross(d, w1);
  double best = kPi;
  for (int k = 0; k < azimuths; ++k) {
    const double phi = 2 * kPi * k / azimuths;
    const Vec3 w = w1 * std::cos(phi) + w2 * std::sin(phi);
    const auto at = [&](double theta) { return d * std::cos(theta) + w * std::sin(theta); };
    double lo = 0;
    for (double theta = step_rad; theta < best; theta += step_rad) {
      if (!Blocked(x, at(theta))) {
        double hi = theta;
        while (hi - lo > 1e-5) {
          const double mid = 0.5 * (lo + hi);
          (Blocked(x, at(mid)) ? lo : hi) = mid;
        }
        best = std::min(best, hi);
        break;
      }
      lo = theta;
    }
  }
  return -best;
}

}  // namespace nerfar
