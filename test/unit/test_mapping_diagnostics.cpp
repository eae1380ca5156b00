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
  // Ten seconds of scans at 10 Hz, then the status.
  const auto tenSeconds = [&] {
    for (int k = 0; k < 100; ++k, t += 0.1) {
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

}  // namespace
}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
