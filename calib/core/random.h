// Counter-based random numbers for every stage that samples (the synthetic
// renderer, NeRF training, environment estimation): a number is fixed by
// (seed, stream, item, sample), so any pixel or sample can be reproduced alone
// and results never depend on the order or thread that computes them.
#pragma once

#include <cmath>
#include <cstdint>

namespace nerfar {

// SplitMix64 finaliser: a bijective 64-bit mixer with full avalanche.
constexpr uint64_t Mix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

// The hash of a counter tuple, and its top bits as a uniform number in [0, 1).
constexpr uint64_t CounterHash(uint64_t seed, uint64_t stream, uint64_t item, uint64_t sample) {
  return Mix64(Mix64(Mix64(Mix64(seed) ^ stream) ^ item) ^ sample);
}
constexpr float UnitFloat(uint64_t h) { return static_cast<float>(h >> 40) * 0x1.0p-24f; }
constexpr double UnitDouble(uint64_t h) { return static_cast<double>(h >> 11) * 0x1.0p-53; }

class Rng {
 public:
  Rng(uint64_t seed, uint64_t stream, uint64_t item, uint64_t sample)
      : state_(CounterHash(seed, stream, item, sample)) {}
  explicit Rng(uint64_t seed) : state_(Mix64(seed)) {}

  uint64_t NextU64() {
    state_ += 0x9e3779b97f4a7c15ull;
    uint64_t z = state_;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  }
  // Uniform in [0, 1): 24 random bits, exactly representable as float.
  float Uniform() { return UnitFloat(NextU64()); }
  double UniformDouble() { return UnitDouble(NextU64()); }
  // Uniform in [lo, hi).
  double Uniform(double lo, double hi) { return lo + (hi - lo) * UniformDouble(); }
  // Standard normal (Box-Muller).
  double Normal() {
    const double u1 = 1.0 - UniformDouble(), u2 = UniformDouble();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
  }

 private:
  uint64_t state_;
};

}  // namespace nerfar
