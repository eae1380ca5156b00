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

struct Motion {
  std::function<Eigen::Vector3d(double)> acceleration_body = [](double) {
    return Eigen::Vector3d::Zero();
  };
  std::function<double(double)> yaw_rate = [](double) { return 0.0; };
  double speed_mps = 0.0;        // the filter's estimate, along x
  double velocity_sigma = 0.05;  // the filter's
  double gyro_bias_sigma = 0.0;  // the filter's
  StandstillDetector::Fixes fixes = StandstillDetector::Fixes::kUnknown;
  Eigen::Vector3d gyro_bias = Eigen::Vector3d(0.004, -0.003, 0.005);  // rad/s, not known
  double gyro_noise_scale = 1.0;  // vibration: the gyro's noise over its configured density
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
    sample.angular_velocity = Eigen::Vector3d(0.0, 0.0, motion.yaw_rate(t)) + motion.gyro_bias +
                              motion.gyro_noise_scale * kGyroDensity * std::sqrt(kRateHz) * noise;
    sample.specific_force =
        motion.acceleration_body(t) + Eigen::Vector3d(0.0, 0.0, 9.81) +
        0.02 * std::sqrt(kRateHz) * Eigen::Vector3d(unit(random), unit(random), unit(random));
    StandstillDetector::Context context;
    context.velocity_sigma_mps = motion.velocity_sigma;
    context.gyro_bias_sigma_radps = motion.gyro_bias_sigma;
    context.fixes = motion.fixes;
    context.gyro_noise_density = kGyroDensity;
    const auto measurement = detector->add(sample, kDt, state, context);
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
  const Outcome still = run(&detector, Motion(), 5.0);
  EXPECT_TRUE(detector.still());
  // The first after the 0.5 s window, the raw readings steady for kSettleS and a 0.1 s interval,
  // then every 0.1 s.
  const double first_s = 0.5 + StandstillDetector::kSettleS + 0.1;
  EXPECT_NEAR(still.first_at_s, first_s, 0.03);
  EXPECT_NEAR(still.measurements, (5.0 - first_s) / 0.1 + 1.0, 1.0);
  // The mean of 10 samples of 0.01 rad/s noise: within 4 sigma of the bias.
  EXPECT_LT((still.last_mean_rate - Motion().gyro_bias).cwiseAbs().maxCoeff(),
            4.0 * 0.01 / std::sqrt(10.0));
  // The density's d^2 / T, or the window's scatter where that came out larger (within noise).
  const double nominal = kGyroDensity * kGyroDensity / 0.1;
  EXPECT_GE(still.last_variance.minCoeff(), nominal);
  EXPECT_LT(still.last_variance.maxCoeff(), 2.0 * nominal);
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
  vague.fixes = StandstillDetector::Fixes::kMoving;
  Motion outage = vague;  // the same without fixes: "cannot tell" is no evidence
  outage.fixes = StandstillDetector::Fixes::kUnknown;
  Motion vetoed = Motion();  // the filter sure it stands, the fixes moving away
  vetoed.fixes = StandstillDetector::Fixes::kMoving;
  for (const auto& [name, motion] : {std::pair{"accelerating", accelerating},
                                     {"turning", turning},
                                     {"cruising", cruising},
                                     {"unknown velocity", unknown},
                                     {"vague velocity, fixes moving", vague},
                                     {"vague velocity, no fixes", outage},
                                     {"fixes moving", vetoed}}) {
    StandstillDetector detector(options);
    EXPECT_EQ(run(&detector, motion, 5.0).measurements, 0) << name;
    EXPECT_FALSE(detector.still()) << name;
  }
}

// A MEMS robot standing with 1.5 m fixes knows its own velocity only to 0.5-1 m/s (the estimate
// wanders over 1 m/s): still once the fixes have stood for their window and the IMU been quiet
// as long; not on the filter's vagueness alone, nor with a jolt inside the window.
TEST(StandstillDetector, AVagueVelocityIsStillOnceTheFixesAndTheImuHaveStoodTheirWindow) {
  StandstillOptions options;
  options.enabled = true;
  Motion vague;
  vague.speed_mps = 1.2;
  vague.velocity_sigma = 0.5;
  vague.fixes = StandstillDetector::Fixes::kStanding;
  StandstillDetector detector(options);
  const Outcome outcome = run(&detector, vague, 22.0);
  // The window (0.5 s), ten steady seconds, the interval (0.1 s).
  EXPECT_NEAR(outcome.first_at_s, 0.5 + StandstillDetector::kFixesWindowS + 0.1, 0.05);
  EXPECT_GT(outcome.measurements, 10);
  Motion no_fixes = vague;
  no_fixes.fixes = StandstillDetector::Fixes::kUnknown;
  StandstillDetector second(options);
  EXPECT_EQ(run(&second, no_fixes, 22.0).measurements, 0);
  Motion jolted = vague;  // 0.2 s of 2 m/s^2 at t = 5 s: the window's steady seconds from its end
  jolted.acceleration_body = [](double t) {
    return Eigen::Vector3d(t > 5.0 && t <= 5.2 ? 2.0 : 0.0, 0.0, 0.0);
  };
  StandstillDetector third(options);
  EXPECT_GT(run(&third, jolted, 27.0).first_at_s, 5.2 + StandstillDetector::kFixesWindowS);
}

// A consumer gyro's turn-on bias of 2.4 deg/s, not learnt yet (its sigma 0.57 deg/s): the rate
// limit widens by three bias sigmas, or the robot never stood still.
TEST(StandstillDetector, AnUnlearntGyroBiasWidensTheRateLimit) {
  StandstillOptions options;
  options.enabled = true;
  Motion biased;
  biased.gyro_bias = Eigen::Vector3d(0.024, -0.018, 0.030);
  StandstillDetector without_sigma(options);
  EXPECT_EQ(run(&without_sigma, biased, 4.0).measurements, 0);
  biased.gyro_bias_sigma = 0.01 * std::sqrt(3.0);
  StandstillDetector with_sigma(options);
  const Outcome outcome = run(&with_sigma, biased, 4.0);
  EXPECT_GT(outcome.measurements, 10);
  EXPECT_LT((outcome.last_mean_rate - biased.gyro_bias).norm(), 0.01);
}

// A gyro shaken three times beyond its configured density: the mean's variance says so (the
// window's scatter), not the density's d^2 / T.
TEST(StandstillDetector, AVibratingGyroGivesTheVarianceItShows) {
  StandstillOptions options;
  options.enabled = true;
  Motion shaken;
  shaken.gyro_noise_scale = 3.0;
  StandstillDetector detector(options);
  const Outcome outcome = run(&detector, shaken, 5.0);
  const double nominal = kGyroDensity * kGyroDensity / 0.1;
  EXPECT_GT(outcome.last_variance.minCoeff(), 4.0 * nominal);
  EXPECT_LT(outcome.last_variance.maxCoeff(), 20.0 * nominal);
}

TEST(StandstillDetector, AJoltEmptiesTheWindowAndAResetForgetsIt) {
  StandstillOptions options;
  options.enabled = true;
  StandstillDetector detector(options);
  Motion jolt;  // 0.2 s of 2 m/s^2 at t = 4 s (a door shut, a bump)
  jolt.acceleration_body = [](double t) {
    return Eigen::Vector3d(t > 4.0 && t <= 4.2 ? 2.0 : 0.0, 0.0, 0.0);
  };
  const Outcome outcome = run(&detector, jolt, 4.0);
  EXPECT_GT(outcome.measurements, 0);
  // From the jolt on, nothing until a window without it has passed and the raw readings have
  // been steady again for kSettleS.
  const Outcome after = run(&detector, jolt, 4.0, 4.0);
  EXPECT_GT(after.first_at_s, 0.2 + 0.5 + StandstillDetector::kSettleS - 0.05);
  detector.reset();
  EXPECT_FALSE(detector.still());
  EXPECT_NEAR(run(&detector, Motion(), 4.0, 10.0).first_at_s,
              0.5 + StandstillDetector::kSettleS + 0.1, 0.03);
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
