#include "render/insert/rasterizer.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>

#include "calib/core/error.h"
#include "calib/core/parallel.h"

namespace nerfar {

PixelRect Union(const PixelRect& a, const PixelRect& b) {
  if (a.empty()) return b;
  if (b.empty()) return a;
  return {std::min(a.x0, b.x0), std::min(a.y0, b.y0), std::max(a.x1, b.x1), std::max(a.y1, b.y1)};
}

PixelRect ClipToImage(const PixelRect& r, int width, int height) {
  PixelRect c{std::max(r.x0, 0), std::max(r.y0, 0), std::min(r.x1, width), std::min(r.y1, height)};
  if (c.empty()) return {};
  return c;
}

Vec3f CameraRayDirection(const CameraIntrinsics& camera, const Pose& T_world_camera, int x, int y) {
  const Vec3 d_camera{(x + 0.5 - camera.cx) / camera.fx, (y + 0.5 - camera.cy) / camera.fy, 1.0};
  return Vec3f(Normalized(T_world_camera.Rotate(d_camera)));
}

PixelRect ProjectBall(const CameraIntrinsics& camera, const Pose& T_world_camera, const Vec3& center, double radius) {
  const PixelRect full{0, 0, camera.width, camera.height};
  const Vec3 c = T_world_camera.Inverse() * center;
  if (!std::isfinite(c.x) || !std::isfinite(c.y) || !std::isfinite(c.z) || !std::isfinite(radius)) return {};
  if (c.z + radius <= 0.0) return {};     // wholly behind the camera
  if (c.z - radius <= 1e-3) return full;  // reaches the camera plane: anything may be covered
  // The ball's bounding box lies in front of the camera, so the hull of its
  // projected corners holds the ball's projection.
  double x_min = std::numeric_limits<double>::infinity(), y_min = x_min;
  double x_max = -x_min, y_max = -x_min;
  for (int i = 0; i < 8; ++i) {
    const Vec3 p{c.x + ((i & 1) ? radius : -radius), c.y + ((i & 2) ? radius : -radius),
                 c.z + ((i & 4) ? radius : -radius)};
    const double u = camera.fx * p.x / p.z + camera.cx, v = camera.fy * p.y / p.z + camera.cy;
    x_min = std::min(x_min, u);
    x_max = std::max(x_max, u);
    y_min = std::min(y_min, v);
    y_max = std::max(y_max, v);
  }
  const double big = 4.0 * (camera.width + camera.height);
  const auto to_int = [big](double v) { return static_cast<int>(std::clamp(v, -big, big)); };
  PixelRect r{to_int(std::floor(x_min)), to_int(std::floor(y_min)), to_int(std::ceil(x_max)) + 1,
              to_int(std::ceil(y_max)) + 1};
  return ClipToImage(r, camera.width, camera.height);
}

namespace {

// A vertex of a near-clipped triangle: camera-frame position and its
// barycentric coordinates in the original triangle (for attributes).
struct ClipVertex {
  Vec3 p;
  Vec3 bary;
};

// A screen triangle ready to scan: projected corners, 1/z, and the original
// barycentrics of each corner.
struct ScreenTriangle {
  double sx[3], sy[3], inv_z[3];
  Vec3 bary[3];
  int32_t object;
  uint32_t triangle;
  PixelRect box;
};

// Sutherland-Hodgman against z >= z_near; up to 4 vertices out.
int ClipNear(const ClipVertex in[3], double z_near, ClipVertex out[4]) {
  int n = 0;
  for (int i = 0; i < 3; ++i) {
    const ClipVertex& a = in[i];
    const ClipVertex& b = in[(i + 1) % 3];
    const bool a_in = a.p.z >= z_near, b_in = b.p.z >= z_near;
    if (a_in) out[n++] = a;
    if (a_in != b_in) {
      const double s = (z_near - a.p.z) / (b.p.z - a.p.z);
      out[n++] = {a.p + (b.p - a.p) * s, a.bary + (b.bary - a.bary) * s};
    }
  }
  return n;
}

}  // namespace

namespace {

// Near-clips and projects every triangle; `rect` grows to cover their pixel
// boxes (each grown by a pixel with coverage: sub-samples of the pixels
// beside a triangle can fall inside it).
std::vector<ScreenTriangle> SetUpTriangles(const CameraIntrinsics& camera, const Pose& T_camera_world,
                                           const std::vector<RasterObject>& objects, const RasterOptions& options,
                                           bool coverage, PixelRect& rect) {
  const PixelRect image{0, 0, camera.width, camera.height};
  std::vector<ScreenTriangle> tris;
  std::vector<Vec3> pc;
  for (size_t o = 0; o < objects.size(); ++o) {
    const TriangleMesh* mesh = objects[o].mesh;
    if (mesh == nullptr) continue;
    const Pose T_camera_object = T_camera_world * objects[o].T_world_object;
    pc.resize(mesh->positions.size());
    for (size_t v = 0; v < pc.size(); ++v) pc[v] = T_camera_object * (Vec3(mesh->positions[v]) * objects[o].scale);
    for (uint32_t t = 0; t < mesh->triangles.size(); ++t) {
      const auto& idx = mesh->triangles[t];
      if (idx[0] >= pc.size() || idx[1] >= pc.size() || idx[2] >= pc.size()) continue;
      ClipVertex in[3] = {{pc[idx[0]], {1, 0, 0}}, {pc[idx[1]], {0, 1, 0}}, {pc[idx[2]], {0, 0, 1}}};
      bool finite = true;
      for (const auto& v : in) finite = finite && std::isfinite(v.p.x) && std::isfinite(v.p.y) && std::isfinite(v.p.z);
      if (!finite) continue;
      if (in[0].p.z < options.z_near_m && in[1].p.z < options.z_near_m && in[2].p.z < options.z_near_m) continue;
      ClipVertex poly[4];
      const int n = ClipNear(in, options.z_near_m, poly);
      for (int k = 1; k + 1 < n; ++k) {
        const ClipVertex* corner[3] = {&poly[0], &poly[k], &poly[k + 1]};
        ScreenTriangle s;
        s.object = static_cast<int32_t>(o);
        s.triangle = t;
        double x_min = std::numeric_limits<double>::infinity(), y_min = x_min, x_max = -x_min, y_max = -x_min;
        for (int c = 0; c < 3; ++c) {
          const Vec3& p = corner[c]->p;
          s.inv_z[c] = 1.0 / p.z;
          s.sx[c] = camera.fx * p.x * s.inv_z[c] + camera.cx;
          s.sy[c] = camera.fy * p.y * s.inv_z[c] + camera.cy;
          s.bary[c] = corner[c]->bary;
          x_min = std::min(x_min, s.sx[c]);
          x_max = std::max(x_max, s.sx[c]);
          y_min = std::min(y_min, s.sy[c]);
          y_max = std::max(y_max, s.sy[c]);
        }
        const double area = (s.sx[1] - s.sx[0]) * (s.sy[2] - s.sy[0]) - (s.sx[2] - s.sx[0]) * (s.sy[1] - s.sy[0]);
        if (!(std::abs(area) > 1e-12) || !std::isfinite(area)) continue;
        // Pixels whose centre (i + 0.5) can fall inside [min, max].
        const double big = 4.0 * (camera.width + camera.height);
        const auto clampi = [big](double v) { return static_cast<int>(std::clamp(v, -big, big)); };
        const int grow = coverage ? 1 : 0;
        s.box = ClipToImage({clampi(std::ceil(x_min - 0.5)) - grow, clampi(std::ceil(y_min - 0.5)) - grow,
                             clampi(std::floor(x_max - 0.5)) + 1 + grow, clampi(std::floor(y_max - 0.5)) + 1 + grow},
                            image.x1, image.y1);
        if (s.box.empty()) continue;
        rect = Union(rect, s.box);
        tris.push_back(s);
      }
    }
  }
  return tris;
}

// The depth buffer and what the scan writes besides the G-buffer.
struct ScanBuffers {
  ObjectGBuffer& g;
  std::vector<float>& z_buffer;
  std::vector<uint16_t>& cover_bits;  // sub-samples inside any triangle (coverage only)
  int grid;                           // sub-samples per axis (coverage only)
  uint16_t full_bits;
};

// One triangle over the pixels of rows [y0, y1): coverage bits, then the
// depth test and the nearest triangle's id and original barycentrics.
void ScanTriangle(const ScreenTriangle& s, int y0, int y1, bool coverage, ScanBuffers& b) {
  ObjectGBuffer& g = b.g;
  const double area2 = (s.sx[1] - s.sx[0]) * (s.sy[2] - s.sy[0]) - (s.sx[2] - s.sx[0]) * (s.sy[1] - s.sy[0]);
  const double inv_area = 1.0 / area2;
  // d l0/dx, d l0/dy, d l1/dx, d l1/dy (for the coverage sub-samples).
  const double dl0x = (s.sy[1] - s.sy[2]) * inv_area, dl0y = (s.sx[2] - s.sx[1]) * inv_area;
  const double dl1x = (s.sy[2] - s.sy[0]) * inv_area, dl1y = (s.sx[0] - s.sx[2]) * inv_area;
  const double reach0 = 0.5 * (std::abs(dl0x) + std::abs(dl0y)), reach1 = 0.5 * (std::abs(dl1x) + std::abs(dl1y));
  const double reach2 = 0.5 * (std::abs(dl0x + dl1x) + std::abs(dl0y + dl1y));
  const int grid = b.grid;
  for (int y = y0; y < y1; ++y) {
    const double py = y + 0.5;
    // The span of this row where each barycentric can reach its threshold (0,
    // or minus its reach with coverage): l_k is affine in x, so solve for x
    // and widen by a pixel; the exact test below still decides every pixel,
    // the span only skips the box's pixels that cannot pass it.
    double span_lo = s.box.x0, span_hi = s.box.x1 - 1;
    {
      const double px0 = s.box.x0 + 0.5;
      const double a0 = ((s.sx[1] - px0) * (s.sy[2] - py) - (s.sx[2] - px0) * (s.sy[1] - py)) * inv_area;
      const double a1 = ((s.sx[2] - px0) * (s.sy[0] - py) - (s.sx[0] - px0) * (s.sy[2] - py)) * inv_area;
      const double value[3] = {a0, a1, 1.0 - a0 - a1}, slope[3] = {dl0x, dl1x, -dl0x - dl1x};
      const double margin[3] = {coverage ? reach0 : 0.0, coverage ? reach1 : 0.0, coverage ? reach2 : 0.0};
      for (int k = 0; k < 3; ++k) {
        const double need = -margin[k] - value[k];  // slope · (x − x0) ≥ need
        if (slope[k] > 1e-12) {
          span_lo = std::max(span_lo, s.box.x0 + need / slope[k] - 1.0);
        } else if (slope[k] < -1e-12) {
          span_hi = std::min(span_hi, s.box.x0 + need / slope[k] + 1.0);
        }
      }
    }
    if (!(span_lo <= span_hi)) continue;
    const int x_first = std::max(s.box.x0, static_cast<int>(std::floor(span_lo)));
    const int x_last = std::min(s.box.x1 - 1, static_cast<int>(std::ceil(span_hi)));
    for (int x = x_first; x <= x_last; ++x) {
      const double px = x + 0.5;
      // Screen-space barycentrics (edge functions over the signed area).
      const double l0 = ((s.sx[1] - px) * (s.sy[2] - py) - (s.sx[2] - px) * (s.sy[1] - py)) * inv_area;
      const double l1 = ((s.sx[2] - px) * (s.sy[0] - py) - (s.sx[0] - px) * (s.sy[2] - py)) * inv_area;
      const double l2 = 1.0 - l0 - l1;
      if (coverage) {
        // The barycentrics are affine in the sample position; a sub-sample is
        // within half a pixel on each axis of the centre, so each changes by
        // at most its reach.
        uint16_t& bits = b.cover_bits[g.Index(x, y)];
        const double lo = std::min({l0 - reach0, l1 - reach1, l2 - reach2});
        const bool none = l0 < -reach0 || l1 < -reach1 || l2 < -reach2;
        if (!none && bits != b.full_bits) {
          if (lo >= 0.0) {
            bits = b.full_bits;
          } else {
            for (int sy = 0; sy < grid; ++sy)
              for (int sx = 0; sx < grid; ++sx) {
                const int bit = sy * grid + sx;
                if (bits & (1u << bit)) continue;
                const double ox = (sx + 0.5) / grid - 0.5, oy = (sy + 0.5) / grid - 0.5;
                const double m0 = l0 + (dl0x * ox + dl0y * oy), m1 = l1 + (dl1x * ox + dl1y * oy);
                if (m0 >= 0.0 && m1 >= 0.0 && 1.0 - m0 - m1 >= 0.0) bits = uint16_t(bits | (1u << bit));
              }
          }
        }
      }
      if (l0 < 0.0 || l1 < 0.0 || l2 < 0.0) continue;
      const double inv_z = l0 * s.inv_z[0] + l1 * s.inv_z[1] + l2 * s.inv_z[2];
      if (!(inv_z > 0.0)) continue;
      const float z = static_cast<float>(1.0 / inv_z);
      const size_t i = g.Index(x, y);
      if (!(z < b.z_buffer[i])) continue;
      // Perspective-correct weights of the clipped corners, then of the original triangle.
      const double w0 = l0 * s.inv_z[0] / inv_z, w1 = l1 * s.inv_z[1] / inv_z, w2 = l2 * s.inv_z[2] / inv_z;
      const Vec3 bary = s.bary[0] * w0 + s.bary[1] * w1 + s.bary[2] * w2;
      b.z_buffer[i] = z;
      g.object[i] = s.object;
      g.triangle[i] = s.triangle;
      g.bary[i] = {static_cast<float>(bary.y), static_cast<float>(bary.z)};
    }
  }
}

// An object's mesh in the world: per vertex positions and normals
// (unnormalised, empty without normals), per triangle face normals;
// computed once per object, not re-transformed per pixel.
struct WorldMesh {
  std::vector<Vec3f> position, normal, face;
};

std::vector<WorldMesh> WorldMeshes(const std::vector<RasterObject>& objects) {
  std::vector<WorldMesh> world(objects.size());
  for (size_t o = 0; o < objects.size(); ++o) {
    const TriangleMesh* mesh = objects[o].mesh;
    if (mesh == nullptr) continue;
    const RasterObject& obj = objects[o];
    WorldMesh& w = world[o];
    w.position.resize(mesh->positions.size());
    for (size_t v = 0; v < w.position.size(); ++v)
      w.position[v] = Vec3f(obj.T_world_object * (Vec3(mesh->positions[v]) * obj.scale));
    if (mesh->normals.size() == mesh->positions.size()) {
      w.normal.resize(mesh->normals.size());
      for (size_t v = 0; v < w.normal.size(); ++v)
        w.normal[v] = Vec3f(obj.T_world_object.Rotate(Vec3(mesh->normals[v])));
    }
    w.face.resize(mesh->triangles.size());
    for (size_t t = 0; t < w.face.size(); ++t) {
      const auto& idx = mesh->triangles[t];
      if (idx[0] >= w.position.size() || idx[1] >= w.position.size() || idx[2] >= w.position.size()) continue;
      const Vec3 face = Cross(Vec3(mesh->positions[idx[1]] - mesh->positions[idx[0]]),
                              Vec3(mesh->positions[idx[2]] - mesh->positions[idx[0]]));
      w.face[t] = Vec3f(obj.T_world_object.Rotate(face));
    }
  }
  return world;
}

// Attributes once per covered pixel of row y, interpolated from the world
// meshes with the pixel's barycentrics; returns the row's covered pixels.
size_t ResolveRow(const CameraIntrinsics& camera, const Vec3f& eye, const std::vector<RasterObject>& objects,
                  const std::vector<WorldMesh>& world, const std::vector<float>& z_buffer, int y, ObjectGBuffer& g) {
  size_t covered = 0;
  const double v = (y + 0.5 - camera.cy) / camera.fy;
  for (int x = g.rect.x0; x < g.rect.x1; ++x) {
    const size_t i = g.Index(x, y);
    const int32_t o = g.object[i];
    if (o < 0) continue;
    ++covered;
    const TriangleMesh& mesh = *objects[o].mesh;
    const WorldMesh& w = world[o];
    const auto& idx = mesh.triangles[g.triangle[i]];
    const float b1 = g.bary[i][0], b2 = g.bary[i][1], b0 = 1.0f - b1 - b2;
    g.position[i] = w.position[idx[0]] * b0 + w.position[idx[1]] * b1 + w.position[idx[2]] * b2;
    // t = z / cos(angle to the optical axis) = z · |(u, v, 1)|.
    const double u = (x + 0.5 - camera.cx) / camera.fx;
    g.t[i] = static_cast<float>(z_buffer[i] * std::sqrt(u * u + v * v + 1.0));
    const Vec3f face = w.face[g.triangle[i]];
    Vec3f n;
    if (!w.normal.empty()) n = w.normal[idx[0]] * b0 + w.normal[idx[1]] * b1 + w.normal[idx[2]] * b2;
    if (!(Dot(n, n) > 1e-20f)) n = face;
    n = Normalized(n);
    // A back face seen (open meshes, inner faces): shade the side the camera sees.
    if (Dot(face, g.position[i] - eye) > 0.0f) n = n * -1.0f;
    g.normal[i] = n;
    if (mesh.uvs.size() == mesh.positions.size()) {
      for (int c = 0; c < 2; ++c)
        g.uv[i][c] = mesh.uvs[idx[0]][c] * b0 + mesh.uvs[idx[1]][c] * b1 + mesh.uvs[idx[2]][c] * b2;
    }
  }
  return covered;
}

}  // namespace

ObjectGBuffer Rasterize(const CameraIntrinsics& camera, const Pose& T_world_camera,
                        const std::vector<RasterObject>& objects, const RasterOptions& options) {
  ObjectGBuffer g;
  const int grid = std::clamp(options.coverage_grid, 0, 4);
  const bool coverage = grid > 1;
  // Set-up: near-clip and project every triangle; their boxes give the rect.
  const std::vector<ScreenTriangle> tris =
      SetUpTriangles(camera, T_world_camera.Inverse(), objects, options, coverage, g.rect);
  if (g.rect.empty()) return g;

  const size_t area = g.rect.area();
  g.object.assign(area, -1);
  g.t.assign(area, 0.0f);
  g.position.assign(area, Vec3f{});
  g.normal.assign(area, Vec3f{});
  g.uv.assign(area, {0.0f, 0.0f});
  std::vector<float> z_buffer(area, std::numeric_limits<float>::infinity());
  std::vector<uint16_t> cover_bits(coverage ? area : 0, 0);
  g.triangle.assign(area, 0);
  g.bary.assign(area, {0.0f, 0.0f});  // original barycentrics b1, b2
  ScanBuffers buffers{g, z_buffer, cover_bits, grid, static_cast<uint16_t>((1u << (grid * grid)) - 1u)};

  // Scan in bands of rows so that threads never share a pixel.
  constexpr int kBand = 8;
  const int bands = (g.rect.height() + kBand - 1) / kBand;
  ParallelFor(
      static_cast<size_t>(bands),
      [&](size_t band) {
        const int y_begin = g.rect.y0 + static_cast<int>(band) * kBand;
        const int y_end = std::min(g.rect.y1, y_begin + kBand);
        for (const ScreenTriangle& s : tris) {
          if (s.box.y1 <= y_begin || s.box.y0 >= y_end) continue;
          const int y0 = std::max(y_begin, s.box.y0), y1 = std::min(y_end, s.box.y1);
          ScanTriangle(s, y0, y1, coverage, buffers);
        }
      },
      1);

  // Resolve: attributes once per covered pixel.
  const std::vector<WorldMesh> world = WorldMeshes(objects);
  const Vec3f eye(T_world_camera.translation);
  std::vector<size_t> covered_per_row(static_cast<size_t>(g.rect.height()), 0);
  ParallelFor(
      static_cast<size_t>(g.rect.height()),
      [&](size_t row) {
        covered_per_row[row] = ResolveRow(camera, eye, objects, world, z_buffer, g.rect.y0 + static_cast<int>(row), g);
      },
      4);
  for (size_t c : covered_per_row) g.covered += c;
  if (coverage) {
    g.coverage.resize(area);
    const float per_sample = 1.0f / static_cast<float>(grid * grid);
    for (size_t i = 0; i < area; ++i) g.coverage[i] = static_cast<float>(std::popcount(cover_bits[i])) * per_sample;
  }
  return g;
}

}  // namespace nerfar
