// MappingMonitor: the map status of semantic_octomap_node's /diagnostics. Scans dropped without a
// pose are judged over the window: a share of them is said while it lasts and clears after.
#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <string>

#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"
#include "inekf_semantic_mapping/ros/mapping_diagnostics.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {
namespace {

using diagnostic_msgs::DiagnosticStatus;

Eigen::Matrix3Xf oneWall() {
  Eigen::Matrix3Xf points(3, 3);
  points << 5, 5, 5, 0, 0.5, 1, 0, 0, 0;
  return points;
}

TEST(MappingMonitor, ScansDroppedWithoutAPoseAreSaidWhileTheyLastAndClearAfter) {
  mapping::SemanticMappingConfig config;
  config.label_wait_s = 0.1;
  config.pose_wait_s = 0.1;
  mapping::SemanticMappingSession session(config);
  int drop_every = 0;  // every n-th scan (by stamp) has no pose in tf (0: none)
  session.setPoseLookup([&](double stamp, const std::string&) -> std::optional<Eigen::Isometry3d> {
    const long frame = std::lround(stamp * 10.0);
    if (drop_every > 0 && frame % drop_every == 0) return std::nullopt;
    return Eigen::Isometry3d::Identity();
  });
  MappingDiagnosticsOptions options;
  options.window_s = 10.0;
  MappingMonitor monitor(options);
  double t = 0.0;  // data and wall time alike
  // Scans at 10 Hz (ten seconds by default), then the status.
  const auto tenSeconds = [&](int scans = 100) {
    for (int k = 0; k < scans; ++k, t += 0.1) {
      monitor.noteScan(t, t);
      session.addScan(t, "velo", oneWall());
      session.advanceTo(t + 0.05);
    }
    session.advanceTo(t + 1.0);
    diagnostic_updater::DiagnosticStatusWrapper status;
    monitor.fillMap(session, SaveRecord{}, SaveRecord{}, t, &status);
    return status;
  };
  EXPECT_EQ(tenSeconds().level, DiagnosticStatus::OK);
  drop_every = 4;  // a quarter: mapping "OK" before
  const diagnostic_updater::DiagnosticStatusWrapper some = tenSeconds();
  EXPECT_EQ(some.level, DiagnosticStatus::WARN);
  EXPECT_NE(some.message.find("some scans dropped without a pose (25 of the last 100"),
            std::string::npos)
      << some.message;
  drop_every = 1;
  const diagnostic_updater::DiagnosticStatusWrapper most = tenSeconds();
  EXPECT_EQ(most.level, DiagnosticStatus::ERROR) << most.message;
  drop_every = 0;  // tf is back: the status clears (it stayed ERROR since the start's count)
  const diagnostic_updater::DiagnosticStatusWrapper back = tenSeconds();
  EXPECT_EQ(back.level, DiagnosticStatus::OK) << back.message;
  EXPECT_EQ(session.statistics().scans_without_pose, 125u);
}

// A reset (~reset, load_map) with more scans since than before it: the counts start again (the
// difference of the drops wrapped around: "most scans dropped (18446744073709551613 of the last
// 22 ...)").
TEST(MappingMonitor, AResetStartsTheDropCountAgain) {
  mapping::SemanticMappingConfig config;
  config.label_wait_s = 0.1;
  config.pose_wait_s = 0.1;
  mapping::SemanticMappingSession session(config);
  bool tf_has_poses = false;
  session.setPoseLookup([&](double, const std::string&) -> std::optional<Eigen::Isometry3d> {
    if (!tf_has_poses) return std::nullopt;
    return Eigen::Isometry3d::Identity();
  });
  MappingMonitor monitor{MappingDiagnosticsOptions{}};
  double t = 0.0;
  const auto scansThenStatus = [&](int scans) {
    for (int k = 0; k < scans; ++k, t += 0.1) {
      monitor.noteScan(t, t);
      session.addScan(t, "velo", oneWall());
      session.advanceTo(t + 0.05);
    }
    session.advanceTo(t + 1.0);
    diagnostic_updater::DiagnosticStatusWrapper status;
    monitor.fillMap(session, SaveRecord{}, SaveRecord{}, t, &status);
    return status;
  };
  EXPECT_EQ(scansThenStatus(8).level, DiagnosticStatus::ERROR);
  session.reset();
  tf_has_poses = true;
  const diagnostic_updater::DiagnosticStatusWrapper after = scansThenStatus(30);
  EXPECT_EQ(after.level, DiagnosticStatus::OK) << after.message;
}

// A label publisher of another encoding: each image refused by the node, counted, and the labels
// status says so (it read "labels arriving").
TEST(MappingMonitor, MostLabelImagesRefusedIsAWarning) {
  mapping::SemanticMappingSession session{mapping::SemanticMappingConfig{}};
  MappingMonitor monitor{MappingDiagnosticsOptions{}};
  for (int k = 0; k < 6; ++k) {
    monitor.noteLabelImage(k);
    session.noteLabelImageRefused();
  }
  diagnostic_updater::DiagnosticStatusWrapper status;
  monitor.fillLabels(session, /*labels_expected=*/true, 6.0, &status);
  EXPECT_EQ(status.level, DiagnosticStatus::WARN);
  EXPECT_NE(status.message.find("most label images refused"), std::string::npos) << status.message;
}

}  // namespace
}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
