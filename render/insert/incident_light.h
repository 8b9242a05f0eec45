// Incident light at a virtual object's centre (paper eq. 1 and §4.4): rays
// leave the centre in N Fibonacci directions through the scene field, and
// L_i(d) = Ĉ(d) + (1 − Ô(d))·L_env(d), where Ĉ = Ô·L_nerf is the field's
// opacity-weighted colour (so this is the paper's (1 − Ô)L_env + Ô·L_nerf).
// The samples are fitted with SGs (render/sg FitSg), warm-started from the
// previous fit, and the result is kept while the centre does not move.
// World frame, metres, linear RGB radiance.
#pragma once

#include <string>
#include <vector>

#include "render/insert/scene_field.h"
#include "render/sg/fit.h"
#include "render/sg/sg.h"
#include "render/sg/sphere.h"

namespace nerfar {

// Which light the object sees: ours, or the paper's two ablations.
enum class LightSource {
  kFull,             // NeRF near field blended with the environment by NeRF opacity
  kNearFieldOnly,    // Ĉ only (no environment light)
  kEnvironmentOnly,  // the environment SGs only (no NeRF rays, no fit)
};
const char* LightSourceName(LightSource source);
// "full", "near", "env"; InputError otherwise.
LightSource ParseLightSource(const std::string& name);

struct IncidentLightOptions {
  int directions = 1024;           // N rays from the centre: more is smoother and slower (linear cost)
  double move_threshold_m = 1e-4;  // the light is recomputed once the centre moved farther than this
  LightSource source = LightSource::kFull;
  SgFitOptions fit;  // lobe count and iterations of the SG fit (render/sg presets)
  // Every problem as "field: what is wrong (what was expected)".
  std::vector<std::string> Validate() const;
};

// Radiance arriving at `center` from each unit direction (solid angle 4π/N
// each), per `source`. `opacity` (optional) receives Ô per direction.
RadianceSamples SampleIncidentLight(const SceneField& scene, const SgMixture& environment, const Vec3& center,
                                    const std::vector<Vec3>& directions, LightSource source,
                                    std::vector<float>* opacity = nullptr);

// One object's incident light, refreshed per frame.
class IncidentLight {
 public:
  struct Update {
    bool recomputed = false;  // false: the cached fit was reused
    double sample_ms = 0;     // ray marching from the centre
    double fit_ms = 0;        // SG fit (0 when reused or for the environment-only source)
    SgFitReport report;
  };

  // Recomputes the light if the centre moved (or the options changed, or on
  // the first call); warm-starts the fit from the last one. Never throws on
  // scene content: non-finite radiance is replaced by 0.
  Update Refresh(const SceneField& scene, const SgMixture& environment, const Vec3& center,
                 const IncidentLightOptions& options);
  // Forget the cache (the next Refresh fits from scratch).
  void Reset();

  bool valid() const { return valid_; }
  const SgMixture& light() const { return light_; }
  const RadianceSamples& samples() const { return samples_; }
  const Vec3& center() const { return center_; }

 private:
  bool valid_ = false;
  Vec3 center_;
  int directions_ = 0;
  LightSource source_ = LightSource::kFull;
  int lobes_ = 0;
  std::vector<Vec3> dirs_;
  RadianceSamples samples_;
  SgMixture light_;
};

}  // namespace nerfar
