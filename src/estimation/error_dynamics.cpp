#include "inekf_semantic_mapping/estimation/error_dynamics.h"

#include <cmath>

#include "inekf_semantic_mapping/lie/so3.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

using lie::gamma0;
using lie::gamma1;
using lie::gamma2;
using lie::hat;

// 4-point Gauss-Legendre on [-1, 1].
constexpr double kNodes[4] = {-0.8611363115940526, -0.3399810435848563, 0.3399810435848563,
                              0.8611363115940526};
constexpr double kWeights[4] = {0.3478548451374538, 0.6521451548625461, 0.6521451548625461,
                                0.3478548451374538};

// The quadratures below (Gauss-Legendre for the bias couplings, Simpson for the noise) are
// accurate on a step of at most this length and turn (every IMU step of a car at 10-100 Hz):
// against Van Loan's exact process noise, the largest relative error of a diagonal entry is
// 7.6e-6 at 0.1 s and 1.3e-5 at 0.13 s (the position's: the gyro noise through the specific
// force, a fourth-power term Simpson's rule does not integrate exactly), far below what the noise
// densities themselves are known to. A longer step (a bridged IMU gap of seconds) is split into 2^k
// equal sub-steps.
constexpr double kMaxQuadratureStepS = 0.25;
constexpr double kMaxQuadratureTurnRad = 0.25;
constexpr int kMaxHalvings = 30;

// The number of halvings that brings dt within the quadratures' range.
int halvingsFor(const Eigen::Vector3d& w, double dt) {
  const double rate = w.norm();
  int k = 0;
  while (k < kMaxHalvings && (dt > kMaxQuadratureStepS || rate * dt > kMaxQuadratureTurnRad)) {
    dt *= 0.5;
    ++k;
  }
  return k;
}

// Phi(dt) in closed form, accurate for dt and |w| dt within the quadratures' range.
Matrix15d closedFormTransition(const Eigen::Vector3d& w, const Eigen::Vector3d& a, double dt) {
  const Eigen::Vector3d phi = w * dt;
  const Eigen::Matrix3d delta_rt = gamma0(phi).transpose();
  const Eigen::Matrix3d g1 = gamma1(phi), g2 = gamma2(phi);

  // Gyro-bias couplings: int_0^dt M(u) du and int_0^dt (dt - u) M(u) du with
  // M(u) = (Exp(w u) a)^ u Gamma1(w u).
  Eigen::Matrix3d int_m = Eigen::Matrix3d::Zero(), int_weighted_m = Eigen::Matrix3d::Zero();
  for (int i = 0; i < 4; ++i) {
    const double u = 0.5 * dt * (kNodes[i] + 1.0);
    const Eigen::Vector3d wu = w * u;
    const Eigen::Matrix3d m = hat(gamma0(wu) * a) * (u * gamma1(wu));
    const double weight = 0.5 * dt * kWeights[i];
    int_m += weight * m;
    int_weighted_m += weight * (dt - u) * m;
  }

  Matrix15d phi_matrix = Matrix15d::Identity();
  phi_matrix.block<3, 3>(0, 0) = delta_rt;
  phi_matrix.block<3, 3>(0, 9) = -delta_rt * g1 * dt;
  phi_matrix.block<3, 3>(3, 0) = -delta_rt * hat(g1 * a * dt);
  phi_matrix.block<3, 3>(3, 3) = delta_rt;
  phi_matrix.block<3, 3>(3, 9) = delta_rt * int_m;
  phi_matrix.block<3, 3>(3, 12) = -delta_rt * g1 * dt;
  phi_matrix.block<3, 3>(6, 0) = -delta_rt * hat(g2 * a * (dt * dt));
  phi_matrix.block<3, 3>(6, 3) = delta_rt * dt;
  phi_matrix.block<3, 3>(6, 6) = delta_rt;
  phi_matrix.block<3, 3>(6, 9) = delta_rt * int_weighted_m;
  phi_matrix.block<3, 3>(6, 12) = -delta_rt * g2 * (dt * dt);
  return phi_matrix;
}

// Simpson's rule of int_0^dt Phi(s) L Phi(s)^T ds; phi_full = Phi(dt).
Matrix15d simpsonProcessNoise(const Eigen::Vector3d& w, const Eigen::Vector3d& a,
                              const ImuNoise& noise, double gyro_noise_scale,
                              double accel_noise_scale, double dt, const Matrix15d& phi_full) {
  Eigen::Matrix<double, 15, 1> diagonal;
  const double gyro_sigma = gyro_noise_scale * noise.gyro_noise_density;
  const double accel_sigma = accel_noise_scale * noise.accel_noise_density;
  diagonal << Eigen::Vector3d::Constant(gyro_sigma * gyro_sigma),
      Eigen::Vector3d::Constant(accel_sigma * accel_sigma), Eigen::Vector3d::Zero(),
      Eigen::Vector3d::Constant(noise.gyro_bias_random_walk * noise.gyro_bias_random_walk),
      Eigen::Vector3d::Constant(noise.accel_bias_random_walk * noise.accel_bias_random_walk);
  // Noise injected at time s reaches dt through Phi(dt - s): Simpson over s. With L diagonal,
  // Phi L Phi^T = (Phi sqrt(L)) (Phi sqrt(L))^T: one product each.
  const Eigen::Matrix<double, 15, 1> sqrt_l = diagonal.cwiseSqrt();
  const Matrix15d full = phi_full * sqrt_l.asDiagonal();
  const Matrix15d half = closedFormTransition(w, a, 0.5 * dt) * sqrt_l.asDiagonal();
  Matrix15d q = full.lazyProduct(full.transpose()) + 4.0 * half.lazyProduct(half.transpose());
  q.diagonal() += diagonal;
  q *= dt / 6.0;
  return 0.5 * (q + q.transpose());
}

}  // namespace

NavState integrateImu(const NavState& state, const Eigen::Vector3d& measured_angular_velocity,
                      const Eigen::Vector3d& measured_specific_force, double gravity_mps2,
                      double dt) {
  const Eigen::Vector3d w = measured_angular_velocity - state.gyro_bias;
  const Eigen::Vector3d a = measured_specific_force - state.accel_bias;
  const Eigen::Vector3d g(0.0, 0.0, -gravity_mps2);
  const Eigen::Vector3d phi = w * dt;
  NavState next = state;
  next.rotation = state.rotation * gamma0(phi);
  next.velocity_map = state.velocity_map + state.rotation * gamma1(phi) * a * dt + g * dt;
  next.position_map = state.position_map + state.velocity_map * dt +
                      state.rotation * gamma2(phi) * a * (dt * dt) + 0.5 * g * (dt * dt);
  next.stamp_s = state.stamp_s + dt;
  return next;
}

// The input is held constant over a step, so the error dynamics are time-invariant over it and
// compose exactly: Phi(2h) = Phi(h)^2.
Matrix15d leftErrorTransition(const Eigen::Vector3d& w, const Eigen::Vector3d& a, double dt) {
  const int halvings = halvingsFor(w, dt);
  Matrix15d phi = closedFormTransition(w, a, std::ldexp(dt, -halvings));
  for (int i = 0; i < halvings; ++i) phi = (phi * phi).eval();
  return phi;
}

Matrix15d leftProcessNoise(const Eigen::Vector3d& w, const Eigen::Vector3d& a,
                           const ImuNoise& noise, double gyro_noise_scale, double accel_noise_scale,
                           double dt) {
  return leftProcessNoise(w, a, noise, gyro_noise_scale, accel_noise_scale, dt,
                          leftErrorTransition(w, a, dt));
}

// Over 2^k sub-steps of length h: Q(2h) = Q(h) + Phi(h) Q(h) Phi(h)^T (time-invariant dynamics).
Matrix15d leftProcessNoise(const Eigen::Vector3d& w, const Eigen::Vector3d& a,
                           const ImuNoise& noise, double gyro_noise_scale, double accel_noise_scale,
                           double dt, const Matrix15d& phi_full) {
  const int halvings = halvingsFor(w, dt);
  if (halvings == 0) {
    return simpsonProcessNoise(w, a, noise, gyro_noise_scale, accel_noise_scale, dt, phi_full);
  }
  const double h = std::ldexp(dt, -halvings);
  Matrix15d phi = closedFormTransition(w, a, h);
  Matrix15d q = simpsonProcessNoise(w, a, noise, gyro_noise_scale, accel_noise_scale, h, phi);
  for (int i = 0; i < halvings; ++i) {
    q += propagateLeftCovariance(phi, q);
    q = (0.5 * (q + q.transpose())).eval();
    phi = (phi * phi).eval();
  }
  return q;
}

Matrix15d propagateLeftCovariance(const Matrix15d& phi, const Matrix15d& p) {
  // phi = [A B; 0 I] (navigation 9, biases 6): skip the products with the known blocks.
  const Eigen::Matrix<double, 9, 9> a = phi.topLeftCorner<9, 9>();
  const Eigen::Matrix<double, 9, 6> b = phi.topRightCorner<9, 6>();
  const Eigen::Matrix<double, 9, 15> top =
      a.lazyProduct(p.topRows<9>()) + b.lazyProduct(p.bottomRows<6>());
  Matrix15d out;
  out.topLeftCorner<9, 9>() =
      top.leftCols<9>().lazyProduct(a.transpose()) + top.rightCols<6>().lazyProduct(b.transpose());
  out.topRightCorner<9, 6>() = top.rightCols<6>();
  out.bottomLeftCorner<6, 9>() = top.rightCols<6>().transpose();
  out.bottomRightCorner<6, 6>() = p.bottomRightCorner<6, 6>();
  return out;
}

}  // namespace estimation
}  // namespace inekf_semantic_mapping
