// SO(3) / SE_2(3): identities, small-angle and near-pi branches, Jacobians by finite differences,
// Gamma integrals by numerical quadrature.
#include <gtest/gtest.h>

#include <Eigen/LU>
#include <cmath>
#include <random>
#include <vector>

#include "inekf_semantic_mapping/lie/se23.h"
#include "inekf_semantic_mapping/lie/so3.h"

namespace inekf_semantic_mapping {
namespace lie {
namespace {

// Reference exponential by a long power series (scaled and squared), independent of the closed
// forms.
Eigen::Matrix3d seriesExp(const Eigen::Vector3d& phi) {
  const Eigen::Matrix3d a = hat(phi) / 16.0;
  Eigen::Matrix3d result = Eigen::Matrix3d::Identity(), term = Eigen::Matrix3d::Identity();
  for (int k = 1; k < 30; ++k) {
    term = term * a / k;
    result += term;
  }
  for (int i = 0; i < 4; ++i) result = result * result;
  return result;
}

// int_0^1 Exp(phi s) ds and int_0^1 (1 - s) Exp(phi s) ds by composite Simpson.
void gammaByQuadrature(const Eigen::Vector3d& phi, Eigen::Matrix3d* g1, Eigen::Matrix3d* g2) {
  const int n = 2000;
  g1->setZero();
  g2->setZero();
  for (int i = 0; i <= n; ++i) {
    const double s = static_cast<double>(i) / n;
    const double w = (i == 0 || i == n) ? 1.0 : (i % 2 ? 4.0 : 2.0);
    const Eigen::Matrix3d e = seriesExp(phi * s);
    *g1 += w * e;
    *g2 += w * (1.0 - s) * e;
  }
  *g1 /= 3.0 * n;
  *g2 /= 3.0 * n;
}

std::vector<double> testAngles() {
  return {0.0, 1e-9, 1e-6, 1e-5, 2e-5, 1e-3, 0.1, 0.19, 0.21, 1.0, 2.5, 3.0, M_PI - 1e-6};
}

Eigen::Vector3d axis() { return Eigen::Vector3d(0.3, -0.5, 0.8).normalized(); }

TEST(So3, ExpMatchesSeriesAndIsARotation) {
  for (double angle : testAngles()) {
    const Eigen::Vector3d phi = angle * axis();
    const Eigen::Matrix3d r = expSO3(phi);
    EXPECT_LT((r - seriesExp(phi)).norm(), 1e-13) << "angle " << angle;
    EXPECT_LT((r.transpose() * r - Eigen::Matrix3d::Identity()).norm(), 1e-14);
    EXPECT_NEAR(r.determinant(), 1.0, 1e-14);
  }
}

TEST(So3, LogInvertsExpIncludingTinyAndNearPi) {
  for (double angle : testAngles()) {
    const Eigen::Vector3d phi = angle * axis();
    const Eigen::Vector3d back = logSO3(expSO3(phi));
    EXPECT_LT((back - phi).norm(), 1e-9 * std::max(1.0, angle) + 1e-15) << "angle " << angle;
    if (angle > 0.0 && angle < 3.0) {
      EXPECT_LT((back - phi).norm() / angle, 1e-10) << "relative, angle " << angle;
    }
  }
  // Exactly pi: either sign of the axis is the same rotation.
  const Eigen::Vector3d half_turn = M_PI * axis();
  const Eigen::Vector3d back = logSO3(expSO3(half_turn));
  EXPECT_NEAR(back.norm(), M_PI, 1e-9);
  EXPECT_LT((expSO3(back) - expSO3(half_turn)).norm(), 1e-9);
}

TEST(So3, GammaFunctionsMatchQuadrature) {
  for (double angle : {0.0, 1e-9, 1e-5, 1e-3, 0.15, 0.25, 1.0, 3.0}) {
    const Eigen::Vector3d phi = angle * axis();
    Eigen::Matrix3d g1, g2;
    gammaByQuadrature(phi, &g1, &g2);
    EXPECT_LT((gamma1(phi) - g1).norm(), 1e-11) << "angle " << angle;
    EXPECT_LT((gamma2(phi) - g2).norm(), 1e-11) << "angle " << angle;
  }
}

TEST(So3, JacobiansMatchFiniteDifferences) {
  const double eps = 1e-6;
  for (double angle : {0.0, 1e-9, 1e-4, 0.1, 1.0, 2.5}) {
    const Eigen::Vector3d phi = angle * axis();
    Eigen::Matrix3d left_numeric, right_numeric;
    for (int i = 0; i < 3; ++i) {
      const Eigen::Vector3d d = eps * Eigen::Vector3d::Unit(i);
      // Exp(phi + d) = Exp(J_l d) Exp(phi) = Exp(phi) Exp(J_r d)
      left_numeric.col(i) = (logSO3(expSO3(phi + d) * expSO3(phi).transpose()) -
                             logSO3(expSO3(phi - d) * expSO3(phi).transpose())) /
                            (2 * eps);
      right_numeric.col(i) = (logSO3(expSO3(phi).transpose() * expSO3(phi + d)) -
                              logSO3(expSO3(phi).transpose() * expSO3(phi - d))) /
                             (2 * eps);
    }
    EXPECT_LT((leftJacobianSO3(phi) - left_numeric).norm(), 1e-8) << "angle " << angle;
    EXPECT_LT((rightJacobianSO3(phi) - right_numeric).norm(), 1e-8) << "angle " << angle;
    EXPECT_LT(
        (leftJacobianInverseSO3(phi) * leftJacobianSO3(phi) - Eigen::Matrix3d::Identity()).norm(),
        1e-12);
    EXPECT_LT(
        (rightJacobianInverseSO3(phi) * rightJacobianSO3(phi) - Eigen::Matrix3d::Identity()).norm(),
        1e-12);
  }
}

TEST(Se23, ExpLogRoundTripAndMatrixExponential) {
  std::mt19937 rng(3);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    Vector9d xi;
    for (int i = 0; i < 9; ++i) xi(i) = normal(rng) * (trial < 5 ? 1e-7 : 1.0);
    const ExtendedPose x = expSE23(xi);
    EXPECT_LT((logSE23(x) - xi).norm(), 1e-10 * std::max(1.0, xi.norm()));
    // Against the 5x5 matrix exponential by series (scaling and squaring).
    const Matrix5d a = hatSE23(xi) / 1024.0;
    Matrix5d series = Matrix5d::Identity(), term = Matrix5d::Identity();
    for (int k = 1; k < 30; ++k) {
      term = term * a / k;
      series += term;
    }
    for (int i = 0; i < 10; ++i) series = series * series;
    EXPECT_LT((x.matrix() - series).norm(), 1e-11);
  }
}

TEST(Se23, AdjointConjugatesTheExponential) {
  Vector9d xi_x, xi;
  xi_x << 0.3, -0.2, 1.1, 4.0, -1.0, 0.5, 100.0, -50.0, 3.0;
  xi << 0.01, 0.02, -0.03, 0.1, 0.2, -0.1, 0.5, -0.4, 0.2;
  const ExtendedPose x = expSE23(xi_x);
  const Matrix5d lhs = x.matrix() * expSE23(xi).matrix() * x.inverse().matrix();
  EXPECT_LT((lhs - expSE23(x.adjoint() * xi).matrix()).norm(), 1e-9);
  EXPECT_LT(((x * x.inverse()).matrix() - Matrix5d::Identity()).norm(), 1e-12);
}

// exp(xi + d) = exp(xi) exp(J_r(xi) d): central differences of log(exp(xi)^-1 exp(xi +- d)), at
// angles on both sides of the series branch and with metre-sized v and p (where a wrong coupling
// block shows most).
TEST(Se23, RightJacobianMatchesFiniteDifferences) {
  const double eps = 1e-6;
  for (double angle : {0.0, 1e-9, 5e-5, 2e-4, 0.1, 1.0, 2.5}) {
    Vector9d xi;
    xi << angle * axis(), 3.0, -1.5, 0.7, 12.0, 5.0, -2.0;
    Matrix9d numeric;
    for (int i = 0; i < 9; ++i) {
      const Vector9d d = eps * Vector9d::Unit(i);
      const ExtendedPose inverse = expSE23(xi).inverse();
      numeric.col(i) =
          (logSE23(inverse * expSE23(xi + d)) - logSE23(inverse * expSE23(xi - d))) / (2 * eps);
    }
    EXPECT_LT((rightJacobianSE23(xi) - numeric).norm(), 1e-7) << "angle " << angle;
  }
  EXPECT_LT((rightJacobianSE23(Vector9d::Zero()) - Matrix9d::Identity()).norm(), 1e-15);
}

// Against the defining series J_r(xi) = sum_n (-ad_xi)^n / (n+1)! (exact in long double for
// these sizes), around the switch from the coefficients' Taylor series to their closed forms:
// just above a switch at 1e-4 rad the closed forms cancelled to c = -1.35 instead of 1/120.
TEST(Se23, RightJacobianMatchesItsSeriesAcrossTheSeriesSwitch) {
  using MatrixL = Eigen::Matrix<long double, 9, 9>;
  const auto hatL = [](const Eigen::Vector3d& w) {
    Eigen::Matrix<long double, 3, 3> m;
    m << 0, -w.z(), w.y(), w.z(), 0, -w.x(), -w.y(), w.x(), 0;
    return m;
  };
  for (double angle : {1.2e-4, 3e-4, 1e-3, 1e-2, 0.15, 0.199, 0.201, 0.5}) {
    Vector9d xi;
    xi << angle * axis(), 3.0, -1.5, 0.7, 12.0, 5.0, -2.0;
    MatrixL ad = MatrixL::Zero();
    const auto phi = hatL(xi.head<3>());
    ad.block<3, 3>(0, 0) = phi;
    ad.block<3, 3>(3, 3) = phi;
    ad.block<3, 3>(6, 6) = phi;
    ad.block<3, 3>(3, 0) = hatL(xi.segment<3>(3));
    ad.block<3, 3>(6, 0) = hatL(xi.segment<3>(6));
    MatrixL term = MatrixL::Identity(), sum = MatrixL::Identity();
    for (int n = 1; n < 120; ++n) {
      term = (term * -ad) / static_cast<long double>(n + 1);
      sum += term;
    }
    const Matrix9d reference = sum.cast<double>();
    EXPECT_LT((rightJacobianSE23(xi) - reference).norm(), 1e-12 * reference.norm())
        << "angle " << angle;
  }
}

}  // namespace
}  // namespace lie
}  // namespace inekf_semantic_mapping
