// The IMU kinematics on SE_2(3) x R^6 and the exact discrete transition of the LEFT-invariant
// error (eta = X_est^-1 X_true) over one step with the sample held constant. The right-invariant
// filter and the ESKF map this transition into their own error coordinates, so all three filters
// share one discretization and differ only in their error definition and update.
#pragma once

#include "inekf_semantic_mapping/estimation/types.h"

namespace inekf_semantic_mapping {
namespace estimation {

using Matrix15d = Eigen::Matrix<double, 15, 15>;

// Closed-form integration with bias-corrected rates w = w_meas - b_g, a = a_meas - b_a:
//   R+ = R Gamma0(w dt), v+ = v + R Gamma1(w dt) a dt + g dt,
//   p+ = p + v dt + R Gamma2(w dt) a dt^2 + g dt^2 / 2,  g = (0, 0, -gravity).
// Biases are unchanged; stamp advances by dt.
NavState integrateImu(const NavState& state, const Eigen::Vector3d& measured_angular_velocity,
                      const Eigen::Vector3d& measured_specific_force, double gravity_mps2,
                      double dt);

// Phi(dt) of the linearized left-invariant error dynamics
//   d/dt xi_R = -w^ xi_R - b~_g,  d/dt xi_v = -a^ xi_R - w^ xi_v - b~_a,
//   d/dt xi_p = xi_v - w^ xi_p,   d/dt b~ = 0,
// in closed form (Gamma functions; the two gyro-bias couplings of v and p by 4-point
// Gauss-Legendre quadrature of a smooth integrand, exact to ~(|w| dt)^8). A step longer than
// 0.25 s or 0.25 rad (a bridged IMU gap) is 2^k equal sub-steps composed by squaring, exact
// for the constant input: accurate for any dt. w and a are the bias-corrected rates.
Matrix15d leftErrorTransition(const Eigen::Vector3d& angular_velocity,
                              const Eigen::Vector3d& specific_force, double dt);

// Discrete process noise of the left-invariant error over dt, Simpson's rule of
// int_0^dt Phi(s) L Phi(s)^T ds with L = diag(sg^2, sa^2, 0, sbg^2, sba^2) (densities squared);
// exact for the dt^3/3 position term that the usual Phi L Phi^T dt overstates threefold. A long
// step is composed from sub-steps as the transition is: Q(2h) = Q(h) + Phi(h) Q(h) Phi(h)^T.
// The scales multiply the white-noise densities only (not the bias random walks).
Matrix15d leftProcessNoise(const Eigen::Vector3d& angular_velocity,
                           const Eigen::Vector3d& specific_force, const ImuNoise& noise,
                           double gyro_noise_scale, double accel_noise_scale, double dt);
// Same, reusing Phi(dt) = leftErrorTransition(angular_velocity, specific_force, dt) (a step that
// is split composes its sub-steps' own instead).
Matrix15d leftProcessNoise(const Eigen::Vector3d& angular_velocity,
                           const Eigen::Vector3d& specific_force, const ImuNoise& noise,
                           double gyro_noise_scale, double accel_noise_scale, double dt,
                           const Matrix15d& transition);

// phi p phi^T for a left transition (bias rows [0 I]), using that structure.
Matrix15d propagateLeftCovariance(const Matrix15d& phi, const Matrix15d& p);

}  // namespace estimation
}  // namespace inekf_semantic_mapping
