// Internal to render/insert: small helpers every stage of a frame uses.
#pragma once

#include <chrono>
#include <cmath>

#include "calib/core/math.h"

namespace nerfar {

using InsertClock = std::chrono::steady_clock;
inline double MsSince(InsertClock::time_point t0) {
  return std::chrono::duration<double, std::milli>(InsertClock::now() - t0).count();
}

// An object's bounding sphere in the world.
struct WorldSphere {
  Vec3f center;
  float radius = 0;
};

}  // namespace nerfar
