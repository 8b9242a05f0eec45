#include "calib/camera_keys.h"

#include <cmath>
#include <nlohmann/json.hpp>

#include "calib/core/image.h"

namespace nerfar {
namespace {

// Largest focal length accepted, in pixels (a 16k-wide image at 0.1 degree).
constexpr double kMaxFocalPx = 1e7;
// Distortion terms beyond this are not a lens but a corrupt file.
constexpr double kMaxDistortion = 1e3;
// camera_angle_x/y must match the focal length within this (radians): files
// written with 4 decimals of a radian still pass, a swapped or stale value not.
constexpr double kAngleTolerance = 1e-3;

std::string FormatNumber(double v) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.10g", v);
  return buffer;
}

// What to do with a lens the OpenCV model (k1 k2 p1 p2 k3) does not describe.
constexpr char kUndistortFirst[] =
    "fisheye and other lens models are not supported: undistort the images first, e.g. with COLMAP's "
    "image_undistorter, and use the pinhole camera it writes";

// instant-ngp's is_fisheye and the fourth radial term of OpenCV's fisheye
// model (nerfstudio writes k4 for OPENCV_FISHEYE): accepted when they say
// "pinhole", refused otherwise.
void RejectFisheyeKeys(JsonObjectReader& reader) {
  if (reader.Has("is_fisheye") && reader.Bool("is_fisheye"))
    reader.problems().Add(reader.PointerTo("is_fisheye"), std::string("is true (") + kUndistortFirst + ")");
  const std::optional<double> k4 = reader.OptionalNumber("k4");
  if (k4.has_value() && *k4 != 0.0)
    reader.problems().Add(reader.PointerTo("k4"),
                          "is " + FormatNumber(*k4) + " (expected 0 or absent; " + kUndistortFirst + ")");
}

double FocalFromAngle(int size_px, double angle_rad) { return 0.5 * size_px / std::tan(0.5 * angle_rad); }

// One focal length: fl (may be absent if the angle is given), angle optional.
double ReadFocal(JsonObjectReader& reader, const char* fl_key, const char* angle_key, int size_px,
                 std::optional<double> fallback) {
  const std::optional<double> angle = reader.OptionalNumber(angle_key, 1e-6, kPi - 1e-6);
  const bool angle_ok = angle.has_value() && *angle > 0 && *angle < kPi;
  std::optional<double> focal;
  if (reader.Has(fl_key)) {
    focal = reader.Number(fl_key, 1e-3, kMaxFocalPx);
  } else {
    reader.OptionalNumber(fl_key);  // marks the key as known
    if (angle_ok && size_px > 0) {
      focal = FocalFromAngle(size_px, *angle);
    } else if (fallback.has_value()) {
      focal = fallback;
    } else {
      reader.problems().Add(reader.PointerTo(fl_key),
                            std::string("missing (expected ") + fl_key + " or " + angle_key + ")");
      return 0.0;
    }
  }
  if (angle_ok && focal.has_value() && *focal > 0 && size_px > 0) {
    const double implied = FieldOfView(size_px, *focal);
    if (std::abs(implied - *angle) > kAngleTolerance)
      reader.problems().Add(reader.PointerTo(angle_key),
                            "is " + FormatNumber(*angle) + " but " + fl_key + " implies " + FormatNumber(implied) +
                                " (expected them to agree within " + FormatNumber(kAngleTolerance) + " rad)");
  }
  return focal.value_or(0.0);
}

}  // namespace

const std::vector<std::string>& CameraKeyNames() {
  static const std::vector<std::string> names = {
      "camera_model", "w",  "h",  "fl_x", "fl_y", "camera_angle_x", "camera_angle_y", "cx", "cy", "k1",
      "k2",           "p1", "p2", "k3",   "k4",   "is_fisheye"};
  return names;
}

double FieldOfView(int size_px, double focal_px) { return 2.0 * std::atan(0.5 * size_px / focal_px); }

std::string ReadCameraKeys(JsonObjectReader& reader, CameraIntrinsics& camera) {
  std::string model = "OPENCV";
  if (const auto m = reader.OptionalString("camera_model")) {
    if (*m == "OPENCV" || *m == "PINHOLE") {
      model = *m;
    } else {
      reader.problems().Add(reader.PointerTo("camera_model"),
                            "is \"" + *m + "\" (expected \"OPENCV\" or \"PINHOLE\"; " + kUndistortFirst + ")");
    }
  }
  RejectFisheyeKeys(reader);
  size_t before = reader.problems().items().size();
  // Whole numbers written as floats (instant-ngp's "w": 1080.0) are sizes too.
  camera.width = static_cast<int>(reader.WholeNumber("w", 1, kMaxImageSide));
  const bool width_ok = reader.problems().items().size() == before;
  before = reader.problems().items().size();
  camera.height = static_cast<int>(reader.WholeNumber("h", 1, kMaxImageSide));
  const bool height_ok = reader.problems().items().size() == before;
  camera.fx = ReadFocal(reader, "fl_x", "camera_angle_x", width_ok ? camera.width : 0, std::nullopt);
  // fl_y defaults to fl_x; when fl_x itself is bad that was reported already.
  const bool have_x = reader.Has("fl_x") || reader.Has("camera_angle_x");
  camera.fy = ReadFocal(reader, "fl_y", "camera_angle_y", height_ok ? camera.height : 0,
                        have_x ? std::optional<double>(camera.fx) : std::nullopt);
  // The principal point lies inside the image for every real camera (checked
  // only against a valid size, so one bad "w" is one problem).
  camera.cx = reader.Number("cx", 0.0, width_ok ? camera.width : kMaxImageSide);
  camera.cy = reader.Number("cy", 0.0, height_ok ? camera.height : kMaxImageSide);
  const char* keys[] = {"k1", "k2", "p1", "p2", "k3"};
  double* values[] = {&camera.k1, &camera.k2, &camera.p1, &camera.p2, &camera.k3};
  for (int i = 0; i < 5; ++i) {
    *values[i] = reader.OptionalNumber(keys[i], -kMaxDistortion, kMaxDistortion).value_or(0.0);
    if (!std::isfinite(*values[i])) *values[i] = 0.0;
    if (model == "PINHOLE" && *values[i] != 0.0)
      reader.problems().Add(reader.PointerTo(keys[i]),
                            "is " + FormatNumber(*values[i]) + " (expected 0 or absent for camera_model PINHOLE)");
  }
  return model;
}

void WriteCameraKeys(const CameraIntrinsics& camera, const std::string& camera_model, Json& object) {
  object["camera_model"] = camera_model;
  object["fl_x"] = camera.fx;
  object["fl_y"] = camera.fy;
  object["cx"] = camera.cx;
  object["cy"] = camera.cy;
  object["w"] = camera.width;
  object["h"] = camera.height;
  object["camera_angle_x"] = FieldOfView(camera.width, camera.fx);
  object["camera_angle_y"] = FieldOfView(camera.height, camera.fy);
  object["k1"] = camera.k1;
  object["k2"] = camera.k2;
  object["p1"] = camera.p1;
  object["p2"] = camera.p2;
  object["k3"] = camera.k3;
}

}  // namespace nerfar
