#include "render/insert/incident_light.h"

#include <chrono>
#include <cmath>

#include "calib/core/error.h"
#include "calib/core/parallel.h"

namespace nerfar {

namespace {
double MillisecondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

const char* LightSourceName(LightSource source) {
  switch (source) {
    case LightSource::kFull:
      return "full";
    case LightSource::kNearFieldOnly:
      return "near";
    case LightSource::kEnvironmentOnly:
      return "env";
  }
  return "?";
}

LightSource ParseLightSource(const std::string& name) {
  if (name == "full") return LightSource::kFull;
  if (name == "near") return LightSource::kNearFieldOnly;
  if (name == "env") return LightSource::kEnvironmentOnly;
  ThrowInputError("light source", "unknown value '" + name + "' (expected full, near or env)");
}

std::vector<std::string> IncidentLightOptions::Validate() const {
  std::vector<std::string> problems;
  if (directions < 16 || directions > (1 << 20))
    problems.push_back("light_directions: " + std::to_string(directions) + " is out of range (expected 16 to 1048576)");
  if (!(move_threshold_m >= 0.0) || !std::isfinite(move_threshold_m))
    problems.push_back("light_move_threshold_m: must be a finite number >= 0");
  for (const std::string& p : fit.Validate()) problems.push_back("fit." + p);
  return problems;
}

RadianceSamples SampleIncidentLight(const SceneField& scene, const SgMixture& environment, const Vec3& center,
                                    const std::vector<Vec3>& directions, LightSource source,
                                    std::vector<float>* opacity) {
  const size_t n = directions.size();
  RadianceSamples samples;
  samples.directions = directions;
  samples.radiance.assign(n, Vec3{});
  samples.solid_angles.assign(n, n > 0 ? 4.0 * kPi / static_cast<double>(n) : 0.0);
  if (opacity) opacity->assign(n, 0.0f);
  SceneSamples field;
  if (source != LightSource::kEnvironmentOnly) {
    // One batch per chunk so that threads share no scratch (RenderRays is const).
    constexpr size_t kChunk = 128;
    const size_t chunks = (n + kChunk - 1) / kChunk;
    field.Resize(n);
    const Aabb box = scene.Box();
    ParallelFor(
        chunks,
        [&](size_t c) {
          SceneRays rays;
          SceneSamples out;
          const size_t begin = c * kChunk, end = std::min(n, begin + kChunk);
          rays.Reserve(end - begin);
          for (size_t i = begin; i < end; ++i) {
            const auto range = IntersectBox(box, center, directions[i]);
            const float t0 = range ? static_cast<float>(range->first) : 0.0f;
            const float t1 = range ? static_cast<float>(range->second) : 0.0f;
            rays.Add(Vec3f(center), Vec3f(directions[i]), t0, t1);
          }
          scene.RenderRays(rays, out);
          for (size_t i = begin; i < end; ++i) {
            field.colour[i] = out.colour[i - begin];
            field.opacity[i] = out.opacity[i - begin];
          }
        },
        1);
  }
  for (size_t i = 0; i < n; ++i) {
    Vec3 near{};
    float o = 0.0f;
    if (source != LightSource::kEnvironmentOnly) {
      near = Vec3(field.colour[i]);
      o = std::clamp(field.opacity[i], 0.0f, 1.0f);
      if (!std::isfinite(o)) o = 0.0f;
    }
    Vec3 env{};
    if (source != LightSource::kNearFieldOnly && !environment.empty())
      env = Evaluate(environment, directions[i]) * (1.0 - o);
    Vec3 l = near + env;
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite(l[c]) || l[c] < 0.0) l[c] = 0.0;
    samples.radiance[i] = l;
    if (opacity) (*opacity)[i] = o;
  }
  return samples;
}

void IncidentLight::Reset() {
  valid_ = false;
  light_.clear();
}

IncidentLight::Update IncidentLight::Refresh(const SceneField& scene, const SgMixture& environment, const Vec3& center,
                                             const IncidentLightOptions& options) {
  Update update;
  const bool same_setup =
      valid_ && directions_ == options.directions && source_ == options.source && lobes_ == options.fit.lobes;
  if (same_setup && Length(center - center_) <= options.move_threshold_m) return update;
  update.recomputed = true;
  if (static_cast<int>(dirs_.size()) != options.directions) dirs_ = FibonacciSphere(options.directions);
  auto t0 = std::chrono::steady_clock::now();
  samples_ = SampleIncidentLight(scene, environment, center, dirs_, options.source);
  update.sample_ms = MillisecondsSince(t0);
  double total = 0.0;
  for (const Vec3& l : samples_.radiance) total += LuminanceOf(l);
  if (options.source == LightSource::kEnvironmentOnly) {
    light_ = environment;  // already SGs: nothing to fit
  } else if (!(total > 0.0)) {
    light_.clear();  // darkness (e.g. the centre inside opaque geometry): no lobe to fit
  } else {
    t0 = std::chrono::steady_clock::now();
    const bool warm = same_setup && static_cast<int>(light_.size()) == options.fit.lobes;
    light_ = FitSg(samples_, options.fit, warm ? &light_ : nullptr, &update.report);
    update.fit_ms = MillisecondsSince(t0);
  }
  valid_ = true;
  center_ = center;
  directions_ = options.directions;
  source_ = options.source;
  lobes_ = options.fit.lobes;
  return update;
}

}  // namespace nerfar
