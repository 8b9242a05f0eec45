#include "calib/camera_file.h"

#include <cmath>
#include <nlohmann/json.hpp>

#include "calib/camera_keys.h"
#include "calib/core/json.h"
#include "calib/dataset.h"

namespace nerfar {
namespace {

constexpr char kResponseModel[] = "debevec_log_exposure";

std::optional<CameraResponse> ReadResponse(const Json& value, Problems& problems) {
  JsonObjectReader reader(value, "/response", problems);
  const size_t before = problems.items().size();
  const std::string model = reader.String("model");
  if (reader.Has("model") && value["model"].is_string() && model != kResponseModel)
    problems.Add("/response/model", "is \"" + model + "\" (expected \"" + kResponseModel + "\")");
  CameraResponse response;
  if (const Json* curves = reader.Array("log_exposure")) {
    if (curves->size() != 1 && curves->size() != 3) {
      problems.Add("/response/log_exposure",
                   "has " + std::to_string(curves->size()) + " curves (expected 1 or 3, one per channel)");
    } else {
      for (size_t c = 0; c < curves->size(); ++c) {
        const Json& curve = (*curves)[c];
        const std::string pointer = "/response/log_exposure/" + std::to_string(c);
        if (!curve.is_array() || curve.size() != kResponseLevels) {
          problems.Add(pointer, "is not an array of 256 numbers (expected g(z) for z = 0..255)");
          continue;
        }
        std::array<float, kResponseLevels> g{};
        for (int z = 0; z < kResponseLevels; ++z) {
          const Json& v = curve[z];
          if (!v.is_number() || !std::isfinite(v.get<double>()) || std::abs(v.get<double>()) > 1e3) {
            problems.Add(pointer + "/" + std::to_string(z), "is not a finite log exposure (expected |g| <= 1000)");
            break;
          }
          g[z] = static_cast<float>(v.get<double>());
        }
        response.log_exposure.push_back(g);
      }
    }
  }
  reader.Finish();
  if (problems.items().size() != before) return std::nullopt;
  for (const std::string& p : response.Validate()) problems.Add("/response/log_exposure", p);
  return response;
}

}  // namespace

CameraFile ReadCameraFile(const std::string& path) {
  const Json doc = ReadJsonFile(path);
  CameraFile file;
  if (doc.is_object() && doc.contains("frames")) {
    const Dataset dataset = ReadDataset(path, /*check_images=*/false);
    file.camera = dataset.camera;
    file.camera_model = dataset.camera_model;
    return file;
  }
  Problems problems(path);
  JsonObjectReader root(doc, "", problems);
  root.Allow({"units", "note", "notes", "comment"});
  if (root.valid()) {
    file.camera_model = ReadCameraKeys(root, file.camera);
    if (const Json* response = root.Object("response", false)) file.response = ReadResponse(*response, problems);
    if (const Json* calibration = root.Object("calibration", false)) {
      JsonObjectReader r(*calibration, "/calibration", problems);
      CalibrationRecord record;
      record.rms_px = r.Number("rms_px", 0.0, 1e6);
      record.views_used = static_cast<int>(r.Integer("views_used", 0, 1 << 24));
      record.views_rejected = static_cast<int>(r.Integer("views_rejected", 0, 1 << 24));
      record.coverage = r.Number("coverage", 0.0, 1.0);
      record.sigma_fx = r.Number("sigma_fl_x", 0.0, 1e7);
      record.sigma_fy = r.Number("sigma_fl_y", 0.0, 1e7);
      record.sigma_cx = r.Number("sigma_cx", 0.0, 1e7);
      record.sigma_cy = r.Number("sigma_cy", 0.0, 1e7);
      r.Finish();
      file.calibration = record;
    }
    root.Finish();
  }
  problems.ThrowIfAny();
  return file;
}

void WriteCameraFile(const std::string& path, const CameraFile& file) {
  Problems problems(path);
  for (const std::string& p : file.camera.Validate()) problems.Add("camera", p);
  if (file.response)
    for (const std::string& p : file.response->Validate()) problems.Add("response", p);
  problems.ThrowIfAny();
  Json doc = Json::object();
  WriteCameraKeys(file.camera, file.camera_model, doc);
  if (file.response) {
    Json curves = Json::array();
    for (const auto& g : file.response->log_exposure) {
      Json curve = Json::array();
      for (float v : g) curve.push_back(static_cast<double>(v));
      curves.push_back(curve);
    }
    doc["response"] = Json{{"model", kResponseModel}, {"log_exposure", curves}};
  }
  if (file.calibration) {
    const CalibrationRecord& r = *file.calibration;
    doc["calibration"] =
        Json{{"rms_px", r.rms_px},     {"views_used", r.views_used}, {"views_rejected", r.views_rejected},
             {"coverage", r.coverage}, {"sigma_fl_x", r.sigma_fx},   {"sigma_fl_y", r.sigma_fy},
             {"sigma_cx", r.sigma_cx}, {"sigma_cy", r.sigma_cy}};
  }
  WriteJsonFile(path, doc);
}

}  // namespace nerfar
