#include "inekf_semantic_mapping/lie/se23.h"

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

}  // namespace lie
}  // namespace inekf_semantic_mapping
