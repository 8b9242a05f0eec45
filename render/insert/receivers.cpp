#include "render/insert/receivers.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <optional>

#include "calib/core/parallel.h"
#include "render/insert/insert_common.h"
#include "render/insert/inserter.h"
#include "render/insert/kappa_lattice.h"

namespace nerfar {

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

void ReceiversOnPlane(const SceneField& scene, const SupportPlane& plane, const Vec3f& eye,
                      const std::vector<Vec3f>& dirs, const std::vector<float>& t_near, std::vector<float>& t,
                      std::vector<uint8_t>& on_plane) {
  on_plane.assign(t.size(), 0);
  // Where the transmittance was still 1 − q: the ray marched again up to
  // its 1/2 point (the same samples as the march that found it).
  SceneRays front;
  std::vector<float> level, t_plane;
  std::vector<size_t> candidate;
  for (size_t i = 0; i < t.size(); ++i) {
    const float cosine = Dot(dirs[i], plane.normal);
    if (!(cosine < 0.0f) || !(t[i] > t_near[i])) continue;  // the plane seen from behind, or along it
    const float t_p = Dot(plane.point - eye, plane.normal) / cosine;
    if (!(t_p >= t_near[i])) continue;
    front.Add(eye, dirs[i], t_near[i], t[i]);
    level.push_back(1.0f - kSupportTerminationShare);
    t_plane.push_back(t_p);
    candidate.push_back(i);
  }
  if (candidate.empty()) return;
  std::vector<float> t_front;
  scene.TransmittanceDepths(front, level, t_front);
  for (size_t k = 0; k < candidate.size(); ++k) {
    const size_t i = candidate[k];
    const float before = t[i] - std::min(t_front[k], t[i]);
    if (t_plane[k] < t[i] - before || t_plane[k] > t[i] + before) continue;  // the ray ends off the plane
    t[i] = t_plane[k];
    on_plane[i] = 1;
  }
}

namespace {

// Whether something the last frame saw may lie between `eye` and p, a
// point on the plane (plane_point, plane_normal) of the last-frame receivers
// it was reused from: the last view cannot see what this eye sees past an
// object's edge. The part of the segment eye → p at least the last frame's
// nearest receiver distance from the last eye is projected into the last
// view and walked at coarse grid steps from p's pixel (the coarse nodes are
// always known; an occluder narrower than a coarse cell can slip through);
// a receiver there off p's plane by more than `tolerance` and
// nearer the last eye than the segment's point means the segment passes
// inside or behind a surface the last view saw: true (march). Also true when
// the walk is longer than kMaxWalkSteps coarse steps (an eye moved too far
// to check cheaply).
bool HiddenFromEye(const ReceiverFrame& r, const Vec3f& eye, const Vec3f& p, const Vec3f& plane_point,
                   const Vec3f& plane_normal, float tolerance) {
  constexpr int kMaxWalkSteps = 16;
  const Vec3 last_eye = r.T_world_camera.translation;
  const double length = Length(Vec3(p - eye));
  // What the last frame saw lies at least nearest − m from this eye (moved
  // by m): nothing of it can come between eye and p when p is nearer than
  // that, and it shifts against p between the two views by at most
  // f·m·(1/(nearest − m) − 1/|p − eye|) pixels. Under half a coarse cell
  // the walk's one sample would fall in p's own cell, whose corners the
  // plane test already holds to p's plane: nothing to walk (a hand-held
  // frame's usual case).
  const double coarse_step = double(r.step) * double(r.factor);
  const double moved = Length(Vec3(eye) - last_eye), near = r.nearest - moved;
  if (length <= near) return false;
  const double shift = near > 0.0 ? std::max(r.camera.fx, r.camera.fy) * moved * (1.0 / near - 1.0 / length) : HUGE_VAL;
  if (shift < 0.5 * coarse_step) return false;
  const double u_min = std::clamp((r.nearest - Length(Vec3(eye) - last_eye)) / length, 0.0, 1.0);
  const auto pixel = [&](const Vec3& w, double& u, double& v) {
    const Vec3 c = r.T_camera_world * w;
    if (!(c.z > 1e-6)) return false;
    u = r.camera.fx * c.x / c.z + r.camera.cx - 0.5;
    v = r.camera.fy * c.y / c.z + r.camera.cy - 0.5;
    return true;
  };
  const Vec3 a = Vec3(eye) + Vec3(p - eye) * u_min, b(p);
  double ua, va, ub, vb;
  if (!pixel(a, ua, va) || !pixel(b, ub, vb)) return true;
  const int steps = static_cast<int>(std::ceil(std::hypot(ua - ub, va - vb) / coarse_step));
  if (steps > kMaxWalkSteps) return true;
  for (int k = 1; k <= steps; ++k) {
    const Vec3 s = b + (a - b) * (double(k) / steps);
    double u, v;
    if (!pixel(s, u, v)) return true;
    const double fx = (u - r.xs.front()) / coarse_step, fy = (v - r.ys.front()) / coarse_step;
    if (fx < -0.5 || fy < -0.5 || fx > r.cx.size() - 0.5 || fy > r.cy.size() - 0.5) continue;
    const size_t node = r.cy[std::min<size_t>(std::lround(fy), r.cy.size() - 1)] * r.xs.size() +
                        r.cx[std::min<size_t>(std::lround(fx), r.cx.size() - 1)];
    if (r.state[node] != 1 || std::abs(Dot(r.point[node] - plane_point, plane_normal)) <= tolerance) continue;
    if (Length(Vec3(r.point[node]) - last_eye) < Length(s - last_eye)) return true;
  }
  return false;
}

}  // namespace

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
  const Vec3f old_eye(r.T_world_camera.translation);
  if (surfaces == 0) {
    // No surface around the same pixel of the last view: kept while this
    // pixel's ray moved by less than a grid step (its eye by the tolerance).
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
    if (HiddenFromEye(r, eye, p, mean, n, tolerance)) return 0;
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

void CellNormals::Resolve(double spacing, std::vector<CellCandidate>& candidates) {
  if (spacing != spacing_ || normals_.size() > kKappaCacheMaxNodes) {
    normals_.clear();
    spacing_ = spacing;
  }
  if (!(spacing > 0)) return;
  const auto index = [spacing](float v) { return int64_t(std::floor(v / spacing)); };
  // Candidates in cells that have a normal take it (read-only look-ups,
  // in parallel); the rest below.
  std::vector<uint64_t> keys(candidates.size());
  std::vector<uint8_t> known(candidates.size(), 0);
  ParallelFor(
      candidates.size(),
      [&](size_t c) {
        const Vec3f& p = candidates[c].point;
        keys[c] = LatticeKey(index(p.x), index(p.y), index(p.z), 0);
        const auto it = normals_.find(keys[c]);
        if (it == normals_.end()) return;
        candidates[c].normal = it->second;
        known[c] = 1;
      },
      512);
  // The usable candidates in cells without a normal yet, sorted by cell and
  // then by their values (a strict total order up to equal values): the sum
  // below runs in the same order whatever order they came in.
  struct Fresh {
    uint64_t key;
    std::array<float, 6> value;  // point, unit normal
  };
  std::vector<Fresh> fresh;
  for (size_t c = 0; c < candidates.size(); ++c) {
    if (known[c]) continue;
    const CellCandidate& cand = candidates[c];
    const Vec3f n = cand.normal;
    if (!Finite(n) || !(Dot(n, n) >= 0.25f)) continue;
    const Vec3f u = Normalized(n);
    fresh.push_back({keys[c], {cand.point.x, cand.point.y, cand.point.z, u.x, u.y, u.z}});
  }
  std::sort(fresh.begin(), fresh.end(),
            [](const Fresh& a, const Fresh& b) { return a.key != b.key ? a.key < b.key : a.value < b.value; });
  // A new cell's normal: the mean of its receivers' unit normals (their
  // scatter averages out; the first one where they cancel).
  for (size_t begin = 0; begin < fresh.size();) {
    size_t end = begin;
    Vec3f sum{};
    while (end < fresh.size() && fresh[end].key == fresh[begin].key) {
      sum = sum + Vec3f{fresh[end].value[3], fresh[end].value[4], fresh[end].value[5]};
      ++end;
    }
    const Vec3f first{fresh[begin].value[3], fresh[begin].value[4], fresh[begin].value[5]};
    normals_.emplace(fresh[begin].key, Dot(sum, sum) > 1e-6f ? Normalized(sum) : first);
    begin = end;
  }
  for (size_t c = 0; c < candidates.size(); ++c) {
    if (known[c]) continue;
    const auto it = normals_.find(keys[c]);
    if (it != normals_.end()) candidates[c].normal = it->second;
  }
}

}  // namespace nerfar
