// StandstillDetector: when a still IMU gives its zero-velocity and zero-rate measurement, and the
// motions that must never give one (accelerating away, turning on the spot, a steady drive the
// filter knows about, a start whose velocity is not known yet).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <functional>
#include <random>
#include <stdexcept>

#include "inekf_semantic_mapping/estimation/standstill_detector.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

constexpr double kRateHz = 100.0, kDt = 1.0 / kRateHz;
constexpr double kGyroDensity = 1e-3;  // rad/s/sqrt(Hz)
const Eigen::Vector3d kGyroBias(0.004, -0.003, 0.005);

struct Motion {
  std::function<Eigen::Vector3d(double)> acceleration_body = [](double) {
    return Eigen::Vector3d::Zero();
  };
  std::function<double(double)> yaw_rate = [](double) { return 0.0; };
  double speed_mps = 0.0;        // the filter's estimate, along x
  double velocity_sigma = 0.05;  // the filter's
  bool fixes_moving = false;     // the recent fixes' verdict
};

struct Outcome {
  int measurements = 0;
  double first_at_s = -1.0;
  Eigen::Vector3d last_mean_rate = Eigen::Vector3d::Zero();
  Eigen::Vector3d last_variance = Eigen::Vector3d::Zero();
};

// A level IMU (its axes the map's, yaw 0.4) for `seconds`, with white gyro and accelerometer
// noise and a gyro bias the filter does not know.
Outcome run(StandstillDetector* detector, const Motion& motion, double seconds, double t0 = 0.0) {
  std::mt19937 random(3);
  std::normal_distribution<double> unit(0.0, 1.0);
  NavState state;
  state.rotation = Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  state.velocity_map = state.rotation * Eigen::Vector3d(motion.speed_mps, 0.0, 0.0);
  Outcome outcome;
  for (int k = 1; k * kDt <= seconds + 1e-9; ++k) {
    const double t = t0 + k * kDt;
    ImuSample sample;
    sample.stamp_s = t;
    const Eigen::Vector3d noise(unit(random), unit(random), unit(random));
    sample.angular_velocity = Eigen::Vector3d(0.0, 0.0, motion.yaw_rate(t)) + kGyroBias +
                              kGyroDensity * std::sqrt(kRateHz) * noise;
    sample.specific_force = motion.acceleration_body(t) + Eigen::Vector3d(0.0, 0.0, 9.81) +
                            0.02 * std::sqrt(kRateHz) *
                                Eigen::Vector3d(unit(random), unit(random), unit(random));
    const auto measurement =
        detector->add(sample, kDt, state, motion.velocity_sigma, motion.fixes_moving, kGyroDensity);
    if (!measurement) continue;
    if (outcome.measurements++ == 0) outcome.first_at_s = t - t0;
    outcome.last_mean_rate = measurement->mean_angular_velocity;
    outcome.last_variance = measurement->angular_velocity_variance;
  }
  return outcome;
}

TEST(StandstillDetector, AStillImuGivesTheGyroBiasOncePerIntervalAfterAFullWindow) {
  StandstillOptions options;
  options.enabled = true;
  StandstillDetector detector(options);
  const Outcome still = run(&detector, Motion(), 3.0);
  EXPECT_TRUE(detector.still());
  // The first after the 0.5 s window and a 0.1 s interval, then every 0.1 s: (3 - 0.5) / 0.1.
  EXPECT_NEAR(still.first_at_s, 0.6, 0.015);
  EXPECT_NEAR(still.measurements, 25, 1);
  // The mean of 10 samples of 0.01 rad/s noise: within 4 sigma of the bias.
  EXPECT_LT((still.last_mean_rate - kGyroBias).cwiseAbs().maxCoeff(), 4.0 * 0.01 / std::sqrt(10.0));
  EXPECT_NEAR(still.last_variance.x(), kGyroDensity * kGyroDensity / 0.1, 1e-9);
}

TEST(StandstillDetector, NoMeasurementWhileTheVehicleMovesOrItsVelocityIsUnknown) {
  StandstillOptions options;
  options.enabled = true;
  Motion accelerating;  // pulling away gently: 0.3 m/s^2
  accelerating.acceleration_body = [](double) { return Eigen::Vector3d(0.3, 0.0, 0.0); };
  Motion turning;  // on the spot at 3 deg/s (a skid-steer robot)
  turning.yaw_rate = [](double) { return 3.0 * M_PI / 180.0; };
  Motion cruising;  // a steady 2 m/s on a smooth road: the IMU looks still, the filter knows
  cruising.speed_mps = 2.0;
  Motion unknown;  // a start without a velocity: zero +- 15 m/s
  unknown.velocity_sigma = 15.0;
  Motion vague;  // cruising at 1.5 m/s, the filter's estimate 0.6 +- 0.5: the fixes tell
  vague.speed_mps = 0.6;
  vague.velocity_sigma = 0.5;
  vague.fixes_moving = true;
  for (const auto& [name, motion] : {std::pair{"accelerating", accelerating},
                                     {"turning", turning},
                                     {"cruising", cruising},
                                     {"unknown velocity", unknown},
                                     {"vague velocity, fixes moving", vague}}) {
    StandstillDetector detector(options);
    EXPECT_EQ(run(&detector, motion, 5.0).measurements, 0) << name;
    EXPECT_FALSE(detector.still()) << name;
  }
}

// A MEMS robot standing with 1.5 m fixes knows its velocity to about 0.5 m/s: standing within
// two sigmas and fixes that do not move will do; a known speed above the limit will not.
TEST(StandstillDetector, AVagueVelocityIsStillWhenTheFixesDoNotMove) {
  StandstillOptions options;
  options.enabled = true;
  Motion vague;
  vague.speed_mps = 0.6;
  vague.velocity_sigma = 0.5;
  StandstillDetector detector(options);
  EXPECT_GT(run(&detector, vague, 2.0).measurements, 10);
  Motion too_vague = vague;  // beyond max_velocity_sigma_mps
  too_vague.velocity_sigma = 1.5;
  StandstillDetector second(options);
  EXPECT_EQ(run(&second, too_vague, 2.0).measurements, 0);
  Motion known = vague;  // 0.6 +- 0.1: moving
  known.velocity_sigma = 0.1;
  StandstillDetector third(options);
  EXPECT_EQ(run(&third, known, 2.0).measurements, 0);
}

TEST(StandstillDetector, AJoltEmptiesTheWindowAndAResetForgetsIt) {
  StandstillOptions options;
  options.enabled = true;
  StandstillDetector detector(options);
  Motion jolt;  // 0.2 s of 2 m/s^2 at t = 2 s (a door shut, a bump)
  jolt.acceleration_body = [](double t) {
    return Eigen::Vector3d(t > 2.0 && t <= 2.2 ? 2.0 : 0.0, 0.0, 0.0);
  };
  const Outcome outcome = run(&detector, jolt, 2.0);
  EXPECT_GT(outcome.measurements, 0);
  // From the jolt on, nothing until a window without it has passed.
  const Outcome after = run(&detector, jolt, 1.0, 2.0);
  EXPECT_GT(after.first_at_s, 0.2 + 0.5 - 0.02);
  detector.reset();
  EXPECT_FALSE(detector.still());
  EXPECT_NEAR(run(&detector, Motion(), 1.0, 10.0).first_at_s, 0.6, 0.015);
}

TEST(StandstillDetector, OptionsOutOfRangeAreNamed) {
  StandstillOptions options;
  options.window_s = 0.0;
  try {
    StandstillDetector detector(options);
    FAIL() << "accepted window_s 0";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("standstill.window_s"), std::string::npos);
  }
  options = StandstillOptions();
  options.velocity_sigma_mps = std::nan("");
  EXPECT_THROW(StandstillDetector{options}, std::invalid_argument);
}

}  // namespace
}  // namespace estimation
}  // namespace inekf_semantic_mapping
