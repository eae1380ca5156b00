// ScanLabelPairing on its own: nearest stamps pair in either arrival order, a scan waits for its
// label image only while one may come, waits for its pose at most pose_wait_s more, and stamps
// going back are seen as a new timeline.
#include <gtest/gtest.h>

#include <vector>

#include "inekf_semantic_mapping/mapping/scan_label_pairing.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"

namespace inekf_semantic_mapping {
namespace mapping {
namespace {

std::shared_ptr<PendingLabels> labelsAt(double stamp) {
  static const std::vector<std::uint8_t> pixels(4, 7);
  return PendingLabels::copyOf(stamp, LabelImageView{pixels.data(), 2, 2, 2});
}

PendingScan scanAt(double stamp) {
  return PendingScan{stamp, "velo", Eigen::Matrix3Xf(3, 0), {}, std::nullopt};
}

const ScanLabelPairing::ApplyLate kNoLate = [](PendingLabels&, InsertedScan&) { return false; };

TEST(ScanLabelPairingTest, TheNearestLabelImageWithinTheTolerancePairsInEitherOrder) {
  MappingStatistics stats;
  ScanLabelPairing pairing(PairingOptions{0.05, 1.0, 1.0}, &stats);
  EXPECT_EQ(pairing.addLabels(labelsAt(0.04), kNoLate), ScanLabelPairing::LabelsPlace::kWaiting);
  EXPECT_EQ(pairing.addLabels(labelsAt(0.01), kNoLate), ScanLabelPairing::LabelsPlace::kWaiting);
  pairing.addScan(scanAt(0.0));
  EXPECT_EQ(pairing.waitingLabelImages(), 1u);  // 0.01 taken, 0.04 left
  pairing.addScan(scanAt(0.1));
  EXPECT_EQ(pairing.addLabels(labelsAt(0.12), kNoLate), ScanLabelPairing::LabelsPlace::kPaired);
  std::vector<std::pair<double, double>> inserted;  // scan stamp, label stamp
  const auto insert = [&](PendingScan& scan) {
    inserted.emplace_back(scan.stamp, scan.labels ? scan.labels->stamp : -1.0);
    return true;
  };
  EXPECT_EQ(pairing.insertReady(0.12, insert), 2u);
  ASSERT_EQ(inserted.size(), 2u);
  EXPECT_DOUBLE_EQ(inserted[0].second, 0.01);
  EXPECT_DOUBLE_EQ(inserted[1].second, 0.12);
  // 0.04 had no scan of its own and a newer scan passed it by more than the keep margin.
  pairing.addScan(scanAt(1.2));
  pairing.insertReady(1.2, insert);
  EXPECT_EQ(pairing.waitingLabelImages(), 0u);
  EXPECT_EQ(stats.label_images_unmatched, 1u);
}

TEST(ScanLabelPairingTest, AScanWaitsForLabelsWhileTheyMayComeThenForItsPoseThenIsDropped) {
  MappingStatistics stats;
  ScanLabelPairing pairing(PairingOptions{0.05, 1.0, 0.5}, &stats);
  pairing.addLabels(labelsAt(0.0), kNoLate);  // segmentation is running
  pairing.addScan(scanAt(0.0));
  pairing.addScan(scanAt(0.1));
  int asked = 0;
  const auto no_pose = [&](PendingScan&) {
    ++asked;
    return false;
  };
  pairing.insertReady(0.5, no_pose);
  EXPECT_EQ(asked, 1);  // 0.0 is paired and asked for its pose; 0.1 still waits for labels
  pairing.insertReady(1.2, no_pose);
  EXPECT_EQ(asked, 3);  // 0.1's wait is over: now both wait for their poses
  EXPECT_EQ(pairing.pendingScans(), 2u);
  pairing.insertReady(1.55, no_pose);  // 0.0 waited 1.0 + 0.5: dropped
  EXPECT_EQ(pairing.pendingScans(), 1u);
  EXPECT_EQ(stats.scans_without_pose, 1u);
}

TEST(ScanLabelPairingTest, ALabelImageForAScanThatWentInAddsLateEvidenceOrWaitsIfItCannot) {
  MappingStatistics stats;
  ScanLabelPairing pairing(PairingOptions{0.05, 1.0, 1.0}, &stats);
  pairing.addScan(scanAt(0.0));
  pairing.insertReady(2.0, [](PendingScan&) { return true; });  // no segmentation yet: in at once
  pairing.keepForLateLabels(InsertedScan{0.0, Eigen::Matrix3Xf(3, 0), {}, "velo", false});
  bool camera_known = false;
  const auto late = [&](PendingLabels&, InsertedScan& scan) {
    EXPECT_DOUBLE_EQ(scan.stamp, 0.0);
    return camera_known;
  };
  EXPECT_EQ(pairing.addLabels(labelsAt(0.02), late), ScanLabelPairing::LabelsPlace::kWaiting);
  camera_known = true;
  EXPECT_EQ(pairing.addLabels(labelsAt(0.01), late), ScanLabelPairing::LabelsPlace::kLate);
  // The scan left the late window with it: a third image of that stamp finds nothing.
  pairing.addScan(scanAt(1.0));
  EXPECT_EQ(pairing.addLabels(labelsAt(0.03), late), ScanLabelPairing::LabelsPlace::kUnmatched);
}

// Segmentation lagging seconds behind (a loaded machine): its label image still reaches a scan
// that went in without labels up to 10 s behind the newest one, and no scan older than that.
TEST(ScanLabelPairingTest, ALateLabelImageReachesScansUpToTenSecondsBack) {
  MappingStatistics stats;
  ScanLabelPairing pairing(PairingOptions{0.05, 1.0, 1.0}, &stats);
  const auto insert = [](PendingScan&) { return true; };
  const auto keep = [&](double stamp) {
    pairing.addScan(scanAt(stamp));
    pairing.flush(insert);
    pairing.keepForLateLabels(InsertedScan{stamp, Eigen::Matrix3Xf(3, 0), {}, "velo", false});
  };
  std::vector<double> applied;
  const auto late = [&](PendingLabels&, InsertedScan& scan) {
    applied.push_back(scan.stamp);
    return true;
  };
  for (const double stamp : {0.0, 0.5, 9.5}) keep(stamp);
  EXPECT_EQ(pairing.addLabels(labelsAt(0.01), late), ScanLabelPairing::LabelsPlace::kLate);
  keep(10.8);  // 0.5 is now more than 10 s back
  EXPECT_EQ(pairing.addLabels(labelsAt(0.51), late), ScanLabelPairing::LabelsPlace::kUnmatched);
  ASSERT_EQ(applied.size(), 1u);
  EXPECT_DOUBLE_EQ(applied[0], 0.0);
}

TEST(ScanLabelPairingTest, StampsThatGoBackByMoreThanASecondAreANewTimeline) {
  MappingStatistics stats;
  ScanLabelPairing pairing(PairingOptions{0.05, 1.0, 1.0}, &stats);
  pairing.addScan(scanAt(100.0));
  EXPECT_FALSE(pairing.wentBack(99.5));  // a scan that lagged in a busy queue
  EXPECT_TRUE(pairing.wentBack(98.5));
  pairing.flush([](PendingScan&) { return true; });
  pairing.restartClock();
  EXPECT_FALSE(pairing.wentBack(0.0));
  EXPECT_EQ(pairing.pendingScans(), 0u);
}

// Segmentation finishing a frame of before a bag loop: its label image comes after the first
// scan of the new timeline. Taken as one of the present it moved the clock 5 s ahead, and the new
// scans, "old" at once, were dropped before their poses came.
TEST(ScanLabelPairingTest, ALabelImageOfTheTimelineThatEndedMovesNoClock) {
  MappingStatistics stats;
  ScanLabelPairing pairing(PairingOptions{0.05, 1.0, 1.0}, &stats);
  const auto insert = [](PendingScan&) { return true; };
  pairing.addLabels(labelsAt(104.9), kNoLate);
  pairing.addScan(scanAt(104.9));
  pairing.addScan(scanAt(105.0));
  ASSERT_TRUE(pairing.wentBack(100.0));
  pairing.flush(insert);
  pairing.restartClock();
  pairing.addScan(scanAt(100.0));
  EXPECT_EQ(pairing.addLabels(labelsAt(105.0), kNoLate), ScanLabelPairing::LabelsPlace::kUnmatched);
  EXPECT_DOUBLE_EQ(pairing.now(), 100.0);
  int asked = 0;
  pairing.insertReady(100.5, [&](PendingScan&) {
    ++asked;
    return false;  // its pose is not in tf yet
  });
  EXPECT_EQ(pairing.pendingScans(), 1u);  // still waiting (for labels, then its pose)
  EXPECT_EQ(stats.scans_without_pose, 0u);
  // A label image of the new timeline pairs as ever.
  EXPECT_EQ(pairing.addLabels(labelsAt(100.0), kNoLate), ScanLabelPairing::LabelsPlace::kPaired);
}

// Past the first seconds of a new timeline a label image stamped ahead of the scans (the scan
// queue lagging) is one of the present again, though the ended timeline reached its stamp.
TEST(ScanLabelPairingTest, TheEndedTimelineRuleHoldsForItsFirstSecondsOnly) {
  MappingStatistics stats;
  ScanLabelPairing pairing(PairingOptions{0.05, 1.0, 1.0}, &stats);
  const auto insert = [](PendingScan&) { return true; };
  pairing.addLabels(labelsAt(100.0), kNoLate);
  pairing.addScan(scanAt(100.0));
  pairing.addScan(scanAt(160.0));  // a minute-long timeline
  pairing.flush(insert);
  pairing.restartClock();
  pairing.addScan(scanAt(100.0));
  EXPECT_EQ(pairing.addLabels(labelsAt(102.0), kNoLate),
            ScanLabelPairing::LabelsPlace::kUnmatched);  // 2 s ahead, just after the loop
  pairing.addScan(scanAt(130.0));
  EXPECT_EQ(pairing.addLabels(labelsAt(131.5), kNoLate), ScanLabelPairing::LabelsPlace::kWaiting);
}

// A reset (~reset) is a new start, not a bag loop: scans wait for the first label image as at the
// start, whatever came before, and no label image is taken for an ended timeline's.
TEST(ScanLabelPairingTest, AClearIsANewStart) {
  MappingStatistics stats;
  ScanLabelPairing pairing(PairingOptions{0.05, 1.0, 1.0}, &stats);
  const auto insert = [](PendingScan&) { return true; };
  pairing.addScan(scanAt(100.0));  // no label image yet
  pairing.clear();
  pairing.addScan(scanAt(101.0));
  EXPECT_EQ(pairing.insertReady(101.0, insert), 0u);  // waits for a first label image
  EXPECT_EQ(pairing.addLabels(labelsAt(103.0), kNoLate), ScanLabelPairing::LabelsPlace::kWaiting);
}

// A lidar-only run: no label image in the timeline that ended, so the new one's scans do not wait
// label_wait_s for a first one (at each loop of a looping bag they did).
TEST(ScanLabelPairingTest, ALidarOnlyRunDoesNotWaitForLabelsAfterARestart) {
  MappingStatistics stats;
  ScanLabelPairing pairing(PairingOptions{0.05, 1.0, 1.0}, &stats);
  std::vector<double> inserted;
  const auto insert = [&](PendingScan& scan) {
    inserted.push_back(scan.stamp);
    return true;
  };
  pairing.addScan(scanAt(100.0));
  EXPECT_EQ(pairing.insertReady(100.0, insert), 0u);  // the start waits for a first label image
  EXPECT_EQ(pairing.insertReady(101.1, insert), 1u);
  pairing.flush(insert);
  pairing.restartClock();
  pairing.addScan(scanAt(50.0));
  EXPECT_EQ(pairing.insertReady(50.0, insert), 1u);
  // With label images in the timeline that ended, the new one waits for its first as at the start.
  pairing.addLabels(labelsAt(50.0), kNoLate);
  pairing.addScan(scanAt(50.05));
  pairing.flush(insert);
  pairing.restartClock();
  pairing.addScan(scanAt(10.0));
  EXPECT_EQ(pairing.insertReady(10.0, insert), 0u);
}

}  // namespace
}  // namespace mapping
}  // namespace inekf_semantic_mapping
