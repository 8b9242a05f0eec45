#include "render/lighting/env_light.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "calib/core/atomic_file.h"
#include "calib/core/error.h"
#include "calib/core/exr.h"
#include "calib/core/json.h"
#include "render/sg/sphere.h"

namespace nerfar {
namespace {

constexpr double kMinSharpness = 1e-4, kMaxSharpness = 1e4;  // DESIGN.md range
constexpr double kMaxAmplitude = 1e7;                        // a sun is 1e6; more is a broken file
constexpr double kAxisTolerance = 1e-3;                      // |p| − 1 accepted (printed with 6+ digits)
constexpr double kMaxDistance = 1e6;                         // metres; farther is distant in any scene

Json ToJson(const Vec3& v) { return Json::array({v.x, v.y, v.z}); }

void CheckLobe(const Sg& lobe, const std::string& where, Problems& problems) {
  const double n = Length(lobe.axis);
  if (!std::isfinite(n) || std::fabs(n - 1.0) > kAxisTolerance)
    problems.Add(where + "/axis", "has length " + std::to_string(n) + " (expected a unit vector)");
  if (!(lobe.sharpness >= kMinSharpness && lobe.sharpness <= kMaxSharpness))
    problems.Add(where + "/sharpness", "is " + std::to_string(lobe.sharpness) + " (expected 1e-4 to 1e4)");
  for (int c = 0; c < 3; ++c)
    if (!(lobe.amplitude[c] >= 0 && lobe.amplitude[c] <= kMaxAmplitude))
      problems.Add(where + "/amplitude/" + std::to_string(c),
                   "is " + std::to_string(lobe.amplitude[c]) + " (expected 0 to 1e7)");
}

void CheckRatio(double value, const char* name, Problems& problems) {
  if (!(value >= 0 && std::isfinite(value)))
    problems.Add(std::string("/energy/") + name, "is " + std::to_string(value) + " (expected a finite number >= 0)");
}

void Check(const EnvLight& env, Problems& problems) {
  if (env.lobes.size() > static_cast<size_t>(kMaxSgLobes))
    problems.Add("/lobes", "has " + std::to_string(env.lobes.size()) + " lobes (expected at most " +
                               std::to_string(kMaxSgLobes) + ")");
  for (size_t k = 0; k < env.lobes.size(); ++k) CheckLobe(env.lobes[k], "/lobes/" + std::to_string(k), problems);
  if (!env.distance_m.empty() && env.distance_m.size() != env.lobes.size())
    problems.Add("/lobes", "has " + std::to_string(env.distance_m.size()) + " distances for " +
                               std::to_string(env.lobes.size()) + " lobes (expected one per lobe, or none)");
  for (size_t k = 0; k < env.distance_m.size(); ++k)
    if (!(env.distance_m[k] >= 0 && env.distance_m[k] <= kMaxDistance))
      problems.Add("/lobes/" + std::to_string(k) + "/distance_m",
                   "is " + std::to_string(env.distance_m[k]) + " (expected 0 to 1e6)");
  CheckRatio(env.env_to_near_surface, "env_to_near_surface", problems);
  CheckRatio(env.env_to_near_center, "env_to_near_center", problems);
  if (!std::isfinite(env.evidence))
    problems.Add("/energy/evidence", "is " + std::to_string(env.evidence) + " (expected a finite number)");
  if (!(env.evidence_needed >= 0 && std::isfinite(env.evidence_needed)))
    problems.Add("/energy/evidence_needed",
                 "is " + std::to_string(env.evidence_needed) + " (expected a finite number >= 0)");
  if (!(env.threshold >= 0 && env.threshold <= 1))
    problems.Add("/energy/threshold", "is " + std::to_string(env.threshold) + " (expected 0 to 1)");
  const EnvFitResidual& fit = env.fit;
  if (fit.samples < 0) problems.Add("/fit/samples", "is " + std::to_string(fit.samples) + " (expected >= 0)");
  const std::pair<const char*, double> residuals[] = {{"/fit/relative_rms", fit.relative_rms},
                                                      {"/fit/loss", fit.loss},
                                                      {"/fit/near_field_only/relative_rms", fit.near_only_relative_rms},
                                                      {"/fit/near_field_only/loss", fit.near_only_loss}};
  for (const auto& [pointer, value] : residuals)
    if (!(value >= 0 && std::isfinite(value)))
      problems.Add(pointer, "is " + std::to_string(value) + " (expected a finite number >= 0)");
}

Json FitToJson(const EnvFitResidual& fit) {
  Json out = {{"samples", fit.samples}, {"relative_rms", fit.relative_rms}, {"loss", fit.loss}};
  if (fit.near_only_fitted)
    out["near_field_only"] = {{"relative_rms", fit.near_only_relative_rms}, {"loss", fit.near_only_loss}};
  return out;
}

EnvFitResidual FitFromJson(const Json& value, Problems& problems) {
  EnvFitResidual fit;
  JsonObjectReader reader(value, "/fit", problems);
  if (!reader.valid()) return fit;
  fit.samples = reader.Integer("samples", 0, 1LL << 40);
  fit.relative_rms = reader.Number("relative_rms", 0, 1e30);
  fit.loss = reader.Number("loss", 0, 1e30);
  if (const Json* near = reader.Object("near_field_only", false)) {
    JsonObjectReader n(*near, "/fit/near_field_only", problems);
    fit.near_only_fitted = true;
    fit.near_only_relative_rms = n.Number("relative_rms", 0, 1e30);
    fit.near_only_loss = n.Number("loss", 0, 1e30);
    n.Finish();
  }
  reader.Finish();
  return fit;
}

}  // namespace

std::vector<std::string> ValidateEnvLight(const EnvLight& env) {
  Problems problems("env");
  Check(env, problems);
  return problems.items();
}

std::string SerializeEnvLight(const EnvLight& env) {
  Problems problems("env light to write");
  Check(env, problems);
  NERFAR_CHECK(problems.empty());  // the estimator only produces valid lights
  Json doc = Json::object();
  doc["format"] = "nerfar-env";
  doc["version"] = kEnvFileVersion;
  Json lobes = Json::array();
  for (size_t k = 0; k < env.lobes.size(); ++k) {
    const Sg& lobe = env.lobes[k];
    Json item = Json::object();
    item["axis"] = ToJson(Normalized(lobe.axis));
    item["sharpness"] = lobe.sharpness;
    item["amplitude"] = ToJson(lobe.amplitude);
    if (k < env.distance_m.size() && env.distance_m[k] > 0) item["distance_m"] = env.distance_m[k];
    lobes.push_back(item);
  }
  doc["lobes"] = lobes;
  doc["negligible"] = env.negligible;
  doc["energy"] = {{"env_to_near_surface", env.env_to_near_surface},
                   {"env_to_near_center", env.env_to_near_center},
                   {"threshold", env.threshold},
                   {"evidence", env.evidence},
                   {"evidence_needed", env.evidence_needed}};
  if (env.fit.samples > 0) doc["fit"] = FitToJson(env.fit);
  if (!env.source.empty()) doc["source"] = env.source;
  if (!env.options_json.empty()) doc["options"] = ParseJson(env.options_json, "env options");
  return DumpJson(doc) + "\n";
}

EnvLight ParseEnvLight(const std::string& text, const std::string& source) {
  const Json doc = ParseJson(text, source);
  Problems problems(source);
  EnvLight env;
  JsonObjectReader root(doc, "", problems);
  root.Allow({"source", "options", "note"});
  if (root.valid()) {
    const std::string format = root.String("format");
    if (root.Has("format") && format != "nerfar-env")
      problems.Add("/format", "is \"" + format + "\" (expected \"nerfar-env\")");
    root.Integer("version", kEnvFileVersion, kEnvFileVersion);
    if (const Json* lobes = root.Array("lobes")) {
      if (lobes->size() > static_cast<size_t>(kMaxSgLobes))
        problems.Add("/lobes", "has " + std::to_string(lobes->size()) + " lobes (expected at most " +
                                   std::to_string(kMaxSgLobes) + ")");
      else
        for (size_t k = 0; k < lobes->size(); ++k) {
          JsonObjectReader item((*lobes)[k], "/lobes/" + std::to_string(k), problems);
          if (!item.valid()) continue;
          const auto axis = item.Vec3("axis");
          const auto amplitude = item.Vec3("amplitude");
          Sg lobe;
          lobe.axis = {axis[0], axis[1], axis[2]};
          lobe.sharpness = item.Number("sharpness");
          lobe.amplitude = {amplitude[0], amplitude[1], amplitude[2]};
          env.distance_m.push_back(item.OptionalNumber("distance_m", 0, kMaxDistance).value_or(0));
          item.Finish();
          CheckLobe(lobe, "/lobes/" + std::to_string(k), problems);
          lobe.axis = Normalized(lobe.axis);
          env.lobes.push_back(lobe);
        }
    }
    if (std::all_of(env.distance_m.begin(), env.distance_m.end(), [](double d) { return d == 0; }))
      env.distance_m.clear();
    env.negligible = root.Bool("negligible");
    if (const Json* energy = root.Object("energy")) {
      JsonObjectReader e(*energy, "/energy", problems);
      env.env_to_near_surface = e.Number("env_to_near_surface", 0, 1e30);
      env.env_to_near_center = e.Number("env_to_near_center", 0, 1e30);
      env.threshold = e.Number("threshold", 0, 1);
      env.evidence = e.OptionalNumber("evidence", -1e300, 1e300).value_or(0);
      env.evidence_needed = e.OptionalNumber("evidence_needed", 0, 1e300).value_or(0);
      e.Finish();
    }
    if (const Json* fit = root.Object("fit", false)) env.fit = FitFromJson(*fit, problems);
    if (root.Has("source")) env.source = root.OptionalString("source").value_or("");
    if (root.Has("options")) {
      const Json* options = root.Object("options");
      if (options != nullptr) {
        env.options_json = DumpJson(*options, -1);
        while (!env.options_json.empty() && env.options_json.back() == '\n') env.options_json.pop_back();
      }
    }
    root.Finish();
  }
  problems.ThrowIfAny();
  return env;
}

void WriteEnvLight(const std::string& path, const EnvLight& env) { WriteFileAtomic(path, SerializeEnvLight(env)); }

EnvLight ReadEnvLight(const std::string& path) { return ParseEnvLight(ReadFileBytes(path, kMaxJsonBytes), path); }

bool DropIfNegligible(EnvLight& env) {
  if (!env.negligible) return false;
  env.lobes.clear();
  env.distance_m.clear();
  return true;
}

void WriteEnvPreview(const std::string& path, const EnvLight& env, int width, int height) {
  WriteExrRgb(path, RenderEquirect(env.lobes, width, height), ExrPixelType::kFloat);
}

}  // namespace nerfar
