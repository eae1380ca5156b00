// LocalizationSession on real OXTS drives of ../shared: the offline run starts at the first fix as
// the node does, and the node's event stream gives inekf_offline's trajectory.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/estimation/localization_session.h"
#include "inekf_semantic_mapping/estimation/oxts_run.h"
#include "inekf_semantic_mapping/kitti/gps_degradation.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

// 2011_09_30_drive_0028 has no GPS solution (posmode < 0) before frame 19, so under the protocol
// the first fix is frame 20's: the offline run starts there, as the node would.
TEST(LocalizationSession, OfflineRunStartsAtTheFirstFixLikeTheNode) {
  const std::string drive = "data/kitti_raw/2011_09_30/2011_09_30_drive_0028_sync/oxts";
  ISM_REQUIRE_SHARED(drive);
  std::vector<kitti::OxtsFrame> frames = kitti::readOxtsFolder(test::sharedPath(drive));
  frames.resize(std::min<std::size_t>(frames.size(), 100));
  OxtsRunOptions options;
  options.gps.every_n_frames = 10;
  const OxtsRunResult run = runLocalizerOnOxts(frames, options);
  ASSERT_EQ(run.first_estimated_frame, 20);
  EXPECT_NEAR(run.states[20].stamp_s, frames[20].stampSeconds(), 1e-9);
  EXPECT_EQ(run.states[0].position_map, run.states[20].position_map);  // held at the start
  EXPECT_EQ(run.states.size(), frames.size());
}

// An IMU silence longer than session.restart_after_imu_gap_s half-way resets the filter, which
// starts again at the next fix. Every frame keeps its own state: the frames between the reset and
// the restart hold the last estimate and are not scored, and the states after the restart are
// those of their own frames (they were shifted by the held frames, the ATE with them), with and
// without smoothing.
TEST(LocalizationSession, FramesBetweenAResetAndTheRestartKeepTheirPlace) {
  const std::string drive = "data/kitti_raw/2011_09_26/2011_09_26_drive_0009_sync/oxts";
  ISM_REQUIRE_SHARED(drive);
  std::vector<kitti::OxtsFrame> frames = kitti::readOxtsFolder(test::sharedPath(drive));
  ASSERT_GT(frames.size(), 300u);
  frames.resize(300);
  constexpr int kSilenceAfter = 205;  // not a fix frame: the restart waits for frame 210's fix
  for (std::size_t k = kSilenceAfter; k < frames.size(); ++k) {
    frames[k].stamp_ns += 15'000'000'000;
  }
  for (const bool smooth : {false, true}) {
    SCOPED_TRACE(smooth ? "smoothed" : "filtered");
    OxtsRunOptions options;
    options.gps = protocolGps();
    options.smooth = smooth;
    const OxtsRunResult run = runLocalizerOnOxts(frames, options);
    ASSERT_EQ(run.first_estimated_frame, 0);
    ASSERT_EQ(run.states.size(), frames.size());
    EXPECT_EQ(run.statistics.resets, 1);
    // The reset is noted whichever of the frame's messages confirmed the jump (its GPS velocity:
    // that note was lost).
    EXPECT_EQ(std::count_if(run.heading_notes.begin(), run.heading_notes.end(),
                            [](const std::string& note) {
                              return note.find("time jumped forward") != std::string::npos;
                            }),
              1);
    ASSERT_FALSE(run.held_frames.empty());
    EXPECT_EQ(run.held_frames.front(), kSilenceAfter);
    EXPECT_LT(run.held_frames.back(), 220);
    const int last_estimated = run.held_frames.front() - 1;
    for (std::size_t k = 0; k < frames.size(); ++k) {
      if (std::binary_search(run.held_frames.begin(), run.held_frames.end(), static_cast<int>(k))) {
        EXPECT_EQ(run.states[k].position_map, run.states[last_estimated].position_map)
            << "frame " << k;
      } else {
        EXPECT_NEAR(run.states[k].stamp_s, frames[k].stampSeconds(), 1e-9) << "frame " << k;
      }
    }
    // After the restart each state is near its own frame's truth (the car moves about 1 m a
    // frame here: a shift by the held frames was metres off).
    double worst_m = 0.0;
    for (std::size_t k = run.held_frames.back() + 20; k < frames.size(); ++k) {
      worst_m = std::max(worst_m, (run.states[k].position_map - run.truth[k].translation()).norm());
    }
    EXPECT_LT(worst_m, 4.0);
    EXPECT_LT(compareWithTruth(run).ate_m, 3.0);
  }
}

// One bad line of timestamps.txt (the frame stamped 6.4 s back), or two in a row: the frames are
// held, and the run scores as without them, filtered and smoothed. One inside a reset's gap
// (before the restart) kept the frames after it in their places too (it shifted them one frame
// early).
TEST(LocalizationSession, AMisstampedFrameIsHeldAndTheDriveGoesOn) {
  const std::string drive = "data/kitti_raw/2011_09_26/2011_09_26_drive_0009_sync/oxts";
  ISM_REQUIRE_SHARED(drive);
  std::vector<kitti::OxtsFrame> clean = kitti::readOxtsFolder(test::sharedPath(drive));
  ASSERT_GT(clean.size(), 300u);
  clean.resize(300);
  for (const std::vector<int>& bad : {std::vector<int>{150}, std::vector<int>{150, 151}}) {
    std::vector<kitti::OxtsFrame> glitched = clean;
    for (int k : bad) glitched[k].stamp_ns -= 6'400'000'000;
    for (const bool smooth : {false, true}) {
      SCOPED_TRACE(std::to_string(bad.size()) + " bad lines, " +
                   (smooth ? "smoothed" : "filtered"));
      OxtsRunOptions options;
      options.gps = protocolGps();
      options.smooth = smooth;
      const OxtsRunResult reference = runLocalizerOnOxts(clean, options);
      const OxtsRunResult run = runLocalizerOnOxts(glitched, options);
      EXPECT_EQ(run.misstamped_frames, bad);
      EXPECT_EQ(run.statistics.resets, 0);
      ASSERT_EQ(run.states.size(), clean.size());
      EXPECT_LT((run.states[bad.back()].position_map - run.states[149].position_map).norm(), 1e-6);
      EXPECT_LT(compareWithTruth(run).ate_m, compareWithTruth(reference).ate_m + 0.1);
    }
  }
  // Inside the gap of a reset (15 s of silence after frame 205; the restart waits for frame
  // 210's fix).
  std::vector<kitti::OxtsFrame> gap = clean;
  for (std::size_t k = 206; k < gap.size(); ++k) gap[k].stamp_ns += 15'000'000'000;
  gap[207].stamp_ns -= 6'400'000'000;
  OxtsRunOptions options;
  options.gps = protocolGps();
  const OxtsRunResult run = runLocalizerOnOxts(gap, options);
  EXPECT_EQ(run.misstamped_frames, std::vector<int>{207});
  ASSERT_EQ(run.states.size(), gap.size());
  for (std::size_t k = 230; k < gap.size(); ++k) {
    EXPECT_NEAR(run.states[k].stamp_s, gap[k].stampSeconds(), 1e-9) << "frame " << k;
  }
}

// A frame stamped as the one before it (a duplicated line of timestamps.txt): the session drops
// its sample, the filter does not move, and the smoother takes an identity step there rather than
// restarting. The frames before it differ from the clean run's by what the lost sample and fix
// change (0.26 m at most; 1.47 m with the restart, frame 49 left at its filtered estimate), the
// ATE 0.885 m against 0.860 (0.925 with the restart).
TEST(LocalizationSession, ADuplicatedStampDoesNotBreakTheSmoother) {
  const std::string drive = "data/kitti_raw/2011_09_26/2011_09_26_drive_0009_sync/oxts";
  ISM_REQUIRE_SHARED(drive);
  std::vector<kitti::OxtsFrame> clean = kitti::readOxtsFolder(test::sharedPath(drive));
  ASSERT_GT(clean.size(), 300u);
  clean.resize(300);
  std::vector<kitti::OxtsFrame> duplicated = clean;
  duplicated[50].stamp_ns = duplicated[49].stamp_ns;
  OxtsRunOptions options;
  options.gps = protocolGps();
  options.smooth = true;
  const OxtsRunResult reference = runLocalizerOnOxts(clean, options);
  const OxtsRunResult run = runLocalizerOnOxts(duplicated, options);
  EXPECT_EQ(run.smoother_breaks, 0);
  ASSERT_EQ(run.states.size(), clean.size());
  double worst_difference_m = 0.0;  // before the duplicate, where the two runs saw the same data
  for (int k = 30; k < 49; ++k) {
    worst_difference_m = std::max(
        worst_difference_m, (run.states[k].position_map - reference.states[k].position_map).norm());
  }
  EXPECT_LT(worst_difference_m, 0.5);
  EXPECT_LT(compareWithTruth(run).ate_m, compareWithTruth(reference).ate_m + 0.04);
}

// inekf_node's path against inekf_offline's on the same data: the events kitti_player /
// kitti2bag publish for the first 450 frames of 2011_09_30_drive_0027 under the protocol (IMU
// with the OXTS orientation, GPS velocity in the map frame, the degraded fix with its
// covariance, the map origin at frame 0 as the rostests set it), delivered with frame 0's fix
// first (it raced ahead of its IMU message); the session's estimate after each frame's messages
// against runLocalizerOnOxts.
// A drive fed to a session as inekf_node gets it (one fix, IMU sample and GPS velocity per OXTS
// frame, the first fix before its IMU message); `edit_fix` may change each fix before it is sent.
// The state after each frame's IMU sample; frames without a new estimate hold a NaN position.
std::vector<NavState> feedAsTheNode(const std::vector<kitti::OxtsFrame>& frames,
                                    const OxtsRunOptions& options,
                                    const std::function<void(GeodeticFixEvent*)>& edit_fix = {}) {
  LocalizationSessionConfig config = options.config;
  const kitti::OxtsRecord& first = frames.front().record;
  config.origin = GeodeticOrigin{first.lat, first.lon, first.alt};
  LocalizationSession node(config);
  kitti::GpsDegrader degrader(options.gps);
  const double t0 = frames.front().stampSeconds();
  std::vector<NavState> states(frames.size());
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const kitti::OxtsRecord& r = frames[k].record;
    const double stamp_s = frames[k].stampSeconds();
    GeodeticFixEvent fix;
    const std::optional<kitti::GeodeticFix> geodetic = degrader.degrade(k, stamp_s - t0, r);
    if (geodetic) {
      fix = fixEventFromDegraded(*geodetic, stamp_s);
      if (edit_fix && k > 0) edit_fix(&fix);
      if (k == 0) {
        EXPECT_FALSE(node.addFix(fix).started);  // before its IMU: waits
      }
    }
    ImuEvent imu;
    imu.sample.stamp_s = stamp_s;
    imu.sample.angular_velocity = Eigen::Vector3d(r.wx, r.wy, r.wz);
    imu.sample.specific_force = Eigen::Vector3d(r.ax, r.ay, r.az);
    imu.sample.interpolated = r.posmode < 0 || (k > 0 && frames[k - 1].record.posmode < 0);
    // As a sensor_msgs/Imu quaternion carries it.
    imu.orientation = Eigen::Quaterniond(kitti::rotationFromRollPitchYaw(r.roll, r.pitch, r.yaw))
                          .normalized()
                          .toRotationMatrix();
    const bool estimate = node.addImu(imu).new_estimate;
    GpsVelocityEvent velocity;
    velocity.stamp_s = stamp_s;
    velocity.velocity = Eigen::Vector3d(r.ve, r.vn, r.vu);
    if (k == 0) {
      EXPECT_TRUE(node.addGpsVelocity(velocity).started);
    }
    if (geodetic && k > 0) node.addFix(fix);
    states[k] = node.state();
    if (!estimate && k > 0) states[k].position_map.setConstant(std::nan(""));
  }
  return states;
}

constexpr char kDrive0027[] = "data/kitti_raw/2011_09_30/2011_09_30_drive_0027_sync/oxts";

// The first 450 frames of 2011_09_30_drive_0027 under the protocol with config/inekf.yaml, and
// inekf_offline's run of them.
struct ProtocolDrive {
  std::vector<kitti::OxtsFrame> frames;
  OxtsRunOptions options;
  OxtsRunResult offline;
};
ProtocolDrive drive0027() {
  ProtocolDrive drive;
  drive.frames = kitti::readOxtsFolder(test::sharedPath(kDrive0027));
  drive.frames.resize(std::min<std::size_t>(drive.frames.size(), 450));
  drive.options.config =
      LocalizationSessionConfig::fromYamlFile(test::repoPath("config/inekf.yaml"));
  drive.options.gps = protocolGps();
  drive.offline = runLocalizerOnOxts(drive.frames, drive.options);
  return drive;
}

TEST(LocalizationSession, NodeStreamAndOfflineRunGiveTheSameTrajectory) {
  ISM_REQUIRE_SHARED(kDrive0027);
  const ProtocolDrive drive = drive0027();
  const std::vector<kitti::OxtsFrame>& frames = drive.frames;
  const OxtsRunOptions& options = drive.options;
  const OxtsRunResult& offline = drive.offline;
  ASSERT_EQ(offline.first_estimated_frame, 0);

  const std::vector<NavState> node = feedAsTheNode(frames, options);
  EXPECT_LT((node[0].position_map - offline.states[0].position_map).norm(), 1e-6);
  int compared = 0;
  double worst_m = 0.0;
  for (std::size_t k = 1; k < frames.size(); ++k) {
    if (!node[k].position_map.allFinite()) continue;
    worst_m = std::max(worst_m, (node[k].position_map - offline.states[k].position_map).norm());
    ++compared;
  }
  EXPECT_EQ(compared, static_cast<int>(frames.size()) - 1);  // every sample after the start
  EXPECT_LT(worst_m, 1e-6);
  std::printf("[ MEASURED ] node stream vs offline run: %d poses, largest difference %.3g m\n",
              compared, worst_m);
}

// A receiver in a 2D mode after the start (every fix's altitude NaN, as NavSatFix gives it): the
// fixes still hold the car on the ground as 3D ones do; the height is the IMU's alone. Ignored, as
// they were, the drive ran on dead reckoning.
TEST(LocalizationSession, FixesWithoutAltitudeHoldTheTrackOnARealDrive) {
  ISM_REQUIRE_SHARED(kDrive0027);
  const ProtocolDrive drive = drive0027();
  const std::vector<kitti::OxtsFrame>& frames = drive.frames;
  const OxtsRunOptions& options = drive.options;
  const OxtsRunResult& offline = drive.offline;
  const std::vector<NavState> with_altitude = feedAsTheNode(frames, options);
  const std::vector<NavState> without_altitude =
      feedAsTheNode(frames, options, [](GeodeticFixEvent* fix) { fix->alt_m = std::nan(""); });
  const auto horizontalRms = [&](const std::vector<NavState>& states) {
    double sum = 0.0;
    int n = 0;
    for (std::size_t k = 0; k < states.size(); ++k) {
      if (!states[k].position_map.allFinite()) continue;
      sum += (states[k].position_map - offline.truth[k].translation()).head<2>().squaredNorm();
      ++n;
    }
    return n > 0 ? std::sqrt(sum / n) : std::numeric_limits<double>::infinity();
  };
  const double rms_3d = horizontalRms(with_altitude);
  const double rms_2d = horizontalRms(without_altitude);
  EXPECT_LT(rms_2d, 1.25 * rms_3d + 0.3);
  EXPECT_TRUE(without_altitude.back().position_map.allFinite());
  std::printf(
      "[ MEASURED ] drive 0027, 450 frames, protocol GPS: horizontal RMS %.2f m with 3D "
      "fixes, %.2f m with 2D fixes after the start\n",
      rms_3d, rms_2d);
}

}  // namespace
}  // namespace estimation
}  // namespace inekf_semantic_mapping
