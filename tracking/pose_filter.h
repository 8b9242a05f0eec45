// Temporal filtering of camera poses T_world_camera (metres, radians) on
// SE(3), treated as rotation (world frame) and camera centre separately.
// kExponential: pose += alpha * (measured - pose); cheap, lags a moving
// camera by (1 - alpha) / alpha frames. kConstantVelocity: an alpha-beta
// filter that predicts with the estimated velocity, so a steady motion has no
// lag, at some overshoot on sudden stops. kNone passes measurements through.
// A measurement farther than the reset distance from the prediction restarts
// the filter (a real jump, or a new track after a loss).
#pragma once

#include <string>
#include <vector>

#include "calib/core/math.h"

namespace nerfar {

enum class FilterKind { kNone, kExponential, kConstantVelocity };
const char* FilterKindName(FilterKind kind);
// "none", "exponential" (or "ema"), "constant-velocity" (or "cv"); InputError otherwise.
FilterKind ParseFilterKind(const std::string& name);

struct PoseFilterOptions {
  FilterKind kind = FilterKind::kConstantVelocity;
  // Weight of a new measurement, (0, 1]. Lower: less jitter, more latency.
  double alpha = 0.5;
  // Velocity gain of the constant-velocity filter, (0, 1); stable for
  // 0 < beta < 4 - 2 alpha, critically damped near beta = alpha^2 / (2 - alpha).
  double beta = 0.15;
  // A measurement this far from the prediction restarts the filter.
  double reset_translation_m = 0.05;
  double reset_rotation_rad = 10.0 * kPi / 180.0;

  std::vector<std::string> Validate() const;
  // "smooth" (low jitter), "balanced" (default), "responsive" (low latency), "none".
  static PoseFilterOptions Preset(const std::string& name);
};

class PoseFilter {
 public:
  explicit PoseFilter(const PoseFilterOptions& options = {});
  const PoseFilterOptions& options() const { return options_; }
  void Reset() { initialized_ = false; }
  bool initialized() const { return initialized_; }
  // Pose expected at the next measurement dt_s seconds after the last one
  // (the last estimate for kNone / kExponential, or if not initialised).
  Pose Predict(double dt_s) const;
  // Feeds a measurement taken dt_s after the previous one (dt_s <= 0: one
  // nominal frame, 1/30 s) and returns the filtered pose.
  Pose Update(const Pose& measured, double dt_s);
  // True if the last Update restarted the filter because of a jump.
  bool last_was_reset() const { return last_reset_; }

 private:
  PoseFilterOptions options_;
  bool initialized_ = false;
  bool last_reset_ = false;
  Pose estimate_;
  Vec3 angular_velocity_;  // rad/s, world frame
  Vec3 linear_velocity_;   // m/s, world frame (camera centre)
};

}  // namespace nerfar
