#include "render/insert/object_shading.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

#include "calib/core/parallel.h"
#include "render/insert/shadow_terms.h"
#include "render/lighting/incident_light.h"

namespace nerfar {

namespace {

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

}  // namespace

DistanceMap ReflectionDistances(const std::vector<Vec3>& directions, const std::vector<float>& opacity,
                                const std::vector<float>& depth, const std::vector<Vec3>& near_radiance,
                                const SgMixture* light) {
  const std::vector<double> inverse =
      NearInverseDistances(light != nullptr ? *light : SgMixture{}, directions, opacity, depth, near_radiance);
  std::vector<float> distance(inverse.size(), std::numeric_limits<float>::infinity());
  for (size_t i = 0; i < inverse.size(); ++i)
    if (inverse[i] > 0.0) distance[i] = static_cast<float>(1.0 / inverse[i]);
  return DistanceMap(std::vector<Vec3>(directions.begin(), directions.begin() + inverse.size()), distance);
}

namespace {

// The call's inputs, shared by every chunk.
struct ShadeInputs {
  const std::vector<InsertObject>& objects;
  const std::vector<WorldSphere>& spheres;
  const std::vector<LightPrep>& preps;
  const std::vector<VertexGamma>* vertex_gamma;
  const std::vector<std::vector<Vec3f>>& vertex_normals;
  const InsertOptions& options;
  const ObjectGBuffer& g;
  const Vec3f& eye;
  const std::vector<PrefilteredRadiance>& specular;
  const PrefilteredRadiance* Map(int32_t o) const {
    return size_t(o) < specular.size() && !specular[o].empty() ? &specular[o] : nullptr;
  }
};

// The smooth part of a pixel's radiance under a prefiltered map: the diffuse
// radiance for a white base colour (times the pixel's base colour gives the
// diffuse term) and the specular's self-shadow ratio V (times the map's
// specular gives the specular term).
// On the grid path also the map's specular split by F0 (ShadeSpecularParts:
// specular = V · (F0 ⊙ s + b)) where `has_specular`.
struct DiffuseAndVisibility {
  float d[3] = {0, 0, 0};
  float visibility = 1;
  float s[3] = {0, 0, 0}, b[3] = {0, 0, 0};
  bool has_specular = false;
};

// Per-chunk buffers (reused across the runs of a chunk).
struct RunScratch {
  std::vector<float> ssd, ssd_min, gamma;
  std::vector<SgMaterial> materials;
  std::vector<Vec3f> normals, views, points, rgb, shadowed, specular_rgb, scaled, biased;
  std::vector<uint32_t> pixels;
  // One chunk's pixels by path (ShadeObjects, step 2).
  std::vector<uint32_t> sg_pixels, map_pixels, exact_pixels, composed_pixels;
  std::vector<DiffuseAndVisibility> values, exact_values, composed_values;
  std::vector<size_t> exact_slot;
  std::vector<Vec3f> sg_rgb;
};
// Per thread, kept between chunks and frames (no allocation per chunk).
RunScratch& ThreadScratch() {
  thread_local RunScratch scratch;
  return scratch;
}

// Material, normal, view, world point and, with `gamma`, γ (per vertex
// interpolated, or per pixel from the SSDF fields) of `count` pixels of
// object o.
void GatherRun(const ShadeInputs& in, int32_t o, const uint32_t* pixels, size_t count, RunScratch& s,
               bool gamma = true) {
  const ObjectGBuffer& g = in.g;
  const LightPrep& p = in.preps[o];
  const size_t m = gamma ? p.axes.size() : 0;
  s.gamma.assign(count * m, 1.0f);
  s.materials.clear();
  s.normals.clear();
  s.views.clear();
  s.points.clear();
  const VertexGamma* vg = in.vertex_gamma ? &(*in.vertex_gamma)[o] : nullptr;
  for (size_t k = 0; k < count; ++k) {
    const uint32_t i = pixels[k];
    const Vec3f n = g.normal[i];
    float* gp = s.gamma.data() + k * m;
    const auto& tri = in.objects[o].mesh->triangles[g.triangle[i]];
    const float b1 = g.bary[i][0], b2 = g.bary[i][1], b0 = 1.0f - b1 - b2;
    const std::vector<Vec3f>& vn = in.vertex_normals[o];
    // Per vertex unless the rasteriser flipped the normal (a back face
    // seen): the vertices' γ belong to the other side.
    if (m > 0 && vg && !vg->gamma.empty() && Dot(vn[tri[0]] * b0 + vn[tri[1]] * b1 + vn[tri[2]] * b2, n) > 0.0f) {
      const float* g0 = &vg->gamma[size_t(tri[0]) * m];
      const float* g1 = &vg->gamma[size_t(tri[1]) * m];
      const float* g2 = &vg->gamma[size_t(tri[2]) * m];
      for (size_t l = 0; l < m; ++l) gp[l] = b0 * g0[l] + b1 * g1[l] + b2 * g2[l];
    } else if (m > 0 && in.options.self_shadow) {
      const Vec3f point =
          g.position[i] + n * static_cast<float>(in.options.self_shadow_offset_radii * in.spheres[o].radius);
      s.ssd_min.assign(m, std::numeric_limits<float>::infinity());
      s.ssd.resize(m);
      for (size_t j = 0; j < in.objects.size(); ++j) {
        if (!p.queries[j]) continue;
        p.queries[j]->Ssd(&point, 1, s.ssd.data());
        for (size_t l = 0; l < m; ++l) s.ssd_min[l] = std::min(s.ssd_min[l], s.ssd[l]);
      }
      GammaFromSsd(p.axes, p.gamma_rows, n, s.ssd_min.data(), in.options.self_shadow_horizon, gp);
    }
    s.materials.push_back(PixelMaterial(in.objects[o], g.uv[i]));
    s.normals.push_back(n);
    s.views.push_back(Normalized(in.eye - g.position[i]));
    s.points.push_back(g.position[i]);
  }
}

// Radiance of `count` pixels of object o with SGs alone (no map).
void ShadeRunSg(const ShadeInputs& in, int32_t o, const uint32_t* pixels, size_t count, RunScratch& s, Vec3f* out) {
  GatherRun(in, o, pixels, count, s);
  std::fill(out, out + count, Vec3f{});
  const LightPrep& p = in.preps[o];
  if (p.axes.empty()) return;
  p.shader->Shade(s.materials.data(), s.normals.data(), s.views.data(), s.gamma.data(), static_cast<int>(count), out,
                  SgTerms::kAll);
}

// D and V (DiffuseAndVisibility) of `count` pixels of object o. With a map,
// V is the SG specular's luminance with γ over that without, summed in the
// diffuse pass (the same lobe loop) when any γ of the run is below 1: the
// SG light knows where the lobes are shadowed, the map what they reflect.
// With `specular_parts` also the map's specular parts (the grid's nodes).
void ShadeRunDiffuseAndVisibility(const ShadeInputs& in, int32_t o, const uint32_t* pixels, size_t count, RunScratch& s,
                                  DiffuseAndVisibility* out, bool specular_parts = false) {
  GatherRun(in, o, pixels, count, s);
  for (size_t k = 0; k < count; ++k) out[k] = DiffuseAndVisibility{};
  if (specular_parts) {
    s.scaled.resize(count), s.biased.resize(count);
    in.Map(o)->ShadeSpecularParts(s.materials.data(), s.normals.data(), s.views.data(), s.points.data(), count,
                                  s.scaled.data(), s.biased.data());
    for (size_t k = 0; k < count; ++k) {
      out[k].has_specular = true;
      out[k].s[0] = s.scaled[k].x, out[k].s[1] = s.scaled[k].y, out[k].s[2] = s.scaled[k].z;
      out[k].b[0] = s.biased[k].x, out[k].b[1] = s.biased[k].y, out[k].b[2] = s.biased[k].z;
    }
  }
  const LightPrep& p = in.preps[o];
  if (p.axes.empty()) return;
  for (SgMaterial& material : s.materials) material.base_color = Vec3(1, 1, 1);
  s.rgb.assign(count, Vec3f{});
  const bool any_shadow = std::any_of(s.gamma.begin(), s.gamma.end(), [](float x) { return x < 1.0f; });
  if (any_shadow) {
    s.shadowed.assign(count, Vec3f{});
    p.shader->Shade(s.materials.data(), s.normals.data(), s.views.data(), s.gamma.data(), static_cast<int>(count),
                    s.rgb.data(), SgTerms::kDiffuseAndVisibility, s.shadowed.data());
  } else {
    p.shader->Shade(s.materials.data(), s.normals.data(), s.views.data(), s.gamma.data(), static_cast<int>(count),
                    s.rgb.data(), SgTerms::kDiffuse);
  }
  for (size_t k = 0; k < count; ++k) {
    out[k].d[0] = s.rgb[k].x, out[k].d[1] = s.rgb[k].y, out[k].d[2] = s.rgb[k].z;
    if (any_shadow && s.shadowed[k].y > 0.0f && std::isfinite(s.shadowed[k].y))
      out[k].visibility = std::clamp(s.shadowed[k].x / s.shadowed[k].y, 0.0f, 1.0f);
  }
}

// Calls f(o, first, count) for each run of consecutive entries of `pixels`
// that belong to one object.
template <class F>
void ForEachRun(const ObjectGBuffer& g, const std::vector<uint32_t>& pixels, F&& f) {
  for (size_t run = 0; run < pixels.size();) {
    const int32_t o = g.object[pixels[run]];
    size_t run_end = run + 1;
    while (run_end < pixels.size() && g.object[pixels[run_end]] == o) ++run_end;
    f(o, run, run_end - run);
    run = run_end;
  }
}

void Store(const Vec3f& rgb, size_t px, ImageF& object) {
  const Vec3f value = Finite(rgb) ? rgb : Vec3f{};
  object.pixels[px * 3 + 0] = std::max(value.x, 0.0f);
  object.pixels[px * 3 + 1] = std::max(value.y, 0.0f);
  object.pixels[px * 3 + 2] = std::max(value.z, 0.0f);
}

// ShadeGrid::cell_agrees values (CellAgrees).
constexpr uint8_t kCellDiffuse = 1, kCellSpecular = 2;

// The mirror directions of a cell's four nodes may differ by at most this
// fraction of the GGX α (radians) for the map's specular to be interpolated
// there. The map at roughness r is the radiance blurred by the GGX lobe, whose
// profile in the mirror direction is no narrower than f(θ) ∝ (1 + θ²/α²)^−2
// (|f''| ≤ 4 f_max / α²); bilinear interpolation over a span Δ errs by at
// most Δ²/8 · |f''| = (Δ/α)²/2 · f_max: at 1/3, 5.6 % of the lobe's peak
// (α ≥ 0.49 at the bench's roughness 0.7: nearly every cell; α 0.0625 at
// roughness 0.25: only objects over ~200 px across).
constexpr float kSpecularCellLobes = 1.0f / 3.0f;

// The coarse grid of D and V (InsertOptions::shade_step): nodes every
// `step` pixels of the G-buffer's rectangle, from its corner.
struct ShadeGrid {
  int step = 1, columns = 0, rows = 0;
  std::vector<int32_t> object;  // per node: the object shaded there, −1: none (uncovered or not on the grid path)
  std::vector<DiffuseAndVisibility> values;
  std::vector<float> mean_brightest;  // per object: mean over its nodes of D's brightest channel
  std::vector<float> mean_specular;   // per object: mean over its nodes of the brightest channel of s + b
  std::vector<float> min_cos_reflect;  // per object: kSpecularCellLobes · α as a cosine (−2: no specular on the grid)
  std::vector<Vec3f> normal;           // per node: the G-buffer's normal there
  std::vector<Vec3f> reflect;          // per node: the view's mirror direction there
  std::vector<uint8_t> cell_agrees;    // per cell (columns − 1 per row): CellAgrees
  size_t Node(int column, int row) const { return size_t(row) * size_t(columns) + size_t(column); }
};

// Whether the grid may stand in for a pixel of object o with normal n in
// the cell whose top-left node is (cx, cy), and if so its D and V: the four
// nodes are that object's, their normals within the cell test's angle of
// the pixel's (a pixel of another surface behind, a crease or a fold in
// the cell: shaded exactly), and their D and V agree to shade_refine_delta
// (CellAgrees, once per cell). Bilinear in the pixel's position between
// the nodes.
bool InterpolateFromGrid(const ShadeGrid& grid, const ObjectGBuffer& g, int32_t o, int x, int y, const Vec3f& n,
                         float min_cos, DiffuseAndVisibility* out) {
  const int step = grid.step;
  const int rx = x - g.rect.x0, ry = y - g.rect.y0;
  const int cx = rx / step, cy = ry / step;
  if (cx + 1 >= grid.columns || cy + 1 >= grid.rows) return false;
  const size_t node = grid.Node(cx, cy);
  if (!grid.cell_agrees[size_t(cy) * size_t(grid.columns - 1) + size_t(cx)] || grid.object[node] != o) return false;
  const size_t nodes[4] = {node, node + 1, node + size_t(grid.columns), node + size_t(grid.columns) + 1};
  for (int k = 0; k < 4; ++k)
    if (Dot(grid.normal[nodes[k]], n) < min_cos) return false;
  const float fx = float(rx - cx * step) / float(step), fy = float(ry - cy * step) / float(step);
  const float w[4] = {(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy};
  *out = DiffuseAndVisibility{};
  out->visibility = 0;
  for (int k = 0; k < 4; ++k) {
    const DiffuseAndVisibility& v = grid.values[nodes[k]];
    for (int c = 0; c < 3; ++c) out->d[c] += w[k] * v.d[c];
    out->visibility += w[k] * v.visibility;
  }
  if (grid.cell_agrees[size_t(cy) * size_t(grid.columns - 1) + size_t(cx)] == kCellSpecular) {
    out->has_specular = true;
    for (int k = 0; k < 4; ++k) {
      const DiffuseAndVisibility& v = grid.values[nodes[k]];
      for (int c = 0; c < 3; ++c) out->s[c] += w[k] * v.s[c], out->b[c] += w[k] * v.b[c];
    }
  }
  return true;
}

// Whether the cell whose top-left node is (cx, cy) has four nodes of one
// object whose D and V agree to delta (InterpolateFromGrid's value test):
// 0 no; kCellDiffuse: D and V; kCellSpecular: the specular parts too, and
// the nodes' mirror directions lie within the object's min_cos_reflect of
// one another (the prefiltered map varies over a lobe's width, so values
// that agree at the corners say little about a sharp lobe between them).
uint8_t CellAgrees(const ShadeGrid& grid, int cx, int cy, float delta) {
  const size_t node = grid.Node(cx, cy);
  const size_t nodes[4] = {node, node + 1, node + size_t(grid.columns), node + size_t(grid.columns) + 1};
  const int32_t o = grid.object[node];
  if (o < 0) return false;
  float lo[4], hi[4];
  for (int c = 0; c < 4; ++c) lo[c] = std::numeric_limits<float>::infinity(), hi[c] = -lo[c];
  for (int k = 0; k < 4; ++k) {
    if (grid.object[nodes[k]] != o) return false;
    const DiffuseAndVisibility& v = grid.values[nodes[k]];
    for (int c = 0; c < 3; ++c) lo[c] = std::min(lo[c], v.d[c]), hi[c] = std::max(hi[c], v.d[c]);
    lo[3] = std::min(lo[3], v.visibility), hi[3] = std::max(hi[3], v.visibility);
  }
  // Relative to the brighter of the cell and the object's mean: a dark
  // cell (the terminator, a shadowed fold) is held to the object's scale.
  const float brightest = std::max({hi[0], hi[1], hi[2], grid.mean_brightest[o]});
  for (int c = 0; c < 3; ++c)
    if (!(hi[c] - lo[c] <= delta * brightest)) return 0;
  if (!(hi[3] - lo[3] <= delta)) return 0;
  const float min_cos = grid.min_cos_reflect[o];
  if (min_cos < -1.0f) return kCellDiffuse;
  for (int a = 0; a < 4; ++a)
    for (int b = a + 1; b < 4; ++b)
      if (!(Dot(grid.reflect[nodes[a]], grid.reflect[nodes[b]]) >= min_cos)) return kCellDiffuse;
  // The specular: F0 ≤ 1 and V ≤ 1, so a channel's specular spans at most
  // the span of s plus that of b; held to the brighter of the cell's
  // diffuse, its specular and the object's means.
  float span[3], top = std::max(brightest, grid.mean_specular[o]);
  for (int c = 0; c < 3; ++c) {
    float slo = std::numeric_limits<float>::infinity(), shi = -slo, blo = slo, bhi = -slo;
    for (int k = 0; k < 4; ++k) {
      const DiffuseAndVisibility& v = grid.values[nodes[k]];
      slo = std::min(slo, v.s[c]), shi = std::max(shi, v.s[c]);
      blo = std::min(blo, v.b[c]), bhi = std::max(bhi, v.b[c]);
      top = std::max(top, v.s[c] + v.b[c]);
    }
    span[c] = (shi - slo) + (bhi - blo);
  }
  for (int c = 0; c < 3; ++c)
    if (!(span[c] <= delta * top)) return kCellDiffuse;
  return kCellSpecular;
}

constexpr size_t kChunk = 256;

// Step 1's values at the grid's nodes: D and V (and the specular parts) of
// each node on an object of the grid path, by chunks of nodes.
void ShadeGridNodes(const ShadeInputs& in, const std::vector<char>& on_grid, ShadeGrid& grid) {
  const ObjectGBuffer& g = in.g;
  const int step = grid.step;
  std::vector<uint32_t> node_pixels;
  for (int r = 0; r < grid.rows; ++r)
    for (int c = 0; c < grid.columns; ++c) {
      const size_t i = g.Index(g.rect.x0 + c * step, g.rect.y0 + r * step);
      if (g.object[i] >= 0 && on_grid[g.object[i]]) node_pixels.push_back(static_cast<uint32_t>(i));
    }
  std::vector<DiffuseAndVisibility> node_values(node_pixels.size());
  ParallelFor((node_pixels.size() + kChunk - 1) / kChunk,
              [&](size_t c) {
                RunScratch& s = ThreadScratch();
                const size_t begin = c * kChunk, end = std::min(node_pixels.size(), begin + kChunk);
                s.pixels.assign(node_pixels.begin() + begin, node_pixels.begin() + end);
                ForEachRun(g, s.pixels, [&](int32_t o, size_t first, size_t count) {
                  ShadeRunDiffuseAndVisibility(in, o, &node_pixels[begin + first], count, s,
                                               &node_values[begin + first], /*specular_parts=*/true);
                });
              },
              1);
  const size_t n_objects = in.objects.size();
  std::vector<double> sum(n_objects, 0.0), count(n_objects, 0.0), specular_sum(n_objects, 0.0);
  for (size_t k = 0; k < node_pixels.size(); ++k) {
    const int x = int(node_pixels[k] % size_t(g.rect.width())), y = int(node_pixels[k] / size_t(g.rect.width()));
    const size_t node = grid.Node(x / step, y / step);
    const int32_t o = g.object[node_pixels[k]];
    const DiffuseAndVisibility& v = node_values[k];
    grid.object[node] = o;
    grid.values[node] = v;
    const float brightest = std::max({v.d[0], v.d[1], v.d[2]});
    const float specular = std::max({v.s[0] + v.b[0], v.s[1] + v.b[1], v.s[2] + v.b[2]});
    if (std::isfinite(brightest) && std::isfinite(specular))
      sum[o] += brightest, specular_sum[o] += specular, count[o] += 1;
  }
  grid.mean_brightest.assign(n_objects, 0.0f);
  grid.mean_specular.assign(n_objects, 0.0f);
  grid.min_cos_reflect.assign(n_objects, -2.0f);
  for (size_t o = 0; o < n_objects; ++o) {
    if (count[o] > 0) {
      grid.mean_brightest[o] = static_cast<float>(sum[o] / count[o]);
      grid.mean_specular[o] = static_cast<float>(specular_sum[o] / count[o]);
    }
    const double r = std::clamp(in.objects[o].material.roughness, 0.0, 1.0);
    if (in.options.shade_specular_on_grid && std::isfinite(in.objects[o].material.roughness))
      grid.min_cos_reflect[o] = static_cast<float>(std::cos(kSpecularCellLobes * r * r));
  }
}

// Step 1: D and V at the grid's nodes, the nodes' normals and mirror
// directions, and which cells may be interpolated (CellAgrees).
ShadeGrid BuildShadeGrid(const ShadeInputs& in, const std::vector<char>& on_grid, int step) {
  const ObjectGBuffer& g = in.g;
  ShadeGrid grid;
  grid.step = step;
  grid.columns = (g.rect.width() - 1) / step + 1;
  grid.rows = (g.rect.height() - 1) / step + 1;
  grid.object.assign(size_t(grid.columns) * size_t(grid.rows), -1);
  grid.values.resize(grid.object.size());
  ShadeGridNodes(in, on_grid, grid);
  grid.normal.assign(grid.object.size(), Vec3f{});
  grid.reflect.assign(grid.object.size(), Vec3f{});
  grid.cell_agrees.assign(size_t(std::max(0, grid.columns - 1)) * size_t(std::max(0, grid.rows - 1)), 0);
  const float delta = static_cast<float>(in.options.shade_refine_delta);
  ParallelFor(
      size_t(grid.rows),
      [&](size_t r) {
        for (int c = 0; c < grid.columns; ++c) {
          const size_t i = g.Index(g.rect.x0 + c * step, g.rect.y0 + int(r) * step), node = grid.Node(c, int(r));
          const Vec3f n = g.normal[i], v = Normalized(in.eye - g.position[i]);
          grid.normal[node] = n;
          grid.reflect[node] = n * (2.0f * Dot(n, v)) - v;
        }
      },
      8);
  ParallelFor(
      size_t(std::max(0, grid.rows - 1)),
      [&](size_t r) {
        for (int c = 0; c + 1 < grid.columns; ++c)
          grid.cell_agrees[r * size_t(grid.columns - 1) + size_t(c)] = CellAgrees(grid, c, int(r), delta);
      },
      8);
  return grid;
}

// Step 2's sorting of one chunk's pixels by path into the scratch: SG-only
// objects (sg_pixels); everything from the grid (composed_pixels with their
// values); D and V from the grid (map_pixels with values); D and V exact
// (map_pixels with an empty value, listed in exact_pixels with its slot).
void SortChunk(const ShadeInputs& in, const ShadeGrid& grid, const std::vector<char>& on_grid, float min_cos,
               const uint32_t* pixels, size_t count, RunScratch& s) {
  const ObjectGBuffer& g = in.g;
  const int step = grid.step;
  s.sg_pixels.clear(), s.map_pixels.clear(), s.exact_pixels.clear(), s.composed_pixels.clear();
  s.values.clear(), s.exact_slot.clear(), s.composed_values.clear();
  for (size_t k = 0; k < count; ++k) {
    const uint32_t i = pixels[k];
    const int32_t o = g.object[i];
    if (in.Map(o) == nullptr) {
      s.sg_pixels.push_back(i);
      continue;
    }
    if (on_grid[o]) {
      // G-buffer indices run over its rectangle.
      const int rx = int(i % size_t(g.rect.width())), ry = int(i / size_t(g.rect.width()));
      DiffuseAndVisibility v;
      const bool from_grid =
          (rx % step == 0 && ry % step == 0)
              ? (v = grid.values[grid.Node(rx / step, ry / step)], true)
              : InterpolateFromGrid(grid, g, o, g.rect.x0 + rx, g.rect.y0 + ry, g.normal[i], min_cos, &v);
      if (from_grid && v.has_specular) {
        s.composed_pixels.push_back(i);
        s.composed_values.push_back(v);
        continue;
      }
      if (from_grid) {
        s.map_pixels.push_back(i);
        s.values.push_back(v);
        continue;
      }
    }
    s.map_pixels.push_back(i);
    s.values.emplace_back();
    s.exact_pixels.push_back(i);
    s.exact_slot.push_back(s.values.size() - 1);
  }
}

// Step 2 for one chunk of pixels: each by its path (SortChunk) into `object`.
void ShadeChunk(const ShadeInputs& in, const ShadeGrid& grid, const std::vector<char>& on_grid, float min_cos,
                const uint32_t* pixels, size_t count, ImageF& object) {
  const ObjectGBuffer& g = in.g;
  RunScratch& s = ThreadScratch();
  SortChunk(in, grid, on_grid, min_cos, pixels, count, s);
  // SG-only objects.
  ForEachRun(g, s.sg_pixels, [&](int32_t o, size_t first, size_t n) {
    s.sg_rgb.resize(n);
    ShadeRunSg(in, o, &s.sg_pixels[first], n, s, s.sg_rgb.data());
    for (size_t k = 0; k < n; ++k) Store(s.sg_rgb[k], s.sg_pixels[first + k], object);
  });
  // D and V where the grid could not stand in.
  s.exact_values.resize(s.exact_pixels.size());
  ForEachRun(g, s.exact_pixels, [&](int32_t o, size_t first, size_t n) {
    ShadeRunDiffuseAndVisibility(in, o, &s.exact_pixels[first], n, s, &s.exact_values[first]);
  });
  for (size_t k = 0; k < s.exact_pixels.size(); ++k) s.values[s.exact_slot[k]] = s.exact_values[k];
  // Everything from the grid: radiance = base ⊙ D + V · (F0 ⊙ s + b).
  for (size_t k = 0; k < s.composed_pixels.size(); ++k) {
    const uint32_t i = s.composed_pixels[k];
    const SgMaterial m = PixelMaterial(in.objects[g.object[i]], g.uv[i]);
    const DiffuseAndVisibility& v = s.composed_values[k];
    const Vec3f specular =
        PrefilteredRadiance::SpecularFromParts(m, {v.s[0], v.s[1], v.s[2]}, {v.b[0], v.b[1], v.b[2]});
    const Vec3f diffuse(float(m.base_color.x) * v.d[0], float(m.base_color.y) * v.d[1], float(m.base_color.z) * v.d[2]);
    Store(diffuse + specular * v.visibility, i, object);
  }
  // The map's specular per pixel: radiance = base ⊙ D + specular · V.
  ForEachRun(g, s.map_pixels, [&](int32_t o, size_t first, size_t n) {
    const uint32_t* run = &s.map_pixels[first];
    GatherRun(in, o, run, n, s, /*gamma=*/false);
    s.specular_rgb.resize(n);
    in.Map(o)->ShadeSpecular(s.materials.data(), s.normals.data(), s.views.data(), s.points.data(), n,
                             s.specular_rgb.data());
    for (size_t k = 0; k < n; ++k) {
      const DiffuseAndVisibility& v = s.values[first + k];
      const Vec3& base = s.materials[k].base_color;
      const Vec3f rgb(float(base.x) * v.d[0], float(base.y) * v.d[1], float(base.z) * v.d[2]);
      Store(rgb + s.specular_rgb[k] * v.visibility, run[k], object);
    }
  });
}

}  // namespace

void ShadeObjects(const std::vector<InsertObject>& objects, const std::vector<WorldSphere>& spheres,
                  const std::vector<LightPrep>& preps, const std::vector<VertexGamma>* vertex_gamma,
                  const std::vector<std::vector<Vec3f>>& vertex_normals, const InsertOptions& options,
                  const ObjectGBuffer& g, const std::vector<uint32_t>& covered, const Vec3f& eye, ImageF& object,
                  const std::vector<PrefilteredRadiance>& specular) {
  const ShadeInputs in{objects, spheres, preps, vertex_gamma, vertex_normals, options, g, eye, specular};
  // The grid path: objects with a map and one roughness and metallic over
  // the whole object (an albedo map is applied per pixel after the grid).
  const int step = std::max(1, options.shade_step);
  std::vector<char> on_grid(objects.size(), 0);
  bool any_on_grid = false;
  for (size_t o = 0; o < objects.size(); ++o) {
    on_grid[o] = step > 1 && in.Map(int32_t(o)) != nullptr && !objects[o].roughness_map && !objects[o].metallic_map;
    any_on_grid = any_on_grid || on_grid[o];
  }
  // 1. D and V at the grid's nodes.
  ShadeGrid grid;
  if (any_on_grid && !covered.empty() && g.rect.width() > 0 && g.rect.height() > 0)
    grid = BuildShadeGrid(in, on_grid, step);
  grid.step = step;
  // 2. Every pixel: from the grid where it may stand in, else exactly.
  const float min_cos = static_cast<float>(std::cos(options.shade_refine_angle_deg * kPi / 180.0));
  ParallelFor((covered.size() + kChunk - 1) / kChunk,
              [&](size_t c) {
                const size_t begin = c * kChunk, end = std::min(covered.size(), begin + kChunk);
                ShadeChunk(in, grid, on_grid, min_cos, &covered[begin], end - begin, object);
              },
              1);
}

}  // namespace nerfar
