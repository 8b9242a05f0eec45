// Ray queries: one bounding-volume hierarchy (binned SAH, 12 bins, leaves of at
// most 4 primitives) over every shape, each primitive tested analytically
// (spheres, yawed boxes, vertical cylinders, rectangles, triangles).
#include "render/synth/scene.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "calib/core/error.h"

namespace nerfar::synth {

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kPiF = static_cast<float>(kPi);

enum class Kind : uint8_t { kSphere, kBox, kCylinder, kRectangle, kTriangle };

struct Prim {
  Kind kind;
  uint32_t shape;     // index into the shape vector of its kind
  uint32_t triangle;  // triangle index for meshes
};

struct Box3 {
  Vec3f lo{kInf, kInf, kInf}, hi{-kInf, -kInf, -kInf};
  void Grow(const Vec3f& p) {
    lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
    hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
  }
  void Grow(const Box3& b) {
    Grow(b.lo);
    Grow(b.hi);
  }
  Vec3f Center() const { return (lo + hi) * 0.5f; }
  float Area() const {
    const Vec3f d = hi - lo;
    return d.x < 0 ? 0.0f : 2.0f * (d.x * d.y + d.y * d.z + d.z * d.x);
  }
};

struct Node {
  Box3 box;
  uint32_t first = 0;  // first primitive (leaf) or left child (inner; right = left + 1)
  uint32_t count = 0;  // primitives in a leaf, 0 for inner nodes
};

Vec3f RotateZ(const Vec3f& v, float c, float s) { return {c * v.x - s * v.y, s * v.x + c * v.y, v.z}; }

// Nearest root of |o + t d - c|^2 = r^2 in (t_min, t_max); d unit.
bool IntersectSphereT(const Vec3f& c, float r, const Ray& ray, float t_max, float& t) {
  const Vec3f oc = ray.origin - c;
  const float b = Dot(oc, ray.dir);
  // Numerically stable: distance of the centre from the ray line.
  const Vec3f closest = oc - ray.dir * b;
  const float disc = r * r - Dot(closest, closest);
  if (disc < 0) return false;
  const float q = std::sqrt(disc);
  const float t0 = -b - q, t1 = -b + q;
  if (t0 > ray.t_min && t0 < t_max) {
    t = t0;
    return true;
  }
  if (t1 > ray.t_min && t1 < t_max) {
    t = t1;
    return true;
  }
  return false;
}

// Slab test against an axis-aligned box; returns the entry (or exit when the
// origin is inside) distance and the axis of that face.
bool IntersectSlabs(const Vec3f& lo, const Vec3f& hi, const Vec3f& o, const Vec3f& d, float t_min, float t_max,
                    float& t, int& axis, bool& exiting) {
  float t_near = -kInf, t_far = kInf;
  int near_axis = 0, far_axis = 0;
  for (int a = 0; a < 3; ++a) {
    const float inv = 1.0f / d[a];
    float t0 = (lo[a] - o[a]) * inv, t1 = (hi[a] - o[a]) * inv;
    if (t0 > t1) std::swap(t0, t1);
    if (std::isnan(t0)) continue;  // parallel ray on the slab boundary
    if (t0 > t_near) t_near = t0, near_axis = a;
    if (t1 < t_far) t_far = t1, far_axis = a;
  }
  if (t_near > t_far) return false;
  if (t_near > t_min && t_near < t_max) {
    t = t_near;
    axis = near_axis;
    exiting = false;
    return true;
  }
  if (t_far > t_min && t_far < t_max) {
    t = t_far;
    axis = far_axis;
    exiting = true;
    return true;
  }
  return false;
}

bool BoxOverlapsRay(const Box3& b, const Vec3f& o, const Vec3f& inv_d, float t_min, float t_max, float& t_entry) {
  float t0 = t_min, t1 = t_max;
  for (int a = 0; a < 3; ++a) {
    float n = (b.lo[a] - o[a]) * inv_d[a], f = (b.hi[a] - o[a]) * inv_d[a];
    if (n > f) std::swap(n, f);
    // NaN (0 * inf) keeps the current bounds: max/min with NaN first return the other.
    t0 = n > t0 ? n : t0;
    t1 = f < t1 ? f : t1;
  }
  t_entry = t0;
  return t0 <= t1;
}

// Environment sampling: piecewise-constant density over the equirect (u, v) square,
// weights = luminance * sin(theta) plus a floor so every direction with radiance has a
// positive density.
struct EnvSampling {
  int w = 0, h = 0;
  std::vector<float> row_cdf;   // h + 1
  std::vector<float> col_cdf;   // h * (w + 1)
  std::vector<float> row_mass;  // probability of each row
  std::vector<float> cell_pdf;  // probability of each cell (row-major)
};

}  // namespace

Vec3 EquirectDirection(double u, double v) {
  const double theta = kPi * v, phi = kPi * (1.0 - 2.0 * u);
  return {std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
}

void EquirectCoordinates(const Vec3& d, double& u, double& v) {
  u = 0.5 - std::atan2(d.y, d.x) / (2.0 * kPi);
  u -= std::floor(u);
  v = std::acos(std::clamp(d.z, -1.0, 1.0)) / kPi;
}

struct Scene::Accel {
  std::vector<Prim> prims;  // in the order the BVH's leaves index
  std::vector<Node> nodes;  // nodes[0] is the root
  EnvSampling env;
};

Scene::Scene() = default;
Scene::~Scene() = default;
Scene::Scene(Scene&&) noexcept = default;
Scene& Scene::operator=(Scene&&) noexcept = default;

int Scene::AddMaterial(const SurfaceMaterial& material) {
  materials.push_back(material);
  return static_cast<int>(materials.size()) - 1;
}

void Scene::AddSphereLight(const SphereLight& light) {
  SurfaceMaterial m;
  m.albedo = {0, 0, 0};
  m.emission = light.radiance;
  spheres.push_back({light.center, light.radius, AddMaterial(m), -1});
  sphere_lights.push_back(light);
}

void Scene::AddRectangleLight(const RectangleLight& light) {
  SurfaceMaterial m;
  m.albedo = {0, 0, 0};
  m.emission = light.radiance;
  m.emits_back = light.two_sided;
  rectangles.push_back({light.center, light.u_axis, light.v_axis, light.half_u, light.half_v, AddMaterial(m), -1});
  rectangle_lights.push_back(light);
}

void Scene::AddBoxLight(const BoxLight& light) {
  SurfaceMaterial m;
  m.albedo = {0, 0, 0};
  m.emission = light.radiance;
  boxes.push_back({light.center, light.half_size, light.yaw_rad, AddMaterial(m), -1});
  box_lights.push_back(light);
}

Scene Scene::Copy() const {
  Scene copy;
  copy.materials = materials;
  copy.textures = textures;
  copy.spheres = spheres;
  copy.boxes = boxes;
  copy.cylinders = cylinders;
  copy.rectangles = rectangles;
  copy.meshes = meshes;
  copy.sphere_lights = sphere_lights;
  copy.rectangle_lights = rectangle_lights;
  copy.box_lights = box_lights;
  copy.environment = environment;
  if (built()) copy.Build();
  return copy;
}

Scene Scene::WithoutObject(int object_id) const {
  Scene copy;
  copy.materials = materials;
  copy.textures = textures;
  copy.sphere_lights = sphere_lights;
  copy.rectangle_lights = rectangle_lights;
  copy.box_lights = box_lights;
  copy.environment = environment;
  auto keep = [object_id](const auto& shapes, auto& out) {
    for (const auto& s : shapes)
      if (s.object_id != object_id) out.push_back(s);
  };
  keep(spheres, copy.spheres);
  keep(boxes, copy.boxes);
  keep(cylinders, copy.cylinders);
  keep(rectangles, copy.rectangles);
  keep(meshes, copy.meshes);
  if (built()) copy.Build();
  return copy;
}

namespace {

// Every shape's primitives (a mesh: one per triangle) with their bounding boxes, padded so that
// the slab tests of flat boxes (rectangles, axis-aligned triangles) are robust.
void CollectPrimitives(const Scene& scene, std::vector<Prim>& prims, std::vector<Box3>& bounds) {
  const int materials = static_cast<int>(scene.materials.size());
  auto add = [&](Kind kind, size_t shape, size_t triangle, const Box3& b) {
    prims.push_back({kind, static_cast<uint32_t>(shape), static_cast<uint32_t>(triangle)});
    bounds.push_back(b);
  };
  for (size_t i = 0; i < scene.spheres.size(); ++i) {
    const auto& s = scene.spheres[i];
    NERFAR_CHECK_LT(s.material, materials);
    const Vec3f r{s.radius, s.radius, s.radius};
    Box3 b;
    b.Grow(s.center - r);
    b.Grow(s.center + r);
    add(Kind::kSphere, i, 0, b);
  }
  for (size_t i = 0; i < scene.boxes.size(); ++i) {
    const auto& s = scene.boxes[i];
    NERFAR_CHECK_LT(s.material, materials);
    const float c = std::cos(s.yaw_rad), sn = std::sin(s.yaw_rad);
    Box3 b;
    for (int k = 0; k < 8; ++k) {
      const Vec3f corner{(k & 1) ? s.half_size.x : -s.half_size.x, (k & 2) ? s.half_size.y : -s.half_size.y,
                         (k & 4) ? s.half_size.z : -s.half_size.z};
      b.Grow(s.center + RotateZ(corner, c, sn));
    }
    add(Kind::kBox, i, 0, b);
  }
  for (size_t i = 0; i < scene.cylinders.size(); ++i) {
    const auto& s = scene.cylinders[i];
    NERFAR_CHECK_LT(s.material, materials);
    Box3 b;
    b.Grow(s.base_center - Vec3f{s.radius, s.radius, 0});
    b.Grow(s.base_center + Vec3f{s.radius, s.radius, s.height});
    add(Kind::kCylinder, i, 0, b);
  }
  for (size_t i = 0; i < scene.rectangles.size(); ++i) {
    const auto& s = scene.rectangles[i];
    NERFAR_CHECK_LT(s.material, materials);
    Box3 b;
    for (int k = 0; k < 4; ++k)
      b.Grow(s.center + s.u_axis * ((k & 1) ? s.half_u : -s.half_u) + s.v_axis * ((k & 2) ? s.half_v : -s.half_v));
    add(Kind::kRectangle, i, 0, b);
  }
  for (size_t i = 0; i < scene.meshes.size(); ++i) {
    const auto& m = scene.meshes[i];
    NERFAR_CHECK_LT(m.material, materials);
    NERFAR_CHECK(m.normals.empty() || m.normals.size() == m.positions.size());
    for (size_t t = 0; t < m.triangles.size(); ++t) {
      Box3 b;
      for (uint32_t v : m.triangles[t]) {
        NERFAR_CHECK_LT(v, m.positions.size());
        b.Grow(m.positions[v]);
      }
      add(Kind::kTriangle, i, t, b);
    }
  }
  for (Box3& b : bounds) {
    b.lo -= Vec3f{1e-6f, 1e-6f, 1e-6f};
    b.hi += Vec3f{1e-6f, 1e-6f, 1e-6f};
  }
}

constexpr int kSahBins = 12;
constexpr uint32_t kMaxLeafSize = 4;      // more primitives than this: try an SAH split
constexpr uint32_t kMedianSplitSize = 8;  // more than this and no SAH split helps: split at the median

// A split of a node's primitives: by centroid along axis, below position to the left.
struct Split {
  int axis = -1;  // -1: none is cheaper than the leaf
  float position = 0;
};

// The binned SAH split of primitives order[begin, end) (box: their bounds, centroids: their
// centroids' bounds) that is cheaper than a leaf, if there is one.
Split FindSahSplit(const std::vector<Box3>& bounds, const std::vector<uint32_t>& order, uint32_t begin, uint32_t end,
                   const Box3& box, const Box3& centroids) {
  Split best;
  float best_cost = static_cast<float>(end - begin) * box.Area();
  for (int axis = 0; axis < 3; ++axis) {
    const float lo = centroids.lo[axis], hi = centroids.hi[axis];
    if (!(hi > lo)) continue;
    Box3 bin_box[kSahBins];
    int bin_count[kSahBins] = {};
    const float scale = kSahBins / (hi - lo);
    for (uint32_t i = begin; i < end; ++i) {
      const int bin = std::min(kSahBins - 1, static_cast<int>((bounds[order[i]].Center()[axis] - lo) * scale));
      bin_box[bin].Grow(bounds[order[i]]);
      ++bin_count[bin];
    }
    float right_area[kSahBins];
    int right_count[kSahBins];
    Box3 acc;
    int n = 0;
    for (int b = kSahBins - 1; b > 0; --b) {
      acc.Grow(bin_box[b]);
      n += bin_count[b];
      right_area[b] = acc.Area();
      right_count[b] = n;
    }
    acc = Box3();
    n = 0;
    for (int b = 0; b < kSahBins - 1; ++b) {
      acc.Grow(bin_box[b]);
      n += bin_count[b];
      if (n == 0 || right_count[b + 1] == 0) continue;
      const float cost = 0.5f * box.Area() + n * acc.Area() + right_count[b + 1] * right_area[b + 1];
      if (cost < best_cost) {
        best_cost = cost;
        best.axis = axis;
        best.position = lo + (b + 1) / scale;
      }
    }
  }
  return best;
}

// The bounding-volume hierarchy over the primitives' boxes (binned SAH, iterative): the nodes
// (root first; an inner node's children are adjacent) and the primitive order its leaves index.
void BuildBvh(const std::vector<Box3>& bounds, std::vector<Node>& nodes, std::vector<uint32_t>& order) {
  order.resize(bounds.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<uint32_t>(i);
  nodes.reserve(2 * bounds.size() + 1);
  nodes.push_back({});
  struct Task {
    uint32_t node, begin, end;
  };
  std::vector<Task> stack;
  if (!bounds.empty()) stack.push_back({0, 0, static_cast<uint32_t>(bounds.size())});
  // Node `task.node` becomes inner with children over [begin, mid) and [mid, end).
  auto split_at = [&](const Task& task, uint32_t mid) {
    const uint32_t left = static_cast<uint32_t>(nodes.size());
    nodes[task.node].first = left;
    nodes[task.node].count = 0;
    nodes.push_back({});
    nodes.push_back({});
    stack.push_back({left, task.begin, mid});
    stack.push_back({left + 1, mid, task.end});
  };
  while (!stack.empty()) {
    const Task task = stack.back();
    stack.pop_back();
    Box3 box, centroids;
    for (uint32_t i = task.begin; i < task.end; ++i) {
      box.Grow(bounds[order[i]]);
      centroids.Grow(bounds[order[i]].Center());
    }
    Node& node = nodes[task.node];
    node.box = box;
    const uint32_t count = task.end - task.begin;
    const Split split =
        count > kMaxLeafSize ? FindSahSplit(bounds, order, task.begin, task.end, box, centroids) : Split{};
    if (split.axis >= 0) {
      auto mid_it = std::partition(order.begin() + task.begin, order.begin() + task.end,
                                   [&](uint32_t p) { return bounds[p].Center()[split.axis] < split.position; });
      const uint32_t mid = static_cast<uint32_t>(mid_it - order.begin());
      NERFAR_CHECK(mid > task.begin && mid < task.end);
      split_at(task, mid);
    } else if (count > kMedianSplitSize) {
      // No useful SAH split: a median split along the centroids' longest axis keeps leaves small.
      int axis = 0;
      const Vec3f ext = centroids.hi - centroids.lo;
      if (ext.y > ext.x) axis = 1;
      if (ext.z > ext[axis]) axis = 2;
      const uint32_t mid = task.begin + count / 2;
      std::nth_element(order.begin() + task.begin, order.begin() + mid, order.begin() + task.end,
                       [&](uint32_t a, uint32_t b) { return bounds[a].Center()[axis] < bounds[b].Center()[axis]; });
      split_at(task, mid);
    } else {
      node.first = task.begin;
      node.count = count;
    }
  }
}

// The environment's sampling table over w x h cells of the equirect square.
EnvSampling BuildEnvSampling(const Scene& scene, int w, int h) {
  std::vector<double> weights(static_cast<size_t>(w) * h);
  double total = 0;
  for (int j = 0; j < h; ++j) {
    const double sin_theta = std::sin(kPi * (j + 0.5) / h);
    for (int i = 0; i < w; ++i) {
      // Max over a 2x2 sub-grid so small bright features are not missed.
      double lum = 0;
      for (int s = 0; s < 4; ++s) {
        const Vec3 d = EquirectDirection((i + 0.25 + 0.5 * (s & 1)) / w, (j + 0.25 + 0.5 * (s >> 1)) / h);
        const Vec3f l = scene.EnvironmentRadiance(Vec3f(d));
        lum = std::max(lum, 0.2126 * l.x + 0.7152 * l.y + 0.0722 * l.z);
      }
      weights[static_cast<size_t>(j) * w + i] = lum * sin_theta;
      total += lum * sin_theta;
    }
  }
  // Floor: 20% of the mean, spread like sin(theta), so surfaces that only see the
  // dim sky (not a bright window) still get samples of it.
  const double floor_w = 0.2 * std::max(total, 1e-12) / (static_cast<double>(w) * h);
  total = 0;
  for (int j = 0; j < h; ++j) {
    const double sin_theta = std::sin(kPi * (j + 0.5) / h);
    for (int i = 0; i < w; ++i) {
      double& x = weights[static_cast<size_t>(j) * w + i];
      x += floor_w * sin_theta;
      total += x;
    }
  }
  EnvSampling a;
  a.w = w;
  a.h = h;
  a.row_cdf.assign(h + 1, 0);
  a.col_cdf.assign(static_cast<size_t>(h) * (w + 1), 0);
  a.row_mass.assign(h, 0);
  a.cell_pdf.assign(static_cast<size_t>(w) * h, 0);
  double row_acc = 0;
  for (int j = 0; j < h; ++j) {
    double row_sum = 0;
    for (int i = 0; i < w; ++i) row_sum += weights[static_cast<size_t>(j) * w + i];
    double col_acc = 0;
    for (int i = 0; i < w; ++i) {
      const double x = weights[static_cast<size_t>(j) * w + i];
      col_acc += x;
      a.col_cdf[static_cast<size_t>(j) * (w + 1) + i + 1] = static_cast<float>(col_acc / row_sum);
      a.cell_pdf[static_cast<size_t>(j) * w + i] = static_cast<float>(x / total);
    }
    a.col_cdf[static_cast<size_t>(j) * (w + 1) + w] = 1.0f;
    row_acc += row_sum;
    a.row_mass[j] = static_cast<float>(row_sum / total);
    a.row_cdf[j + 1] = static_cast<float>(row_acc / total);
  }
  a.row_cdf[h] = 1.0f;
  return a;
}

}  // namespace

void Scene::Build() {
  for (const auto& m : materials) NERFAR_CHECK_LT(m.texture, static_cast<int>(textures.size()));
  auto accel = std::make_unique<Accel>();
  std::vector<Box3> bounds;
  CollectPrimitives(*this, accel->prims, bounds);
  std::vector<uint32_t> order;
  BuildBvh(bounds, accel->nodes, order);
  std::vector<Prim> ordered(order.size());
  for (size_t i = 0; i < order.size(); ++i) ordered[i] = accel->prims[order[i]];
  accel->prims.swap(ordered);
  if (accel->prims.empty()) accel->nodes[0].box = Box3();
  // The sampling table: 512 x 256 cells (the window scene's sky map has as many texels).
  if (environment.Present()) accel->env = BuildEnvSampling(*this, 512, 256);
  accel_ = std::move(accel);
}

namespace {

// Full hit details for primitive `p` at distance t.
void FillHit(const Scene& scene, const Prim& p, const Ray& ray, float t, float bu, float bv, Hit& hit) {
  hit.t = t;
  hit.point = ray.origin + ray.dir * t;
  Vec3f gn, sn;
  switch (p.kind) {
    case Kind::kSphere: {
      const auto& s = scene.spheres[p.shape];
      gn = sn = Normalized(hit.point - s.center);
      hit.material = s.material;
      hit.object_id = s.object_id;
      break;
    }
    case Kind::kBox: {
      const auto& s = scene.boxes[p.shape];
      const float c = std::cos(s.yaw_rad), sn_ = std::sin(s.yaw_rad);
      const Vec3f local = RotateZ(hit.point - s.center, c, -sn_);
      // Face: the axis where |local| / half_size is largest.
      int axis = 0;
      float best = -1;
      for (int a = 0; a < 3; ++a) {
        const float r = std::fabs(local[a]) / s.half_size[a];
        if (r > best) best = r, axis = a;
      }
      Vec3f n{0, 0, 0};
      n[axis] = local[axis] > 0 ? 1.0f : -1.0f;
      gn = sn = RotateZ(n, c, sn_);
      hit.material = s.material;
      hit.object_id = s.object_id;
      break;
    }
    case Kind::kCylinder: {
      const auto& s = scene.cylinders[p.shape];
      const Vec3f local = hit.point - s.base_center;
      const float radial = std::sqrt(local.x * local.x + local.y * local.y);
      const float cap_dist = std::min(std::fabs(local.z), std::fabs(local.z - s.height));
      if (std::fabs(radial - s.radius) < cap_dist) {
        gn = Vec3f{local.x, local.y, 0} / std::max(radial, 1e-12f);
      } else {
        gn = Vec3f{0, 0, std::fabs(local.z) < std::fabs(local.z - s.height) ? -1.0f : 1.0f};
      }
      sn = gn;
      hit.material = s.material;
      hit.object_id = s.object_id;
      break;
    }
    case Kind::kRectangle: {
      const auto& s = scene.rectangles[p.shape];
      gn = sn = Cross(s.u_axis, s.v_axis);
      hit.material = s.material;
      hit.object_id = s.object_id;
      break;
    }
    case Kind::kTriangle: {
      const auto& m = scene.meshes[p.shape];
      const auto& tri = m.triangles[p.triangle];
      const Vec3f& a = m.positions[tri[0]];
      gn = Normalized(Cross(m.positions[tri[1]] - a, m.positions[tri[2]] - a));
      if (!m.normals.empty()) {
        sn = Normalized(m.normals[tri[0]] * (1 - bu - bv) + m.normals[tri[1]] * bu + m.normals[tri[2]] * bv);
        if (Dot(sn, sn) == 0) sn = gn;
      } else {
        sn = gn;
      }
      hit.material = m.material;
      hit.object_id = m.object_id;
      break;
    }
  }
  hit.geometric_normal = gn;
  hit.front = Dot(gn, ray.dir) < 0;
  // Shading normal on the side of the viewer; keep it in the same hemisphere as the geometric one.
  const Vec3f facing_gn = hit.front ? gn : -gn;
  if (Dot(sn, facing_gn) < 0) sn = -sn;
  if (!hit.front && p.kind == Kind::kTriangle) sn = -sn;
  if (Dot(sn, facing_gn) <= 0) sn = facing_gn;
  hit.normal = Normalized(sn);
}

// Tests one primitive; on a hit closer than t_max returns its distance (and
// barycentrics for triangles).
bool IntersectPrim(const Scene& scene, const Prim& p, const Ray& ray, float t_max, float& t, float& bu, float& bv) {
  switch (p.kind) {
    case Kind::kSphere: {
      const auto& s = scene.spheres[p.shape];
      return IntersectSphereT(s.center, s.radius, ray, t_max, t);
    }
    case Kind::kBox: {
      const auto& s = scene.boxes[p.shape];
      const float c = std::cos(s.yaw_rad), sn = std::sin(s.yaw_rad);
      const Vec3f o = RotateZ(ray.origin - s.center, c, -sn), d = RotateZ(ray.dir, c, -sn);
      int axis;
      bool exiting;
      return IntersectSlabs(-s.half_size, s.half_size, o, d, ray.t_min, t_max, t, axis, exiting);
    }
    case Kind::kCylinder: {
      const auto& s = scene.cylinders[p.shape];
      const Vec3f o = ray.origin - s.base_center;
      const Vec3f& d = ray.dir;
      float best = t_max;
      bool found = false;
      // Side: (ox + t dx)^2 + (oy + t dy)^2 = r^2.
      const float a = d.x * d.x + d.y * d.y;
      if (a > 1e-12f) {
        const float b = o.x * d.x + o.y * d.y;
        // Stable: distance of the axis from the ray's xy line.
        const float px = o.x - d.x * (b / a), py = o.y - d.y * (b / a);
        const float disc = (s.radius * s.radius - (px * px + py * py)) * a;
        if (disc >= 0) {
          const float q = std::sqrt(disc);
          for (float tc : {(-b - q) / a, (-b + q) / a}) {
            if (tc > ray.t_min && tc < best) {
              const float z = o.z + tc * d.z;
              if (z >= 0 && z <= s.height) {
                best = tc;
                found = true;
                break;
              }
            }
          }
        }
      }
      if (std::fabs(d.z) > 1e-12f) {
        for (float zc : {0.0f, s.height}) {
          const float tc = (zc - o.z) / d.z;
          if (tc > ray.t_min && tc < best) {
            const float x = o.x + tc * d.x, y = o.y + tc * d.y;
            if (x * x + y * y <= s.radius * s.radius) {
              best = tc;
              found = true;
            }
          }
        }
      }
      if (found) t = best;
      return found;
    }
    case Kind::kRectangle: {
      const auto& s = scene.rectangles[p.shape];
      const Vec3f n = Cross(s.u_axis, s.v_axis);
      const float denom = Dot(n, ray.dir);
      if (std::fabs(denom) < 1e-12f) return false;
      const float tc = Dot(s.center - ray.origin, n) / denom;
      if (!(tc > ray.t_min && tc < t_max)) return false;
      const Vec3f q = ray.origin + ray.dir * tc - s.center;
      if (std::fabs(Dot(q, s.u_axis)) > s.half_u || std::fabs(Dot(q, s.v_axis)) > s.half_v) return false;
      t = tc;
      return true;
    }
    case Kind::kTriangle: {
      const auto& m = scene.meshes[p.shape];
      const auto& tri = m.triangles[p.triangle];
      const Vec3f& v0 = m.positions[tri[0]];
      const Vec3f e1 = m.positions[tri[1]] - v0, e2 = m.positions[tri[2]] - v0;
      const Vec3f pv = Cross(ray.dir, e2);
      const float det = Dot(e1, pv);
      if (std::fabs(det) < 1e-14f) return false;
      const float inv = 1.0f / det;
      const Vec3f tv = ray.origin - v0;
      const float u = Dot(tv, pv) * inv;
      if (u < 0 || u > 1) return false;
      const Vec3f qv = Cross(tv, e1);
      const float v = Dot(ray.dir, qv) * inv;
      if (v < 0 || u + v > 1) return false;
      const float tc = Dot(e2, qv) * inv;
      if (!(tc > ray.t_min && tc < t_max)) return false;
      t = tc;
      bu = u;
      bv = v;
      return true;
    }
  }
  return false;
}

template <bool kAnyHit>
bool Traverse(const Scene& scene, const std::vector<Node>& nodes, const std::vector<Prim>& prims, const Ray& ray,
              int& hit_prim, float& hit_t, float& hit_u, float& hit_v) {
  if (prims.empty()) return false;
  const Vec3f inv_d{1.0f / ray.dir.x, 1.0f / ray.dir.y, 1.0f / ray.dir.z};
  float t_max = ray.t_max;
  bool found = false;
  uint32_t stack[64];
  int top = 0;
  float t_entry;
  if (!BoxOverlapsRay(nodes[0].box, ray.origin, inv_d, ray.t_min, t_max, t_entry)) return false;
  stack[top++] = 0;
  while (top > 0) {
    const Node& node = nodes[stack[--top]];
    if (node.count > 0) {
      for (uint32_t i = node.first; i < node.first + node.count; ++i) {
        float t, u = 0, v = 0;
        if (IntersectPrim(scene, prims[i], ray, t_max, t, u, v)) {
          if (kAnyHit) return true;
          found = true;
          t_max = t;
          hit_prim = static_cast<int>(i);
          hit_t = t;
          hit_u = u;
          hit_v = v;
        }
      }
      continue;
    }
    float t_left, t_right;
    const bool hit_left = BoxOverlapsRay(nodes[node.first].box, ray.origin, inv_d, ray.t_min, t_max, t_left);
    const bool hit_right = BoxOverlapsRay(nodes[node.first + 1].box, ray.origin, inv_d, ray.t_min, t_max, t_right);
    NERFAR_CHECK_LT(top, 62);
    if (hit_left && hit_right) {
      // Visit the nearer child first.
      if (t_left <= t_right) {
        stack[top++] = node.first + 1;
        stack[top++] = node.first;
      } else {
        stack[top++] = node.first;
        stack[top++] = node.first + 1;
      }
    } else if (hit_left) {
      stack[top++] = node.first;
    } else if (hit_right) {
      stack[top++] = node.first + 1;
    }
  }
  return found;
}

}  // namespace

bool Scene::Intersect(const Ray& ray, Hit& hit) const {
  NERFAR_CHECK(built());
  int prim = -1;
  float t = 0, u = 0, v = 0;
  if (!Traverse<false>(*this, accel_->nodes, accel_->prims, ray, prim, t, u, v)) return false;
  FillHit(*this, accel_->prims[prim], ray, t, u, v, hit);
  return true;
}

bool Scene::Occluded(const Ray& ray) const {
  NERFAR_CHECK(built());
  int prim;
  float t, u, v;
  return Traverse<true>(*this, accel_->nodes, accel_->prims, ray, prim, t, u, v);
}

Vec3f Scene::Albedo(const Hit& hit) const {
  const SurfaceMaterial& m = materials[hit.material];
  if (m.texture < 0) return m.albedo;
  const PlanarTexture& tex = textures[m.texture];
  const Vec3f q = hit.point - tex.origin;
  const int w = tex.image.width, h = tex.image.height;
  const int x = std::clamp(static_cast<int>(std::floor(Dot(q, tex.u_axis) / tex.size_u * w)), 0, w - 1);
  const int y = std::clamp(static_cast<int>(std::floor(Dot(q, tex.v_axis) / tex.size_v * h)), 0, h - 1);
  const float* p = tex.image.Pixel(x, y);
  return m.albedo * Vec3f{p[0], p[1], p[2]};
}

Vec3f Scene::Emission(const Hit& hit) const {
  const SurfaceMaterial& m = materials[hit.material];
  if (!hit.front && !m.emits_back) return {0, 0, 0};
  return m.emission;
}

Vec3f Scene::EnvironmentRadiance(const Vec3f& d) const {
  Vec3f sum{0, 0, 0};
  for (const EnvLobe& lobe : environment.lobes) {
    // Exponent <= 0 for unit vectors: never overflows.
    const float e = lobe.sharpness * std::min(0.0f, Dot(d, lobe.axis) - 1.0f);
    sum += lobe.amplitude * std::exp(e);
  }
  if (!environment.map.empty()) {
    double u, v;
    EquirectCoordinates(Vec3(d), u, v);
    const ImageF& map = environment.map;
    const int x = std::clamp(static_cast<int>(u * map.width), 0, map.width - 1);
    const int y = std::clamp(static_cast<int>(v * map.height), 0, map.height - 1);
    const float* p = map.Pixel(x, y);
    sum += Vec3f{p[0], p[1], p[2]};
  }
  return sum;
}

int Scene::LightCount() const {
  return static_cast<int>(sphere_lights.size() + rectangle_lights.size() + box_lights.size()) +
         (environment.Present() ? 1 : 0);
}

LightSample Scene::SampleLight(int index, const Vec3f& x, float u1, float u2, float u3) const {
  LightSample out;
  out.radiance = {0, 0, 0};
  if (index < static_cast<int>(sphere_lights.size())) {
    // Uniform in the cone the sphere subtends: exact solid-angle pdf.
    const SphereLight& l = sphere_lights[index];
    const Vec3f to_c = l.center - x;
    const float d2 = Dot(to_c, to_c), d = std::sqrt(d2);
    if (d <= l.radius) return out;
    const float sin2_max = l.radius * l.radius / d2;
    const float cos_max = std::sqrt(std::max(0.0f, 1.0f - sin2_max));
    const float one_minus_cos_max = sin2_max / (1.0f + cos_max);  // no cancellation for tiny lights
    const float one_minus_cos = u1 * one_minus_cos_max;
    const float cos_t = 1.0f - one_minus_cos;
    const float sin_t = std::sqrt(std::max(0.0f, one_minus_cos * (2.0f - one_minus_cos)));
    const float phi = 2.0f * kPiF * u2;
    const Vec3f w = to_c / d;
    const Vec3f a = std::fabs(w.x) > 0.9f ? Vec3f{0, 1, 0} : Vec3f{1, 0, 0};
    const Vec3f t1 = Normalized(Cross(a, w)), t2 = Cross(w, t1);
    out.wi = Normalized(t1 * (sin_t * std::cos(phi)) + t2 * (sin_t * std::sin(phi)) + w * cos_t);
    // Distance to the near side of the sphere along wi.
    const float b = Dot(out.wi, to_c);
    const float disc = std::max(0.0f, l.radius * l.radius - (d2 - b * b));
    // The shadow ray stops at the nearest point of the sphere (d - r): near the
    // cone's edge the exact entry distance is ill-conditioned in float and a
    // shadow ray to it can clip the light itself.
    out.distance = std::min(b - std::sqrt(disc), d - l.radius);
    out.radiance = l.radiance;
    out.pdf = 1.0f / (2.0f * kPiF * one_minus_cos_max);
    return out;
  }
  index -= static_cast<int>(sphere_lights.size());
  if (index < static_cast<int>(rectangle_lights.size())) {
    // Uniform over the area, converted to solid angle.
    const RectangleLight& l = rectangle_lights[index];
    const Vec3f p = l.center + l.u_axis * ((2 * u1 - 1) * l.half_u) + l.v_axis * ((2 * u2 - 1) * l.half_v);
    const Vec3f n = Cross(l.u_axis, l.v_axis);
    const Vec3f to_p = p - x;
    const float d2 = Dot(to_p, to_p), d = std::sqrt(d2);
    if (d <= 0) return out;
    out.wi = to_p / d;
    const float cos_l = -Dot(out.wi, n);
    if (cos_l <= 0 && !l.two_sided) return out;
    if (std::fabs(cos_l) < 1e-8f) return out;
    out.distance = d;
    out.radiance = l.radiance;
    out.pdf = d2 / (4 * l.half_u * l.half_v * std::fabs(cos_l));
    return out;
  }
  index -= static_cast<int>(rectangle_lights.size());
  if (index < static_cast<int>(box_lights.size())) {
    // Area sampling over the faces that face x (at most three), by area.
    const BoxLight& l = box_lights[index];
    const float c = std::cos(l.yaw_rad), s = std::sin(l.yaw_rad);
    const Vec3f local = RotateZ(x - l.center, c, -s);
    int faces[3];
    float areas[3], total = 0;
    int n_faces = 0;
    for (int a = 0; a < 3; ++a) {
      if (std::fabs(local[a]) <= l.half_size[a]) continue;
      faces[n_faces] = local[a] > 0 ? a : a + 3;
      const int b = (a + 1) % 3, e = (a + 2) % 3;
      areas[n_faces] = 4 * l.half_size[b] * l.half_size[e];
      total += areas[n_faces++];
    }
    if (n_faces == 0) return out;
    float pick = u3 * total;
    int k = 0;
    while (k < n_faces - 1 && pick >= areas[k]) pick -= areas[k++];
    const int axis = faces[k] % 3;
    const float sign = faces[k] < 3 ? 1.0f : -1.0f;
    const int b = (axis + 1) % 3, e = (axis + 2) % 3;
    Vec3f pl{0, 0, 0}, nl{0, 0, 0};
    pl[axis] = sign * l.half_size[axis];
    pl[b] = (2 * u1 - 1) * l.half_size[b];
    pl[e] = (2 * u2 - 1) * l.half_size[e];
    nl[axis] = sign;
    const Vec3f p = l.center + RotateZ(pl, c, s), n = RotateZ(nl, c, s);
    const Vec3f to_p = p - x;
    const float d2 = Dot(to_p, to_p), d = std::sqrt(d2);
    out.wi = to_p / d;
    const float cos_l = -Dot(out.wi, n);
    if (cos_l <= 1e-8f) return out;
    out.distance = d;
    out.radiance = l.radiance;
    out.pdf = d2 / (total * cos_l);
    return out;
  }
  // Environment: piecewise-constant over the equirect (u, v) square.
  const EnvSampling& a = accel_->env;
  const int h = a.h, w = a.w;
  int row = static_cast<int>(std::upper_bound(a.row_cdf.begin(), a.row_cdf.end(), u1) - a.row_cdf.begin()) - 1;
  row = std::clamp(row, 0, h - 1);
  while (row < h - 1 && a.row_mass[row] <= 0) ++row;
  const float row_lo = a.row_cdf[row], row_mass = std::max(a.row_mass[row], 1e-30f);
  const float fv = std::clamp((u1 - row_lo) / row_mass, 0.0f, 1.0f);
  const float* cdf = a.col_cdf.data() + static_cast<size_t>(row) * (w + 1);
  int col = static_cast<int>(std::upper_bound(cdf, cdf + w + 1, u2) - cdf) - 1;
  col = std::clamp(col, 0, w - 1);
  const float col_mass = std::max(cdf[col + 1] - cdf[col], 1e-30f);
  const float fu = std::clamp((u2 - cdf[col]) / col_mass, 0.0f, 1.0f);
  const double u = (col + fu) / w, v = (row + fv) / h;
  const Vec3 d = EquirectDirection(u, v);
  const double sin_theta = std::sin(kPi * v);
  if (sin_theta <= 1e-7) return out;
  const double pdf_uv = static_cast<double>(a.cell_pdf[static_cast<size_t>(row) * w + col]) * w * h;
  out.wi = Vec3f(d);
  out.distance = kInf;
  out.radiance = EnvironmentRadiance(out.wi);
  out.pdf = static_cast<float>(pdf_uv / (2.0 * kPi * kPi * sin_theta));
  return out;
}

}  // namespace nerfar::synth
