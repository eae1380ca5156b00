// SE_2(3), the "extended pose" group of (R, v, p) as the 5x5 matrix
//   X = [R v p; 0 1 0; 0 0 1],
// with tangent vectors xi = (xi_R, xi_v, xi_p) in R^9 (this order everywhere).
#pragma once

#include <Eigen/Core>

namespace inekf_semantic_mapping {
namespace lie {

using Vector9d = Eigen::Matrix<double, 9, 1>;
using Matrix9d = Eigen::Matrix<double, 9, 9>;
using Matrix5d = Eigen::Matrix<double, 5, 5>;

struct ExtendedPose {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
  Eigen::Vector3d position = Eigen::Vector3d::Zero();

  Matrix5d matrix() const;
  static ExtendedPose fromMatrix(const Matrix5d& m);
  ExtendedPose inverse() const;
  ExtendedPose operator*(const ExtendedPose& other) const;
  // Adjoint: X exp(xi) X^-1 = exp(Ad_X xi).
  Matrix9d adjoint() const;
};

Matrix5d hatSE23(const Vector9d& xi);
ExtendedPose expSE23(const Vector9d& xi);  // exact: (Exp(phi), J_l(phi) v, J_l(phi) p)
Vector9d logSE23(const ExtendedPose& x);
// Right Jacobian: exp(xi + d) = exp(xi) exp(J_r(xi) d) to first order in d. Its (phi, p) rows and
// columns are SE(3)'s right Jacobian (the pose part of exp does not depend on v). Series below
// 0.2 rad.
Matrix9d rightJacobianSE23(const Vector9d& xi);

}  // namespace lie
}  // namespace inekf_semantic_mapping
