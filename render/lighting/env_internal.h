// Small helpers shared by the environment estimate's source files
// (render/lighting/env_*.cpp); not part of the module's interface.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "calib/core/math.h"
#include "calib/core/random.h"
#include "render/sg/sg.h"

namespace nerfar::env_internal {

// Counter-based randomness: a number is fixed by (seed, stream, item, k), so
// results do not depend on the order or the thread that draws them.
inline double Uniform(uint64_t seed, uint64_t stream, uint64_t item, uint64_t k) {
  return UnitDouble(CounterHash(seed, stream, item, k));
}
enum Stream : uint64_t { kViewDir = 1, kPixelPick = 2, kRayTurn = 3, kBundleTurn = 4 };

inline double Y(const Vec3& rgb) { return LuminanceOf(rgb); }
inline Vec3 ToD(const Vec3f& v) { return Vec3(v); }
inline double Channel(const Vec3f& v, int c) { return v[c]; }

// t, b with (t, b, n) a right-handed orthonormal frame (n unit).
inline void OrthonormalBasis(const Vec3& n, Vec3& t, Vec3& b) {
  const Vec3 helper = std::fabs(n.z) < 0.9 ? Vec3{0, 0, 1} : Vec3{1, 0, 0};
  t = Normalized(Cross(helper, n));
  b = Cross(n, t);
}

}  // namespace nerfar::env_internal
