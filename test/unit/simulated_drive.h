// Simulated drives for the filter and smoother tests: a drive with exact truth, and Monte-Carlo
// runs of a filter over it with IMU noise, bias random walks and GPS fixes.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <functional>
#include <random>
#include <vector>

#include "inekf_semantic_mapping/estimation/error_dynamics.h"
#include "inekf_semantic_mapping/estimation/navigation_filter.h"
#include "inekf_semantic_mapping/lie/so3.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace test_drive {

constexpr double kGravity = 9.81;

// A state away from every special value (turned, moving, biased), for single-step checks.
inline NavState someState() {
  NavState s;
  s.stamp_s = 10.0;
  s.rotation = lie::expSO3(Eigen::Vector3d(0.1, -0.2, 2.0));
  s.velocity_map = Eigen::Vector3d(8.0, -3.0, 0.2);
  s.position_map = Eigen::Vector3d(120.0, -45.0, 3.0);
  s.gyro_bias = Eigen::Vector3d(0.002, -0.001, 0.003);
  s.accel_bias = Eigen::Vector3d(0.05, -0.02, 0.1);
  return s;
}

// A drive with piecewise-constant body rates (turning and accelerating), integrated
// independently by RK4 with fine substeps.
struct SimulatedDrive {
  std::vector<NavState> truth;  // at each sample stamp
  std::vector<ImuSample> imu;   // imu[k] holds over (t_{k-1}, t_k]; imu[0] unused
};

inline SimulatedDrive simulateDrive(int steps, double dt) {
  SimulatedDrive drive;
  NavState s;
  s.rotation = lie::expSO3(Eigen::Vector3d(0.02, -0.03, 0.7));
  s.velocity_map = s.rotation * Eigen::Vector3d(5.0, 0.0, 0.0);
  drive.truth.push_back(s);
  drive.imu.push_back(ImuSample());
  const Eigen::Vector3d g(0, 0, -kGravity);
  for (int k = 1; k <= steps; ++k) {
    ImuSample sample;
    sample.stamp_s = k * dt;
    sample.angular_velocity =
        Eigen::Vector3d(0.02 * std::sin(0.3 * k), 0.01, 0.25 * std::cos(0.05 * k));
    sample.specific_force =
        Eigen::Vector3d(0.6, 0.25 * std::sin(0.1 * k), kGravity + 0.1 * std::cos(0.2 * k));
    const int substeps = 50;
    const double h = dt / substeps;
    Eigen::Matrix3d r = s.rotation;
    Eigen::Vector3d v = s.velocity_map, p = s.position_map;
    const Eigen::Matrix3d w = lie::hat(sample.angular_velocity);
    const Eigen::Vector3d f = sample.specific_force;
    for (int i = 0; i < substeps; ++i) {
      // RK4 on (R, v, p) with dR = R w^, dv = R f + g, dp = v.
      const Eigen::Matrix3d k1r = r * w;
      const Eigen::Vector3d k1v = r * f + g, k1p = v;
      const Eigen::Matrix3d r2 = r + 0.5 * h * k1r;
      const Eigen::Matrix3d k2r = r2 * w;
      const Eigen::Vector3d k2v = r2 * f + g, k2p = v + 0.5 * h * k1v;
      const Eigen::Matrix3d r3 = r + 0.5 * h * k2r;
      const Eigen::Matrix3d k3r = r3 * w;
      const Eigen::Vector3d k3v = r3 * f + g, k3p = v + 0.5 * h * k2v;
      const Eigen::Matrix3d r4 = r + h * k3r;
      const Eigen::Matrix3d k4r = r4 * w;
      const Eigen::Vector3d k4v = r4 * f + g, k4p = v + h * k3v;
      r += h / 6 * (k1r + 2 * k2r + 2 * k3r + k4r);
      v += h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
      p += h / 6 * (k1p + 2 * k2p + 2 * k3p + k4p);
    }
    s.rotation = lie::normalizeRotation(r);
    s.velocity_map = v;
    s.position_map = p;
    s.stamp_s = sample.stamp_s;
    drive.truth.push_back(s);
    drive.imu.push_back(sample);
  }
  return drive;
}

inline PositionFix fixAt(const Eigen::Vector3d& p, double stamp, double sigma) {
  PositionFix fix;
  fix.stamp_s = stamp;
  fix.position_map = p;
  fix.covariance_map = Eigen::Matrix3d::Identity() * sigma * sigma;
  return fix;
}

// The noise of a Monte-Carlo run: IMU densities, the initial error's sigmas (world frame:
// rotation, velocity, position, gyro bias, accel bias) and the GPS.
struct RunNoise {
  ImuNoise imu;
  Eigen::Matrix<double, 15, 1> initial_sigma;
  double gps_sigma = 1.0;
  int fix_every = 10;  // steps
  RunNoise() {
    imu.gyro_noise_density = 2e-3;
    imu.accel_noise_density = 3e-2;
    imu.gyro_bias_random_walk = 1e-4;
    imu.accel_bias_random_walk = 1e-3;
    initial_sigma << 0.01, 0.01, 0.05, 0.2, 0.2, 0.2, 1.0, 1.0, 1.0, 2e-3, 2e-3, 2e-3, 0.05, 0.05,
        0.05;
  }
};

// What a step of a run gives its observer: the truth, and the filter right after the IMU step
// (before the fix) and after the fix.
struct RunStep {
  int k = 0;
  NavState truth;
  ImuSample measured;
  NavState predicted;
  ErrorCovariance predicted_covariance;
  bool fixed = false;
  const NavigationFilter* filter = nullptr;
};

// One run of `type` over `drive`: the estimate starts at the truth minus a draw from the initial
// covariance; the truth follows the noise-free inputs with random-walk biases; the filter sees
// them biased and noisy, and a fix every fix_every steps. on_step after every step.
inline void simulateNoisyRun(FilterType type, const SimulatedDrive& drive, const RunNoise& noise,
                             std::mt19937* rng,
                             const std::function<void(const RunStep&)>& on_step) {
  const double dt = drive.imu[1].stamp_s - drive.truth[0].stamp_s;
  std::normal_distribution<double> normal(0.0, 1.0);
  auto gaussian3 = [&]() {
    Eigen::Vector3d v;
    v.x() = normal(*rng);
    v.y() = normal(*rng);
    v.z() = normal(*rng);
    return v;
  };
  const ErrorCovariance world = noise.initial_sigma.cwiseAbs2().asDiagonal();
  Eigen::Matrix<double, 15, 1> e;
  for (int i = 0; i < 15; ++i) e(i) = noise.initial_sigma(i) * normal(*rng);
  NavState truth = drive.truth[0];
  truth.gyro_bias = e.segment<3>(9);
  truth.accel_bias = e.segment<3>(12);
  NavState start = drive.truth[0];
  start.rotation = lie::expSO3(-e.head<3>()) * truth.rotation;
  start.velocity_map = truth.velocity_map - e.segment<3>(3);
  start.position_map = truth.position_map - e.segment<3>(6);
  auto filter = makeFilter(type, noise.imu);
  filter->initialize(start, filter->fromWorldCovariance(start, world));
  const int steps = static_cast<int>(drive.truth.size()) - 1;
  for (int k = 1; k <= steps; ++k) {
    ImuSample measured = drive.imu[k];
    NavState true_next = drive.truth[k];  // exact truth pose of the drive
    measured.angular_velocity +=
        truth.gyro_bias + noise.imu.gyro_noise_density / std::sqrt(dt) * gaussian3();
    measured.specific_force +=
        truth.accel_bias + noise.imu.accel_noise_density / std::sqrt(dt) * gaussian3();
    true_next.gyro_bias =
        truth.gyro_bias + noise.imu.gyro_bias_random_walk * std::sqrt(dt) * gaussian3();
    true_next.accel_bias =
        truth.accel_bias + noise.imu.accel_bias_random_walk * std::sqrt(dt) * gaussian3();
    truth = true_next;
    filter->propagate(measured, dt);
    RunStep step;
    step.k = k;
    step.truth = truth;
    step.measured = measured;
    step.predicted = filter->state();
    step.predicted_covariance = filter->covariance();
    if (k % noise.fix_every == 0) {
      filter->correctPosition(
          fixAt(truth.position_map + noise.gps_sigma * gaussian3(), k * dt, noise.gps_sigma), 1e9);
      step.fixed = true;
    }
    step.filter = filter.get();
    on_step(step);
  }
}

}  // namespace test_drive
}  // namespace estimation
}  // namespace inekf_semantic_mapping
