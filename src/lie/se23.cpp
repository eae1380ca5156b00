#include "inekf_semantic_mapping/lie/se23.h"

#include <cmath>

#include "inekf_semantic_mapping/lie/so3.h"

namespace inekf_semantic_mapping {
namespace lie {

Matrix5d ExtendedPose::matrix() const {
  Matrix5d m = Matrix5d::Identity();
  m.block<3, 3>(0, 0) = rotation;
  m.block<3, 1>(0, 3) = velocity;
  m.block<3, 1>(0, 4) = position;
  return m;
}

ExtendedPose ExtendedPose::fromMatrix(const Matrix5d& m) {
  ExtendedPose x;
  x.rotation = m.block<3, 3>(0, 0);
  x.velocity = m.block<3, 1>(0, 3);
  x.position = m.block<3, 1>(0, 4);
  return x;
}

ExtendedPose ExtendedPose::inverse() const {
  ExtendedPose x;
  x.rotation = rotation.transpose();
  x.velocity = -x.rotation * velocity;
  x.position = -x.rotation * position;
  return x;
}

ExtendedPose ExtendedPose::operator*(const ExtendedPose& other) const {
  ExtendedPose x;
  x.rotation = rotation * other.rotation;
  x.velocity = rotation * other.velocity + velocity;
  x.position = rotation * other.position + position;
  return x;
}

Matrix9d ExtendedPose::adjoint() const {
  Matrix9d ad = Matrix9d::Zero();
  ad.block<3, 3>(0, 0) = rotation;
  ad.block<3, 3>(3, 3) = rotation;
  ad.block<3, 3>(6, 6) = rotation;
  ad.block<3, 3>(3, 0) = hat(velocity) * rotation;
  ad.block<3, 3>(6, 0) = hat(position) * rotation;
  return ad;
}

Matrix5d hatSE23(const Vector9d& xi) {
  Matrix5d m = Matrix5d::Zero();
  m.block<3, 3>(0, 0) = hat(xi.head<3>());
  m.block<3, 1>(0, 3) = xi.segment<3>(3);
  m.block<3, 1>(0, 4) = xi.segment<3>(6);
  return m;
}

ExtendedPose expSE23(const Vector9d& xi) {
  const Eigen::Matrix3d jl = leftJacobianSO3(xi.head<3>());
  ExtendedPose x;
  x.rotation = expSO3(xi.head<3>());
  x.velocity = jl * xi.segment<3>(3);
  x.position = jl * xi.segment<3>(6);
  return x;
}

Vector9d logSE23(const ExtendedPose& x) {
  Vector9d xi;
  xi.head<3>() = logSO3(x.rotation);
  const Eigen::Matrix3d jl_inv = leftJacobianInverseSO3(xi.head<3>());
  xi.segment<3>(3) = jl_inv * x.velocity;
  xi.segment<3>(6) = jl_inv * x.position;
  return xi;
}

namespace {

// The coupling block Q(phi, u) of SE(3)'s left Jacobian [J_l(phi) 0; Q J_l(phi)] for a tangent
// (phi, u) (Barfoot, State Estimation for Robotics, eq. 7.86b):
//   Q = 1/2 U + a (P U + U P + P U P) + b (P P U + U P P - 3 P U P) + c (P U P P + P P U P),
//   P = phi^, U = u^, a = (t - sin t) / t^3, b = (t^2 + 2 cos t - 2) / (2 t^4),
//   c = (2 t - 3 sin t + t cos t) / (2 t^5), t = |phi|.
// Below 0.2 rad the closed forms cancel (c's numerator is t^5 / 60 out of terms of size t: at
// 1e-4 rad it came out -1.35 instead of 1/120), so their Taylor series to t^6 instead, whose
// first omitted terms are below 1e-12 of each coefficient there (so3.cpp switches at the same
// angle for the same reason).
Eigen::Matrix3d couplingSE3(const Eigen::Vector3d& phi, const Eigen::Vector3d& u) {
  const double t = phi.norm();
  double a, b, c;
  if (t < 0.2) {
    const double t2 = t * t, t4 = t2 * t2, t6 = t4 * t2;
    a = 1.0 / 6.0 - t2 / 120.0 + t4 / 5040.0 - t6 / 362880.0;
    b = 1.0 / 24.0 - t2 / 720.0 + t4 / 40320.0 - t6 / 3628800.0;
    c = 1.0 / 120.0 - t2 / 2520.0 + t4 / 120960.0 - t6 / 9979200.0;
  } else {
    const double s = std::sin(t), co = std::cos(t), t2 = t * t;
    a = (t - s) / (t2 * t);
    b = (t2 + 2.0 * co - 2.0) / (2.0 * t2 * t2);
    c = (2.0 * t - 3.0 * s + t * co) / (2.0 * t2 * t2 * t);
  }
  const Eigen::Matrix3d p = hat(phi), uu = hat(u);
  const Eigen::Matrix3d pu = p * uu, up = uu * p, pup = p * up;
  return 0.5 * uu + a * (pu + up + pup) + b * (p * pu + up * p - 3.0 * pup) +
         c * (pup * p + p * pup);
}

}  // namespace

Matrix9d rightJacobianSE23(const Vector9d& xi) {
  // J_r(xi) = J_l(-xi); J_l has J_l(phi) on the diagonal and Q(phi, v), Q(phi, p) below.
  const Eigen::Vector3d phi = -xi.head<3>();
  const Eigen::Matrix3d jl = leftJacobianSO3(phi);
  Matrix9d j = Matrix9d::Zero();
  j.block<3, 3>(0, 0) = jl;
  j.block<3, 3>(3, 3) = jl;
  j.block<3, 3>(6, 6) = jl;
  j.block<3, 3>(3, 0) = couplingSE3(phi, -xi.segment<3>(3));
  j.block<3, 3>(6, 0) = couplingSE3(phi, -xi.segment<3>(6));
  return j;
}

}  // namespace lie
}  // namespace inekf_semantic_mapping
