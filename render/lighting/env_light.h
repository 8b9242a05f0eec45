// The distant environment light estimated by `nerfar env` (paper §4.2, eq. 2)
// and its file, env.json, which insertion reads. The light is a sum of SG
// lobes (render/sg: axis unit vector in the world frame, z up; sharpness λ;
// linear RGB amplitude μ in image radiance units). `negligible` says the
// estimate is small against the NeRF's own near-field light (all light is
// inside the NeRF): insertion then drops the environment term.
//
// env.json (strict: unknown keys are errors):
//   { "format": "nerfar-env", "version": 1,
//     "lobes": [ {"axis": [x, y, z], "sharpness": λ, "amplitude": [r, g, b],
//                 "distance_m": d}, ... ],      (distance_m optional: absent for distant light)
//     "negligible": false,
//     "energy": { "env_to_near_surface": r1, "env_to_near_center": r2, "threshold": t,
//                 "evidence": e, "evidence_needed": b },   (the last two optional, default 0)
//     "fit": { "samples": n, "relative_rms": r, "loss": l,
//              "near_field_only": {"relative_rms": r0, "loss": l0} },   (optional; its last member too)
//     "source": "...", "options": {...} }        (the last three: documentation only)
#pragma once

#include <string>
#include <vector>

#include "render/sg/sg.h"

namespace nerfar {

inline constexpr int kEnvFileVersion = 1;

// How well the fit explains what the views saw (render/lighting/env_fit.h):
// relative RMS of the model's luminance against the observed, over the
// surface samples, and the fit's robust loss per sample; the same for the
// best fit without environment (near field and albedo only).
struct EnvFitResidual {
  long long samples = 0;  // surface samples fitted; 0: not recorded (files written before it was)
  double relative_rms = 0, loss = 0;
  bool near_only_fitted = false;  // the fit without environment ran (model selection on)
  double near_only_relative_rms = 0, near_only_loss = 0;
};

struct EnvLight {
  SgMixture lobes;  // L_env(d) = Σ_k G(d; p_k, λ_k, μ_k); at most kMaxSgLobes
  // Per lobe (or empty: all distant): how far from the origin along its axis
  // the lobe's light stands, in metres, where `nerfar env` placed a source at
  // a distance (a ceiling light); 0: distant. The lobe is that light as seen
  // from the origin; seen from elsewhere it turns and falls off
  // (EnvironmentSeenFrom, render/lighting/incident_light.h).
  std::vector<double> distance_m;
  bool negligible = false;  // true: insertion drops the environment term
  // Luminance of the environment's irradiance over that of the NeRF near
  // field, summed over the surface samples the estimate used (E_env with NeRF
  // visibility, E_nerf by ray casting).
  double env_to_near_surface = 0;
  // The same at the NeRF volume's centre, averaged over normals spread over the sphere.
  double env_to_near_center = 0;
  // `negligible` is set when both ratios are below this, ...
  double threshold = 0.05;
  // ... or when the environment does not explain the observations better
  // than the near field alone by more than BIC's penalty for its parameters:
  // its log-likelihood gain `evidence` is at most `evidence_needed`
  // (render/lighting/env_fit.h; both 0 when the test was off).
  double evidence = 0;
  double evidence_needed = 0;
  EnvFitResidual fit;        // documentation
  std::string source;        // the .nerf it came from (documentation)
  std::string options_json;  // the estimator's options as compact JSON ("" or an object; documentation)
};

// Every problem with the values as "field: what (expected)"; empty when valid.
std::vector<std::string> ValidateEnvLight(const EnvLight& env);

std::string SerializeEnvLight(const EnvLight& env);
// InputError "source: /json/pointer: what (expected)" listing every problem.
EnvLight ParseEnvLight(const std::string& text, const std::string& source);

void WriteEnvLight(const std::string& path, const EnvLight& env);  // atomic
EnvLight ReadEnvLight(const std::string& path);
// What insertion does with an estimate marked negligible: its lobes and
// their distances are dropped. Returns whether they were.
bool DropIfNegligible(EnvLight& env);

// The lobes as a 3-channel float panorama (scenes/README.md equirect
// convention), e.g. 256 x 128 for the preview EXR.
void WriteEnvPreview(const std::string& path, const EnvLight& env, int width = 256, int height = 128);

}  // namespace nerfar
