#include "calib/scene_frame.h"

#include <Eigen/Dense>
#include <cmath>

namespace nerfar {
namespace {

Eigen::Vector3d ToEigen(const Vec3& v) { return {v.x, v.y, v.z}; }

Aabb MovedBox(const Aabb& box, const Similarity& s) {
  Aabb out{{1e300, 1e300, 1e300}, {-1e300, -1e300, -1e300}};
  for (int corner = 0; corner < 8; ++corner) {
    const Vec3 p = s.Apply(Vec3{corner & 1 ? box.max.x : box.min.x, corner & 2 ? box.max.y : box.min.y,
                                corner & 4 ? box.max.z : box.min.z});
    for (int k = 0; k < 3; ++k) {
      out.min[k] = std::min(out.min[k], p[k]);
      out.max[k] = std::max(out.max[k], p[k]);
    }
  }
  return out;
}

}  // namespace

bool ClosestPointToLines(const std::vector<Vec3>& origins, const std::vector<Vec3>& directions, Vec3& point) {
  // Σ (I - d dᵀ) p = Σ (I - d dᵀ) o.
  Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < origins.size() && i < directions.size(); ++i) {
    const Eigen::Vector3d d = ToEigen(directions[i]).normalized();
    const Eigen::Matrix3d projector = Eigen::Matrix3d::Identity() - d * d.transpose();
    a += projector;
    b += projector * ToEigen(origins[i]);
  }
  if (origins.size() < 2) return false;
  // Parallel lines leave a null direction: the smallest eigenvalue near 0.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(a);
  if (!(eigen.eigenvalues()(0) > 1e-6 * eigen.eigenvalues()(2))) return false;
  const Eigen::Vector3d p = a.ldlt().solve(b);
  point = {p.x(), p.y(), p.z()};
  return true;
}

Similarity FitSimilarity(const std::vector<Vec3>& from, const std::vector<Vec3>& to, double* rms) {
  const size_t n = std::min(from.size(), to.size());
  Eigen::Vector3d mean_from = Eigen::Vector3d::Zero(), mean_to = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < n; ++i) mean_from += ToEigen(from[i]) / double(n), mean_to += ToEigen(to[i]) / double(n);
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  double variance_from = 0;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d a = ToEigen(from[i]) - mean_from, b = ToEigen(to[i]) - mean_to;
    covariance += b * a.transpose() / double(n);
    variance_from += a.squaredNorm() / double(n);
  }
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(covariance, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d sign = Eigen::Matrix3d::Identity();
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0) sign(2, 2) = -1;
  const Eigen::Matrix3d r = svd.matrixU() * sign * svd.matrixV().transpose();
  Similarity s;
  s.scale = (svd.singularValues().asDiagonal() * sign).trace() / variance_from;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) s.rotation(i, j) = r(i, j);
  const Eigen::Vector3d t = mean_to - s.scale * r * mean_from;
  s.translation = {t.x(), t.y(), t.z()};
  if (rms != nullptr) {
    double sum = 0;
    for (size_t i = 0; i < n; ++i) sum += std::pow(Length(s.Apply(from[i]) - to[i]), 2);
    *rms = n > 0 ? std::sqrt(sum / double(n)) : 0;
  }
  return s;
}

Vec3 UpFromCameras(const std::vector<Pose>& T_world_cameras) {
  // Without roll every camera's x axis (image right) is horizontal: up is the
  // direction most nearly perpendicular to all of them, the eigenvector of
  // Σ x xᵀ with the smallest eigenvalue. Its sign: along the image-up axes
  // (OpenCV -y), which all lean up.
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  Vec3 image_up;
  for (const Pose& pose : T_world_cameras) {
    const Eigen::Vector3d x = ToEigen(pose.rotation.Column(0));
    scatter += x * x.transpose();
    image_up -= pose.rotation.Column(1);
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(scatter);
  const Eigen::Vector3d e = eigen.eigenvectors().col(0);
  const Vec3 up{e.x(), e.y(), e.z()};
  return Dot(up, image_up) < 0 ? -up : up;
}

Mat3 RotationBetween(const Vec3& from, const Vec3& to) {
  const Vec3 axis = Cross(from, to);
  const double sine = Length(axis), cosine = Dot(from, to);
  if (sine < 1e-12) {
    if (cosine > 0) return Mat3::Identity();
    // Opposite: half a turn about any axis perpendicular to `from`.
    const Vec3 other = std::abs(from.x) < 0.9 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
    return RotationFromAxisAngle(Cross(from, other), kPi);
  }
  return RotationFromAxisAngle(axis, std::atan2(sine, cosine));
}

Dataset TransformDataset(const Dataset& dataset, const Similarity& similarity) {
  Dataset out = dataset;
  for (DatasetFrame& frame : out.frames) frame.T_world_camera = similarity.Apply(frame.T_world_camera);
  if (out.aabb) out.aabb = MovedBox(*out.aabb, similarity);
  if (out.ngp_box) out.ngp_box = MovedBox(*out.ngp_box, similarity);
  return out;
}

}  // namespace nerfar
