// Small fixed-size vector and rigid-transform types used across modules.
// Vec3 is double (poses, geometry), Vec3f float (per-pixel and per-sample hot
// paths). Pose T_a_b maps points in frame b to frame a: p_a = T_a_b * p_b, and
// T_a_b * T_b_c = T_a_c. Heavier linear algebra (solvers) uses Eigen in .cpp.
#pragma once

#include <array>
#include <cmath>

namespace nerfar {

template <typename T>
struct Vec3T {
  T x = 0, y = 0, z = 0;

  constexpr Vec3T() = default;
  constexpr Vec3T(T x_, T y_, T z_) : x(x_), y(y_), z(z_) {}
  template <typename U>
  constexpr explicit Vec3T(const Vec3T<U>& o)
      : x(static_cast<T>(o.x)), y(static_cast<T>(o.y)), z(static_cast<T>(o.z)) {}

  constexpr T operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  constexpr T& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
  constexpr Vec3T operator+(const Vec3T& o) const { return {x + o.x, y + o.y, z + o.z}; }
  constexpr Vec3T operator-(const Vec3T& o) const { return {x - o.x, y - o.y, z - o.z}; }
  constexpr Vec3T operator-() const { return {-x, -y, -z}; }
  constexpr Vec3T operator*(T s) const { return {x * s, y * s, z * s}; }
  constexpr Vec3T operator/(T s) const { return {x / s, y / s, z / s}; }
  constexpr Vec3T operator*(const Vec3T& o) const { return {x * o.x, y * o.y, z * o.z}; }
  Vec3T& operator+=(const Vec3T& o) {
    x += o.x;
    y += o.y;
    z += o.z;
    return *this;
  }
  Vec3T& operator-=(const Vec3T& o) {
    x -= o.x;
    y -= o.y;
    z -= o.z;
    return *this;
  }
  Vec3T& operator*=(T s) {
    x *= s;
    y *= s;
    z *= s;
    return *this;
  }
  constexpr bool operator==(const Vec3T& o) const = default;
};

template <typename T>
constexpr Vec3T<T> operator*(T s, const Vec3T<T>& v) {
  return v * s;
}
template <typename T>
constexpr T Dot(const Vec3T<T>& a, const Vec3T<T>& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
template <typename T>
constexpr Vec3T<T> Cross(const Vec3T<T>& a, const Vec3T<T>& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <typename T>
T Length(const Vec3T<T>& v) {
  return std::sqrt(Dot(v, v));
}
// Unit vector; the zero vector stays zero (callers that need a direction check).
template <typename T>
Vec3T<T> Normalized(const Vec3T<T>& v) {
  const T n = Length(v);
  return n > T(0) ? v / n : v;
}

// Every component finite (no NaN, no infinity).
template <typename T>
bool Finite(const Vec3T<T>& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

using Vec3 = Vec3T<double>;
using Vec3f = Vec3T<float>;

// Row-major 3x3 matrix.
struct Mat3 {
  std::array<double, 9> m{1, 0, 0, 0, 1, 0, 0, 0, 1};

  static Mat3 Identity() { return {}; }
  static Mat3 FromRows(const Vec3& r0, const Vec3& r1, const Vec3& r2) {
    return {{r0.x, r0.y, r0.z, r1.x, r1.y, r1.z, r2.x, r2.y, r2.z}};
  }
  static Mat3 FromColumns(const Vec3& c0, const Vec3& c1, const Vec3& c2) {
    return {{c0.x, c1.x, c2.x, c0.y, c1.y, c2.y, c0.z, c1.z, c2.z}};
  }
  double operator()(int r, int c) const { return m[r * 3 + c]; }
  double& operator()(int r, int c) { return m[r * 3 + c]; }
  Vec3 Row(int r) const { return {m[r * 3], m[r * 3 + 1], m[r * 3 + 2]}; }
  Vec3 Column(int c) const { return {m[c], m[3 + c], m[6 + c]}; }
  Vec3 operator*(const Vec3& v) const { return {Dot(Row(0), v), Dot(Row(1), v), Dot(Row(2), v)}; }
  Mat3 operator*(const Mat3& o) const {
    Mat3 r;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) r(i, j) = Dot(Row(i), o.Column(j));
    return r;
  }
  Mat3 Transposed() const { return FromColumns(Row(0), Row(1), Row(2)); }
};

// Rotation matrix from axis-angle (Rodrigues); axis need not be unit, angle in radians.
Mat3 RotationFromAxisAngle(const Vec3& axis, double angle_rad);
// Rotation vector (axis * angle, radians) of a rotation matrix.
Vec3 AxisAngleFromRotation(const Mat3& rotation);
// Angle in radians of the relative rotation a^T b.
double RotationAngleBetween(const Mat3& a, const Mat3& b);

// Rigid transform T_a_b: p_a = rotation * p_b + translation.
struct Pose {
  Mat3 rotation;
  Vec3 translation;

  static Pose Identity() { return {}; }
  Vec3 operator*(const Vec3& p) const { return rotation * p + translation; }
  Pose operator*(const Pose& o) const { return {rotation * o.rotation, rotation * o.translation + translation}; }
  Pose Inverse() const {
    const Mat3 rt = rotation.Transposed();
    return {rt, -(rt * translation)};
  }
  Vec3 Rotate(const Vec3& v) const { return rotation * v; }
  // Row-major 4x4 with last row 0 0 0 1.
  std::array<double, 16> ToMatrix4() const;
  // From a row-major 4x4; the rotation block is re-orthonormalised (SVD-free:
  // Gram-Schmidt), so slightly noisy files are accepted.
  static Pose FromMatrix4(const std::array<double, 16>& m);
};

// Camera pose T_world_camera (OpenCV axes: x right, y down, z forward) at
// `eye` looking at `target`, world z up, no roll (x horizontal). Looking
// straight up or down, x is world +x.
Pose LookAt(const Vec3& eye, const Vec3& target);

constexpr double kPi = 3.14159265358979323846;

}  // namespace nerfar
