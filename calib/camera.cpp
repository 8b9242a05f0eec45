#include "calib/camera.h"

#include <algorithm>
#include <cmath>

#include "calib/core/error.h"
#include "calib/core/image.h"

namespace nerfar {
namespace {

bool Finite(double v) { return std::isfinite(v); }

// Jacobian of Distort at (x, y): [[a, b], [c, d]].
void DistortJacobian(const CameraIntrinsics& cam, double x, double y, double& a, double& b, double& c, double& d) {
  const double r2 = x * x + y * y;
  const double radial = 1 + r2 * (cam.k1 + r2 * (cam.k2 + r2 * cam.k3));
  // d(radial)/d(r2)
  const double dradial = cam.k1 + r2 * (2 * cam.k2 + 3 * cam.k3 * r2);
  // xd = x*radial + 2 p1 x y + p2 (r2 + 2 x^2); yd = y*radial + p1 (r2 + 2 y^2) + 2 p2 x y
  a = radial + x * dradial * 2 * x + 2 * cam.p1 * y + cam.p2 * 6 * x;
  b = x * dradial * 2 * y + 2 * cam.p1 * x + cam.p2 * 2 * y;
  c = y * dradial * 2 * x + cam.p1 * 2 * x + 2 * cam.p2 * y;
  d = radial + y * dradial * 2 * y + cam.p1 * 6 * y + 2 * cam.p2 * x;
}

}  // namespace

std::vector<std::string> CameraIntrinsics::Validate() const {
  std::vector<std::string> problems;
  if (width < 1 || width > kMaxImageSide)
    problems.push_back("width is " + std::to_string(width) + " (expected 1 to " + std::to_string(kMaxImageSide) + ")");
  if (height < 1 || height > kMaxImageSide)
    problems.push_back("height is " + std::to_string(height) + " (expected 1 to " + std::to_string(kMaxImageSide) +
                       ")");
  if (!Finite(fx) || !(fx > 0)) problems.push_back("fx is " + std::to_string(fx) + " (expected a positive number)");
  if (!Finite(fy) || !(fy > 0)) problems.push_back("fy is " + std::to_string(fy) + " (expected a positive number)");
  if (!Finite(cx)) problems.push_back("cx is not finite (expected a finite number)");
  if (!Finite(cy)) problems.push_back("cy is not finite (expected a finite number)");
  const char* names[] = {"k1", "k2", "p1", "p2", "k3"};
  const double values[] = {k1, k2, p1, p2, k3};
  for (int i = 0; i < 5; ++i)
    if (!Finite(values[i])) problems.push_back(std::string(names[i]) + " is not finite (expected a finite number)");
  return problems;
}

CameraIntrinsics CameraIntrinsics::Scaled(int new_width, int new_height) const {
  NERFAR_CHECK_GT(width, 0);
  NERFAR_CHECK_GT(height, 0);
  CameraIntrinsics out = *this;
  const double sx = static_cast<double>(new_width) / width;
  const double sy = static_cast<double>(new_height) / height;
  out.width = new_width;
  out.height = new_height;
  // Continuous coordinates with the origin at the image corner scale exactly.
  out.fx = fx * sx;
  out.cx = cx * sx;
  out.fy = fy * sy;
  out.cy = cy * sy;
  return out;
}

Vec2 ToOpenCvPrincipalPoint(const CameraIntrinsics& camera) { return {camera.cx - 0.5, camera.cy - 0.5}; }

void FromOpenCvPrincipalPoint(CameraIntrinsics& camera, double cx_opencv, double cy_opencv) {
  camera.cx = cx_opencv + 0.5;
  camera.cy = cy_opencv + 0.5;
}

Vec2 Distort(const CameraIntrinsics& cam, const Vec2& p) {
  const double x = p.x, y = p.y;
  const double r2 = x * x + y * y;
  const double radial = 1 + r2 * (cam.k1 + r2 * (cam.k2 + r2 * cam.k3));
  return {x * radial + 2 * cam.p1 * x * y + cam.p2 * (r2 + 2 * x * x),
          y * radial + cam.p1 * (r2 + 2 * y * y) + 2 * cam.p2 * x * y};
}

Vec2 Undistort(const CameraIntrinsics& cam, const Vec2& distorted) {
  if (!cam.HasDistortion()) return distorted;
  // Fixed-point iteration gets close for moderate distortion; Newton steps
  // with the analytic Jacobian then converge quadratically. Each Newton step
  // is accepted only if it lowers the residual, so a poorly conditioned
  // corner (far outside the image) cannot diverge.
  Vec2 u = distorted;
  for (int i = 0; i < 5; ++i) {
    const double x = u.x, y = u.y;
    const double r2 = x * x + y * y;
    const double radial = 1 + r2 * (cam.k1 + r2 * (cam.k2 + r2 * cam.k3));
    if (!(std::abs(radial) > 1e-6)) break;
    const double dx = 2 * cam.p1 * x * y + cam.p2 * (r2 + 2 * x * x);
    const double dy = cam.p1 * (r2 + 2 * y * y) + 2 * cam.p2 * x * y;
    const Vec2 next{(distorted.x - dx) / radial, (distorted.y - dy) / radial};
    if (!Finite(next.x) || !Finite(next.y)) break;
    u = next;
  }
  const auto residual = [&](const Vec2& q) {
    const Vec2 d = Distort(cam, q);
    return Vec2{d.x - distorted.x, d.y - distorted.y};
  };
  Vec2 r = residual(u);
  double err = r.x * r.x + r.y * r.y;
  for (int i = 0; i < 20 && err > 1e-30; ++i) {
    double a, b, c, d;
    DistortJacobian(cam, u.x, u.y, a, b, c, d);
    const double det = a * d - b * c;
    if (!(std::abs(det) > 1e-300)) break;
    const Vec2 step{(d * r.x - b * r.y) / det, (-c * r.x + a * r.y) / det};
    const Vec2 candidate{u.x - step.x, u.y - step.y};
    const Vec2 rc = residual(candidate);
    const double err_c = rc.x * rc.x + rc.y * rc.y;
    if (!(err_c < err)) break;
    u = candidate;
    r = rc;
    err = err_c;
  }
  return u;
}

bool Project(const CameraIntrinsics& camera, const Vec3& p_camera, Vec2& pixel) {
  if (!(p_camera.z > 0)) return false;
  const Vec2 d = Distort(camera, {p_camera.x / p_camera.z, p_camera.y / p_camera.z});
  pixel = {camera.fx * d.x + camera.cx, camera.fy * d.y + camera.cy};
  return true;
}

Vec3 Unproject(const CameraIntrinsics& camera, const Vec2& pixel) {
  const Vec2 u = Undistort(camera, {(pixel.x - camera.cx) / camera.fx, (pixel.y - camera.cy) / camera.fy});
  return Normalized(Vec3{u.x, u.y, 1.0});
}

void UndistortMaps(const CameraIntrinsics& camera, std::vector<float>& map_x, std::vector<float>& map_y) {
  NERFAR_CHECK(camera.Validate().empty());
  const size_t count = static_cast<size_t>(camera.width) * camera.height;
  map_x.resize(count);
  map_y.resize(count);
  for (int j = 0; j < camera.height; ++j) {
    const double yn = (j + 0.5 - camera.cy) / camera.fy;
    for (int i = 0; i < camera.width; ++i) {
      const Vec2 d = Distort(camera, {(i + 0.5 - camera.cx) / camera.fx, yn});
      const size_t k = static_cast<size_t>(j) * camera.width + i;
      map_x[k] = static_cast<float>(camera.fx * d.x + camera.cx);
      map_y[k] = static_cast<float>(camera.fy * d.y + camera.cy);
    }
  }
}

}  // namespace nerfar
