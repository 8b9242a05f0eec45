#include "render/insert/object_shading.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "calib/core/parallel.h"
#include "render/insert/incident_light.h"
#include "render/insert/shadow_terms.h"

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

void ShadeObjects(const std::vector<InsertObject>& objects, const std::vector<WorldSphere>& spheres,
                  const std::vector<LightPrep>& preps, const std::vector<VertexGamma>* vertex_gamma,
                  const std::vector<std::vector<Vec3f>>& vertex_normals, const InsertOptions& options,
                  const ObjectGBuffer& g, const std::vector<uint32_t>& covered, const Vec3f& eye, ImageF& object,
                  const std::vector<PrefilteredRadiance>& specular) {
  const size_t n_objects = objects.size();
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
        std::vector<Vec3f> normals, views, points, rgb, shadowed, specular_rgb;
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
          points.clear();
          const VertexGamma* vg = vertex_gamma ? &(*vertex_gamma)[o] : nullptr;
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
            } else if (options.self_shadow && m > 0) {
              point = g.position[i] + n * static_cast<float>(options.self_shadow_offset_radii * spheres[o].radius);
              ssd_min.assign(m, std::numeric_limits<float>::infinity());
              ssd.resize(m);
              for (size_t j = 0; j < n_objects; ++j) {
                if (!p.queries[j]) continue;
                p.queries[j]->Ssd(&point, 1, ssd.data());
                for (size_t l = 0; l < m; ++l) ssd_min[l] = std::min(ssd_min[l], ssd[l]);
              }
              GammaFromSsd(p.axes, p.gamma_rows, n, ssd_min.data(), options.self_shadow_horizon, gp);
            }
            materials.push_back(PixelMaterial(objects[o], g.uv[i]));
            normals.push_back(n);
            views.push_back(Normalized(eye - g.position[i]));
            points.push_back(g.position[i]);
          }
          rgb.assign(count, Vec3f{});
          const PrefilteredRadiance* map = size_t(o) < specular.size() && !specular[o].empty() ? &specular[o] : nullptr;
          // With a map, the specular's self-shadow is the SG specular's
          // luminance with γ over that without, summed in the diffuse pass
          // (the same lobe loop) when any γ of the run is below 1.
          const bool any_shadow = map && std::any_of(gamma.begin(), gamma.end(), [](float x) { return x < 1.0f; });
          if (m > 0 && any_shadow) {
            shadowed.assign(count, Vec3f{});
            p.shader->Shade(materials.data(), normals.data(), views.data(), gamma.data(), static_cast<int>(count),
                            rgb.data(), SgTerms::kDiffuseAndVisibility, shadowed.data());
          } else if (m > 0) {
            p.shader->Shade(materials.data(), normals.data(), views.data(), gamma.data(), static_cast<int>(count),
                            rgb.data(), map ? SgTerms::kDiffuse : SgTerms::kAll);
          }
          if (map) {
            specular_rgb.resize(count);
            map->ShadeSpecular(materials.data(), normals.data(), views.data(), points.data(), count,
                               specular_rgb.data());
            for (size_t k = 0; k < count; ++k) {
              float visibility = 1.0f;
              if (m > 0 && any_shadow && shadowed[k].y > 0.0f && std::isfinite(shadowed[k].y))
                visibility = std::clamp(shadowed[k].x / shadowed[k].y, 0.0f, 1.0f);
              rgb[k] += specular_rgb[k] * visibility;
            }
          }
          for (size_t k = run; k < run_end; ++k) {
            const size_t px = covered[k];  // same layout as the G-buffer
            const Vec3f value = Finite(rgb[k - run]) ? rgb[k - run] : Vec3f{};
            object.pixels[px * 3 + 0] = std::max(value.x, 0.0f);
            object.pixels[px * 3 + 1] = std::max(value.y, 0.0f);
            object.pixels[px * 3 + 2] = std::max(value.z, 0.0f);
          }
          run = run_end;
        }
      },
      1);
}

}  // namespace nerfar
