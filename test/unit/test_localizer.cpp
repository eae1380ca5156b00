// Localizer: stamp policies (duplicate, out of order, gap), stale and non-finite fixes, lazy
// initialization, reset, statistics, and the YAML config (defaults == config/inekf.yaml).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <optional>
#include <vector>

#include "inekf_semantic_mapping/estimation/localizer.h"
#include "inekf_semantic_mapping/lie/so3.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

ImuSample restingSample(double stamp) {
  ImuSample s;
  s.stamp_s = stamp;
  s.specific_force = Eigen::Vector3d(0.0, 0.0, 9.81);
  return s;
}

PositionFix fixAt(double stamp, const Eigen::Vector3d& p, double sigma = 1.0) {
  PositionFix f;
  f.stamp_s = stamp;
  f.position_map = p;
  f.covariance_map = Eigen::Matrix3d::Identity() * sigma * sigma;
  return f;
}

NavState startState(double stamp) {
  NavState s;
  s.stamp_s = stamp;
  return s;
}

TEST(Localizer, DropsDuplicateAndOutOfOrderSamplesAndCountsThem) {
  Localizer localizer{LocalizerConfig()};
  localizer.initialize(startState(100.0));
  EXPECT_EQ(localizer.addImu(restingSample(100.1)), Localizer::ImuStatus::kUsed);
  const NavState after_first = localizer.state();
  EXPECT_EQ(localizer.addImu(restingSample(100.1)), Localizer::ImuStatus::kDroppedDuplicate);
  EXPECT_EQ(localizer.addImu(restingSample(100.05)), Localizer::ImuStatus::kDroppedOutOfOrder);
  EXPECT_EQ(localizer.state().stamp_s, after_first.stamp_s);
  EXPECT_EQ(localizer.addImu(restingSample(100.2)), Localizer::ImuStatus::kUsed);
  const Localizer::Statistics stats = localizer.statistics();
  EXPECT_EQ(stats.imu_used, 2);
  EXPECT_EQ(stats.imu_dropped, 2);
  EXPECT_NEAR(localizer.state().stamp_s, 100.2, 1e-12);
  // At rest with gravity compensated, the state stays put.
  EXPECT_LT(localizer.state().position_map.norm(), 1e-9);
}

// Found by review: a propagation the filter refuses (its covariance would overflow: here a step
// of 1e200 s) left the state at its stamp but was reported kUsed, and the node published the
// old state under the new stamp.
TEST(Localizer, APropagationTheFilterRefusesIsNotReportedUsed) {
  Localizer localizer{LocalizerConfig()};
  localizer.initialize(startState(100.0));
  ASSERT_EQ(localizer.addImu(restingSample(100.1)), Localizer::ImuStatus::kUsed);
  EXPECT_EQ(localizer.addImu(restingSample(1e200)), Localizer::ImuStatus::kRefused);
  EXPECT_NEAR(localizer.state().stamp_s, 100.1, 1e-12);
  EXPECT_TRUE(localizer.filter().covariance().allFinite());
  EXPECT_EQ(localizer.statistics().imu_dropped, 1);
  EXPECT_EQ(localizer.statistics().imu_used, 1);
  EXPECT_EQ(localizer.addImu(restingSample(100.2)), Localizer::ImuStatus::kUsed);  // goes on
}

TEST(Localizer, BridgesAGapWithInflatedNoise) {
  LocalizerConfig config;
  config.max_imu_gap_s = 0.5;
  Localizer nominal(config), gapped(config);
  config.gap_noise_scale = 1.0;
  config.gap_gyro_noise_scale_per_s = 0.0;
  Localizer unscaled(config);
  // A near-zero initial covariance: what grows is the process noise alone.
  for (Localizer* l : {&nominal, &gapped, &unscaled}) {
    l->initialize(startState(0.0), ErrorCovariance::Identity() * 1e-12);
  }
  for (int k = 1; k <= 20; ++k) nominal.addImu(restingSample(0.1 * k));
  EXPECT_EQ(gapped.addImu(restingSample(2.0)), Localizer::ImuStatus::kGap);
  EXPECT_EQ(unscaled.addImu(restingSample(2.0)), Localizer::ImuStatus::kGap);
  EXPECT_EQ(gapped.statistics().imu_gaps, 1);
  EXPECT_NEAR(gapped.state().stamp_s, 2.0, 1e-12);
  // Same span: noise densities x10 -> the velocity variance grows ~100x.
  const double gapped_v = gapped.filter().covariance().block<3, 3>(3, 3).trace();
  const double unscaled_v = unscaled.filter().covariance().block<3, 3>(3, 3).trace();
  EXPECT_GT(gapped_v, 50.0 * unscaled_v);
  // Bridged in one step or in twenty, without inflation the uncertainty is about the same.
  const double nominal_v = nominal.filter().covariance().block<3, 3>(3, 3).trace();
  EXPECT_NEAR(unscaled_v / nominal_v, 1.0, 0.2);
  // The heading after a 2 s gap is unknown by what a car turns in it: the gyro's scale grows
  // with the gap (200 here: sigma about 11 deg; 10 stated 0.6 deg for a 20 deg error).
  const double yaw_sigma_deg = std::sqrt(gapped.filter().covariance()(2, 2)) * 180.0 / M_PI;
  EXPECT_GT(yaw_sigma_deg, 8.0);
  EXPECT_LT(yaw_sigma_deg, 15.0);
}

TEST(Localizer, RejectsStaleAndNonFiniteFixesAndInflatesSlightlyOldOnes) {
  LocalizerConfig config;
  config.max_fix_age_s = 0.5;
  config.fix_history_s = 0.0;  // no rewinding: the fix at 10.8 s is applied at 11 s, inflated
  Localizer localizer(config);
  localizer.initialize(startState(10.0));
  localizer.addImu(restingSample(11.0));
  CorrectionResult stale = localizer.addPositionFix(fixAt(9.0, Eigen::Vector3d::Zero()));
  EXPECT_FALSE(stale.accepted);
  EXPECT_NE(stale.reason.find("stale"), std::string::npos) << stale.reason;
  PositionFix bad = fixAt(11.0, Eigen::Vector3d(NAN, 0, 0));
  EXPECT_FALSE(localizer.addPositionFix(bad).accepted);
  EXPECT_TRUE(localizer.state().position_map.allFinite());
  const CorrectionResult fresh = localizer.addPositionFix(fixAt(10.8, Eigen::Vector3d(0.5, 0, 0)));
  EXPECT_TRUE(fresh.accepted) << fresh.reason;
  EXPECT_GT(localizer.state().position_map.x(), 0.0);
  const Localizer::Statistics stats = localizer.statistics();
  EXPECT_EQ(stats.gps_used, 1);
  EXPECT_EQ(stats.gps_rejected, 2);
  EXPECT_DOUBLE_EQ(stats.last_mahalanobis_squared, fresh.mahalanobis_squared);
}

TEST(Localizer, GateRejectsAJumpingFix) {
  Localizer localizer{LocalizerConfig()};
  localizer.initialize(startState(0.0));
  localizer.addImu(restingSample(0.1));
  const CorrectionResult result = localizer.addPositionFix(fixAt(0.1, Eigen::Vector3d(100, 0, 0)));
  EXPECT_FALSE(result.accepted);
  EXPECT_GT(result.mahalanobis_squared, localizer.config().gps_gate_mahalanobis_squared);
  EXPECT_LT(localizer.state().position_map.norm(), 1e-9);
}

// The heading monitor off: for tests of the mechanisms under it (re-acquisition, the
// constraint, the start's sigmas) in isolation.
LocalizerConfig withoutHeadingMonitor(LocalizerConfig config) {
  config.heading_from_track = false;
  config.heading_reopen_after_rejected_fixes = 0;
  config.heading_nis_window_fixes = 0;
  return config;
}

TEST(Localizer, TheTwoDofGateHasTheThreeDofGatesTailProbability) {
  // Chi-square tables: the 3-dof and 2-dof quantiles at 95 %, 99 % and 99.9 %.
  EXPECT_NEAR(twoDofGateOfSameTail(7.815), 5.991, 2e-3);
  EXPECT_NEAR(twoDofGateOfSameTail(11.345), 9.210, 2e-3);
  EXPECT_NEAR(twoDofGateOfSameTail(16.266), 13.816, 2e-3);
  EXPECT_NEAR(twoDofGateOfSameTail(30.0), 26.987, 2e-3);
}

// A fix without altitude has a 2-dof innovation: at the same tail probability its gate is 27.0,
// not the 3-dof 30 (the looser gate let through what a 3D fix at that d^2 would be as unlikely).
TEST(Localizer, AFixWithoutAltitudeIsGatedWithTwoDegreesOfFreedom) {
  const LocalizerConfig config = withoutHeadingMonitor(LocalizerConfig());
  const auto firstFix = [&](const PositionFix& fix) {
    Localizer localizer{config};
    localizer.initialize(startState(0.0));
    localizer.addImu(restingSample(0.1));
    return localizer.addPositionFix(fix);
  };
  const auto horizontalFix = [](double east_m, bool flagged) {
    PositionFix fix = fixAt(0.1, Eigen::Vector3d(east_m, 0, 0));
    fix.covariance_map(2, 2) = 1e6;  // the session's nil weight on the height
    fix.horizontal_only = flagged;
    return fix;
  };
  const double d2_at_1m = firstFix(fixAt(0.1, Eigen::Vector3d(1, 0, 0))).mahalanobis_squared;
  ASSERT_GT(d2_at_1m, 0.0);
  const double east_m = std::sqrt(28.5 / d2_at_1m);  // d^2 28.5: between 27.0 and 30
  const CorrectionResult as_3d = firstFix(fixAt(0.1, Eigen::Vector3d(east_m, 0, 0)));
  EXPECT_TRUE(as_3d.accepted) << as_3d.reason;
  EXPECT_NEAR(as_3d.mahalanobis_squared, 28.5, 0.01);
  const CorrectionResult unflagged = firstFix(horizontalFix(east_m, false));
  EXPECT_TRUE(unflagged.accepted) << unflagged.reason;
  const CorrectionResult as_2d = firstFix(horizontalFix(east_m, true));
  EXPECT_FALSE(as_2d.accepted);
  EXPECT_NEAR(as_2d.mahalanobis_squared, 28.5, 0.05);
  // Well inside both gates a 2D fix is taken.
  EXPECT_TRUE(firstFix(horizontalFix(0.5 * east_m, true)).accepted);
}

TEST(Localizer, ReacquiresAfterConsecutiveRejectedFixes) {
  LocalizerConfig config = withoutHeadingMonitor(LocalizerConfig());
  config.max_consecutive_rejected_fixes = 3;
  Localizer localizer(config);
  localizer.initialize(startState(0.0));
  const Eigen::Vector3d far(60.0, 0.0, 0.0);  // the filter, not the receiver, is wrong
  for (int k = 1; k <= 3; ++k) {
    for (int i = 1; i <= 10; ++i) localizer.addImu(restingSample(k - 1 + 0.1 * i));
    const CorrectionResult result = localizer.addPositionFix(fixAt(k, far));
    EXPECT_EQ(result.accepted, k == 3) << "fix " << k << ": " << result.reason;
  }
  EXPECT_EQ(localizer.statistics().gps_reacquisitions, 1);
  EXPECT_EQ(localizer.statistics().gps_rejected, 2);
  EXPECT_LT((localizer.state().position_map - far).norm(), 5.0);
  // Consistent fixes shrink the inflated covariance again; then gating works as before.
  for (int k = 4; k <= 12; ++k) {
    for (int i = 1; i <= 10; ++i) localizer.addImu(restingSample(k - 1 + 0.1 * i));
    EXPECT_TRUE(localizer.addPositionFix(fixAt(k, far)).accepted) << "fix " << k;
  }
  for (int i = 1; i <= 10; ++i) localizer.addImu(restingSample(12.0 + 0.1 * i));
  EXPECT_FALSE(localizer.addPositionFix(fixAt(13.0, far + Eigen::Vector3d(0, 30, 0))).accepted);
}

// Fault injection found: ten fixes 1000 km away, the fifth accepted by re-acquisition and the
// odometry published 1110 km off. Re-acquisition never moves the estimate faster than a car.
TEST(Localizer, NeverReacquiresAFixFartherThanACarCanMove) {
  LocalizerConfig config;
  config.max_consecutive_rejected_fixes = 3;
  Localizer localizer(config);
  localizer.initialize(startState(0.0));
  const Eigen::Vector3d far(1.0e6, 0.0, 0.0);
  for (int k = 1; k <= 10; ++k) {
    for (int i = 1; i <= 10; ++i) localizer.addImu(restingSample(k - 1 + 0.1 * i));
    const CorrectionResult result = localizer.addPositionFix(fixAt(k, far));
    EXPECT_FALSE(result.accepted) << "fix " << k;
    if (k >= 3) {
      EXPECT_NE(result.reason.find("re-acquisition refused"), std::string::npos);
    }
  }
  EXPECT_EQ(localizer.statistics().gps_reacquisitions, 0);
  EXPECT_LT(localizer.state().position_map.norm(), 1.0);
}

// Found by review: a start 200 m off in altitude. The fixes kept failing the gate on z, each
// re-open of the heading made it unknown, the next fix realigned it from the track and zeroed the
// count of rejected fixes, so re-acquisition never fired: 0 of 300 fixes accepted, the estimate
// 200 m off for good. The track cannot see altitude; the count must go on.
TEST(Localizer, RecoversFromAnAltitudeErrorTheHeadingTrackCannotSee) {
  Localizer localizer{LocalizerConfig()};  // the defaults: heading monitor on
  NavState start = startState(0.0);
  start.velocity_map = Eigen::Vector3d(10.0, 0.0, 0.0);
  start.position_map.z() = 200.0;
  localizer.initialize(start);
  ImuSample sample = restingSample(0.0);
  int accepted = 0;
  for (int i = 1; i <= 600; ++i) {  // 60 s straight at 10 m/s, a fix every second
    sample.stamp_s = 0.1 * i;
    localizer.addImu(sample);
    if (i % 10 != 0) continue;
    PositionFix fix = fixAt(sample.stamp_s, Eigen::Vector3d(1.0 * i, 0.0, 0.0), 1.5);
    fix.covariance_map(2, 2) = 9.0;
    if (localizer.addPositionFix(fix).accepted) ++accepted;
  }
  EXPECT_GE(localizer.statistics().gps_reacquisitions, 1);
  EXPECT_GT(accepted, 45);  // of 60
  EXPECT_LT((localizer.state().position_map - Eigen::Vector3d(600.0, 0.0, 0.0)).norm(), 5.0)
      << localizer.state().position_map.transpose();
}

// Found by review: a first fix 500 m off with the car standing still. The next good fix the gate
// let through explained the 500 m by a velocity of about 70 m/s; the estimate ran off faster than
// the re-acquisition bound, which compared the fixes with the runaway estimate, so every later
// fix was refused as "a broken receiver" (20,000 km off after 50 min). The bound is now on the
// fixes themselves: these ones stay put.
TEST(Localizer, ABadFirstFixDoesNotSendAStandingCarAway) {
  Localizer localizer{LocalizerConfig()};
  localizer.addImu(restingSample(0.0));
  ASSERT_TRUE(localizer.addPositionFix(fixAt(0.0, Eigen::Vector3d(500.0, 0.0, 0.0), 1.5)).accepted);
  for (int i = 1; i <= 1200; ++i) {  // 120 s, a fix every second, all at the true place
    localizer.addImu(restingSample(0.1 * i));
    if (i % 10 == 0) localizer.addPositionFix(fixAt(0.1 * i, Eigen::Vector3d::Zero(), 1.5));
  }
  EXPECT_LT(localizer.state().position_map.norm(), 5.0)
      << localizer.state().position_map.transpose();
  EXPECT_LT(localizer.state().velocity_map.norm(), 1.0)
      << localizer.state().velocity_map.transpose();
}

TEST(Localizer, DropsImuSamplesBeyondTheSensorRange) {
  Localizer localizer{LocalizerConfig()};
  localizer.initialize(startState(0.0));
  localizer.addImu(restingSample(0.1));
  const std::int64_t dropped_before = localizer.statistics().imu_dropped;
  ImuSample spinning = restingSample(0.2);
  spinning.angular_velocity = Eigen::Vector3d(0.0, 0.0, 1.0e6);
  EXPECT_EQ(localizer.addImu(spinning), Localizer::ImuStatus::kDroppedDuplicate);
  ImuSample crashing = restingSample(0.2);
  crashing.specific_force = Eigen::Vector3d(1.0e4, 0.0, 9.81);
  EXPECT_EQ(localizer.addImu(crashing), Localizer::ImuStatus::kDroppedDuplicate);
  EXPECT_EQ(localizer.statistics().imu_dropped, dropped_before + 2);
  EXPECT_NE(localizer.addImu(restingSample(0.2)), Localizer::ImuStatus::kDroppedDuplicate);
  EXPECT_TRUE(localizer.state().rotation.isApprox(Eigen::Matrix3d::Identity(), 1e-6));
}

TEST(Localizer, LazyInitializationLevelsFromGravityOrUsesTheReference) {
  LocalizerConfig config;
  config.init_orientation_from_reference = false;
  Localizer levelled(config);
  ImuSample tilted = restingSample(5.0);
  const double roll = 0.1, pitch = -0.05;
  const Eigen::Matrix3d r_true = (Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                                  Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
                                     .toRotationMatrix();
  tilted.specific_force = r_true.transpose() * Eigen::Vector3d(0, 0, 9.81);
  EXPECT_EQ(levelled.addImu(tilted), Localizer::ImuStatus::kNotInitialized);
  EXPECT_FALSE(levelled.initialized());
  const CorrectionResult init = levelled.addPositionFix(fixAt(5.0, Eigen::Vector3d(3, 4, 5)));
  EXPECT_TRUE(init.accepted);
  ASSERT_TRUE(levelled.initialized());
  EXPECT_LT((levelled.state().position_map - Eigen::Vector3d(3, 4, 5)).norm(), 1e-12);
  EXPECT_LT(lie::logSO3(levelled.state().rotation.transpose() * r_true).norm(), 1e-9);

  config.init_orientation_from_reference = true;
  Localizer referenced(config);
  const Eigen::Matrix3d reference = lie::expSO3(Eigen::Vector3d(0.0, 0.0, 1.2));
  referenced.setInitialReference(reference, Eigen::Vector3d(2, 0, 0));
  referenced.addPositionFix(fixAt(1.0, Eigen::Vector3d::Zero()));
  EXPECT_LT((referenced.state().rotation - reference).norm(), 1e-12);
  EXPECT_EQ(referenced.state().velocity_map, Eigen::Vector3d(2, 0, 0));

  referenced.reset();
  EXPECT_FALSE(referenced.initialized());
  EXPECT_EQ(referenced.addImu(restingSample(0.5)), Localizer::ImuStatus::kNotInitialized);
}

// A car driving north-east at 10 m/s when the lazy start happens, straight for 5 s (so levelling
// from the specific force is exact) and then turning left at 0.2 rad/s (the centripetal
// acceleration makes the yaw observable from the fixes). It starts with the true orientation as
// the reference but no velocity, or with no reference at all (levelled from gravity). 100 Hz
// IMU, exact fixes claiming 1.5 m once a second, 40 s.
struct LazyStartOutcome {
  Localizer::Statistics statistics;
  double velocity_error_mps = 0.0;
  double yaw_error_deg = 0.0;
};

LazyStartOutcome lazyStartWhileDriving(const LocalizerConfig& config, bool orientation_reference) {
  constexpr double kSpeed = 10.0, kTurnRate = 0.2, kTurnStartS = 5.0, kDt = 0.01;
  Localizer localizer(config);
  double yaw = M_PI / 4;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  if (orientation_reference) {
    localizer.setInitialReference(lie::expSO3(Eigen::Vector3d(0.0, 0.0, yaw)), std::nullopt);
  }
  for (int k = 0; k <= 4000; ++k) {
    const double t = kDt * k;
    // The sample at t holds over (t - kDt, t]: turning when that interval is inside the turn.
    const double turn_rate = t - kDt / 2 < kTurnStartS ? 0.0 : kTurnRate;
    if (k > 0) {  // exact arc (or segment) over the interval
      const double new_yaw = yaw + turn_rate * kDt;
      position += turn_rate == 0.0
                      ? kSpeed * kDt * Eigen::Vector3d(std::cos(yaw), std::sin(yaw), 0.0)
                      : kSpeed / turn_rate *
                            Eigen::Vector3d(std::sin(new_yaw) - std::sin(yaw),
                                            std::cos(yaw) - std::cos(new_yaw), 0.0);
      yaw = new_yaw;
    }
    ImuSample sample;
    sample.stamp_s = t;
    sample.angular_velocity = Eigen::Vector3d(0.0, 0.0, turn_rate);
    sample.specific_force = Eigen::Vector3d(0.0, kSpeed * turn_rate, 9.81);
    localizer.addImu(sample);
    if (k % 100 == 0) localizer.addPositionFix(fixAt(t, position, 1.5));
  }
  LazyStartOutcome outcome;
  outcome.statistics = localizer.statistics();
  outcome.velocity_error_mps =
      (localizer.state().velocity_map - kSpeed * Eigen::Vector3d(std::cos(yaw), std::sin(yaw), 0))
          .norm();
  outcome.yaw_error_deg =
      std::abs(
          lie::logSO3(lie::expSO3(Eigen::Vector3d(0, 0, -yaw)) * localizer.state().rotation).z()) *
      180.0 / M_PI;
  return outcome;
}

TEST(Localizer, LazyStartWithoutAVelocityLearnsTheSpeedFromTheFixes) {
  LocalizerConfig config;
  const LazyStartOutcome honest = lazyStartWhileDriving(config, /*orientation_reference=*/true);
  EXPECT_EQ(honest.statistics.starts_without_velocity, 1);
  EXPECT_EQ(honest.statistics.gps_rejected, 0);
  EXPECT_EQ(honest.statistics.gps_used, 41);
  EXPECT_LT(honest.velocity_error_mps, 0.3);
  EXPECT_LT(honest.yaw_error_deg, 0.5);

  // Zero velocity claimed to +-0.5 m/s instead (inekf_node before): the first fixes fail the gate
  // (with the heading monitor the third re-opens the state: it is off here).
  config = withoutHeadingMonitor(config);
  config.unknown_velocity_sigma_horizontal_mps = config.initial_velocity_sigma_mps;
  config.unknown_velocity_sigma_vertical_mps = config.initial_velocity_sigma_mps;
  EXPECT_GE(lazyStartWhileDriving(config, true).statistics.gps_rejected, 3);
}

TEST(Localizer, LazyStartLevelledFromGravityLearnsTheYawOnceTheCarTurns) {
  LocalizerConfig config;
  config.init_orientation_from_reference = false;
  const LazyStartOutcome honest = lazyStartWhileDriving(config, /*orientation_reference=*/false);
  EXPECT_EQ(honest.statistics.gps_rejected, 0);
  EXPECT_LT(honest.velocity_error_mps, 0.3);
  EXPECT_LT(honest.yaw_error_deg, 1.0);

  // Yaw 0 claimed to the configured 1 deg instead (the truth is 45 deg): it never recovers.
  // This is how e2e_real_oxts failed when the first fix beat the first Imu message (42 deg).
  config.unknown_yaw_sigma_deg = config.initial_yaw_sigma_deg;
  EXPECT_GT(lazyStartWhileDriving(withoutHeadingMonitor(config), false).yaw_error_deg, 20.0);
  // The heading monitor notices that the GPS track disagrees and re-initialises the heading.
  const LazyStartOutcome monitored = lazyStartWhileDriving(config, false);
  EXPECT_GE(monitored.statistics.heading_recoveries + monitored.statistics.heading_reopens, 1);
  EXPECT_LT(monitored.yaw_error_deg, 2.0);
}

// While the heading is unknown the fixes correct position and velocity but do not rotate it:
// its cross-covariances are dropped before each fix (heading_hold_unknown_yaw), and the GPS
// track aligns it instead. A car accelerating at 1 m/s^2 along 45 deg, started level with yaw
// 0 +- 180 deg, the track's alignment put out of reach: with the hold the yaw stays at the
// gyro's 0 while the position follows the fixes; without it the first-order update rotates the
// 180-deg-sigma heading (on this clean straight run, to the true 45 deg: the hold gives that
// up, which is why it is off by default).
TEST(Localizer, AnUnknownHeadingIsNotRotatedByTheFixes) {
  LocalizerConfig config;
  config.init_orientation_from_reference = false;
  config.heading_align_max_sigma_deg = 1e-9;  // the track never aligns
  config.heading_reopen_after_rejected_fixes = 0;
  config.heading_nis_window_fixes = 0;
  config.heading_hold_unknown_yaw = true;  // off by default (see config/inekf.yaml)
  const auto drive = [](const LocalizerConfig& c, double* position_error_m) {
    constexpr double kYaw = M_PI / 4, kAcceleration = 1.0, kDt = 0.01;
    const Eigen::Vector3d direction(std::cos(kYaw), std::sin(kYaw), 0.0);
    Localizer localizer(c);
    double t = 0.0;
    for (int k = 0; k <= 1000; ++k) {
      t = kDt * k;
      ImuSample sample = restingSample(t);
      if (k > 0) sample.specific_force.x() = kAcceleration;  // along the body x axis
      localizer.addImu(sample);
      if (k % 100 == 0) {
        localizer.addPositionFix(fixAt(t, 0.5 * kAcceleration * t * t * direction, 1.5));
      }
    }
    *position_error_m =
        (localizer.state().position_map - 0.5 * kAcceleration * t * t * direction).norm();
    return std::atan2(localizer.state().rotation(1, 0), localizer.state().rotation(0, 0)) * 180.0 /
           M_PI;
  };
  double held_error_m = 0.0, free_error_m = 0.0;
  const double held_yaw_deg = drive(config, &held_error_m);
  EXPECT_LT(std::abs(held_yaw_deg), 0.5);
  EXPECT_LT(held_error_m, 3.0);
  config.heading_hold_unknown_yaw = false;
  const double free_yaw_deg = drive(config, &free_error_m);
  EXPECT_GT(std::abs(free_yaw_deg), 2.0);
  std::printf(
      "[ HOLD     ] yaw after 10 s: held %.2f deg (position error %.2f m), free %.2f deg "
      "(%.2f m)\n",
      held_yaw_deg, held_error_m, free_yaw_deg, free_error_m);
}

TEST(Localizer, AFixBeforeAnyImuSampleDoesNotStartTheFilterBlind) {
  // inekf_node: the first fix can be handled before the first Imu message (separate
  // connections). Starting then would mean yaw 0 +- 1 deg on a car heading 45 deg.
  Localizer localizer{LocalizerConfig()};
  const CorrectionResult early = localizer.addPositionFix(fixAt(0.0, Eigen::Vector3d::Zero()));
  EXPECT_FALSE(early.accepted);
  EXPECT_FALSE(localizer.initialized());
  EXPECT_EQ(localizer.statistics().gps_before_start, 1);
  EXPECT_EQ(localizer.statistics().gps_rejected, 0);

  const Eigen::Matrix3d heading = lie::expSO3(Eigen::Vector3d(0.0, 0.0, M_PI / 4));
  localizer.setInitialReference(heading, Eigen::Vector3d(7.0, 7.0, 0.0));
  EXPECT_EQ(localizer.addImu(restingSample(0.0)), Localizer::ImuStatus::kNotInitialized);
  EXPECT_TRUE(localizer.addPositionFix(fixAt(1.0, Eigen::Vector3d(7, 7, 0))).accepted);
  ASSERT_TRUE(localizer.initialized());
  EXPECT_LT((localizer.state().rotation - heading).norm(), 1e-12);
  EXPECT_EQ(localizer.state().velocity_map, Eigen::Vector3d(7.0, 7.0, 0.0));
}

// The turning drive of lazyStartWhileDriving with noisy fixes once a second, stamped
// fix_offset_s before an IMU sample, each handed to the Localizer `fix_delay_steps` IMU samples
// after its stamp (it travelled on a slower connection). With imu_sample_at_fixes an extra IMU
// sample (the same constant rates) is stamped at each fix, so that an in-order fix falls exactly
// on a step: the reference for a late fix that the Localizer must place inside a step.
struct DelayedFixRun {
  NavState final_state;
  Localizer::Statistics statistics;
};

DelayedFixRun driveWithDelayedFixes(const LocalizerConfig& config, int fix_delay_steps,
                                    double fix_offset_s = 0.0, bool imu_sample_at_fixes = false) {
  constexpr double kSpeed = 10.0, kTurnRate = 0.2, kDt = 0.01;
  Localizer localizer(config);
  NavState start;
  start.rotation = lie::expSO3(Eigen::Vector3d(0.0, 0.0, 0.3));
  start.velocity_map = start.rotation * Eigen::Vector3d(kSpeed, 0.0, 0.0);
  localizer.initialize(start);
  std::vector<PositionFix> pending;
  std::uint32_t noise_state = 12345;
  const auto noise = [&noise_state] {  // deterministic, roughly N(0, 1)
    double sum = 0.0;
    for (int i = 0; i < 12; ++i) {
      noise_state = noise_state * 1664525u + 1013904223u;
      sum += noise_state / 4294967296.0;
    }
    return sum - 6.0;
  };
  const auto imuAt = [&](double t) {
    ImuSample sample;
    sample.stamp_s = t;
    sample.angular_velocity = Eigen::Vector3d(0.0, 0.0, kTurnRate);
    sample.specific_force = Eigen::Vector3d(0.0, kSpeed * kTurnRate, 9.81);
    localizer.addImu(sample);
  };
  const auto deliverDue = [&](double now) {
    while (!pending.empty() && now >= pending.front().stamp_s + fix_delay_steps * kDt - 1e-9) {
      localizer.addPositionFix(pending.front());
      pending.erase(pending.begin());
    }
  };
  for (int k = 1; k <= 1600; ++k) {  // fixes until 15 s, the last one arriving by 16 s
    const double t = kDt * k;
    const bool fix_now = k % 100 == 0 && k <= 1500;
    const double fix_stamp = t - fix_offset_s;
    if (fix_now) {
      const double yaw = 0.3 + kTurnRate * fix_stamp;
      const Eigen::Vector3d truth =
          kSpeed / kTurnRate *
          Eigen::Vector3d(std::sin(yaw) - std::sin(0.3), std::cos(0.3) - std::cos(yaw), 0.0);
      pending.push_back(
          fixAt(fix_stamp, truth + 1.5 * Eigen::Vector3d(noise(), noise(), noise()), 1.5));
      if (imu_sample_at_fixes && fix_offset_s > 0.0) {
        imuAt(fix_stamp);
        deliverDue(fix_stamp);
      }
    }
    imuAt(t);
    deliverDue(t);
  }
  return {localizer.state(), localizer.statistics()};
}

void expectSameState(const NavState& a, const NavState& b) {
  EXPECT_NEAR(a.stamp_s, b.stamp_s, 1e-9);
  EXPECT_LT((a.position_map - b.position_map).norm(), 1e-6);
  EXPECT_LT((a.velocity_map - b.velocity_map).norm(), 1e-6);
  EXPECT_LT(lie::logSO3(a.rotation.transpose() * b.rotation).norm(), 1e-9);
  EXPECT_LT((a.gyro_bias - b.gyro_bias).norm(), 1e-9);
  EXPECT_LT((a.accel_bias - b.accel_bias).norm(), 1e-9);
}

TEST(Localizer, ALateFixIsAppliedAtItsOwnTimeAsIfItHadComeInOrder) {
  const LocalizerConfig config;
  const DelayedFixRun in_order = driveWithDelayedFixes(config, 0);
  const DelayedFixRun late = driveWithDelayedFixes(config, 70);  // 0.7 s late
  EXPECT_EQ(in_order.statistics.gps_applied_late, 0);
  EXPECT_EQ(late.statistics.gps_applied_late, 15);
  EXPECT_EQ(late.statistics.gps_used, 15);
  expectSameState(in_order.final_state, late.final_state);

  // A fix stamped between two IMU samples: the step is split at the fix. The reference has an
  // IMU sample at each fix's stamp and its fixes in order.
  const DelayedFixRun split_in_order = driveWithDelayedFixes(config, 0, 0.006, true);
  const DelayedFixRun split_late = driveWithDelayedFixes(config, 70, 0.006);
  EXPECT_EQ(split_in_order.statistics.gps_applied_late, 0);
  EXPECT_EQ(split_late.statistics.gps_applied_late, 15);
  expectSameState(split_in_order.final_state, split_late.final_state);

  // Without the history the same late fixes are stale (0.7 s > max_fix_age_s) and all lost.
  LocalizerConfig no_history = config;
  no_history.fix_history_s = 0.0;
  const DelayedFixRun lost = driveWithDelayedFixes(no_history, 70);
  EXPECT_EQ(lost.statistics.gps_used, 0);
  EXPECT_EQ(lost.statistics.gps_rejected, 15);

  // Older than the history: rejected as stale, nothing rewound.
  LocalizerConfig short_history = config;
  short_history.fix_history_s = 0.5;
  const DelayedFixRun too_old = driveWithDelayedFixes(short_history, 70);
  EXPECT_EQ(too_old.statistics.gps_applied_late, 0);
  EXPECT_EQ(too_old.statistics.gps_rejected, 15);
}

TEST(Localizer, AFixOlderThanOneAlreadyAppliedIsNotReplayedOverIt) {
  Localizer localizer{LocalizerConfig()};
  localizer.initialize(startState(0.0));
  for (int k = 1; k <= 100; ++k) localizer.addImu(restingSample(0.01 * k));
  EXPECT_TRUE(localizer.addPositionFix(fixAt(0.8, Eigen::Vector3d(0.3, 0, 0))).accepted);
  const NavState after_newer = localizer.state();
  // Rewinding to 0.5 s would replay over the 0.8 s fix and lose it: the Localizer applies the
  // older fix at the state's time instead (0.5 s old: within max_fix_age_s).
  localizer.addPositionFix(fixAt(0.5, Eigen::Vector3d(0.3, 0, 0)));
  EXPECT_EQ(localizer.statistics().gps_applied_late, 1);  // only the first
  EXPECT_GT(localizer.state().position_map.x(), 0.5 * after_newer.position_map.x());
}

// A car at constant speed on a straight road with an unmodelled gyro bias: GPS positions say
// nothing about its heading, which drifts with the gyro; the land-vehicle constraint ties the
// heading to the velocity the fixes do observe. With the heading too uncertain the constraint
// waits (it cannot tell forward from backward).
double headingErrorAfterStraightDrive(bool nonholonomic, double initial_yaw_sigma_deg,
                                      Localizer::Statistics* statistics) {
  // The constraint alone: the heading monitor's track assumes the gyro heading drifts little
  // over its 20 s window, which this unmodelled 0.17 deg/s bias breaks (with the monitor the
  // constrained run ends 2.0 deg off instead of < 1: see docs/localization_imu_gps_only.md).
  LocalizerConfig config = withoutHeadingMonitor(LocalizerConfig());
  config.nonholonomic = nonholonomic;
  config.initial_yaw_sigma_deg = initial_yaw_sigma_deg;
  Localizer localizer(config);
  constexpr double kSpeed = 15.0, kDt = 0.1, kGyroBiasZ = 0.003;  // rad/s, not modelled
  const double yaw = 0.6;
  NavState start;
  start.rotation = lie::expSO3(Eigen::Vector3d(0.0, 0.0, yaw));
  start.velocity_map = kSpeed * Eigen::Vector3d(std::cos(yaw), std::sin(yaw), 0.0);
  localizer.initialize(start);
  std::uint32_t lcg = 12345;  // deterministic GPS noise
  const auto noise = [&lcg]() {
    double sum = 0.0;  // Irwin-Hall: sum of 12 uniforms - 6 ~ N(0, 1)
    for (int i = 0; i < 12; ++i) {
      lcg = lcg * 1664525u + 1013904223u;
      sum += lcg / 4294967296.0;
    }
    return sum - 6.0;
  };
  for (int k = 1; k <= 1200; ++k) {
    ImuSample sample = restingSample(k * kDt);
    sample.angular_velocity.z() = kGyroBiasZ;
    localizer.addImu(sample);
    if (k % 10 == 0) {
      const Eigen::Vector3d truth = start.velocity_map * (k * kDt);
      localizer.addPositionFix(fixAt(
          k * kDt, truth + Eigen::Vector3d(1.5 * noise(), 1.5 * noise(), 3.0 * noise()), 1.5));
    }
  }
  *statistics = localizer.statistics();
  const Eigen::Matrix3d error =
      lie::expSO3(Eigen::Vector3d(0.0, 0.0, -yaw)) * localizer.state().rotation;
  return std::abs(lie::logSO3(error).z()) * 180.0 / M_PI;
}

TEST(Localizer, TheLandVehicleConstraintHoldsTheHeadingOnAStraightRoad) {
  Localizer::Statistics statistics;
  const double without = headingErrorAfterStraightDrive(false, 1.0, &statistics);
  EXPECT_EQ(statistics.nonholonomic_used, 0);
  const double with = headingErrorAfterStraightDrive(true, 1.0, &statistics);
  EXPECT_GT(without, 10.0);  // 0.003 rad/s over 120 s: about 20 deg
  EXPECT_LT(with, 1.0);
  EXPECT_GT(statistics.nonholonomic_used, 1000);
  EXPECT_EQ(statistics.nonholonomic_skipped, 0);
  // Heading unknown to 1 sigma = 30 deg, unobservable on this road: the constraint never applies.
  headingErrorAfterStraightDrive(true, 30.0, &statistics);
  EXPECT_EQ(statistics.nonholonomic_used, 0);
  EXPECT_EQ(statistics.nonholonomic_skipped, 1200);
}

// The estimate's lateral velocity 0.3 s after a start 1 m/s off sideways (the car drives 15 m/s
// along a straight road, no fixes), its IMU at `rate_hz`, the land-vehicle constraint at
// min_step_s: how hard the constraint pulled it back.
double lateralVelocityAfterAStartOff(double rate_hz, double min_step_s) {
  LocalizerConfig config;
  config.nonholonomic_min_step_s = min_step_s;
  Localizer localizer(config);
  NavState start;
  start.velocity_map = Eigen::Vector3d(15.0, 1.0, 0.0);
  localizer.initialize(start);
  const int steps = static_cast<int>(std::lround(0.3 * rate_hz));
  for (int k = 1; k <= steps; ++k) localizer.addImu(restingSample(k / rate_hz));
  EXPECT_EQ(localizer.statistics().nonholonomic_used, steps);
  return localizer.state().velocity_map.y();
}

// Found by review: the constraint was one measurement per IMU step, so a 100 Hz IMU held the
// velocity ten times as hard per second as KITTI's 10 Hz OXTS its sigmas were tuned on. A short
// step's variances are scaled by min_step_s / dt: the same information per second at any rate.
TEST(Localizer, TheLandVehicleConstraintHoldsAsHardPerSecondAtAnyImuRate) {
  const double at_10_hz = lateralVelocityAfterAStartOff(10.0, 0.1);
  const double at_100_hz = lateralVelocityAfterAStartOff(100.0, 0.1);
  const double at_100_hz_by_step = lateralVelocityAfterAStartOff(100.0, 0.0);
  EXPECT_GT(at_10_hz, 0.1);  // pulled part of the way back in 0.3 s
  EXPECT_NEAR(at_100_hz, at_10_hz, 0.2 * at_10_hz);
  EXPECT_LT(at_100_hz_by_step, 0.75 * at_10_hz);  // the old way: every step as the sigmas say
  // KITTI's steps (0.06 s and longer) are left as they were by the default 0.05.
  EXPECT_EQ(lateralVelocityAfterAStartOff(10.0, 0.05), lateralVelocityAfterAStartOff(10.0, 0.0));
}

// A car on a level straight road whose IMU is mounted pitched: its x axis points
// `mount_pitch_deg` below the direction of travel, so the velocity has an upward component in
// the IMU's axes. GPS fixes as above. Returns the final pitch error of the IMU's attitude (deg).
double pitchErrorWithMountedImu(double mount_pitch_deg, double configured_pitch_deg) {
  LocalizerConfig config;
  config.nonholonomic_vertical_sigma_mps = 0.1;  // tight: what a known mounting allows
  config.nonholonomic_vehicle_pitch_deg = configured_pitch_deg;
  Localizer localizer(config);
  constexpr double kSpeed = 15.0, kDt = 0.1;
  const double pitch = mount_pitch_deg * M_PI / 180.0;
  NavState start;
  start.rotation = lie::expSO3(Eigen::Vector3d(0.0, pitch, 0.0));  // x axis tipped down
  start.velocity_map = Eigen::Vector3d(kSpeed, 0.0, 0.0);
  localizer.initialize(start);
  std::uint32_t lcg = 777;
  const auto noise = [&lcg]() {
    lcg = lcg * 1664525u + 1013904223u;
    return lcg / 4294967296.0 - 0.5;  // uniform, sigma 0.29
  };
  for (int k = 1; k <= 600; ++k) {
    ImuSample sample = restingSample(k * kDt);
    sample.specific_force = start.rotation.transpose() * Eigen::Vector3d(0.0, 0.0, 9.81);
    localizer.addImu(sample);
    if (k % 10 == 0) {
      const Eigen::Vector3d truth = start.velocity_map * (k * kDt);
      localizer.addPositionFix(fixAt(k * kDt, truth + Eigen::Vector3d(noise(), noise(), noise())));
    }
  }
  EXPECT_GT(localizer.statistics().nonholonomic_used, 500);
  const Eigen::Matrix3d error = start.rotation.transpose() * localizer.state().rotation;
  return lie::logSO3(error).y() * 180.0 / M_PI;
}

// The constraint waits while the heading about the map's z axis is unknown, however the IMU is
// mounted: for a board upright (its x axis up) the pose covariance's yaw is about a horizontal
// axis, known from gravity, and the constraint ran from the start and pinned the unknown heading
// 19 deg off (found by review).
TEST(Localizer, TheLandVehicleConstraintWaitsForTheHeadingHoweverTheImuIsMounted) {
  for (const double pitch_deg : {0.0, -90.0}) {
    SCOPED_TRACE(pitch_deg);
    LocalizerConfig config;
    config.init_orientation_from_reference = false;
    Localizer localizer(config);
    const Eigen::Matrix3d base_from_imu =
        Eigen::AngleAxisd(pitch_deg * M_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
    ASSERT_TRUE(localizer.setImuMounting(base_from_imu));
    ImuSample sample = restingSample(0.0);
    sample.specific_force = base_from_imu.transpose() * Eigen::Vector3d(0.0, 0.0, 9.81);
    localizer.addImu(sample);
    ASSERT_TRUE(localizer.addPositionFix(fixAt(0.0, Eigen::Vector3d::Zero())).accepted);
    for (int k = 1; k <= 10; ++k) {
      sample.stamp_s = 0.1 * k;
      localizer.addImu(sample);
    }
    EXPECT_GT(localizer.yawSigma(), M_PI / 2);
    EXPECT_EQ(localizer.statistics().nonholonomic_used, 0);
    EXPECT_EQ(localizer.statistics().nonholonomic_skipped, 10);
  }
}

TEST(Localizer, TheLandVehicleConstraintTakesTheImuMountingFromTheConfig) {
  const double ignored = pitchErrorWithMountedImu(1.0, 0.0);
  const double configured = pitchErrorWithMountedImu(1.0, 1.0);
  const double wrong_sign = pitchErrorWithMountedImu(1.0, -1.0);
  std::printf("pitch error: mounting ignored %.3f deg, configured %.3f, wrong sign %.3f\n", ignored,
              configured, wrong_sign);
  EXPECT_LT(std::abs(configured), 0.05);
  EXPECT_GT(std::abs(ignored), 0.5);
  EXPECT_GT(std::abs(wrong_sign), 1.5 * std::abs(ignored));
  // An aligned IMU with nothing configured stays right too.
  EXPECT_LT(std::abs(pitchErrorWithMountedImu(0.0, 0.0)), 0.05);
}

// A vehicle standing 40 s, its fixes once a second on time or each 0.5 s late (applied by
// rewinding the history and replaying the standstill updates stored with the steps): the same
// updates, counted once. Found by review: a replay counted them again (296 -> 794 updates with
// fixes 1.9 s late).
TEST(Localizer, StandstillUpdatesReplayedForALateFixAreCountedOnce) {
  const auto run = [](double fix_delay_s) {
    LocalizerConfig config;
    config.standstill.enabled = true;
    Localizer localizer(config);
    NavState start;
    start.stamp_s = 0.0;
    localizer.initialize(start);
    std::vector<double> pending;  // stamps of fixes not yet delivered
    for (int k = 1; k <= 4000; ++k) {
      const double t = 0.01 * k;
      localizer.addImu(restingSample(t));
      if (k % 100 == 0) pending.push_back(t);
      while (!pending.empty() && pending.front() <= t - fix_delay_s + 1e-9) {
        localizer.addPositionFix(fixAt(pending.front(), Eigen::Vector3d::Zero(), 1.5));
        pending.erase(pending.begin());
      }
    }
    return localizer.statistics();
  };
  const Localizer::Statistics on_time = run(0.0), late = run(0.5);
  EXPECT_GT(on_time.standstill_used, 150);  // from the fixes' 20 s on
  EXPECT_GT(late.gps_applied_late, 30);
  EXPECT_NEAR(static_cast<double>(late.standstill_used),
              static_cast<double>(on_time.standstill_used), 10.0);
}

TEST(LocalizerConfig, RepositoryYamlEqualsTheBuiltInDefaults) {
  const LocalizerConfig loaded = LocalizerConfig::fromYamlFile(test::repoPath("config/inekf.yaml"));
  const LocalizerConfig defaults;
  EXPECT_EQ(loaded.filter_type, defaults.filter_type);
  EXPECT_DOUBLE_EQ(loaded.imu_noise.gyro_noise_density, defaults.imu_noise.gyro_noise_density);
  EXPECT_DOUBLE_EQ(loaded.imu_noise.accel_noise_density, defaults.imu_noise.accel_noise_density);
  EXPECT_DOUBLE_EQ(loaded.imu_noise.gyro_bias_random_walk,
                   defaults.imu_noise.gyro_bias_random_walk);
  EXPECT_DOUBLE_EQ(loaded.imu_noise.accel_bias_random_walk,
                   defaults.imu_noise.accel_bias_random_walk);
  EXPECT_DOUBLE_EQ(loaded.imu_noise.gravity_mps2, defaults.imu_noise.gravity_mps2);
  EXPECT_DOUBLE_EQ(loaded.initial_rotation_sigma_deg, defaults.initial_rotation_sigma_deg);
  EXPECT_DOUBLE_EQ(loaded.initial_yaw_sigma_deg, defaults.initial_yaw_sigma_deg);
  EXPECT_EQ(loaded.nonholonomic, defaults.nonholonomic);
  EXPECT_DOUBLE_EQ(loaded.nonholonomic_lateral_sigma_mps, defaults.nonholonomic_lateral_sigma_mps);
  EXPECT_DOUBLE_EQ(loaded.nonholonomic_vertical_sigma_mps,
                   defaults.nonholonomic_vertical_sigma_mps);
  EXPECT_DOUBLE_EQ(loaded.nonholonomic_min_step_s, defaults.nonholonomic_min_step_s);
  EXPECT_DOUBLE_EQ(loaded.nonholonomic_gate_mahalanobis_squared,
                   defaults.nonholonomic_gate_mahalanobis_squared);
  EXPECT_DOUBLE_EQ(loaded.nonholonomic_max_heading_sigma_deg,
                   defaults.nonholonomic_max_heading_sigma_deg);
  // The one value that is KITTI's rig, not a default for any vehicle: the IMU's mounting.
  EXPECT_DOUBLE_EQ(loaded.nonholonomic_vehicle_pitch_deg, 0.65);
  EXPECT_DOUBLE_EQ(defaults.nonholonomic_vehicle_pitch_deg, 0.0);
  EXPECT_DOUBLE_EQ(loaded.nonholonomic_vehicle_yaw_deg, defaults.nonholonomic_vehicle_yaw_deg);
  EXPECT_DOUBLE_EQ(loaded.initial_velocity_sigma_mps, defaults.initial_velocity_sigma_mps);
  EXPECT_DOUBLE_EQ(loaded.unknown_velocity_sigma_horizontal_mps,
                   defaults.unknown_velocity_sigma_horizontal_mps);
  EXPECT_DOUBLE_EQ(loaded.unknown_velocity_sigma_vertical_mps,
                   defaults.unknown_velocity_sigma_vertical_mps);
  EXPECT_DOUBLE_EQ(loaded.unknown_yaw_sigma_deg, defaults.unknown_yaw_sigma_deg);
  EXPECT_DOUBLE_EQ(loaded.max_fix_age_s, defaults.max_fix_age_s);
  EXPECT_DOUBLE_EQ(loaded.fix_history_s, defaults.fix_history_s);
  EXPECT_DOUBLE_EQ(loaded.initial_position_sigma_m, defaults.initial_position_sigma_m);
  EXPECT_DOUBLE_EQ(loaded.initial_gyro_bias_sigma_radps, defaults.initial_gyro_bias_sigma_radps);
  EXPECT_DOUBLE_EQ(loaded.initial_accel_bias_sigma_mps2, defaults.initial_accel_bias_sigma_mps2);
  EXPECT_DOUBLE_EQ(loaded.gps_gate_mahalanobis_squared, defaults.gps_gate_mahalanobis_squared);
  EXPECT_DOUBLE_EQ(loaded.min_gps_sigma_m, defaults.min_gps_sigma_m);
  EXPECT_DOUBLE_EQ(loaded.max_fix_age_s, defaults.max_fix_age_s);
  EXPECT_EQ(loaded.max_consecutive_rejected_fixes, defaults.max_consecutive_rejected_fixes);
  EXPECT_DOUBLE_EQ(loaded.max_reacquisition_speed_mps, defaults.max_reacquisition_speed_mps);
  EXPECT_DOUBLE_EQ(loaded.max_angular_rate_radps, defaults.max_angular_rate_radps);
  EXPECT_DOUBLE_EQ(loaded.max_specific_force_mps2, defaults.max_specific_force_mps2);
  EXPECT_DOUBLE_EQ(loaded.max_imu_gap_s, defaults.max_imu_gap_s);
  EXPECT_DOUBLE_EQ(loaded.gap_noise_scale, defaults.gap_noise_scale);
  EXPECT_DOUBLE_EQ(loaded.gap_gyro_noise_scale_per_s, defaults.gap_gyro_noise_scale_per_s);
  EXPECT_DOUBLE_EQ(loaded.interpolated_gyro_noise_scale_per_s,
                   defaults.interpolated_gyro_noise_scale_per_s);
  EXPECT_DOUBLE_EQ(loaded.interpolated_accel_noise_scale, defaults.interpolated_accel_noise_scale);
  EXPECT_EQ(loaded.init_orientation_from_reference, defaults.init_orientation_from_reference);
  const StandstillOptions &still = loaded.standstill, &still_default = defaults.standstill;
  EXPECT_EQ(still.enabled, still_default.enabled);
  EXPECT_DOUBLE_EQ(still.window_s, still_default.window_s);
  EXPECT_DOUBLE_EQ(still.max_acceleration_mps2, still_default.max_acceleration_mps2);
  EXPECT_DOUBLE_EQ(still.max_rate_degps, still_default.max_rate_degps);
  EXPECT_DOUBLE_EQ(still.max_speed_mps, still_default.max_speed_mps);
  EXPECT_DOUBLE_EQ(still.velocity_sigma_mps, still_default.velocity_sigma_mps);
  EXPECT_DOUBLE_EQ(still.update_interval_s, still_default.update_interval_s);
  EXPECT_DOUBLE_EQ(still.gate_mahalanobis_squared, still_default.gate_mahalanobis_squared);
  const LocalizerConfig::WheelSpeedOptions &wheel = loaded.wheel_speed,
                                           &wheel_default = defaults.wheel_speed;
  EXPECT_EQ(wheel.enabled, wheel_default.enabled);
  EXPECT_DOUBLE_EQ(wheel.default_sigma_mps, wheel_default.default_sigma_mps);
  EXPECT_DOUBLE_EQ(wheel.min_sigma_mps, wheel_default.min_sigma_mps);
  EXPECT_DOUBLE_EQ(wheel.max_age_s, wheel_default.max_age_s);
  EXPECT_DOUBLE_EQ(wheel.max_acceleration_mps2, wheel_default.max_acceleration_mps2);
  EXPECT_DOUBLE_EQ(wheel.gate_mahalanobis_squared, wheel_default.gate_mahalanobis_squared);
  EXPECT_DOUBLE_EQ(wheel.scale_sigma, wheel_default.scale_sigma);
  EXPECT_DOUBLE_EQ(wheel.min_interval_s, wheel_default.min_interval_s);
  EXPECT_EQ(wheel.max_rejected_in_a_row, wheel_default.max_rejected_in_a_row);
  EXPECT_DOUBLE_EQ(loaded.heading_track_min_chord_m, defaults.heading_track_min_chord_m);
  EXPECT_DOUBLE_EQ(loaded.heading_track_max_chord_s, defaults.heading_track_max_chord_s);
  EXPECT_DOUBLE_EQ(loaded.heading_track_max_turn_deg, defaults.heading_track_max_turn_deg);
  EXPECT_DOUBLE_EQ(loaded.heading_track_turn_weight, defaults.heading_track_turn_weight);
  EXPECT_EQ(loaded.heading_hold_unknown_yaw, defaults.heading_hold_unknown_yaw);
}

TEST(LocalizerConfig, BadFilesNameTheFileAndTheKey) {
  const std::string dir = test::makeTempDir("localizer_config");
  auto expectError = [&](const std::string& text, const std::string& needle) {
    const std::string path = dir + "/c.yaml";
    std::ofstream(path) << text;
    try {
      LocalizerConfig::fromYamlFile(path);
      ADD_FAILURE() << "no error for: " << text;
    } catch (const std::exception& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(path), std::string::npos) << what;
      EXPECT_NE(what.find(needle), std::string::npos) << what;
    }
  };
  expectError("imu_noise:\n  gyro_noise_densty: 1e-3\n", "imu_noise.gyro_noise_densty");
  expectError("imu_noise:\n  gyro_noise_density: fast\n", "imu_noise.gyro_noise_density");
  expectError("gps:\n  gate_mahalanobis_squared: -3\n", "gps.gate_mahalanobis_squared");
  expectError("filter: middle\n", "filter");
  expectError("nonholonomic:\n  vehicle_pitch_deg: 90\n", "nonholonomic.vehicle_pitch_deg");
  expectError("gps:\n  max_consecutive_rejected_fixes: 1e30\n",
              "gps.max_consecutive_rejected_fixes");
  expectError("imu: [1, 2]\n", "imu");
  // A list or a map where a number belongs (was a bare "bad conversion").
  expectError("imu:\n  max_gap_s: [1, 2]\n", "imu.max_gap_s");
  expectError("gps:\n  min_sigma_m: {a: 1}\n", "gps.min_sigma_m");
  expectError("init_orientation_from_reference: [true]\n", "init_orientation_from_reference");
  expectError("standstill:\n  window_s: 0\n", "standstill.window_s");
  expectError("standstill:\n  max_rate_degps: 200\n", "standstill.max_rate_degps");
  expectError("wheel_speed:\n  min_sigma_mps: 0\n", "wheel_speed.min_sigma_mps");
  expectError("wheel_speed:\n  max_age_s: -1\n", "wheel_speed.max_age_s");
  expectError("wheel_speed:\n  enable: true\n", "wheel_speed.enable");
  expectError("a: [\n", "YAML syntax error");
  // A folder passed as the config file.
  try {
    LocalizerConfig::fromYamlFile(dir);
    ADD_FAILURE() << "a directory was read as a config";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find(dir), std::string::npos) << e.what();
  }
  // A node-only section and a partial file are fine.
  const std::string path = dir + "/ok.yaml";
  std::ofstream(path)
      << "filter: ekf\nnode:\n  publish_tf: true\nimu_noise:\n  gyro_noise_density: "
         "0.002\nstandstill:\n  enabled: true\n  max_speed_mps: 0.1\n";
  const LocalizerConfig ok = LocalizerConfig::fromYamlFile(path);
  EXPECT_EQ(ok.filter_type, FilterType::kQuaternionEskf);
  EXPECT_DOUBLE_EQ(ok.imu_noise.gyro_noise_density, 0.002);
  EXPECT_DOUBLE_EQ(ok.imu_noise.accel_noise_density,
                   LocalizerConfig().imu_noise.accel_noise_density);
  EXPECT_TRUE(ok.standstill.enabled);
  EXPECT_DOUBLE_EQ(ok.standstill.max_speed_mps, 0.1);
}

// The hold keeps the yaw's variance (it only drops its cross-covariances): after 10 s of fixes
// the heading is still unknown.
TEST(Localizer, HoldingAnUnknownYawKeepsItsVariance) {
  LocalizerConfig config;
  config.init_orientation_from_reference = false;
  config.heading_align_max_sigma_deg = 1e-9;
  config.heading_reopen_after_rejected_fixes = 0;
  config.heading_nis_window_fixes = 0;
  config.heading_hold_unknown_yaw = true;
  Localizer localizer(config);
  for (int k = 0; k <= 1000; ++k) {
    const double t = 0.01 * k;
    ImuSample sample = restingSample(t);
    if (k > 0) sample.specific_force.x() = 1.0;
    localizer.addImu(sample);
    if (k % 100 == 0) {
      const Eigen::Vector3d direction(std::cos(M_PI / 4), std::sin(M_PI / 4), 0.0);
      localizer.addPositionFix(fixAt(t, 0.5 * t * t * direction, 1.5));
    }
  }
  EXPECT_GT(localizer.yawSigma(), 90.0 * M_PI / 180.0);
}

// Only the NIS window can re-open a wrong heading here (track alignment and the rejected-in-a-row
// trigger off, the gate wide open): it must.
TEST(Localizer, TheNisWindowReopensAWrongHeading) {
  LocalizerConfig config;
  config.init_orientation_from_reference = false;
  config.unknown_yaw_sigma_deg = config.initial_yaw_sigma_deg;  // yaw 0 claimed to 1 deg
  config.heading_align_max_sigma_deg = 1e-9;
  config.heading_reopen_after_rejected_fixes = 0;
  config.gps_gate_mahalanobis_squared = 50.0;  // NIS clipped below 10 x the window's 6
  const LazyStartOutcome outcome = lazyStartWhileDriving(config, false);
  EXPECT_GE(outcome.statistics.heading_reopens, 1);
}

// While a fix has failed the gate and none has been accepted since, the land-vehicle constraint
// waits: it would only hold the heading the fixes disagree with.
TEST(Localizer, TheLandVehicleConstraintWaitsWhileTheFixesAreRejected) {
  Localizer localizer{withoutHeadingMonitor(LocalizerConfig())};
  constexpr double kSpeed = 10.0;
  NavState start = startState(0.0);
  start.velocity_map = Eigen::Vector3d(kSpeed, 0.0, 0.0);
  localizer.initialize(start);
  const auto driveOneSecond = [&localizer](int second) {
    for (int i = 1; i <= 10; ++i) localizer.addImu(restingSample(second - 1 + 0.1 * i));
  };
  driveOneSecond(1);
  ASSERT_TRUE(localizer.addPositionFix(fixAt(1.0, Eigen::Vector3d(kSpeed, 0, 0))).accepted);
  driveOneSecond(2);
  ASSERT_FALSE(localizer.addPositionFix(fixAt(2.0, Eigen::Vector3d(2 * kSpeed, 50, 0))).accepted);
  EXPECT_EQ(localizer.statistics().nonholonomic_suspended, 0);
  EXPECT_EQ(localizer.statistics().nonholonomic_used, 20);
  driveOneSecond(3);
  EXPECT_EQ(localizer.statistics().nonholonomic_suspended, 10);
  EXPECT_EQ(localizer.statistics().nonholonomic_used, 20);
  // An accepted fix ends the suspension.
  ASSERT_TRUE(localizer.addPositionFix(fixAt(3.0, Eigen::Vector3d(3 * kSpeed, 0, 0))).accepted);
  driveOneSecond(4);
  EXPECT_EQ(localizer.statistics().nonholonomic_suspended, 10);
  EXPECT_EQ(localizer.statistics().nonholonomic_used, 30);
}

// The filter believes the car stands while it drives at 20 m/s: re-acquisition opens the
// velocity as well as the position, so the fixes after the re-acquired one teach the speed and
// are taken, not gated out until the next re-acquisition.
TEST(Localizer, ReacquisitionOpensTheVelocityOfAMovingCar) {
  LocalizerConfig config = withoutHeadingMonitor(LocalizerConfig());
  config.max_consecutive_rejected_fixes = 3;
  Localizer localizer(config);
  localizer.initialize(startState(0.0));
  constexpr double kSpeed = 20.0;
  for (int k = 1; k <= 10; ++k) {
    for (int i = 1; i <= 10; ++i) localizer.addImu(restingSample(k - 1 + 0.1 * i));
    const CorrectionResult result =
        localizer.addPositionFix(fixAt(k, Eigen::Vector3d(kSpeed * k, 0.0, 0.0)));
    EXPECT_EQ(result.accepted, k >= 3) << "fix " << k << ": " << result.reason;
  }
  EXPECT_EQ(localizer.statistics().gps_reacquisitions, 1);
  EXPECT_LT((localizer.state().velocity_map - Eigen::Vector3d(kSpeed, 0.0, 0.0)).norm(), 1.0)
      << localizer.state().velocity_map.transpose();
}

// A fix that jumps 12 m sideways makes the chord ending at it disagree with the others by about
// 30 deg: the track's heading leaves that chord out instead of averaging it in, and the unknown
// heading of a start levelled from gravity is aligned to the true one.
TEST(Localizer, TheGpsTrackLeavesOutAChordThatDisagrees) {
  LocalizerConfig config;
  config.init_orientation_from_reference = false;
  constexpr double kSpeed = 10.0, kYaw = M_PI / 4, kDt = 0.01;
  const Eigen::Vector3d direction(std::cos(kYaw), std::sin(kYaw), 0.0);
  const Eigen::Vector3d left(-std::sin(kYaw), std::cos(kYaw), 0.0);
  Localizer localizer(config);
  double aligned_yaw_error_deg = -1.0;
  for (int k = 0; k <= 1000 && aligned_yaw_error_deg < 0.0; ++k) {
    const double t = kDt * k;
    localizer.addImu(restingSample(t));
    if (k % 100 != 0) continue;
    const Eigen::Vector3d jump = k == 400 ? Eigen::Vector3d(12.0 * left) : Eigen::Vector3d::Zero();
    localizer.addPositionFix(fixAt(t, kSpeed * t * direction + jump, 1.5));
    if (localizer.statistics().heading_alignments > 0) {
      const Eigen::Matrix3d& r = localizer.state().rotation;
      aligned_yaw_error_deg = std::abs(std::atan2(r(1, 0), r(0, 0)) - kYaw) * 180.0 / M_PI;
    }
  }
  ASSERT_GE(aligned_yaw_error_deg, 0.0) << "the heading was never aligned";
  EXPECT_LT(aligned_yaw_error_deg, 3.0);
}

// A car at constant speed on a straight road whose heading is `yaw_error_deg` off, stated to
// `yaw_sigma_deg` (no constraint: the fixes cannot observe it there), exact fixes once a second
// for 30 s; `chord_floor_deg` sets the track's sigma. Returns the heading recoveries.
std::int64_t headingRecoveriesOnAStraightRoad(double yaw_error_deg, double yaw_sigma_deg,
                                              double chord_floor_deg) {
  LocalizerConfig config;
  config.nonholonomic = false;
  config.initial_yaw_sigma_deg = yaw_sigma_deg;
  config.heading_track_chord_floor_deg = chord_floor_deg;
  Localizer localizer(config);
  constexpr double kSpeed = 10.0, kYaw = 0.3;
  NavState start;
  start.rotation = lie::expSO3(Eigen::Vector3d(0.0, 0.0, kYaw + yaw_error_deg * M_PI / 180.0));
  start.velocity_map = kSpeed * Eigen::Vector3d(std::cos(kYaw), std::sin(kYaw), 0.0);
  localizer.initialize(start);
  for (int k = 1; k <= 300; ++k) {
    const double t = 0.1 * k;
    localizer.addImu(restingSample(t));
    if (k % 10 == 0) localizer.addPositionFix(fixAt(t, start.velocity_map * t, 1.5));
  }
  return localizer.statistics().heading_recoveries;
}

// The heading check combines both sigmas (4 x their root sum of squares): a disagreement that
// only one of them would call significant is no recovery, one beyond the combined sigma is.
TEST(Localizer, TheHeadingCheckCombinesTheFiltersAndTheTracksSigmas) {
  // Filter sure (0.5 deg), track loose (about 3 deg): 8 deg off is within 4 combined sigmas.
  EXPECT_EQ(headingRecoveriesOnAStraightRoad(8.0, 0.5, 12.0), 0);
  // Filter loose (6 deg), track sure (1.5 to 3.7 deg): 18 deg off is within them too.
  EXPECT_EQ(headingRecoveriesOnAStraightRoad(18.0, 6.0, 2.0), 0);
  // 3 deg and 1.5 deg: 15.5 deg is beyond 4 x 3.4 deg (not beyond 4 x their sum).
  EXPECT_GE(headingRecoveriesOnAStraightRoad(15.5, 3.0, 2.0), 1);
}
}  // namespace
}  // namespace estimation
}  // namespace inekf_semantic_mapping
