// Localizer: stamp policies (duplicate, out of order, gap), stale and non-finite fixes, lazy
// initialization, reset, statistics, and the YAML config (defaults == config/inekf.yaml).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <fstream>

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

TEST(Localizer, BridgesAGapWithInflatedNoise) {
  LocalizerConfig config;
  config.max_imu_gap_s = 0.5;
  Localizer nominal(config), gapped(config);
  config.gap_noise_scale = 1.0;
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
}

TEST(Localizer, RejectsStaleAndNonFiniteFixesAndInflatesSlightlyOldOnes) {
  LocalizerConfig config;
  config.max_fix_age_s = 0.5;
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

TEST(Localizer, ReacquiresAfterConsecutiveRejectedFixes) {
  LocalizerConfig config;
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
  EXPECT_DOUBLE_EQ(loaded.initial_velocity_sigma_mps, defaults.initial_velocity_sigma_mps);
  EXPECT_DOUBLE_EQ(loaded.initial_position_sigma_m, defaults.initial_position_sigma_m);
  EXPECT_DOUBLE_EQ(loaded.initial_gyro_bias_sigma_radps, defaults.initial_gyro_bias_sigma_radps);
  EXPECT_DOUBLE_EQ(loaded.initial_accel_bias_sigma_mps2, defaults.initial_accel_bias_sigma_mps2);
  EXPECT_DOUBLE_EQ(loaded.gps_gate_mahalanobis_squared, defaults.gps_gate_mahalanobis_squared);
  EXPECT_DOUBLE_EQ(loaded.min_gps_sigma_m, defaults.min_gps_sigma_m);
  EXPECT_DOUBLE_EQ(loaded.max_fix_age_s, defaults.max_fix_age_s);
  EXPECT_EQ(loaded.max_consecutive_rejected_fixes, defaults.max_consecutive_rejected_fixes);
  EXPECT_DOUBLE_EQ(loaded.max_imu_gap_s, defaults.max_imu_gap_s);
  EXPECT_DOUBLE_EQ(loaded.gap_noise_scale, defaults.gap_noise_scale);
  EXPECT_DOUBLE_EQ(loaded.interpolated_gyro_noise_scale_per_s,
                   defaults.interpolated_gyro_noise_scale_per_s);
  EXPECT_DOUBLE_EQ(loaded.interpolated_accel_noise_scale, defaults.interpolated_accel_noise_scale);
  EXPECT_EQ(loaded.init_orientation_from_reference, defaults.init_orientation_from_reference);
}

TEST(LocalizerConfig, BadFilesNameTheFileAndTheKey) {
  const std::string dir = test::makeTempDir("localizer_config");
  auto expectError = [&](const std::string& text, const std::string& needle) {
    const std::string path = dir + "/c.yaml";
    std::ofstream(path) << text;
    try {
      LocalizerConfig::fromYamlFile(path);
      ADD_FAILURE() << "no error for: " << text;
    } catch (const std::runtime_error& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(path), std::string::npos) << what;
      EXPECT_NE(what.find(needle), std::string::npos) << what;
    }
  };
  expectError("imu_noise:\n  gyro_noise_densty: 1e-3\n", "imu_noise.gyro_noise_densty");
  expectError("imu_noise:\n  gyro_noise_density: fast\n", "imu_noise.gyro_noise_density");
  expectError("gps:\n  gate_mahalanobis_squared: -3\n", "gps.gate_mahalanobis_squared");
  expectError("filter: middle\n", "filter");
  expectError("imu: [1, 2]\n", "imu");
  expectError("a: [\n", "cannot read");
  // A node-only section and a partial file are fine.
  const std::string path = dir + "/ok.yaml";
  std::ofstream(path)
      << "filter: ekf\nnode:\n  publish_tf: true\nimu_noise:\n  gyro_noise_density: 0.002\n";
  const LocalizerConfig ok = LocalizerConfig::fromYamlFile(path);
  EXPECT_EQ(ok.filter_type, FilterType::kQuaternionEskf);
  EXPECT_DOUBLE_EQ(ok.imu_noise.gyro_noise_density, 0.002);
  EXPECT_DOUBLE_EQ(ok.imu_noise.accel_noise_density,
                   LocalizerConfig().imu_noise.accel_noise_density);
}

}  // namespace
}  // namespace estimation
}  // namespace inekf_semantic_mapping
