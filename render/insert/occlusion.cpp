#include "render/insert/occlusion.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>

#include "calib/core/parallel.h"
#include "render/insert/insert_common.h"

namespace nerfar {

namespace {

// The ray of pixel (x, y) over the scene's box up to `depth` (the object).
struct OcclusionRays {
  const CameraIntrinsics& camera;
  const Pose& T_world_camera;
  Vec3f eye;
  Aabb box;
  void Add(SceneRays& rays, int x, int y, float depth) const {
    const Vec3f d = CameraRayDirection(camera, T_world_camera, x, y);
    const auto range = IntersectBox(box, Vec3(eye), Vec3(d));
    float t_near = 0.0f, t_far = 0.0f;
    if (range) {
      t_near = std::min(depth, static_cast<float>(range->first));
      t_far = std::min(depth, static_cast<float>(range->second));
    }
    rays.Add(eye, d, t_near, t_far);
  }
};

// Coarse pass: rays at the corners of occlusion_step-sized blocks, each up
// to the farthest object depth of the blocks it touches; per G-buffer pixel,
// 1 where the corners of its block all see (almost) nothing, so that the
// pixel needs no ray of its own.
std::vector<uint8_t> ClearPixels(const SceneField& scene, const InsertOptions& options, const OcclusionRays& add,
                                 const std::vector<uint32_t>& covered, const ObjectGBuffer& g) {
  std::vector<uint8_t> clear(g.object.size(), 0);
  if (options.occlusion_step <= 1 || covered.empty()) return clear;
  const int s = options.occlusion_step, w = g.rect.width(), h = g.rect.height();
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
          add.Add(rays, g.rect.x0 + std::min(u * s, w - 1), g.rect.y0 + std::min(v * s, h - 1), far);
          cols.push_back(u);
        }
        if (cols.empty()) return;
        scene.RenderRays(rays, out);
        for (size_t k = 0; k < cols.size(); ++k)
          node_opacity[row * nx + cols[k]] = std::isfinite(out.opacity[k]) ? out.opacity[k] : 1.0f;
      },
      1);
  const float limit = static_cast<float>(options.occlusion_clear_opacity);
  for (uint32_t i : covered) {
    const size_t u = (i % w) / s, v = i / w / s;
    clear[i] = node_opacity[v * nx + u] < limit && node_opacity[v * nx + u + 1] < limit &&
               node_opacity[(v + 1) * nx + u] < limit && node_opacity[(v + 1) * nx + u + 1] < limit;
  }
  return clear;
}

// The covered pixels [begin, end): the scene in front of the object up to
// its depth (paper eq. 7), composited over the frame; edge pixels' background
// shares into `shares`; returns the non-finite samples replaced.
size_t CompositeChunk(const SceneField& scene, const OcclusionRays& add, const std::vector<uint32_t>& covered,
                      size_t begin, size_t end, const std::vector<uint8_t>& clear, const ReceiverOverride& receivers,
                      ImageF& frame, InsertLayers& layers, std::vector<InsertLayers::EdgeShare>& shares) {
  const ObjectGBuffer& g = layers.gbuffer;
  size_t fixed = 0;
  SceneRays rays;
  SceneSamples out;
  rays.Reserve(end - begin);
  std::vector<int> ray_of(end - begin, -1);
  for (size_t k = begin; k < end; ++k) {
    const uint32_t i = covered[k];
    if (clear[i]) continue;
    ray_of[k - begin] = static_cast<int>(rays.size());
    add.Add(rays, g.rect.x0 + static_cast<int>(i % g.rect.width()), g.rect.y0 + static_cast<int>(i / g.rect.width()),
            g.t[i]);
  }
  if (rays.size() > 0) scene.RenderRays(rays, out);
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
      ++fixed;
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
    if (cover < 1.0f) {
      InsertLayers::EdgeShare share;
      share.index = i;
      for (int ch = 0; ch < 3; ++ch) share.rgb[ch] = (1.0f - cover) * frame.at(x, y, ch);
      shares.push_back(share);
    }
    for (int ch = 0; ch < 3; ++ch) {
      const float composite = front[ch] + w * layers.object.pixels[static_cast<size_t>(i) * 3 + ch];
      frame.at(x, y, ch) = cover * composite + (1.0f - cover) * frame.at(x, y, ch);
    }
  }
  return fixed;
}

}  // namespace

void OccludeAndComposite(const SceneField& scene, const InsertOptions& options, const CameraIntrinsics& camera,
                         const Pose& T_world_camera, const std::vector<uint32_t>& covered,
                         const ReceiverOverride& receivers, ImageF& frame, InsertLayers& layers) {
  const ObjectGBuffer& g = layers.gbuffer;
  constexpr size_t kChunk = 256;
  const size_t chunks = (covered.size() + kChunk - 1) / kChunk;
  const OcclusionRays add{camera, T_world_camera, Vec3f(T_world_camera.translation), scene.Box()};
  const std::vector<uint8_t> clear = ClearPixels(scene, options, add, covered, g);
  std::vector<size_t> fixed_per_chunk(chunks, 0);
  std::vector<std::vector<InsertLayers::EdgeShare>> shares(chunks);
  ParallelFor(
      chunks,
      [&](size_t c) {
        const size_t begin = c * kChunk, end = std::min(covered.size(), begin + kChunk);
        fixed_per_chunk[c] =
            CompositeChunk(scene, add, covered, begin, end, clear, receivers, frame, layers, shares[c]);
      },
      1);
  for (size_t f : fixed_per_chunk) layers.nonfinite_fixed += f;
  layers.edge_background.clear();
  for (const auto& chunk : shares)
    layers.edge_background.insert(layers.edge_background.end(), chunk.begin(), chunk.end());
}

void CompositeEdges(const ReceiverOverride& receivers, ImageF& frame, const InsertLayers& layers) {
  const ObjectGBuffer& g = layers.gbuffer;
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
  // Edge pixels whose centre is covered: the background's share of the
  // composite was taken before κ, which the shadow pass leaves alone on
  // object pixels; it takes the mean κ of the pixel's uncovered neighbours
  // (the contact shadow next to the silhouette, the darkest part of it).
  const PixelRect& kr = layers.kappa_rect;
  if (!layers.edge_background.empty() && layers.kappa.width == kr.width() && layers.kappa.height == kr.height()) {
    for (const InsertLayers::EdgeShare& share : layers.edge_background) {
      const int x = g.rect.x0 + static_cast<int>(share.index % g.rect.width());
      const int y = g.rect.y0 + static_cast<int>(share.index / g.rect.width());
      float sum = 0.0f;
      int n = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int xx = x + dx, yy = y + dy;
          if (xx < 0 || yy < 0 || xx >= frame.width || yy >= frame.height) continue;
          if (g.rect.Contains(xx, yy) && g.object[g.Index(xx, yy)] >= 0) continue;
          sum += kr.Contains(xx, yy) ? layers.kappa.at(xx - kr.x0, yy - kr.y0) : 1.0f;  // 1 outside the rect
          ++n;
        }
      if (n == 0) continue;
      const float k = std::clamp(sum / float(n), 0.0f, 1.0f);
      for (int ch = 0; ch < 3; ++ch) frame.at(x, y, ch) += (k - 1.0f) * share.rgb[ch];
    }
  }
}

}  // namespace nerfar
