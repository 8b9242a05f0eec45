#include "tracking/pose_filter.h"

#include <cmath>

#include "calib/core/error.h"

namespace nerfar {
namespace {
constexpr double kNominalDt = 1.0 / 30.0;

// R advanced by the world-frame rotation vector w: exp(w) * R.
Mat3 Rotated(const Mat3& rotation, const Vec3& w) {
  const double angle = Length(w);
  if (angle < 1e-15) return rotation;
  return RotationFromAxisAngle(w, angle) * rotation;
}
}  // namespace

const char* FilterKindName(FilterKind kind) {
  switch (kind) {
    case FilterKind::kNone:
      return "none";
    case FilterKind::kExponential:
      return "exponential";
    case FilterKind::kConstantVelocity:
      return "constant-velocity";
  }
  return "unknown";
}

FilterKind ParseFilterKind(const std::string& name) {
  if (name == "none") return FilterKind::kNone;
  if (name == "exponential" || name == "ema") return FilterKind::kExponential;
  if (name == "constant-velocity" || name == "cv") return FilterKind::kConstantVelocity;
  ThrowInputError("filter", "'" + name + "' is unknown (expected none, exponential or constant-velocity)");
}

std::vector<std::string> PoseFilterOptions::Validate() const {
  std::vector<std::string> problems;
  if (!(alpha > 0 && alpha <= 1)) problems.push_back("alpha: " + std::to_string(alpha) + " (expected 0 < alpha <= 1)");
  if (!(beta > 0 && beta < 4 - 2 * alpha && beta < 1))
    problems.push_back("beta: " + std::to_string(beta) + " (expected 0 < beta < min(1, 4 - 2 alpha))");
  if (!(reset_translation_m > 0)) problems.push_back("reset_translation_m: must be > 0 metres");
  if (!(reset_rotation_rad > 0 && reset_rotation_rad <= kPi))
    problems.push_back("reset_rotation_rad: must be in (0, pi]");
  return problems;
}

PoseFilterOptions PoseFilterOptions::Preset(const std::string& name) {
  PoseFilterOptions o;
  if (name == "none") {
    o.kind = FilterKind::kNone;
  } else if (name == "smooth") {
    o.alpha = 0.3;
    o.beta = 0.05;
  } else if (name == "balanced") {
    o.alpha = 0.5;
    o.beta = 0.15;
  } else if (name == "responsive") {
    o.alpha = 0.75;
    o.beta = 0.35;
  } else {
    ThrowInputError("filter preset", "'" + name + "' is unknown (expected smooth, balanced, responsive or none)");
  }
  return o;
}

PoseFilter::PoseFilter(const PoseFilterOptions& options) : options_(options) {
  const std::vector<std::string> problems = options.Validate();
  if (!problems.empty()) {
    Problems list("pose filter options");
    for (const std::string& p : problems) list.Add("", p);
    list.ThrowIfAny();
  }
}

Pose PoseFilter::Predict(double dt_s) const {
  if (!initialized_ || options_.kind != FilterKind::kConstantVelocity) return estimate_;
  const double dt = dt_s > 0 ? dt_s : kNominalDt;
  return {Rotated(estimate_.rotation, angular_velocity_ * dt), estimate_.translation + linear_velocity_ * dt};
}

Pose PoseFilter::Update(const Pose& measured, double dt_s) {
  last_reset_ = false;
  const double dt = dt_s > 0 ? dt_s : kNominalDt;
  if (options_.kind == FilterKind::kNone) {
    estimate_ = measured;
    initialized_ = true;
    return estimate_;
  }
  const Pose predicted = Predict(dt);
  const Vec3 dr = AxisAngleFromRotation(measured.rotation * predicted.rotation.Transposed());  // world frame
  const Vec3 dt_m = measured.translation - predicted.translation;
  if (!initialized_ || Length(dr) > options_.reset_rotation_rad || Length(dt_m) > options_.reset_translation_m) {
    last_reset_ = initialized_;
    initialized_ = true;
    estimate_ = measured;
    angular_velocity_ = {};
    linear_velocity_ = {};
    return estimate_;
  }
  const double a = options_.alpha;
  estimate_ = {Rotated(predicted.rotation, dr * a), predicted.translation + dt_m * a};
  if (options_.kind == FilterKind::kConstantVelocity) {
    const double b = options_.beta / dt;
    angular_velocity_ += dr * b;
    linear_velocity_ += dt_m * b;
  }
  return estimate_;
}

}  // namespace nerfar
