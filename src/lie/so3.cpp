#include "inekf_semantic_mapping/lie/so3.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace inekf_semantic_mapping {
namespace lie {
namespace {

// Below this angle the coefficient closed forms lose digits to cancellation (e.g. Gamma_2's
// (t^2 + 2 cos t - 2) / (2 t^4) keeps only ~4 digits at t = 1e-3), so they are evaluated by
// their Taylor series, truncated where the next term is below 1e-17 of the leading one.
constexpr double kSeriesAngle = 0.2;

struct GammaCoefficients {
  double a, b, c, d;  // sin t / t, (1 - cos t) / t^2, (t - sin t) / t^3, (t^2 + 2cos t - 2)/(2t^4)
};

GammaCoefficients coefficients(double theta) {
  const double t2 = theta * theta;
  if (theta < kSeriesAngle) {
    const double t4 = t2 * t2, t6 = t4 * t2, t8 = t4 * t4;
    return {1.0 - t2 / 6.0 + t4 / 120.0 - t6 / 5040.0 + t8 / 362880.0,
            0.5 - t2 / 24.0 + t4 / 720.0 - t6 / 40320.0 + t8 / 3628800.0,
            1.0 / 6.0 - t2 / 120.0 + t4 / 5040.0 - t6 / 362880.0 + t8 / 39916800.0,
            1.0 / 24.0 - t2 / 720.0 + t4 / 40320.0 - t6 / 3628800.0 + t8 / 479001600.0};
  }
  const double s = std::sin(theta), c = std::cos(theta);
  return {s / theta, (1.0 - c) / t2, (theta - s) / (t2 * theta),
          (t2 + 2.0 * c - 2.0) / (2.0 * t2 * t2)};
}

}  // namespace

Eigen::Matrix3d hat(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return m;
}

Eigen::Vector3d vee(const Eigen::Matrix3d& m) {
  return 0.5 * Eigen::Vector3d(m(2, 1) - m(1, 2), m(0, 2) - m(2, 0), m(1, 0) - m(0, 1));
}

Eigen::Matrix3d gamma0(const Eigen::Vector3d& phi) {
  const GammaCoefficients k = coefficients(phi.norm());
  const Eigen::Matrix3d w = hat(phi);
  return Eigen::Matrix3d::Identity() + k.a * w + k.b * w * w;
}

Eigen::Matrix3d gamma1(const Eigen::Vector3d& phi) {
  const GammaCoefficients k = coefficients(phi.norm());
  const Eigen::Matrix3d w = hat(phi);
  return Eigen::Matrix3d::Identity() + k.b * w + k.c * w * w;
}

Eigen::Matrix3d gamma2(const Eigen::Vector3d& phi) {
  const GammaCoefficients k = coefficients(phi.norm());
  const Eigen::Matrix3d w = hat(phi);
  return 0.5 * Eigen::Matrix3d::Identity() + k.c * w + k.d * w * w;
}

Eigen::Matrix3d expSO3(const Eigen::Vector3d& phi) { return gamma0(phi); }

Eigen::Vector3d logSO3(const Eigen::Matrix3d& r) {
  const double cos_theta = std::clamp(0.5 * (r.trace() - 1.0), -1.0, 1.0);
  const Eigen::Vector3d sin_axis = vee(r);  // sin(theta) * axis
  const double sin_theta = sin_axis.norm();
  const double theta = std::atan2(sin_theta, cos_theta);
  if (cos_theta > -0.9) {
    // theta / sin(theta) has no cancellation; only 0/0 at theta -> 0 needs the series.
    const double scale = theta < kSmallAngle ? 1.0 + theta * theta / 6.0 : theta / sin_theta;
    return scale * sin_axis;
  }
  // Near pi sin(theta) carries no precision: take the axis from the symmetric part,
  // (R + R^T)/2 - cos(theta) I = (1 - cos(theta)) n n^T, and its sign from the skew part.
  const Eigen::Matrix3d nnt =
      (0.5 * (r + r.transpose()) - cos_theta * Eigen::Matrix3d::Identity()) / (1.0 - cos_theta);
  int column = 0;
  nnt.diagonal().maxCoeff(&column);
  Eigen::Vector3d axis = nnt.col(column) / std::sqrt(std::max(nnt(column, column), 1e-300));
  axis.normalize();
  if (axis.dot(sin_axis) < 0.0) axis = -axis;
  return theta * axis;
}

Eigen::Matrix3d leftJacobianSO3(const Eigen::Vector3d& phi) { return gamma1(phi); }
Eigen::Matrix3d rightJacobianSO3(const Eigen::Vector3d& phi) { return gamma1(-phi); }

Eigen::Matrix3d leftJacobianInverseSO3(const Eigen::Vector3d& phi) {
  const double theta = phi.norm();
  const double t2 = theta * theta;
  // 1/t^2 - (1 + cos t) / (2 t sin t)
  const double e = theta < kSeriesAngle
                       ? 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0 + t2 * t2 * t2 / 1209600.0
                       : 1.0 / t2 - (1.0 + std::cos(theta)) / (2.0 * theta * std::sin(theta));
  const Eigen::Matrix3d w = hat(phi);
  return Eigen::Matrix3d::Identity() - 0.5 * w + e * w * w;
}

Eigen::Matrix3d rightJacobianInverseSO3(const Eigen::Vector3d& phi) {
  return leftJacobianInverseSO3(-phi);
}

Eigen::Matrix3d normalizeRotation(const Eigen::Matrix3d& r) {
  return Eigen::Quaterniond(r).normalized().toRotationMatrix();
}

}  // namespace lie
}  // namespace inekf_semantic_mapping
