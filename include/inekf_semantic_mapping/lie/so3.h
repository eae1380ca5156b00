// SO(3) tools: hat/vee, Exp/Log, left/right Jacobians and their inverses, and the Gamma_n
// series used by the closed-form IMU integration on SE_2(3):
//   Gamma_n(phi) = sum_k (phi^)^k / (k + n)!,  Gamma_0 = Exp, Gamma_1 = J_left,
//   int_0^t Exp(w s) ds = t Gamma_1(w t),  int_0^t int_0^s Exp(w u) du ds = t^2 Gamma_2(w t).
// Every function has a Taylor branch for small angles so it stays exact near zero.
#pragma once

#include <Eigen/Core>

namespace inekf_semantic_mapping {
namespace lie {

// Below this angle (rad) the closed forms switch to their Taylor series.
constexpr double kSmallAngle = 1e-5;

Eigen::Matrix3d hat(const Eigen::Vector3d& v);
Eigen::Vector3d vee(const Eigen::Matrix3d& m);  // of the skew part

Eigen::Matrix3d expSO3(const Eigen::Vector3d& phi);  // = Gamma_0
// The rotation vector of r, angle in [0, pi]; accurate near pi.
Eigen::Vector3d logSO3(const Eigen::Matrix3d& r);

Eigen::Matrix3d gamma0(const Eigen::Vector3d& phi);
Eigen::Matrix3d gamma1(const Eigen::Vector3d& phi);
Eigen::Matrix3d gamma2(const Eigen::Vector3d& phi);

// Exp(phi + d) ~ Exp(J_l(phi) d) Exp(phi) ~ Exp(phi) Exp(J_r(phi) d).
Eigen::Matrix3d leftJacobianSO3(const Eigen::Vector3d& phi);
Eigen::Matrix3d rightJacobianSO3(const Eigen::Vector3d& phi);
Eigen::Matrix3d leftJacobianInverseSO3(const Eigen::Vector3d& phi);
Eigen::Matrix3d rightJacobianInverseSO3(const Eigen::Vector3d& phi);

// Projects a near-rotation back onto SO(3) (SVD), to remove round-off drift.
Eigen::Matrix3d normalizeRotation(const Eigen::Matrix3d& r);

}  // namespace lie
}  // namespace inekf_semantic_mapping
