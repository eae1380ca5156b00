// MappingMonitor: the map status of semantic_octomap_node's /diagnostics. Scans dropped without a
// pose are judged over the window: a share of them is said while it lasts and clears after.
#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <string>

#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"
#include "inekf_semantic_mapping/ros/mapping_conversions.h"
#include "inekf_semantic_mapping/ros/mapping_diagnostics.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {
namespace {

using diagnostic_msgs::DiagnosticStatus;

// A session fed scans of one wall at 10 Hz (data and wall time alike) whose poses tf has unless
// `drop_every` says (every n-th scan by stamp has none; 0: every scan has one), and its monitor.
class MonitoredScans {
 public:
  MonitoredScans() : session_(config()), monitor_(MappingDiagnosticsOptions{}) {
    session_.setPoseLookup([this](double stamp, const std::string&) {
      const long frame = std::lround(stamp * 10.0);
      return drop_every > 0 && frame % drop_every == 0
                 ? std::nullopt
                 : std::optional<Eigen::Isometry3d>(Eigen::Isometry3d::Identity());
    });
  }
  // `scans` more scans, then the map status.
  diagnostic_updater::DiagnosticStatusWrapper statusAfter(int scans) {
    Eigen::Matrix3Xf wall(3, 3);
    wall << 5, 5, 5, 0, 0.5, 1, 0, 0, 0;
    for (int k = 0; k < scans; ++k, t_ += 0.1) {
      monitor_.noteScan(t_, t_);
      session_.addScan(t_, "velo", wall);
      session_.advanceTo(t_ + 0.05);
    }
    session_.advanceTo(t_ + 1.0);
    diagnostic_updater::DiagnosticStatusWrapper status;
    monitor_.fillMap(session_, SaveRecord{}, SaveRecord{}, t_, &status);
    return status;
  }
  mapping::SemanticMappingSession& session() { return session_; }
  int drop_every = 0;

 private:
  static mapping::SemanticMappingConfig config() {
    mapping::SemanticMappingConfig config;
    config.label_wait_s = 0.1;
    config.pose_wait_s = 0.1;
    return config;
  }
  mapping::SemanticMappingSession session_;
  MappingMonitor monitor_;  // window_s 10
  double t_ = 0.0;
};

TEST(MappingMonitor, ScansDroppedWithoutAPoseAreSaidWhileTheyLastAndClearAfter) {
  MonitoredScans scans;
  EXPECT_EQ(scans.statusAfter(100).level, DiagnosticStatus::OK);
  scans.drop_every = 4;  // a quarter: mapping "OK" before
  const diagnostic_updater::DiagnosticStatusWrapper some = scans.statusAfter(100);
  EXPECT_EQ(some.level, DiagnosticStatus::WARN);
  EXPECT_NE(some.message.find("some scans dropped without a pose (25 of the last 100"),
            std::string::npos)
      << some.message;
  scans.drop_every = 1;
  const diagnostic_updater::DiagnosticStatusWrapper most = scans.statusAfter(100);
  EXPECT_EQ(most.level, DiagnosticStatus::ERROR) << most.message;
  scans.drop_every = 0;  // tf is back: the status clears (it stayed ERROR since the start's count)
  const diagnostic_updater::DiagnosticStatusWrapper back = scans.statusAfter(100);
  EXPECT_EQ(back.level, DiagnosticStatus::OK) << back.message;
  EXPECT_EQ(scans.session().statistics().scans_without_pose, 125u);
}

// A reset (~reset, load_map) with more scans since than before it: the counts start again (the
// difference of the drops wrapped around: "most scans dropped (18446744073709551613 of the last
// 22 ...)").
TEST(MappingMonitor, AResetStartsTheDropCountAgain) {
  MonitoredScans scans;
  scans.drop_every = 0;
  EXPECT_EQ(scans.statusAfter(10).level, DiagnosticStatus::OK);
  scans.drop_every = 1;
  EXPECT_EQ(scans.statusAfter(12).level, DiagnosticStatus::ERROR);
  scans.session().reset();
  scans.drop_every = 0;
  const diagnostic_updater::DiagnosticStatusWrapper after = scans.statusAfter(30);
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

// Before any scan has had a pose (a localization waiting for its heading holds tf back) the
// drops are said as that, WARN, not "most scans dropped" ERROR; ERROR after 30 s of it. Once scans
// go in, the window counts from there.
TEST(MappingMonitor, NoPoseYetIsAWarningUntilItLasts) {
  MonitoredScans scans;
  scans.drop_every = 1;
  const diagnostic_updater::DiagnosticStatusWrapper waiting = scans.statusAfter(20);
  EXPECT_EQ(waiting.level, DiagnosticStatus::WARN) << waiting.message;
  EXPECT_NE(waiting.message.find("no scan has had a pose yet (20 dropped"), std::string::npos)
      << waiting.message;
  EXPECT_EQ(scans.statusAfter(300).level, DiagnosticStatus::ERROR);  // 30 s more
  scans.drop_every = 0;
  const diagnostic_updater::DiagnosticStatusWrapper mapping = scans.statusAfter(20);
  EXPECT_EQ(mapping.level, DiagnosticStatus::OK) << mapping.message;
}

// Clouds the node cannot read (an Ouster-like driver's integer x/y/z): counted and said in the
// map status while they last (it read "waiting for scans" OK with every scan refused).
TEST(MappingMonitor, RefusedScansAreSaidWhileTheyLast) {
  mapping::SemanticMappingSession session{mapping::SemanticMappingConfig{}};
  MappingMonitor monitor{MappingDiagnosticsOptions{}};  // window 10 s
  const auto statusAt = [&](double wall_s) {
    diagnostic_updater::DiagnosticStatusWrapper status;
    monitor.fillMap(session, SaveRecord{}, SaveRecord{}, wall_s, &status);
    return status;
  };
  for (int k = 0; k < 10; ++k) {
    monitor.noteScan(k * 0.1, k * 0.1);
    if (k % 5 == 0) monitor.noteScanRefused(k * 0.1, "field 'x' has datatype INT32");
  }
  const diagnostic_updater::DiagnosticStatusWrapper some = statusAt(1.0);
  EXPECT_EQ(some.level, DiagnosticStatus::WARN) << some.message;
  EXPECT_NE(
      some.message.find("some scans refused (2 of the last 10): field 'x' has datatype INT32"),
      std::string::npos)
      << some.message;
  for (int k = 10; k < 20; ++k) {
    monitor.noteScan(k * 0.1, k * 0.1);
    monitor.noteScanRefused(k * 0.1, "no frame_id");
  }
  EXPECT_EQ(statusAt(2.0).level, DiagnosticStatus::ERROR);
  EXPECT_EQ(statusAt(20.0).level, DiagnosticStatus::OK);  // over: the window forgot them
  bool counted = false;
  for (const auto& value : statusAt(20.0).values) {
    if (value.key == "scans refused (unreadable)") counted = value.value == "12";
  }
  EXPECT_TRUE(counted);
}

// A coordinate field of another type is refused naming the field and its type by name.
TEST(MappingConversions, ACoordinateOfAnotherTypeIsNamed) {
  sensor_msgs::PointCloud2 cloud;
  cloud.height = 1;
  cloud.width = 1;
  cloud.point_step = 12;
  cloud.row_step = 12;
  cloud.data.assign(12, 0);
  for (const char* name : {"x", "y", "z"}) {
    sensor_msgs::PointField field;
    field.name = name;
    field.offset = static_cast<std::uint32_t>(4 * cloud.fields.size());
    field.datatype = sensor_msgs::PointField::INT32;
    field.count = 1;
    cloud.fields.push_back(field);
  }
  try {
    pointsFromCloud(cloud);
    FAIL() << "an INT32 x was read";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("field 'x' has datatype INT32, need FLOAT32"),
              std::string::npos)
        << error.what();
  }
}

}  // namespace
}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
