#include "render/insert/inserter.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <mutex>
#include <nlohmann/json.hpp>
#include <unordered_map>

#include "calib/core/error.h"
#include "calib/core/json.h"
#include "calib/core/parallel.h"
#include "render/sg/visibility.h"

namespace nerfar {

namespace {

using Clock = std::chrono::steady_clock;
double Ms(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

// Bilinear texture look-up with wrap-around; v = 0 is the top row.
void SampleMap(const ImageF& map, float u, float v, float* out, int channels) {
  if (map.empty() || !std::isfinite(u) || !std::isfinite(v)) return;
  const float fx = (u - std::floor(u)) * map.width - 0.5f, fy = (v - std::floor(v)) * map.height - 0.5f;
  const int x0 = static_cast<int>(std::floor(fx)), y0 = static_cast<int>(std::floor(fy));
  const float ax = fx - x0, ay = fy - y0;
  const auto wrap = [](int i, int n) { return ((i % n) + n) % n; };
  const int xa = wrap(x0, map.width), xb = wrap(x0 + 1, map.width);
  const int ya = wrap(y0, map.height), yb = wrap(y0 + 1, map.height);
  for (int c = 0; c < channels; ++c) {
    const int mc = std::min(c, map.channels - 1);
    out[c] = (1 - ax) * (1 - ay) * map.at(xa, ya, mc) + ax * (1 - ay) * map.at(xb, ya, mc) +
             (1 - ax) * ay * map.at(xa, yb, mc) + ax * ay * map.at(xb, yb, mc);
  }
}

SgMaterial PixelMaterial(const InsertObject& object, const std::array<float, 2>& uv) {
  SgMaterial m = object.material;
  float value[3];
  if (object.albedo_map) {
    SampleMap(*object.albedo_map, uv[0], uv[1], value, 3);
    m.base_color = {std::clamp(value[0], 0.0f, 1.0f), std::clamp(value[1], 0.0f, 1.0f),
                    std::clamp(value[2], 0.0f, 1.0f)};
  }
  if (object.roughness_map) {
    SampleMap(*object.roughness_map, uv[0], uv[1], value, 1);
    m.roughness = std::clamp(value[0], 0.0f, 1.0f);
  }
  if (object.metallic_map) {
    SampleMap(*object.metallic_map, uv[0], uv[1], value, 1);
    m.metallic = std::clamp(value[0], 0.0f, 1.0f);
  }
  return m;
}

bool Finite(const Vec3f& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

// κ (paper eqs. 8-9) with the half-space visibility of f_h bounded by the
// occluder's size. f_h treats everything beyond the silhouette's nearest
// point as blocked (a half-space), which for a broad lobe and a small, far
// occluder blocks far more than the object can: the object lies inside a cap
// of angular radius α (its bounding sphere seen from x) whose centre is α
// beyond the nearest silhouette point, so a broad lobe k loses about
// G(cap centre) × solid angle(cap). Broad lobes take the smaller estimate,
// sharp ones (√λ·α ≥ 1.5) the half-space one, which is then render/sg's
// ShadowRatio exactly; in between they blend.
double ShadowRatioCapped(const SgMixture& cosine_weighted, const Vec3& normal, const std::vector<double>& ssd,
                         const std::vector<double>& cap_radius) {
  double visible = 0.0, total = 0.0;
  for (size_t k = 0; k < cosine_weighted.size(); ++k) {
    const Sg& sg = cosine_weighted[k];
    const LobeShadow lobe = ShadowOfLobe(sg, normal, ssd[k]);
    if (!(lobe.total > 0.0)) continue;
    const double lobe_total = lobe.total;
    double blocked = lobe.total - lobe.visible;
    if (blocked > 0.0) {
      const double alpha = std::clamp(cap_radius[k], 0.0, 0.5 * kPi);
      const double centre = std::clamp(ssd[k] + alpha, 0.0, kPi);  // the cap centre's angle from the lobe axis
      const double solid = 2.0 * kPi * (1.0 - std::cos(alpha));
      const double cap = LuminanceOf(sg.amplitude) * std::exp(sg.sharpness * (std::cos(centre) - 1.0)) * solid;
      // The cap estimate (value at its centre × its solid angle) holds for
      // lobes broader than the cap; for sharper ones it misses the peak, and
      // the half-space estimate is the right one: blend on √λ·α.
      const double t = std::clamp(std::sqrt(sg.sharpness) * alpha - 0.5, 0.0, 1.0);
      blocked = (1.0 - t) * std::min(blocked, cap) + t * blocked;
    }
    total += lobe_total;
    visible += lobe_total - std::min(blocked, lobe_total);
  }
  if (!(total > 0.0)) return 1.0;
  return std::clamp(visible / total, 0.0, 1.0);
}

struct WorldSphere {
  Vec3f center;
  float radius = 0;
};

// γ_k of every lobe at a surface point with normal n from the union SSD
// there (paper eq. 10; with `horizon`, relative to the part of the lobe above
// the surface's horizon, see InsertOptions::self_shadow_horizon).
void GammaFromSsd(const std::vector<Vec3f>& axes, const std::vector<SgTableRow>& rows, const Vec3f& n,
                  const float* ssd_min, bool horizon, float* gamma) {
  for (size_t l = 0; l < axes.size(); ++l) {
    gamma[l] = 1.0f;
    if (!(ssd_min[l] < 0.5f * static_cast<float>(kPi))) continue;  // nothing in the way: γ = 1
    if (horizon) {
      const float e = std::asin(std::clamp(Dot(axes[l], n), -1.0f, 1.0f));
      const float full = GammaPrepared(rows[l], e);
      gamma[l] = full > 1e-6f ? GammaPrepared(rows[l], std::min(ssd_min[l], e)) / full : 1.0f;
    } else {
      gamma[l] = GammaPrepared(rows[l], ssd_min[l]);
    }
    gamma[l] = std::isfinite(gamma[l]) ? std::clamp(gamma[l], 0.0f, 1.0f) : 1.0f;
  }
}

// Unit world normals per vertex: the mesh's own, else area-weighted face normals.
std::vector<Vec3f> WorldVertexNormals(const TriangleMesh& mesh, const Pose& T_world_object) {
  const size_t nv = mesh.positions.size();
  std::vector<Vec3> n(nv);
  if (mesh.normals.size() == nv) {
    for (size_t v = 0; v < nv; ++v) n[v] = Vec3(mesh.normals[v]);
  } else {
    for (const auto& t : mesh.triangles) {
      if (t[0] >= nv || t[1] >= nv || t[2] >= nv) continue;
      const Vec3 face =
          Cross(Vec3(mesh.positions[t[1]] - mesh.positions[t[0]]), Vec3(mesh.positions[t[2]] - mesh.positions[t[0]]));
      if (!(std::isfinite(face.x) && std::isfinite(face.y) && std::isfinite(face.z))) continue;
      for (int c = 0; c < 3; ++c) n[t[c]] = n[t[c]] + face;
    }
  }
  std::vector<Vec3f> out(nv);
  for (size_t v = 0; v < nv; ++v) {
    const Vec3 w = T_world_object.Rotate(n[v]);
    out[v] = Dot(w, w) > 1e-30 ? Vec3f(Normalized(w)) : Vec3f{};
  }
  return out;
}

// A coarse κ cell whose receivers lie on one plane.
struct CellPlane {
  bool valid = false;
  Vec3f point, normal;         // a point of the plane and its unit normal (facing the camera)
  float t_min = 0, t_max = 0;  // range of the corners' ray distances
};

// Scratch of one κ evaluation (kept per thread to avoid allocations).
struct KappaScratch {
  std::vector<double> s_bound, s_exact, cap;
  std::vector<float> ssd;
  // The lattice nodes this thread looked up last (direct-mapped by key; value
  // -1: empty): neighbouring receivers of a row share most of their 8 nodes,
  // and the shared lattice's hash look-up (a cache miss or two) is what
  // dominates κ on a hand-held frame. Holds exactly the lattice's values.
  static constexpr size_t kMemo = 256;
  std::array<uint64_t, kMemo> memo_key{};
  std::array<float, kMemo> memo_value = MemoEmpty();
  static std::array<float, kMemo> MemoEmpty() {
    std::array<float, kMemo> v;
    v.fill(-1.0f);
    return v;
  }
  static size_t MemoSlot(uint64_t key) { return (key * 0x9E3779B97F4A7C15ull) >> 56; }
};

// Receiver normals in 32×32 octahedral cells (the κ lattice is kept per cell).
constexpr int kNormalCells = 32;
uint32_t NormalCell(const Vec3f& n) {
  const float l1 = std::abs(n.x) + std::abs(n.y) + std::abs(n.z);
  float u = n.x / l1, v = n.y / l1;
  if (n.z < 0) {
    const float pu = (1 - std::abs(v)) * (u >= 0 ? 1.0f : -1.0f), pv = (1 - std::abs(u)) * (v >= 0 ? 1.0f : -1.0f);
    u = pu;
    v = pv;
  }
  const auto cell = [](float t) {
    return static_cast<uint32_t>(std::clamp(static_cast<int>((t + 1) * 0.5f * kNormalCells), 0, kNormalCells - 1));
  };
  return cell(v) * kNormalCells + cell(u);
}
Vec3f CellNormal(uint32_t cell) {
  const float u = ((cell % kNormalCells) + 0.5f) / kNormalCells * 2 - 1;
  const float v = ((cell / kNormalCells) + 0.5f) / kNormalCells * 2 - 1;
  Vec3f n{u, v, 1 - std::abs(u) - std::abs(v)};
  if (n.z < 0) {
    const float x = (1 - std::abs(v)) * (u >= 0 ? 1.0f : -1.0f), y = (1 - std::abs(u)) * (v >= 0 ? 1.0f : -1.0f);
    n.x = x;
    n.y = y;
  }
  return Normalized(n);
}
// Lattice node (i, j, k) (18 bits each, offset) and normal cell (10 bits).
uint64_t LatticeKey(int64_t i, int64_t j, int64_t k, uint32_t cell) {
  constexpr int64_t kOffset = int64_t(1) << 17, kMask = (int64_t(1) << 18) - 1;
  return (uint64_t((i + kOffset) & kMask) << 46) | (uint64_t((j + kOffset) & kMask) << 28) |
         (uint64_t((k + kOffset) & kMask) << 10) | cell;
}
constexpr size_t kKappaCacheMaxNodes = size_t(1) << 22;  // ~4 M nodes (~100 MB): cleared beyond

// What a cached per-pose value depends on, as numbers compared exactly.
void AppendPoseKey(const Pose& pose, double scale, std::vector<double>& key) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) key.push_back(pose.rotation(r, c));
  for (int c = 0; c < 3; ++c) key.push_back(pose.translation[c]);
  key.push_back(scale);
}
void AppendObjectKey(const InsertObject& object, std::vector<double>& key) {
  key.push_back(double(reinterpret_cast<uintptr_t>(object.visibility)));
  key.push_back(double(reinterpret_cast<uintptr_t>(object.mesh)));
  AppendPoseKey(object.T_world_object, object.scale, key);
  if (object.visibility) {
    const Vec3 c = object.visibility->Center();
    key.insert(key.end(), {c.x, c.y, c.z, object.visibility->Radius()});
  }
}
void AppendLightKey(const SgMixture& light, std::vector<double>& key) {
  key.push_back(double(light.size()));
  for (const Sg& lobe : light)
    key.insert(key.end(), {lobe.axis.x, lobe.axis.y, lobe.axis.z, lobe.sharpness, lobe.amplitude.x, lobe.amplitude.y,
                           lobe.amplitude.z});
}

}  // namespace

// ------------------------------------------------------------------ options

InsertOptions InsertOptions::Preset(const std::string& name) {
  InsertOptions o;
  o.light.fit = SgFitOptions::Preset(name);
  if (name == "fast") {
    o.light.directions = 512;
    o.shadow_reach_radii = 8.0;
    o.shadow_epsilon = 5e-3;
    o.kappa_step = 4;
    o.occlusion_step = 4;
    o.kappa_cache_spacing_radii = 0.15;
    o.antialias_edges = false;  // the coverage sub-samples double the raster time
  } else if (name == "balanced") {
  } else if (name == "accurate") {
    o.light.directions = 2048;
    o.shadow_reach_radii = 20.0;
    o.shadow_epsilon = 5e-4;
    o.kappa_step = 1;
    o.self_shadow_per_vertex = false;
    o.occlusion_step = 1;
    o.kappa_cache_spacing_radii = 0.0;
    o.kappa_plane_upsampling = false;
    o.kappa_receiver_reuse = false;
    o.receiver_normal_per_cell = false;
    o.kappa_coarse_factor = 2;
    o.kappa_refine_delta = 0.01;
  } else {
    ThrowInputError("preset", "unknown preset '" + name + "' (expected fast, balanced or accurate)");
  }
  return o;
}

std::vector<std::string> InsertOptions::Validate() const {
  std::vector<std::string> problems = light.Validate();
  const auto check = [&problems](bool ok, const std::string& what) {
    if (!ok) problems.push_back(what);
  };
  check(std::isfinite(self_shadow_offset_radii) && self_shadow_offset_radii >= 0 && self_shadow_offset_radii <= 1,
        "self_shadow_offset_radii: out of range (expected 0 to 1)");
  check(std::isfinite(shadow_reach_radii) && shadow_reach_radii >= 1 && shadow_reach_radii <= 1000,
        "shadow_reach_radii: out of range (expected 1 to 1000)");
  check(std::isfinite(shadow_epsilon) && shadow_epsilon >= 0 && shadow_epsilon < 1,
        "shadow_epsilon: out of range (expected 0 <= value < 1)");
  check(occlusion_step >= 1 && occlusion_step <= 64, "occlusion_step: out of range (expected 1 to 64)");
  check(std::isfinite(occlusion_clear_opacity) && occlusion_clear_opacity >= 0 && occlusion_clear_opacity < 1,
        "occlusion_clear_opacity: out of range (expected 0 <= value < 1)");
  check(std::isfinite(kappa_cache_spacing_radii) && kappa_cache_spacing_radii >= 0 && kappa_cache_spacing_radii <= 10,
        "kappa_cache_spacing_radii: out of range (expected 0 to 10)");
  check(std::isfinite(kappa_reuse_tolerance_radii) && kappa_reuse_tolerance_radii >= 0 &&
            kappa_reuse_tolerance_radii <= 1,
        "kappa_reuse_tolerance_radii: out of range (expected 0 to 1)");
  check(kappa_step >= 1 && kappa_step <= 64, "kappa_step: out of range (expected 1 to 64)");
  check(kappa_coarse_factor >= 1 && kappa_coarse_factor <= 64, "kappa_coarse_factor: out of range (expected 1 to 64)");
  check(std::isfinite(kappa_refine_delta) && kappa_refine_delta >= 0 && kappa_refine_delta <= 1,
        "kappa_refine_delta: out of range (expected 0 to 1)");
  check(std::isfinite(receiver_min_opacity) && receiver_min_opacity >= 0 && receiver_min_opacity <= 1,
        "receiver_min_opacity: out of range (expected 0 to 1)");
  return problems;
}

std::string InsertOptions::ToJson() const {
  nlohmann::json j;
  j["light_directions"] = light.directions;
  j["light_move_threshold_m"] = light.move_threshold_m;
  j["light_source"] = LightSourceName(light.source);
  j["sg_lobes"] = light.fit.lobes;
  j["sg_cold_iterations"] = light.fit.cold_iterations;
  j["sg_warm_iterations"] = light.fit.warm_iterations;
  j["self_shadow"] = self_shadow;
  j["self_shadow_horizon"] = self_shadow_horizon;
  j["self_shadow_offset_radii"] = self_shadow_offset_radii;
  j["shadows"] = shadows;
  j["shadow_reach_radii"] = shadow_reach_radii;
  j["shadow_epsilon"] = shadow_epsilon;
  j["self_shadow_per_vertex"] = self_shadow_per_vertex;
  j["antialias_edges"] = antialias_edges;
  j["occlusion_step"] = occlusion_step;
  j["occlusion_clear_opacity"] = occlusion_clear_opacity;
  j["kappa_cache_spacing_radii"] = kappa_cache_spacing_radii;
  j["kappa_plane_upsampling"] = kappa_plane_upsampling;
  j["kappa_receiver_reuse"] = kappa_receiver_reuse;
  j["receiver_normal_per_cell"] = receiver_normal_per_cell;
  j["kappa_reuse_tolerance_radii"] = kappa_reuse_tolerance_radii;
  j["kappa_step"] = kappa_step;
  j["kappa_coarse_factor"] = kappa_coarse_factor;
  j["kappa_refine_delta"] = kappa_refine_delta;
  j["receiver_min_opacity"] = receiver_min_opacity;
  return j.dump();
}

ImageF ExpandLayer(const ImageF& layer, const PixelRect& rect, int width, int height, float fill) {
  const int channels = layer.channels > 0 ? layer.channels : 1;
  ImageF full(width, height, channels, fill);
  if (layer.empty()) return full;
  for (int y = rect.y0; y < rect.y1; ++y)
    for (int x = rect.x0; x < rect.x1; ++x)
      for (int c = 0; c < channels; ++c) full.at(x, y, c) = layer.at(x - rect.x0, y - rect.y0, c);
  return full;
}

void ReceiversFromDepth(const ImageF& depth_z, const CameraIntrinsics& camera, const Pose& T_world_camera,
                        ImageF& distance, ImageF& normal) {
  const int w = depth_z.width, h = depth_z.height;
  distance = ImageF(w, h, 1, 0.0f);
  normal = ImageF(w, h, 3, 0.0f);
  std::vector<Vec3> p(static_cast<size_t>(w) * h);
  std::vector<uint8_t> valid(p.size(), 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float z = depth_z.at(x, y, 0);
      if (!(z > 0.0f) || !std::isfinite(z)) continue;
      const Vec3 ray_camera{(x + 0.5 - camera.cx) / camera.fx, (y + 0.5 - camera.cy) / camera.fy, 1.0};
      const size_t i = static_cast<size_t>(y) * w + x;
      p[i] = T_world_camera * (ray_camera * static_cast<double>(z));
      valid[i] = 1;
      distance.at(x, y) = static_cast<float>(z * Length(ray_camera));
    }
  const Vec3 eye = T_world_camera.translation;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const size_t i = static_cast<size_t>(y) * w + x;
      if (!valid[i]) continue;
      // One-sided differences; per axis the neighbour nearer in depth.
      const auto pick = [&](int dx, int dy) -> std::optional<Vec3> {
        std::optional<Vec3> best;
        double best_jump = std::numeric_limits<double>::infinity();
        for (int s : {-1, 1}) {
          const int xx = x + s * dx, yy = y + s * dy;
          if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
          const size_t j = static_cast<size_t>(yy) * w + xx;
          if (!valid[j]) continue;
          const double jump = std::abs(depth_z.pixels[j] - depth_z.pixels[i]);
          if (jump < best_jump) {
            best_jump = jump;
            best = (p[j] - p[i]) * static_cast<double>(s);
          }
        }
        return best;
      };
      const auto du = pick(1, 0), dv = pick(0, 1);
      if (!du || !dv) continue;
      Vec3 n = Normalized(Cross(*du, *dv));
      if (Dot(n, eye - p[i]) < 0) n = -n;
      for (int c = 0; c < 3; ++c) normal.at(x, y, c) = static_cast<float>(n[c]);
    }
}

namespace {

// The last frame's NeRF receivers at its κ grid nodes.
struct ReceiverFrame {
  bool valid = false;
  float min_opacity = 0;
  CameraIntrinsics camera;
  Pose T_world_camera, T_camera_world;
  std::vector<int> xs, ys;     // the grid's pixel columns and rows
  std::vector<size_t> cx, cy;  // its coarse nodes (indices into xs, ys)
  size_t factor = 1;
  int step = 1;
  std::vector<uint8_t> state;  // per node: 0 unknown, 1 surface, 2 no surface
  std::vector<Vec3f> point, normal;
};

// The last frame's receiver for a new grid node's ray (eye, d), if its
// receivers can give it (InsertOptions::kappa_receiver_reuse): 1 with
// `point`/`normal`, 2 for no surface, 0 to march.
int ReuseReceiver(const ReceiverFrame& r, const Vec3f& eye, const Vec3f& d, int x, int y, float tolerance, Vec3f& point,
                  Vec3f& normal) {
  const size_t nx = r.xs.size(), ny = r.ys.size();
  if (!r.valid || nx < 2 || ny < 2) return 0;
  // The four receivers of the last grid's cell holding pixel (u, v): the fine
  // cell when all four are known, else its coarse cell (always known).
  const auto cell = [&](double u, double v, size_t idx[4]) -> bool {
    if (!(u >= r.xs.front() && u <= r.xs.back() && v >= r.ys.front() && v <= r.ys.back())) return false;
    const size_t ix = std::min<size_t>(static_cast<size_t>((u - r.xs.front()) / r.step), nx - 2);
    const size_t iy = std::min<size_t>(static_cast<size_t>((v - r.ys.front()) / r.step), ny - 2);
    const size_t fine[4] = {iy * nx + ix, iy * nx + ix + 1, (iy + 1) * nx + ix, (iy + 1) * nx + ix + 1};
    if (r.state[fine[0]] && r.state[fine[1]] && r.state[fine[2]] && r.state[fine[3]]) {
      std::copy(fine, fine + 4, idx);
      return true;
    }
    const size_t i = std::min<size_t>(ix / r.factor, r.cx.size() - 2),
                 j = std::min<size_t>(iy / r.factor, r.cy.size() - 2);
    const size_t coarse[4] = {r.cy[j] * nx + r.cx[i], r.cy[j] * nx + r.cx[i + 1], r.cy[j + 1] * nx + r.cx[i],
                              r.cy[j + 1] * nx + r.cx[i + 1]};
    for (size_t c : coarse)
      if (!r.state[c]) return false;
    std::copy(coarse, coarse + 4, idx);
    return true;
  };
  // The corner nearest (u, v) in pixels.
  const auto nearest = [&](double u, double v, const size_t idx[4]) {
    size_t best = idx[0];
    double best_d = std::numeric_limits<double>::infinity();
    for (int c = 0; c < 4; ++c) {
      const double du = r.xs[idx[c] % nx] - u, dv = r.ys[idx[c] / nx] - v;
      if (du * du + dv * dv < best_d) {
        best_d = du * du + dv * dv;
        best = idx[c];
      }
    }
    return best;
  };
  size_t idx[4];
  if (!cell(x, y, idx)) return 0;
  int surfaces = 0;
  for (size_t c : idx) surfaces += r.state[c] == 1;
  if (surfaces == 0) {
    // No surface around the same pixel of the last view: kept while this
    // pixel's ray moved by less than a grid step (its eye by the tolerance).
    const Vec3f old_eye(r.T_world_camera.translation);
    const Vec3f old_d = CameraRayDirection(r.camera, r.T_world_camera, x, y);
    const float max_angle = static_cast<float>(r.step / std::max(r.camera.fx, r.camera.fy));
    return Length(eye - old_eye) <= tolerance && Dot(d, old_d) >= std::cos(max_angle) ? 2 : 0;
  }
  if (surfaces < 4) return 0;
  // The plane through a cell's four receivers (normal from its diagonals,
  // facing the ray); false when a receiver lies farther than the tolerance
  // from it. The receivers' own NeRF normals are not compared: they scatter
  // by more than 10° between neighbours on a flat grid-NeRF table.
  const auto cell_plane = [&](const size_t c[4], Vec3f& mean, Vec3f& n) -> bool {
    mean = (r.point[c[0]] + r.point[c[1]] + r.point[c[2]] + r.point[c[3]]) * 0.25f;
    n = Cross(r.point[c[3]] - r.point[c[0]], r.point[c[2]] - r.point[c[1]]);
    if (!(Dot(n, n) > 1e-20f)) return false;
    n = Normalized(n);
    if (Dot(n, d) > 0) n = n * -1.0f;
    for (int k = 0; k < 4; ++k)
      if (!(std::abs(Dot(r.point[c[k]] - mean, n)) <= tolerance)) return false;
    return true;
  };
  size_t at[4];
  std::copy(idx, idx + 4, at);
  for (int iteration = 0; iteration < 2; ++iteration) {
    Vec3f mean, n;
    if (!cell_plane(at, mean, n)) return 0;
    const float cosine = Dot(d, n);
    if (!(cosine < -0.05f)) return 0;  // grazing: march
    const float t = Dot(mean - eye, n) / cosine;
    if (!(t > 0.0f)) return 0;
    const Vec3f p = eye + d * t;
    const Vec3 c = r.T_camera_world * Vec3(p);
    if (!(c.z > 1e-6)) return 0;
    const double u = r.camera.fx * c.x / c.z + r.camera.cx - 0.5, v = r.camera.fy * c.y / c.z + r.camera.cy - 0.5;
    size_t landed[4];
    if (!cell(u, v, landed)) return 0;
    bool same = true;
    for (int k = 0; k < 4; ++k) same = same && landed[k] == at[k];
    bool surface = true;
    for (size_t k : landed) surface = surface && r.state[k] == 1;
    if (!surface) return 0;
    if (same) {
      // The point lies on its own cell's plane: taken, with the NeRF normal
      // of the nearest receiver (its lattice normal cell is already filled).
      point = p;
      normal = r.normal[nearest(u, v, landed)];
      return 1;
    }
    std::copy(landed, landed + 4, at);  // once more with the cell it landed in
  }
  return 0;
}

}  // namespace

// ------------------------------------------------------------------ inserter

// κ at world lattice nodes per receiver-normal cell, shared by the threads of
// a frame; `key` says which objects and lights it holds. Each shard holds a
// read-only snapshot (`frozen`, the nodes of earlier frames: read without a
// lock, nothing writes it during a frame) and the nodes computed this frame
// (`fresh`, under the shard's mutex); Publish() (single-threaded, at the
// start of a frame) moves the fresh nodes into the snapshot.
struct Inserter::KappaCache {
  static constexpr size_t kShards = 64;
  struct Shard {
    std::unordered_map<uint64_t, float> frozen;
    std::mutex mutex;
    std::unordered_map<uint64_t, float> fresh;
  };
  std::vector<double> key;
  std::array<Shard, kShards> shards;

  static size_t ShardOf(uint64_t key) { return (key * 0x9E3779B97F4A7C15ull) >> 58; }
  bool Find(uint64_t node, float* value) {
    Shard& s = shards[ShardOf(node)];
    const auto it = s.frozen.find(node);  // read-only during the frame: no lock
    if (it != s.frozen.end()) {
      *value = it->second;
      return true;
    }
    std::lock_guard<std::mutex> lock(s.mutex);
    const auto jt = s.fresh.find(node);
    if (jt == s.fresh.end()) return false;
    *value = jt->second;
    return true;
  }
  void Insert(uint64_t node, float value) {
    Shard& s = shards[ShardOf(node)];
    std::lock_guard<std::mutex> lock(s.mutex);
    s.fresh.emplace(node, value);
  }
  // Single-threaded, between frames: this frame's nodes join the snapshot.
  void Publish() {
    for (Shard& s : shards) {
      if (s.fresh.empty()) continue;
      s.frozen.insert(s.fresh.begin(), s.fresh.end());
      s.fresh.clear();
    }
  }
  size_t Size() {
    size_t n = 0;
    for (Shard& s : shards) {
      std::lock_guard<std::mutex> lock(s.mutex);
      n += s.frozen.size() + s.fresh.size();
    }
    return n;
  }
  void Clear() {
    for (Shard& s : shards) {
      std::lock_guard<std::mutex> lock(s.mutex);
      s.frozen.clear();
      s.fresh.clear();
    }
    std::lock_guard<std::mutex> lock(box_mutex);
    shadow_min = Vec3f{std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
                       std::numeric_limits<float>::infinity()};
    shadow_max = shadow_min * -1.0f;
    explored.clear();
    last_view.clear();
    last_kappa = ImageF();
  }
  // World box of the nodes computed with κ < 1 − ε (all others hold κ ≥ 1 − ε).
  void GrowShadow(const Vec3f& node) {
    std::lock_guard<std::mutex> lock(box_mutex);
    shadow_min = {std::min(shadow_min.x, node.x), std::min(shadow_min.y, node.y), std::min(shadow_min.z, node.z)};
    shadow_max = {std::max(shadow_max.x, node.x), std::max(shadow_max.y, node.y), std::max(shadow_max.z, node.z)};
  }
  std::mutex box_mutex;
  Vec3f shadow_min{std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
                   std::numeric_limits<float>::infinity()};
  Vec3f shadow_max{-std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
                   -std::numeric_limits<float>::infinity()};
  // Views (camera pose, intrinsics) whose whole reach rectangle was passed
  // under the current key: each visible receiver there has its nodes here.
  std::vector<std::vector<double>> explored;
  // The last frame's κ layer, its rectangle and its exact view.
  std::vector<double> last_view;
  PixelRect last_rect;
  ImageF last_kappa;
  // The last frame's NeRF receivers (kept across Clear: they depend on the
  // scene and the opacity threshold only).
  ReceiverFrame receivers;
  // Receiver normals per world cell (InsertOptions::receiver_normal_per_cell):
  // the NeRF normal at the first receiver found in a lattice cell, for every
  // receiver in it from any view; kept across Clear while the spacing holds.
  std::mutex normal_mutex;
  double normal_spacing = 0;
  std::unordered_map<uint64_t, Vec3f> cell_normals;
};

Inserter::~Inserter() = default;
Inserter::Inserter(Inserter&&) noexcept = default;

Inserter::Inserter(const SceneField& scene, SgMixture environment, InsertOptions options)
    : scene_(scene), environment_(std::move(environment)), options_(std::move(options)) {
  Problems problems("insert options");
  for (const std::string& p : options_.Validate()) problems.Add("", p);
  problems.ThrowIfAny();
}

const SgMixture& Inserter::Light(size_t object) const { return used_lights_.at(object); }

ImageF Inserter::RenderBackground(const CameraIntrinsics& camera, const Pose& T_world_camera) const {
  ImageF image(camera.width, camera.height, 3, 0.0f);
  const Aabb box = scene_.Box();
  const Vec3 eye = T_world_camera.translation;
  ParallelFor(
      static_cast<size_t>(camera.height),
      [&](size_t row) {
        const int y = static_cast<int>(row);
        SceneRays rays;
        SceneSamples out;
        rays.Reserve(camera.width);
        for (int x = 0; x < camera.width; ++x) {
          const Vec3f d = CameraRayDirection(camera, T_world_camera, x, y);
          const auto range = IntersectBox(box, eye, Vec3(d));
          rays.Add(Vec3f(eye), d, range ? static_cast<float>(range->first) : 0.0f,
                   range ? static_cast<float>(range->second) : 0.0f);
        }
        scene_.RenderRays(rays, out);
        for (int x = 0; x < camera.width; ++x) {
          const Vec3f c = Finite(out.colour[x]) ? out.colour[x] : Vec3f{};
          image.at(x, y, 0) = c.x;
          image.at(x, y, 1) = c.y;
          image.at(x, y, 2) = c.z;
        }
      },
      1);
  return image;
}

InsertTimings Inserter::Render(const CameraIntrinsics& camera, const Pose& T_world_camera,
                               const std::vector<InsertObject>& objects, ImageF& frame, InsertLayers* layers_out,
                               const ReceiverOverride& receivers) {
  const auto t_start = Clock::now();
  InsertTimings times;
  if (frame.width != camera.width || frame.height != camera.height || frame.channels != 3) {
    ThrowInputError("frame", "size " + std::to_string(frame.width) + "x" + std::to_string(frame.height) + "x" +
                                 std::to_string(frame.channels) + " does not match the camera (expected " +
                                 std::to_string(camera.width) + "x" + std::to_string(camera.height) + "x3)");
  }
  InsertLayers local_layers;
  InsertLayers& layers = layers_out ? *layers_out : local_layers;
  layers = InsertLayers{};
  const size_t n_objects = objects.size();
  lights_.resize(n_objects);
  used_lights_.resize(n_objects);

  // World bounding spheres of the objects.
  std::vector<WorldSphere> spheres(n_objects);
  for (size_t i = 0; i < n_objects; ++i) {
    if (objects[i].mesh == nullptr || objects[i].mesh->positions.empty()) continue;
    const BoundingSphere bs = ComputeBoundingSphere(*objects[i].mesh);
    spheres[i].center = Vec3f(objects[i].T_world_object * (bs.center * objects[i].scale));
    spheres[i].radius = static_cast<float>(bs.radius * std::abs(objects[i].scale));
  }

  // 1. Incident light per object (cached while it stands still).
  for (size_t i = 0; i < n_objects; ++i) {
    if (objects[i].light_override) {
      used_lights_[i] = *objects[i].light_override;
      continue;
    }
    const Vec3 at = objects[i].light_center.value_or(Vec3(spheres[i].center));
    const IncidentLight::Update u = lights_[i].Refresh(scene_, environment_, at, options_.light);
    times.light_ms += u.sample_ms;
    times.fit_ms += u.fit_ms;
    times.lights_recomputed += u.recomputed ? 1 : 0;
    used_lights_[i] = lights_[i].light();
  }

  // 2. G-buffer.
  auto t0 = Clock::now();
  std::vector<RasterObject> raster(n_objects);
  for (size_t i = 0; i < n_objects; ++i) raster[i] = {objects[i].mesh, objects[i].T_world_object, objects[i].scale};
  RasterOptions raster_options;
  raster_options.coverage_grid = options_.antialias_edges ? 4 : 0;
  layers.gbuffer = Rasterize(camera, T_world_camera, raster, raster_options);
  const ObjectGBuffer& g = layers.gbuffer;
  times.raster_ms = Ms(t0);

  // Covered pixels (G-buffer indices), in scan order.
  std::vector<uint32_t> covered;
  covered.reserve(g.covered);
  for (size_t i = 0; i < g.object.size(); ++i)
    if (g.object[i] >= 0) covered.push_back(static_cast<uint32_t>(i));

  // 3. Shading with self-shadows: lobes of each object's light, SSD of every
  // shadow-casting object at those axes (the union takes the minimum).
  t0 = Clock::now();
  layers.object = ImageF(g.rect.width(), g.rect.height(), 3, 0.0f);
  layers.alpha = ImageF(g.rect.width(), g.rect.height(), 1, 0.0f);
  struct LightPrep {
    std::unique_ptr<SgShader> shader;
    std::vector<Vec3f> axes;
    std::vector<SgTableRow> gamma_rows;
    std::vector<std::unique_ptr<VisibilityQuery>> queries;  // one per object (nullptr: no field)
  };
  std::vector<LightPrep> preps(n_objects);
  const auto prepare = [&](size_t o) {
    LightPrep& p = preps[o];
    if (p.shader) return;
    const SgMixture& light = used_lights_[o];
    p.shader = std::make_unique<SgShader>(light);
    for (const Sg& lobe : light) {
      p.axes.push_back(Vec3f(Normalized(lobe.axis)));
      p.gamma_rows.push_back(PrepareGamma(lobe.sharpness));
    }
    p.queries.resize(n_objects);
    for (size_t j = 0; j < n_objects; ++j)
      if (objects[j].visibility && !p.axes.empty()) p.queries[j] = objects[j].visibility->Prepare(p.axes);
  };
  for (size_t o = 0; o < n_objects; ++o) {
    bool seen = false;
    for (uint32_t i : covered) seen = seen || g.object[i] == static_cast<int32_t>(o);
    if (seen) prepare(o);
  }
  // Self-shadow γ per mesh vertex, kept while the objects and the light
  // stand still (it does not depend on the view).
  const bool per_vertex = options_.self_shadow && options_.self_shadow_per_vertex;
  vertex_gamma_.resize(n_objects);
  std::vector<std::vector<Vec3f>> vertex_normals(n_objects);
  for (size_t o = 0; o < n_objects; ++o) {
    if (!per_vertex || !preps[o].shader || objects[o].mesh == nullptr) continue;
    const TriangleMesh& mesh = *objects[o].mesh;
    vertex_normals[o] = WorldVertexNormals(mesh, objects[o].T_world_object);
    std::vector<double> key = {double(reinterpret_cast<uintptr_t>(&mesh)), options_.self_shadow_offset_radii,
                               options_.self_shadow_horizon ? 1.0 : 0.0};
    AppendLightKey(used_lights_[o], key);
    for (size_t j = 0; j < n_objects; ++j) AppendObjectKey(objects[j], key);
    VertexGamma& vg = vertex_gamma_[o];
    if (key == vg.key) continue;
    times.gamma_recomputed = true;
    vg.key = std::move(key);
    const LightPrep& p = preps[o];
    const size_t m = p.axes.size(), nv = mesh.positions.size();
    vg.gamma.assign(nv * m, 1.0f);
    if (m == 0) continue;
    const float offset = static_cast<float>(options_.self_shadow_offset_radii * spheres[o].radius);
    std::vector<Vec3f> points(nv);
    for (size_t v = 0; v < nv; ++v)
      points[v] = Vec3f(objects[o].T_world_object * (Vec3(mesh.positions[v]) * objects[o].scale)) +
                  vertex_normals[o][v] * offset;
    constexpr size_t kVertexChunk = 128;
    ParallelFor((nv + kVertexChunk - 1) / kVertexChunk,
                [&](size_t c) {
                  const size_t begin = c * kVertexChunk, end = std::min(nv, begin + kVertexChunk);
                  std::vector<float> ssd((end - begin) * m),
                      ssd_min((end - begin) * m, std::numeric_limits<float>::infinity());
                  for (size_t j = 0; j < n_objects; ++j) {
                    if (!p.queries[j]) continue;
                    p.queries[j]->Ssd(&points[begin], end - begin, ssd.data());
                    for (size_t q = 0; q < ssd.size(); ++q) ssd_min[q] = std::min(ssd_min[q], ssd[q]);
                  }
                  for (size_t v = begin; v < end; ++v)
                    GammaFromSsd(p.axes, p.gamma_rows, vertex_normals[o][v], &ssd_min[(v - begin) * m],
                                 options_.self_shadow_horizon, &vg.gamma[v * m]);
                },
                1);
  }

  const Vec3f eye(T_world_camera.translation);
  constexpr size_t kChunk = 256;
  const size_t chunks = (covered.size() + kChunk - 1) / kChunk;
  // γ per pixel (interpolated or queried), then render/sg's many-pixel Shade
  // over each run of pixels of one object in the chunk.
  ParallelFor(
      chunks,
      [&](size_t c) {
        const size_t begin = c * kChunk, end = std::min(covered.size(), begin + kChunk);
        std::vector<float> ssd, ssd_min;
        std::vector<float> gamma;
        std::vector<SgMaterial> materials;
        std::vector<Vec3f> normals, views, rgb;
        materials.reserve(end - begin);
        normals.reserve(end - begin);
        views.reserve(end - begin);
        Vec3f point;
        for (size_t run = begin; run < end;) {
          const int32_t o = g.object[covered[run]];
          size_t run_end = run + 1;
          while (run_end < end && g.object[covered[run_end]] == o) ++run_end;
          const LightPrep& p = preps[o];
          const size_t m = p.axes.size();
          const size_t count = run_end - run;
          gamma.assign(count * m, 1.0f);
          materials.clear();
          normals.clear();
          views.clear();
          const VertexGamma* vg = per_vertex ? &vertex_gamma_[o] : nullptr;
          for (size_t k = run; k < run_end; ++k) {
            const uint32_t i = covered[k];
            const Vec3f n = g.normal[i];
            float* gp = gamma.data() + (k - run) * m;
            const auto& tri = objects[o].mesh->triangles[g.triangle[i]];
            const float b1 = g.bary[i][0], b2 = g.bary[i][1], b0 = 1.0f - b1 - b2;
            // Per vertex unless the rasteriser flipped the normal (a back face
            // seen): the vertices' γ belong to the other side.
            if (vg && !vg->gamma.empty() &&
                Dot(vertex_normals[o][tri[0]] * b0 + vertex_normals[o][tri[1]] * b1 + vertex_normals[o][tri[2]] * b2,
                    n) > 0.0f) {
              const float* g0 = &vg->gamma[size_t(tri[0]) * m];
              const float* g1 = &vg->gamma[size_t(tri[1]) * m];
              const float* g2 = &vg->gamma[size_t(tri[2]) * m];
              for (size_t l = 0; l < m; ++l) gp[l] = b0 * g0[l] + b1 * g1[l] + b2 * g2[l];
            } else if (options_.self_shadow && m > 0) {
              point = g.position[i] + n * static_cast<float>(options_.self_shadow_offset_radii * spheres[o].radius);
              ssd_min.assign(m, std::numeric_limits<float>::infinity());
              ssd.resize(m);
              for (size_t j = 0; j < n_objects; ++j) {
                if (!p.queries[j]) continue;
                p.queries[j]->Ssd(&point, 1, ssd.data());
                for (size_t l = 0; l < m; ++l) ssd_min[l] = std::min(ssd_min[l], ssd[l]);
              }
              GammaFromSsd(p.axes, p.gamma_rows, n, ssd_min.data(), options_.self_shadow_horizon, gp);
            }
            materials.push_back(PixelMaterial(objects[o], g.uv[i]));
            normals.push_back(n);
            views.push_back(Normalized(eye - g.position[i]));
          }
          rgb.assign(count, Vec3f{});
          if (m > 0)
            p.shader->Shade(materials.data(), normals.data(), views.data(), gamma.data(), static_cast<int>(count),
                            rgb.data());
          for (size_t k = run; k < run_end; ++k) {
            const size_t px = covered[k];  // same layout as the G-buffer
            const Vec3f value = Finite(rgb[k - run]) ? rgb[k - run] : Vec3f{};
            layers.object.pixels[px * 3 + 0] = std::max(value.x, 0.0f);
            layers.object.pixels[px * 3 + 1] = std::max(value.y, 0.0f);
            layers.object.pixels[px * 3 + 2] = std::max(value.z, 0.0f);
          }
          run = run_end;
        }
      },
      1);
  times.shade_ms = Ms(t0);

  // 4. Occlusion and composite on object pixels (paper eq. 7 and Fig. "sample").
  t0 = Clock::now();
  const Aabb box = scene_.Box();
  // The ray of pixel (x, y) over the scene up to `depth` (the object).
  const auto add_ray = [&](SceneRays& rays, int x, int y, float depth) {
    const Vec3f d = CameraRayDirection(camera, T_world_camera, x, y);
    const auto range = IntersectBox(box, Vec3(eye), Vec3(d));
    float t_near = 0.0f, t_far = 0.0f;
    if (range) {
      t_near = std::min(depth, static_cast<float>(range->first));
      t_far = std::min(depth, static_cast<float>(range->second));
    }
    rays.Add(eye, d, t_near, t_far);
  };
  // Coarse pass: rays at the corners of occlusion_step-sized blocks, each up
  // to the farthest object depth of the blocks it touches; blocks whose
  // corners all see (almost) nothing need no ray per pixel.
  std::vector<uint8_t> clear(g.object.size(), 0);
  if (options_.occlusion_step > 1 && !covered.empty()) {
    const int s = options_.occlusion_step, w = g.rect.width(), h = g.rect.height();
    const int bx = (w + s - 1) / s, by = (h + s - 1) / s;
    std::vector<float> block_far(static_cast<size_t>(bx) * by, 0.0f);
    for (uint32_t i : covered) {
      float& f = block_far[static_cast<size_t>(i / w / s) * bx + (i % w) / s];
      f = std::max(f, g.t[i]);
    }
    const int nx = bx + 1, ny = by + 1;
    std::vector<float> node_opacity(static_cast<size_t>(nx) * ny, 0.0f);
    ParallelFor(
        static_cast<size_t>(ny),
        [&](size_t row) {
          const int v = static_cast<int>(row);
          SceneRays rays;
          SceneSamples out;
          std::vector<int> cols;
          for (int u = 0; u < nx; ++u) {
            float far = 0.0f;
            for (int b = v - 1; b <= v; ++b)
              for (int a = u - 1; a <= u; ++a)
                if (a >= 0 && b >= 0 && a < bx && b < by) far = std::max(far, block_far[size_t(b) * bx + a]);
            if (!(far > 0.0f)) continue;
            add_ray(rays, g.rect.x0 + std::min(u * s, w - 1), g.rect.y0 + std::min(v * s, h - 1), far);
            cols.push_back(u);
          }
          if (cols.empty()) return;
          scene_.RenderRays(rays, out);
          for (size_t k = 0; k < cols.size(); ++k)
            node_opacity[row * nx + cols[k]] = std::isfinite(out.opacity[k]) ? out.opacity[k] : 1.0f;
        },
        1);
    const float limit = static_cast<float>(options_.occlusion_clear_opacity);
    for (uint32_t i : covered) {
      const size_t u = (i % w) / s, v = i / w / s;
      clear[i] = node_opacity[v * nx + u] < limit && node_opacity[v * nx + u + 1] < limit &&
                 node_opacity[(v + 1) * nx + u] < limit && node_opacity[(v + 1) * nx + u + 1] < limit;
    }
  }
  std::vector<size_t> fixed_per_chunk(chunks, 0);
  ParallelFor(
      chunks,
      [&](size_t c) {
        const size_t begin = c * kChunk, end = std::min(covered.size(), begin + kChunk);
        SceneRays rays;
        SceneSamples out;
        rays.Reserve(end - begin);
        std::vector<int> ray_of(end - begin, -1);
        for (size_t k = begin; k < end; ++k) {
          const uint32_t i = covered[k];
          if (clear[i]) continue;
          ray_of[k - begin] = static_cast<int>(rays.size());
          add_ray(rays, g.rect.x0 + static_cast<int>(i % g.rect.width()),
                  g.rect.y0 + static_cast<int>(i / g.rect.width()), g.t[i]);
        }
        if (rays.size() > 0) scene_.RenderRays(rays, out);
        for (size_t k = begin; k < end; ++k) {
          const uint32_t i = covered[k];
          const int x = g.rect.x0 + static_cast<int>(i % g.rect.width());
          const int y = g.rect.y0 + static_cast<int>(i / g.rect.width());
          const int r = ray_of[k - begin];
          float opacity = r >= 0 ? out.opacity[r] : 0.0f;
          Vec3f front = r >= 0 ? out.colour[r] : Vec3f{};
          if (!std::isfinite(opacity) || !Finite(front)) {
            opacity = 0.0f;
            front = {};
            ++fixed_per_chunk[c];
          }
          opacity = std::clamp(opacity, 0.0f, 1.0f);
          if (receivers.occlude_with_distance && receivers.distance) {
            const float scene_t = receivers.distance->at(x, y);
            if (scene_t > 0.0f && scene_t < 0.99f * g.t[i]) {  // the scene is in front: keep the frame
              layers.alpha.pixels[i] = 0.0f;
              continue;
            }
          }
          const float w = 1.0f - opacity;
          layers.alpha.pixels[i] = w;
          // Ĉ = I_α·I_c (opacity-weighted), so this is I_α·I_c + (1 − I_α)·I_v.
          // Edge pixels: the object over the part of the pixel it covers.
          const float cover = g.coverage.empty() ? 1.0f : g.coverage[i];
          for (int ch = 0; ch < 3; ++ch) {
            const float composite = front[ch] + w * layers.object.pixels[static_cast<size_t>(i) * 3 + ch];
            frame.at(x, y, ch) = cover * composite + (1.0f - cover) * frame.at(x, y, ch);
          }
        }
      },
      1);
  for (size_t f : fixed_per_chunk) layers.nonfinite_fixed += f;
  times.occlusion_ms = Ms(t0);

  // 5. Shadows κ on the scene where an object can shadow.
  t0 = Clock::now();
  std::vector<size_t> casters;
  for (size_t j = 0; j < n_objects; ++j)
    if (objects[j].visibility && spheres[j].radius > 0) casters.push_back(j);
  if (options_.shadows && !casters.empty()) {
    PixelRect rect;
    for (size_t j : casters)
      rect = Union(rect, ProjectBall(camera, T_world_camera, Vec3(spheres[j].center),
                                     options_.shadow_reach_radii * spheres[j].radius));
    rect = ClipToImage(rect, camera.width, camera.height);
    // The world lattice of κ, dropped when a caster or a light changed.
    KappaCache* cache = nullptr;
    double spacing = 0.0;
    float smallest = std::numeric_limits<float>::infinity();
    for (size_t j : casters) smallest = std::min(smallest, spheres[j].radius);
    if (options_.kappa_cache_spacing_radii > 0) {
      spacing = options_.kappa_cache_spacing_radii * smallest;
      // Also what shapes the κ layer kept for an unchanged camera.
      std::vector<double> key = {spacing,
                                 options_.shadow_reach_radii,
                                 options_.shadow_epsilon,
                                 double(options_.kappa_step),
                                 double(options_.kappa_coarse_factor),
                                 options_.kappa_refine_delta,
                                 options_.kappa_plane_upsampling ? 1.0 : 0.0,
                                 options_.receiver_min_opacity};
      for (size_t j : casters) AppendObjectKey(objects[j], key);
      for (const SgMixture& light : used_lights_) AppendLightKey(light, key);
      if (!kappa_cache_) kappa_cache_ = std::make_unique<KappaCache>();
      if (key != kappa_cache_->key || kappa_cache_->Size() > kKappaCacheMaxNodes) {
        kappa_cache_->Clear();
        kappa_cache_->key = std::move(key);
      }
      kappa_cache_->Publish();  // the last frame's nodes: read without locks this frame
      cache = kappa_cache_.get();
    }
    // A view already passed whole under this cache (receivers marched by
    // the NeRF, the same camera within a lattice spacing and 0.1 mrad): its
    // receivers' κ < 1 − ε lie within one spacing of the shadowed nodes'
    // box, so only that box's projection needs a pass (aligned to the
    // coarse grid of the whole rectangle, so its values are unchanged).
    std::vector<double> view = {
        camera.fx, camera.fy, camera.cx, camera.cy, double(camera.width), double(camera.height)};
    AppendPoseKey(T_world_camera, 1.0, view);
    if (cache != nullptr && receivers.distance == nullptr && !rect.empty()) {
      bool seen = false;
      for (const std::vector<double>& e : cache->explored) {
        bool same = e.size() == view.size();
        for (size_t i = 0; same && i < 6; ++i) same = e[i] == view[i];
        for (size_t i = 6; same && i < 15; ++i) same = std::abs(e[i] - view[i]) <= 1e-4;            // rotation entries
        for (size_t i = 15; same && i < 18; ++i) same = std::abs(e[i] - view[i]) <= 0.5 * spacing;  // translation
        seen = seen || same;
      }
      if (!seen) {
        if (cache->explored.size() >= 16) cache->explored.erase(cache->explored.begin());  // a moving camera
        cache->explored.push_back(view);
      } else {
        PixelRect shadow;
        const Vec3f lo = cache->shadow_min, hi = cache->shadow_max;
        if (lo.x <= hi.x) {
          const Vec3 centre = Vec3((lo + hi) * 0.5f);
          const double radius = 0.5 * Length(Vec3(hi - lo)) + 1.75 * spacing;  // + the nodes' trilinear support
          shadow = ClipToImage(ProjectBall(camera, T_world_camera, centre, radius), camera.width, camera.height);
        }
        if (shadow.empty()) {
          rect = {};
        } else {
          const int unit = options_.kappa_step * std::max(1, options_.kappa_coarse_factor);
          const auto down = [&](int v, int origin) { return origin + (std::max(v, origin) - origin) / unit * unit; };
          PixelRect r{down(shadow.x0 - unit, rect.x0), down(shadow.y0 - unit, rect.y0),
                      down(shadow.x1 + 2 * unit, rect.x0) + 1, down(shadow.y1 + 2 * unit, rect.y0) + 1};
          r = {std::max(r.x0, rect.x0), std::max(r.y0, rect.y0), std::min(r.x1, rect.x1), std::min(r.y1, rect.y1)};
          rect = r.empty() ? PixelRect{} : r;
        }
      }
    }
    layers.kappa_rect = rect;
    layers.kappa = ImageF(rect.width(), rect.height(), 1, 1.0f);
    // The same camera exactly, the same rectangle, nothing moved: the last
    // frame's κ layer holds (NeRF receivers only).
    const bool reuse = cache != nullptr && receivers.distance == nullptr && !rect.empty() && view == cache->last_view &&
                       rect.x0 == cache->last_rect.x0 && rect.y0 == cache->last_rect.y0 &&
                       rect.x1 == cache->last_rect.x1 && rect.y1 == cache->last_rect.y1;
    if (reuse) {
      layers.kappa = cache->last_kappa;
      ParallelFor(
          static_cast<size_t>(rect.height()),
          [&](size_t r) {
            const int y = rect.y0 + static_cast<int>(r);
            for (int x = rect.x0; x < rect.x1; ++x) {
              const float k = layers.kappa.at(x - rect.x0, y - rect.y0);
              if (k >= 1.0f) continue;
              if (g.rect.Contains(x, y) && g.object[g.Index(x, y)] >= 0) continue;
              for (int ch = 0; ch < 3; ++ch) frame.at(x, y, ch) *= k;
            }
          },
          4);
    } else if (!rect.empty()) {
      // Light owners: each receiver takes the light of its nearest object
      // (relative to size); queries of every caster at each owner's lobe axes.
      for (size_t o = 0; o < n_objects; ++o) prepare(o);
      const int step = options_.kappa_step;
      const auto grid_axis = [step](int lo, int hi) {
        std::vector<int> s;
        for (int v = lo; v < hi; v += step) s.push_back(v);
        if (s.back() != hi - 1) s.push_back(hi - 1);
        return s;
      };
      const std::vector<int> xs = grid_axis(rect.x0, rect.x1), ys = grid_axis(rect.y0, rect.y1);
      const size_t nx = xs.size(), ny = ys.size();
      std::vector<float> kappa_grid(nx * ny, 1.0f);
      std::vector<size_t> queries_per_row(ny, 0);
      const float reach = static_cast<float>(options_.shadow_reach_radii);
      const float min_opacity = static_cast<float>(options_.receiver_min_opacity);
      const double one_minus_eps = 1.0 - options_.shadow_epsilon;
      std::vector<size_t> evaluated_per_row(ny, 0), marched_per_row(ny, 0), reused_per_row(ny, 0);
      // The last frame's receivers, when they can stand for marching.
      const bool reuse_receivers = cache != nullptr && receivers.distance == nullptr && options_.kappa_receiver_reuse &&
                                   cache->receivers.valid &&
                                   cache->receivers.min_opacity == static_cast<float>(options_.receiver_min_opacity);
      const bool cell_normals = cache != nullptr && receivers.distance == nullptr && options_.receiver_normal_per_cell;
      if (cell_normals && (cache->normal_spacing != spacing || cache->cell_normals.size() > kKappaCacheMaxNodes)) {
        cache->cell_normals.clear();
        cache->normal_spacing = spacing;
      }
      const float reuse_tolerance = static_cast<float>(options_.kappa_reuse_tolerance_radii * smallest);
      // κ at world point x with unit normal n (1 where no caster is within
      // reach or the bounding spheres cannot darken it below 1 − ε); with
      // bound_only, 0 for "needs the SSDF" instead of evaluating it.
      const auto kappa_at = [&](const Vec3f& x, const Vec3f& n, KappaScratch& sc, bool* queried,
                                bool bound_only = false) -> float {
        // The owner of the light: the caster nearest in units of its radius.
        size_t owner = casters[0];
        float best = std::numeric_limits<float>::infinity();
        for (size_t j : casters) {
          const float rel = Length(x - spheres[j].center) / spheres[j].radius;
          if (rel < best) {
            best = rel;
            owner = j;
          }
        }
        if (!(best <= reach)) return 1.0f;
        const LightPrep& p = preps[owner];
        const size_t m = p.axes.size();
        if (m == 0) return 1.0f;
        const SgMixture cw = CosineWeightedLight(used_lights_[owner], Vec3(n));
        // Lower bound of S from the bounding spheres: if even that leaves
        // κ ≥ 1 − ε, nothing needs the SSDF.
        sc.s_bound.assign(m, kPi);
        for (size_t j : casters)
          for (size_t l = 0; l < m; ++l)
            sc.s_bound[l] =
                std::min<double>(sc.s_bound[l], BallSsdLowerBound(spheres[j].center, spheres[j].radius, x, p.axes[l]));
        if (ShadowRatio(cw, Vec3(n), sc.s_bound) >= one_minus_eps) return 1.0f;
        if (bound_only) return 0.0f;
        if (queried) *queried = true;
        sc.s_exact.assign(m, kPi);
        sc.cap.assign(m, 0.0);
        sc.ssd.resize(m);
        for (size_t j : casters) {
          if (!p.queries[j]) continue;
          p.queries[j]->Ssd(&x, 1, sc.ssd.data());
          const float dist = Length(x - spheres[j].center);
          const double alpha =
              dist > spheres[j].radius ? std::asin(std::min(1.0f, spheres[j].radius / dist)) : 0.5 * kPi;
          for (size_t l = 0; l < m; ++l) {
            if (sc.ssd[l] < sc.s_exact[l]) {
              sc.s_exact[l] = sc.ssd[l];
              sc.cap[l] = alpha;
            }
          }
        }
        const double k = ShadowRatioCapped(cw, Vec3(n), sc.s_exact, sc.cap);
        return std::isfinite(k) ? static_cast<float>(std::clamp(k, 0.0, 1.0)) : 1.0f;
      };
      // κ at receiver x (normal n): exact, or trilinear in the world lattice.
      const auto receiver_kappa = [&](const Vec3f& x, const Vec3f& n, KappaScratch& sc, size_t row) -> float {
        if (cache == nullptr) {
          bool queried = false;
          const float k = kappa_at(x, n, sc, &queried);
          ++evaluated_per_row[row];
          if (queried) ++queries_per_row[row];
          return k;
        }
        // No bound test here: nodes that the bound clears hold κ = 1.
        // Trilinear over the lattice nodes around x, for x's normal cell.
        const uint32_t cell = NormalCell(n);
        const Vec3f n_cell = CellNormal(cell);
        const double fx = x.x / spacing, fy = x.y / spacing, fz = x.z / spacing;
        const double bx = std::floor(fx), by = std::floor(fy), bz = std::floor(fz);
        const double wx = fx - bx, wy = fy - by, wz = fz - bz;
        double sum = 0.0, total = 0.0;
        for (int corner = 0; corner < 8; ++corner) {
          const int dx = corner & 1, dy = (corner >> 1) & 1, dz = corner >> 2;
          const double weight = (dx ? wx : 1 - wx) * (dy ? wy : 1 - wy) * (dz ? wz : 1 - wz);
          // Nodes that hardly count are not computed (a receiver plane on a
          // lattice plane would otherwise pull in the layer beyond it).
          if (weight < 1e-3) continue;
          total += weight;
          const int64_t i = int64_t(bx) + dx, j = int64_t(by) + dy, k = int64_t(bz) + dz;
          const uint64_t key = LatticeKey(i, j, k, cell);
          const size_t slot = KappaScratch::MemoSlot(key);
          float value;
          if (sc.memo_key[slot] == key && sc.memo_value[slot] >= 0.0f) {
            value = sc.memo_value[slot];
          } else if (!cache->Find(key, &value)) {
            bool queried = false;
            const Vec3f node(Vec3(double(i), double(j), double(k)) * spacing);
            value = kappa_at(node, n_cell, sc, &queried);
            cache->Insert(key, value);
            if (value < one_minus_eps) cache->GrowShadow(node);
            ++evaluated_per_row[row];
            if (queried) ++queries_per_row[row];
          }
          sc.memo_key[slot] = key;
          sc.memo_value[slot] = value;
          sum += weight * value;
        }
        return total > 0.0 ? static_cast<float>(std::clamp(sum / total, 0.0, 1.0)) : 1.0f;
      };
      // What the receiver pass found at each grid node (for the upsampling).
      std::vector<Vec3f> node_point(nx * ny), node_normal(nx * ny);
      std::vector<uint8_t> node_valid(nx * ny, 0);
      std::vector<uint8_t> node_state(nx * ny, 0);  // 0 not found, 1 surface, 2 no surface (as ReceiverFrame)
      // κ at the grid nodes (row, cols[j]) of one row.
      const auto eval_row = [&](size_t row, const std::vector<size_t>& cols) {
        if (cols.empty()) return;
        const int y = ys[row];
        const size_t nc = cols.size();
        SceneRays rays;
        SceneSamples out;
        std::vector<Vec3f> points(nc), normals;
        std::vector<float> opacity(nc, 0.0f);
        std::vector<Vec3f> dirs(nc);
        for (size_t ix = 0; ix < nc; ++ix) dirs[ix] = CameraRayDirection(camera, T_world_camera, xs[cols[ix]], y);
        if (receivers.distance) {
          for (size_t ix = 0; ix < nc; ++ix) {
            const float t = receivers.distance->at(xs[cols[ix]], y);
            opacity[ix] = t > 0.0f && std::isfinite(t) ? 1.0f : 0.0f;
            points[ix] = eye + dirs[ix] * (opacity[ix] > 0 ? t : 0.0f);
          }
        } else {
          // Receivers the last frame gives (state 1 or 2); the rest marched.
          std::vector<uint8_t> given(nc, 0);
          std::vector<Vec3f> given_normal(nc);
          std::vector<size_t> march;
          march.reserve(nc);
          for (size_t ix = 0; ix < nc; ++ix) {
            if (reuse_receivers)
              given[ix] = static_cast<uint8_t>(ReuseReceiver(cache->receivers, eye, dirs[ix], xs[cols[ix]], y,
                                                             reuse_tolerance, points[ix], given_normal[ix]));
            if (given[ix] == 1) opacity[ix] = 1.0f;
            if (given[ix] == 0) march.push_back(ix);
          }
          reused_per_row[row] += nc - march.size();
          if (!march.empty()) {
            rays.Reserve(march.size());
            for (size_t ix : march) {
              const auto range = IntersectBox(box, Vec3(eye), Vec3(dirs[ix]));
              rays.Add(eye, dirs[ix], range ? static_cast<float>(range->first) : 0.0f,
                       range ? static_cast<float>(range->second) : 0.0f);
            }
            scene_.RenderRays(rays, out);
            marched_per_row[row] += march.size();
            std::vector<Vec3f> marched_points(march.size()), marched_normals;
            for (size_t m = 0; m < march.size(); ++m) {
              const size_t ix = march[m];
              opacity[ix] = std::isfinite(out.opacity[m]) ? out.opacity[m] : 0.0f;
              const float t = std::isfinite(out.depth[m]) ? out.depth[m] : 0.0f;
              points[ix] = marched_points[m] = eye + dirs[ix] * t;
            }
            scene_.Normals(marched_points, marched_normals);
            for (size_t m = 0; m < march.size(); ++m) given_normal[march[m]] = marched_normals[m];
          }
          if (cell_normals) {
            // One normal per world cell: the first found there stands for all.
            std::lock_guard<std::mutex> lock(cache->normal_mutex);
            for (size_t ix = 0; ix < nc; ++ix) {
              if (given[ix] == 2 || !Finite(points[ix]) || !Finite(given_normal[ix])) continue;
              const uint64_t key =
                  LatticeKey(int64_t(std::floor(points[ix].x / spacing)), int64_t(std::floor(points[ix].y / spacing)),
                             int64_t(std::floor(points[ix].z / spacing)), 0);
              const auto [it, added] = cache->cell_normals.emplace(key, given_normal[ix]);
              if (!added) given_normal[ix] = it->second;
            }
          }
          normals = std::move(given_normal);
        }
        if (receivers.normal) {
          normals.resize(nc);
          for (size_t ix = 0; ix < nc; ++ix)
            normals[ix] = {receivers.normal->at(xs[cols[ix]], y, 0), receivers.normal->at(xs[cols[ix]], y, 1),
                           receivers.normal->at(xs[cols[ix]], y, 2)};
        } else if (receivers.distance) {
          scene_.Normals(points, normals);
        }
        KappaScratch scratch;
        for (size_t ix = 0; ix < nc; ++ix) {
          float& kappa = kappa_grid[row * nx + cols[ix]];
          node_state[row * nx + cols[ix]] = 2;
          if (opacity[ix] < min_opacity || !Finite(points[ix])) continue;
          Vec3f n = normals[ix];
          if (!Finite(n) || Dot(n, n) < 0.25f) continue;
          n = Normalized(n);
          node_state[row * nx + cols[ix]] = 1;
          node_point[row * nx + cols[ix]] = points[ix];
          node_normal[row * nx + cols[ix]] = n;
          node_valid[row * nx + cols[ix]] = 1;
          kappa = receiver_kappa(points[ix], n, scratch, row);
        }
      };
      // Coarse to fine: κ at every coarse_factor-th node; cells whose corners
      // differ by more than kappa_refine_delta get all their nodes, the
      // others are interpolated (κ varies slowly away from edges).
      size_t factor = static_cast<size_t>(std::max(1, options_.kappa_coarse_factor));
      if (nx < 2 * factor || ny < 2 * factor) factor = 1;  // too small a grid to coarsen
      const auto coarse_axis = [factor](size_t n) {
        std::vector<size_t> c;
        for (size_t i = 0; i < n; i += factor) c.push_back(i);
        if (c.back() != n - 1) c.push_back(n - 1);
        return c;
      };
      const std::vector<size_t> cx = coarse_axis(nx), cy = coarse_axis(ny);
      std::vector<uint8_t> is_coarse_row(ny, 0);
      for (size_t r : cy) is_coarse_row[r] = 1;
      ParallelFor(
          cy.size(), [&](size_t i) { eval_row(cy[i], cx); }, 1);
      if (factor > 1) {
        // Nodes that need their own κ: those of cells with differing corners.
        std::vector<uint8_t> need(nx * ny, 0);
        const float delta = static_cast<float>(options_.kappa_refine_delta);
        for (size_t j = 0; j + 1 < cy.size(); ++j)
          for (size_t i = 0; i + 1 < cx.size(); ++i) {
            const float a = kappa_grid[cy[j] * nx + cx[i]], b = kappa_grid[cy[j] * nx + cx[i + 1]];
            const float c = kappa_grid[cy[j + 1] * nx + cx[i]], d = kappa_grid[cy[j + 1] * nx + cx[i + 1]];
            if (std::max({a, b, c, d}) - std::min({a, b, c, d}) <= delta) continue;
            for (size_t r = cy[j]; r <= cy[j + 1]; ++r)
              for (size_t q = cx[i]; q <= cx[i + 1]; ++q) need[r * nx + q] = 1;
          }
        std::vector<uint8_t> is_coarse_col(nx, 0);
        for (size_t q : cx) is_coarse_col[q] = 1;
        // Coarse cells whose four receivers lie on one plane (normals within
        // 10° of their mean, points within 5% of the cell's size of the
        // plane through their mean); only where the receivers were marched.
        std::vector<CellPlane> planes((cy.size() - 1) * (cx.size() - 1));
        if (options_.kappa_plane_upsampling && receivers.distance == nullptr) {
          for (size_t j = 0; j + 1 < cy.size(); ++j)
            for (size_t i = 0; i + 1 < cx.size(); ++i) {
              const size_t corner[4] = {cy[j] * nx + cx[i], cy[j] * nx + cx[i + 1], cy[j + 1] * nx + cx[i],
                                        cy[j + 1] * nx + cx[i + 1]};
              CellPlane& plane = planes[j * (cx.size() - 1) + i];
              Vec3f mean_p{}, mean_n{};
              bool ok = true;
              for (size_t c : corner) {
                ok = ok && node_valid[c];
                mean_p = mean_p + node_point[c] * 0.25f;
                mean_n = mean_n + node_normal[c];
              }
              if (!ok || !(Dot(mean_n, mean_n) > 1e-6f)) continue;
              mean_n = Normalized(mean_n);
              float size = 0.0f, off = 0.0f;
              plane.t_min = std::numeric_limits<float>::infinity();
              plane.t_max = 0.0f;
              for (size_t c : corner) {
                ok = ok && Dot(node_normal[c], mean_n) > 0.985f;
                size = std::max(size, Length(node_point[c] - mean_p));
                off = std::max(off, std::abs(Dot(node_point[c] - mean_p, mean_n)));
                const float t = Length(node_point[c] - eye);
                plane.t_min = std::min(plane.t_min, t);
                plane.t_max = std::max(plane.t_max, t);
              }
              if (!ok || off > 0.05f * size) continue;
              plane.valid = true;
              plane.point = mean_p;
              plane.normal = mean_n;
            }
        }
        ParallelFor(
            ny,
            [&](size_t r) {
              std::vector<size_t> cols;
              const size_t j = std::min<size_t>(r / factor, cy.size() - 2);
              KappaScratch scratch;
              for (size_t q = 0; q < nx; ++q) {
                if (!need[r * nx + q] || (is_coarse_row[r] && is_coarse_col[q])) continue;
                // Depth-aware upsampling: inside a planar coarse cell the
                // receiver is where this node's ray meets the plane.
                const CellPlane& plane = planes[j * (cx.size() - 1) + std::min<size_t>(q / factor, cx.size() - 2)];
                if (plane.valid) {
                  const Vec3f d = CameraRayDirection(camera, T_world_camera, xs[q], ys[r]);
                  const float cosine = Dot(d, plane.normal);
                  const float t = cosine < -0.05f ? Dot(plane.point - eye, plane.normal) / cosine : -1.0f;
                  if (t >= 0.9f * plane.t_min && t <= 1.1f * plane.t_max) {
                    kappa_grid[r * nx + q] = receiver_kappa(eye + d * t, plane.normal, scratch, r);
                    continue;
                  }
                }
                cols.push_back(q);
              }
              eval_row(r, cols);
              // The rest: bilinear in their coarse cell.
              const float wy = float(r - cy[j]) / float(cy[j + 1] - cy[j]);
              for (size_t q = 0; q < nx; ++q) {
                if (need[r * nx + q] || (is_coarse_row[r] && is_coarse_col[q])) continue;
                const size_t i = std::min<size_t>(q / factor, cx.size() - 2);
                const float wx = float(q - cx[i]) / float(cx[i + 1] - cx[i]);
                kappa_grid[r * nx + q] = (1 - wx) * (1 - wy) * kappa_grid[cy[j] * nx + cx[i]] +
                                         wx * (1 - wy) * kappa_grid[cy[j] * nx + cx[i + 1]] +
                                         (1 - wx) * wy * kappa_grid[cy[j + 1] * nx + cx[i]] +
                                         wx * wy * kappa_grid[cy[j + 1] * nx + cx[i + 1]];
              }
            },
            1);
      }
      for (size_t q : queries_per_row) layers.kappa_queries += q;
      for (size_t q : evaluated_per_row) times.kappa_evaluated += q;
      for (size_t q : marched_per_row) times.kappa_marched += q;
      for (size_t q : reused_per_row) times.kappa_reused += q;
      if (cache != nullptr && receivers.distance == nullptr && options_.kappa_receiver_reuse) {
        // Kept for the next frame (nodes only interpolated or plane-placed
        // stay unknown).
        ReceiverFrame& kept = cache->receivers;
        kept.valid = true;
        kept.min_opacity = static_cast<float>(options_.receiver_min_opacity);
        kept.camera = camera;
        kept.T_world_camera = T_world_camera;
        kept.T_camera_world = T_world_camera.Inverse();
        kept.xs = xs;
        kept.ys = ys;
        kept.cx = cx;
        kept.cy = cy;
        kept.factor = factor;
        kept.step = step;
        kept.state = std::move(node_state);
        kept.point = std::move(node_point);
        kept.normal = std::move(node_normal);
      }
      // Bilinear from the sample grid to every pixel; multiply the background
      // where no object covers it. Cell by cell of the grid: a cell whose
      // four nodes hold κ = 1 is skipped whole (the layer is 1 already; the
      // per-pixel sum of its weights could round 1 ulp under 1, the only
      // difference from doing every pixel).
      ParallelFor(
          static_cast<size_t>(rect.height()),
          [&](size_t r) {
            const int y = rect.y0 + static_cast<int>(r);
            const size_t iy = std::min<size_t>((y - rect.y0) / step, ny >= 2 ? ny - 2 : 0);
            const float wy = ny >= 2 ? float(y - ys[iy]) / float(ys[iy + 1] - ys[iy]) : 0.0f;
            const size_t iy1 = ny >= 2 ? iy + 1 : iy;
            const float* g0 = &kappa_grid[iy * nx];
            const float* g1 = &kappa_grid[iy1 * nx];
            float* out = &layers.kappa.at(0, y - rect.y0);
            const bool object_row = y >= g.rect.y0 && y < g.rect.y1;
            const size_t cells = nx >= 2 ? nx - 1 : 1;
            for (size_t ix = 0; ix < cells; ++ix) {
              const size_t ix1 = nx >= 2 ? ix + 1 : ix;
              const float a = g0[ix], b = g0[ix1], c = g1[ix], d = g1[ix1];
              if (a >= 1.0f && b >= 1.0f && c >= 1.0f && d >= 1.0f) continue;
              const int x_begin = nx >= 2 ? xs[ix] : rect.x0;
              const int x_end = nx >= 2 && ix + 2 < nx ? xs[ix1] : rect.x1;
              const float span = nx >= 2 ? float(xs[ix1] - xs[ix]) : 1.0f;
              for (int x = x_begin; x < x_end; ++x) {
                const float wx = nx >= 2 ? float(x - xs[ix]) / span : 0.0f;
                const float k = (1 - wx) * (1 - wy) * a + wx * (1 - wy) * b + (1 - wx) * wy * c + wx * wy * d;
                out[x - rect.x0] = k;
                if (k >= 1.0f) continue;
                if (object_row && g.rect.Contains(x, y) && g.object[g.Index(x, y)] >= 0) continue;
                for (int ch = 0; ch < 3; ++ch) frame.at(x, y, ch) *= k;
              }
            }
          },
          4);
      if (cache != nullptr && receivers.distance == nullptr) {
        cache->last_view = view;
        cache->last_rect = rect;
        cache->last_kappa = layers.kappa;
      }
    }
  }
  times.kappa_ms = Ms(t0);

  // Pixels partly covered by an object whose centre misses it: the
  // composite of the nearest covered neighbour over the covered part.
  if (!g.coverage.empty() && g.covered > 0) {
    std::vector<std::array<float, 3>> partial;
    std::vector<std::pair<int, int>> where;
    for (int y = g.rect.y0; y < g.rect.y1; ++y)
      for (int x = g.rect.x0; x < g.rect.x1; ++x) {
        const size_t i = g.Index(x, y);
        if (g.object[i] >= 0 || !(g.coverage[i] > 0.0f)) continue;
        int best = -1;
        float best_d = 3.0f;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int xx = x + dx, yy = y + dy;
            if (!g.rect.Contains(xx, yy)) continue;
            const size_t j = g.Index(xx, yy);
            const float d = float(dx * dx + dy * dy);
            if (g.object[j] >= 0 && layers.alpha.pixels[j] > 0.0f && d < best_d) {
              best_d = d;
              best = static_cast<int>(j);
            }
          }
        if (best < 0) continue;
        if (receivers.occlude_with_distance && receivers.distance) {
          const float scene_t = receivers.distance->at(x, y);
          if (scene_t > 0.0f && scene_t < 0.99f * g.t[best]) continue;  // the scene is in front here
        }
        // The neighbour's object radiance weighted by its visibility.
        const float a = layers.alpha.pixels[best], c = g.coverage[i] * a;
        std::array<float, 3> v;
        for (int ch = 0; ch < 3; ++ch)
          v[ch] = c * layers.object.pixels[static_cast<size_t>(best) * 3 + ch] + (1.0f - c) * frame.at(x, y, ch);
        partial.push_back(v);
        where.push_back({x, y});
      }
    for (size_t k = 0; k < partial.size(); ++k)
      for (int ch = 0; ch < 3; ++ch) frame.at(where[k].first, where[k].second, ch) = partial[k][ch];
  }
  times.total_ms = Ms(t_start);
  return times;
}

}  // namespace nerfar
