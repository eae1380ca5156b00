// LocalizationSession: the start, the map origin, the fix covariance policy, the time-jump reset
// and the statistics; the fault cases the inekf_node rostests inject (a fix before its IMU
// message, late fixes, a bag loop, bad samples) on the session directly. On real drives:
// test/data/test_localization_session_data.cpp.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/estimation/localization_session.h"
#include "inekf_semantic_mapping/estimation/oxts_run.h"
#include "inekf_semantic_mapping/kitti/gps_degradation.h"
#include "inekf_semantic_mapping/kitti/mercator.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kLat0 = 48.98523696217, kLon0 = 8.3936414564418, kAlt0 = 116.37242889404;

const Eigen::Matrix3d kHeading =
    Eigen::AngleAxisd(-0.56, Eigen::Vector3d::UnitZ()).toRotationMatrix();

ImuEvent restingImu(double stamp_s, bool with_orientation = true) {
  ImuEvent event;
  event.sample.stamp_s = stamp_s;
  event.sample.specific_force = Eigen::Vector3d(0.0, 0.0, 9.81);
  if (with_orientation) event.orientation = kHeading;
  return event;
}

// A fix `east_m` east of the origin.
GeodeticFixEvent fixAt(double stamp_s, double east_m = 0.0) {
  const kitti::MercatorProjection projection(kLat0, kLon0, kAlt0);
  GeodeticFixEvent fix;
  fix.stamp_s = stamp_s;
  projection.toGeodetic(Eigen::Vector3d(east_m, 0.0, 0.0), &fix.lat_deg, &fix.lon_deg, &fix.alt_m);
  fix.covariance_enu = Eigen::Matrix3d::Identity();
  return fix;
}

GpsVelocityEvent stillAt(double stamp_s) {
  GpsVelocityEvent velocity;
  velocity.stamp_s = stamp_s;
  return velocity;
}

// A car at rest from t0 for duration_s: IMU at 10 Hz, a GPS velocity and a fix every second.
void standStill(LocalizationSession* session, double t0, double duration_s) {
  for (int k = 0; 0.1 * k <= duration_s + 1e-9; ++k) {
    const double t = t0 + 0.1 * k;
    session->addImu(restingImu(t));
    if (k % 10 == 0) {
      session->addGpsVelocity(stillAt(t));
      session->addFix(fixAt(t));
    }
  }
}

// IMU samples every 0.1 s after t0_s: each one an estimate, none a reset.
void expectEstimatesGoOn(LocalizationSession* session, double t0_s, int samples) {
  for (int k = 1; k <= samples; ++k) {
    const LocalizationSession::Update next = session->addImu(restingImu(t0_s + 0.1 * k));
    EXPECT_FALSE(next.reset) << next.note;
    EXPECT_TRUE(next.new_estimate) << t0_s + 0.1 * k;
  }
}

LocalizationSessionConfig originConfig() {
  LocalizationSessionConfig config;
  config.origin = GeodeticOrigin{kLat0, kLon0, kAlt0};
  return config;
}

TEST(LocalizationSession, AFixBeforeItsImuWaitsForTheOrientationAndVelocity) {
  LocalizationSession session(originConfig());
  EXPECT_FALSE(session.addFix(fixAt(10.0)).started);       // nothing else yet: no yaw-0 start
  EXPECT_FALSE(session.addImu(restingImu(10.0)).started);  // its velocity is on its way
  const LocalizationSession::Update update = session.addGpsVelocity(stillAt(10.0));
  ASSERT_TRUE(update.started) << update.note;
  EXPECT_TRUE(session.state().rotation.isApprox(kHeading, 1e-12));
  EXPECT_NEAR(session.state().stamp_s, 10.0, 1e-12);
  EXPECT_NE(update.note.find("orientation from the IMU"), std::string::npos) << update.note;
  // The start is an estimate to publish, at the fix's stamp, although the velocity completed it
  // (otherwise a scan between the fix and the next sample would have no pose).
  ASSERT_TRUE(update.start_estimate.has_value());
  EXPECT_FALSE(update.new_estimate);
  EXPECT_NEAR(update.start_estimate->state.stamp_s, 10.0, 1e-12);
  EXPECT_TRUE(update.start_estimate->state.position_map.isApprox(session.state().position_map));
  EXPECT_TRUE(update.start_estimate->pose_covariance.isApprox(session.poseCovariance()));
  // The next sample carries the state on and is an estimate to publish.
  EXPECT_TRUE(session.addImu(restingImu(10.1)).new_estimate);
  EXPECT_NEAR(session.state().stamp_s, 10.1, 1e-12);
  EXPECT_EQ(session.statistics().starts, 1);
}

TEST(LocalizationSession, AStartOnAnImuSampleAfterTheFixCarriesOnToTheSample) {
  LocalizationSession session(originConfig());
  session.setGpsVelocityExpected(false);
  session.addImu(restingImu(9.9, /*with_orientation=*/false));
  session.addFix(fixAt(10.0));  // waits for an orientation
  const LocalizationSession::Update update = session.addImu(restingImu(10.05));
  ASSERT_TRUE(update.started);
  EXPECT_TRUE(update.new_estimate);  // at the sample's stamp, ...
  EXPECT_NEAR(session.state().stamp_s, 10.05, 1e-12);
  ASSERT_TRUE(update.start_estimate.has_value());  // ... after the start's at the fix's
  EXPECT_NEAR(update.start_estimate->state.stamp_s, 10.0, 1e-12);
  EXPECT_EQ(session.statistics().filter.imu_dropped, 0);  // no duplicate at the start
}

TEST(LocalizationSession, AStartOnASampleAtTheFixStampIsAnEstimateNotADrop) {
  LocalizationSession session(originConfig());
  session.setGpsVelocityExpected(false);
  session.addFix(fixAt(10.0));
  const LocalizationSession::Update update = session.addImu(restingImu(10.0));
  ASSERT_TRUE(update.started);
  EXPECT_TRUE(update.new_estimate);
  EXPECT_FALSE(update.start_estimate.has_value());  // new_estimate is the start: not twice
  EXPECT_EQ(update.note.find("dropped"), std::string::npos) << update.note;
  EXPECT_EQ(session.statistics().filter.imu_dropped, 0);
}

TEST(LocalizationSession, AStartMadeByTheFixIsAnEstimateAtTheFixStamp) {
  LocalizationSession session(originConfig());
  EXPECT_FALSE(session.addImu(restingImu(10.0)).started);
  EXPECT_FALSE(session.addGpsVelocity(stillAt(10.0)).started);
  const LocalizationSession::Update update = session.addFix(fixAt(10.0));
  ASSERT_TRUE(update.started) << update.note;
  EXPECT_FALSE(update.new_estimate);
  ASSERT_TRUE(update.start_estimate.has_value());
  EXPECT_NEAR(update.start_estimate->state.stamp_s, 10.0, 1e-12);
  // Only the start carries one.
  EXPECT_FALSE(session.addImu(restingImu(10.1)).start_estimate.has_value());
  EXPECT_FALSE(session.addFix(fixAt(10.1)).start_estimate.has_value());
}

TEST(LocalizationSession, WithoutOrientationTheStartLevelsAfterMaxWait) {
  LocalizationSession session(originConfig());
  session.setGpsVelocityExpected(false);
  session.addImu(restingImu(10.0, false));
  session.addFix(fixAt(10.0));
  EXPECT_FALSE(session.started());
  session.addImu(restingImu(10.1, false));
  EXPECT_FALSE(session.started());  // still within start_max_wait_s
  const LocalizationSession::Update update = session.addImu(restingImu(10.3, false));
  ASSERT_TRUE(update.started);
  EXPECT_NE(update.note.find("levelled from gravity"), std::string::npos) << update.note;
}

// A 10 Hz GPS and a 100 Hz IMU without orientation (a u-blox receiver and a plain MEMS IMU): each
// fix restarted the 0.2 s wait and the filter never started, with no word of why.
TEST(LocalizationSession, AFastGpsAndAnImuWithoutOrientationStart) {
  LocalizationSession session(originConfig());
  session.setGpsVelocityExpected(false);
  bool started = false;
  for (int k = 0; k < 300 && !started; ++k) {
    const double t = 10.0 + 0.01 * k;
    started = session.addImu(restingImu(t, false)).started;
    if (k % 10 == 0) started = session.addFix(fixAt(t)).started || started;
  }
  ASSERT_TRUE(session.started());
  EXPECT_LT(session.state().stamp_s, 10.35);
}

TEST(LocalizationSession, MapOriginIsTheFirstUsableFixUnlessConfigured) {
  LocalizationSession session{LocalizationSessionConfig()};
  GeodeticFixEvent no_solution = fixAt(9.0, 50.0);
  no_solution.has_solution = false;
  session.addFix(no_solution);
  GeodeticFixEvent nan_fix = fixAt(9.5, 50.0);
  nan_fix.lat_deg = kNaN;
  session.addFix(nan_fix);
  // Beyond the pole: as the origin it would make every later fix not finite.
  GeodeticFixEvent polar_fix = fixAt(9.6, 50.0);
  polar_fix.lat_deg = 95.0;
  EXPECT_NE(session.addFix(polar_fix).note.find("latitude 95"), std::string::npos);
  EXPECT_FALSE(session.projection().has_value());
  session.addImu(restingImu(10.0));
  session.addGpsVelocity(stillAt(10.0));
  session.addFix(fixAt(10.0, 20.0));
  ASSERT_TRUE(session.started());
  EXPECT_LT(session.state().position_map.norm(), 1e-9);  // the origin is this fix
  EXPECT_EQ(session.statistics().fixes_ignored, 3);
  EXPECT_EQ(session.statistics().fixes_received, 4);
  EXPECT_TRUE(session.state().position_map.allFinite());

  LocalizationSession configured(originConfig());
  configured.addImu(restingImu(10.0));
  configured.addGpsVelocity(stillAt(10.0));
  configured.addFix(fixAt(10.0, 20.0));
  ASSERT_TRUE(configured.started());
  EXPECT_NEAR(configured.state().position_map.x(), 20.0, 1e-6);

  LocalizationSessionConfig polar = originConfig();
  polar.origin->lat_deg = -90.0;
  EXPECT_THROW(LocalizationSession{polar}, std::invalid_argument);
}

// The position covariance the filter starts with is the fix's, after the session's policy.
double startVarianceEast(const std::optional<Eigen::Matrix3d>& covariance) {
  LocalizationSession session(originConfig());
  session.addImu(restingImu(10.0));
  session.addGpsVelocity(stillAt(10.0));
  GeodeticFixEvent fix = fixAt(10.0);
  fix.covariance_enu = covariance;
  session.addFix(fix);
  EXPECT_TRUE(session.started());
  return session.poseCovariance()(0, 0);
}

// A restarted inekf_node took a new origin at its own first fix: the map frame moved by metres
// under the map and rviz (5 m on a review's bag). An earlier run's origin near the first fix is
// taken again; one far away (another drive) is not.
TEST(LocalizationSession, AnEarlierRunsOriginIsResumedWhenNearTheFirstFix) {
  for (const double east_m : {100.0, 50000.0}) {
    LocalizationSessionConfig config;
    config.resume_origin = GeodeticOrigin{kLat0, kLon0, kAlt0};
    LocalizationSession session(config);
    session.setGpsVelocityExpected(false);
    session.addImu(restingImu(10.0));
    const LocalizationSession::Update update = session.addFix(fixAt(10.0, east_m));
    ASSERT_TRUE(session.started()) << update.note;
    const bool resumed = east_m < config.resume_origin_max_m;
    EXPECT_NE(update.note.find(resumed ? "resumed from an earlier run" : "not resumed"),
              std::string::npos)
        << update.note;
    EXPECT_NEAR(session.state().position_map.x(), resumed ? east_m : 0.0, 0.01) << east_m;
    EXPECT_NEAR(session.projection()->lat0Deg(), resumed ? kLat0 : session.projection()->lat0Deg(),
                1e-12);
  }
}

TEST(LocalizationSession, FixCovarianceDefaultsAndOneFloor) {
  const LocalizationSessionConfig config;
  const double floor = config.localizer.min_gps_sigma_m * config.localizer.min_gps_sigma_m;
  EXPECT_NEAR(startVarianceEast(Eigen::Matrix3d::Identity() * 4.0), 4.0, 1e-9);
  EXPECT_NEAR(startVarianceEast(Eigen::Matrix3d::Identity() * 1e-4), floor, 1e-9);
  const double h = config.default_fix_sigma_horizontal_m;
  EXPECT_NEAR(startVarianceEast(std::nullopt), h * h, 1e-9);
  Eigen::Matrix3d broken = Eigen::Matrix3d::Identity();
  broken(1, 1) = kNaN;
  EXPECT_NEAR(startVarianceEast(broken), h * h, 1e-9);
}

TEST(LocalizationSession, BadSamplesAreCountedAndTheFilterKeepsGoing) {
  LocalizationSession session(originConfig());
  session.addImu(restingImu(10.0));
  session.addGpsVelocity(stillAt(10.0));
  session.addFix(fixAt(10.0));
  ASSERT_TRUE(session.started());
  EXPECT_TRUE(session.addImu(restingImu(10.1)).new_estimate);
  EXPECT_FALSE(session.addImu(restingImu(10.1)).new_estimate);  // duplicate
  ImuEvent nan_sample = restingImu(10.2);
  nan_sample.sample.specific_force.x() = kNaN;
  const LocalizationSession::Update nan_update = session.addImu(nan_sample);
  EXPECT_FALSE(nan_update.new_estimate);
  EXPECT_NE(nan_update.note.find("linear acceleration is not finite"), std::string::npos)
      << nan_update.note;
  EXPECT_TRUE(session.addImu(restingImu(10.3)).new_estimate);
  EXPECT_FALSE(session.addImu(restingImu(10.25)).new_estimate);  // out of order
  GeodeticFixEvent nan_fix = fixAt(10.3);
  nan_fix.lat_deg = kNaN;
  const LocalizationSession::Update no_latitude = session.addFix(nan_fix);
  EXPECT_FALSE(no_latitude.correction.has_value());
  EXPECT_NE(no_latitude.note.find("latitude must be"), std::string::npos) << no_latitude.note;
  GeodeticFixEvent no_fix = fixAt(10.3);
  no_fix.has_solution = false;
  EXPECT_NE(session.addFix(no_fix).note.find("reports no solution"), std::string::npos);
  EXPECT_TRUE(session.addFix(fixAt(10.3)).correction->accepted);
  const LocalizationSession::Statistics statistics = session.statistics();
  EXPECT_EQ(statistics.imu_samples, 6);
  EXPECT_EQ(statistics.imu_invalid, 1);
  EXPECT_EQ(statistics.filter.imu_dropped, 2);
  EXPECT_EQ(statistics.fixes_ignored, 2);
  EXPECT_EQ(statistics.filter.gps_used, 2);  // the start and 10.3
  EXPECT_EQ(statistics.resets, 0);
  EXPECT_TRUE(session.state().position_map.allFinite());
}

// A receiver in a 2D mode (NavSatFix altitude NaN): nothing to start from, but once the filter
// runs its fixes place the car on the ground and leave its height alone.
TEST(LocalizationSession, FixesWithoutAltitudeAreUsedHorizontallyOnceStarted) {
  LocalizationSession session(originConfig());
  GeodeticFixEvent first = fixAt(10.0);
  first.alt_m = kNaN;
  session.addImu(restingImu(10.0));
  session.addGpsVelocity(stillAt(10.0));
  const LocalizationSession::Update refused = session.addFix(first);
  EXPECT_FALSE(session.started());
  EXPECT_NE(refused.note.find("starts from a 3D fix"), std::string::npos) << refused.note;
  standStill(&session, 10.1, 3.0);
  ASSERT_TRUE(session.started());
  EXPECT_EQ(session.lastInnovationDegreesOfFreedom(), 3);
  const double height_before = session.state().position_map.z();
  const double east_before = session.state().position_map.x();
  // 2D fixes 3 m east of where the car stands.
  int accepted = 0;
  for (int k = 1; k <= 5; ++k) {
    const double t = 13.1 + 0.1 * k;
    session.addImu(restingImu(t));
    GeodeticFixEvent flat = fixAt(t, 3.0);
    flat.alt_m = kNaN;
    const LocalizationSession::Update update = session.addFix(flat);
    ASSERT_TRUE(update.correction.has_value()) << update.note;
    accepted += update.correction->accepted ? 1 : 0;
    EXPECT_EQ(session.lastInnovationDegreesOfFreedom(), 2);
  }
  EXPECT_EQ(accepted, 5);
  EXPECT_GT(session.state().position_map.x() - east_before, 1.0);
  EXPECT_NEAR(session.state().position_map.z(), height_before, 0.01);
  EXPECT_TRUE(session.state().position_map.allFinite());
  const LocalizationSession::Statistics statistics = session.statistics();
  EXPECT_EQ(statistics.fixes_horizontal_only, 5);
  EXPECT_EQ(statistics.fixes_ignored, 1);  // the first, before the start
  EXPECT_NE(session.summary().find("5 2D"), std::string::npos) << session.summary();
}

// A bag loop: one reset, and what is still queued of the old loop (IMU, fixes and velocities come
// on separate connections) is dropped rather than taken as the newest stamp. Found by review: an
// old-loop message after the first new-loop one became the newest stamp and the next new-loop
// message reset the session again (2-3 resets a loop with the clock also resetting; the new
// loop's start lost for a GPS period).
TEST(LocalizationSession, ABagLoopIsOneResetAndTheOldLoopsLeftoversAreDropped) {
  LocalizationSession session(originConfig());
  standStill(&session, 100.0, 2.0);
  ASSERT_TRUE(session.started());
  // The loop's first message is held back (one stamp alone may be a glitch); its second confirms
  // the jump back and resets, and the first then goes through.
  const LocalizationSession::Update first = session.addImu(restingImu(100.0));
  EXPECT_FALSE(first.reset);
  EXPECT_NE(first.note.find("behind the newest"), std::string::npos) << first.note;
  EXPECT_TRUE(session.addImu(restingImu(100.1)).reset);
  const LocalizationSession::Update stale = session.addFix(fixAt(102.0));
  EXPECT_FALSE(stale.reset);
  EXPECT_FALSE(stale.started);
  EXPECT_NE(stale.note.find("before the jump back"), std::string::npos) << stale.note;
  EXPECT_FALSE(session.addImu(restingImu(101.9)).reset);  // dropped too
  session.addGpsVelocity(stillAt(100.0));
  ASSERT_TRUE(session.addFix(fixAt(100.0)).started);
  EXPECT_EQ(session.statistics().resets, 1);
  EXPECT_EQ(session.statistics().messages_of_previous_time_line, 2);
  EXPECT_EQ(session.statistics().messages_held_for_a_jump, 1);
  EXPECT_EQ(session.statistics().messages_off_the_time_line, 0);
  // The new loop goes on past the old one's end: nothing of it is dropped.
  for (int k = 2; k <= 40; ++k) {
    EXPECT_TRUE(session.addImu(restingImu(100.0 + 0.1 * k)).new_estimate) << k;
  }
  EXPECT_EQ(session.statistics().resets, 1);
  EXPECT_EQ(session.statistics().messages_of_previous_time_line, 2);
}

// inekf_node's ~reset: the filter starts over at the next fix (not at the IMU alone), in the map
// frame of the first start (a start at its own fix's position would move the map under the map).
TEST(LocalizationSession, ARestartOnRequestStartsOverAtTheNextFixInTheSameFrame) {
  LocalizationSession session{LocalizationSessionConfig()};  // origin: the first fix
  standStill(&session, 100.0, 2.0);
  ASSERT_TRUE(session.started());
  ASSERT_TRUE(session.projection().has_value());
  const double origin_lat = session.projection()->lat0Deg();
  const LocalizationSession::Update restart = session.restart("~reset called");
  EXPECT_TRUE(restart.reset);
  EXPECT_EQ(restart.note, "~reset called");
  EXPECT_FALSE(session.started());
  EXPECT_EQ(session.statistics().resets, 1);
  EXPECT_FALSE(session.addImu(restingImu(102.1)).new_estimate);
  session.addGpsVelocity(stillAt(102.2));
  session.addImu(restingImu(102.2));
  const LocalizationSession::Update start = session.addFix(fixAt(102.2, 30.0));
  ASSERT_TRUE(start.started) << start.note;
  EXPECT_NEAR(session.state().position_map.x(), 30.0, 1e-6);  // the first start's frame
  EXPECT_EQ(session.projection()->lat0Deg(), origin_lat);
  expectEstimatesGoOn(&session, 102.2, 10);
  EXPECT_EQ(session.statistics().resets, 1);
}

// Found by review: one fix stamped 1000 s ahead (a receiver's glitch) became the newest stamp,
// and the next ordinary IMU sample a jump back that reset a healthy filter. A message far ahead
// is dropped until a second one confirms the jump.
TEST(LocalizationSession, OneMessageFarAheadDoesNotResetAHealthyFilter) {
  LocalizationSession session(originConfig());
  standStill(&session, 100.0, 2.0);
  ASSERT_TRUE(session.started());
  const LocalizationSession::Update glitch = session.addFix(fixAt(1102.0, 500.0));
  EXPECT_FALSE(glitch.reset);
  EXPECT_NE(glitch.note.find("ahead of the newest"), std::string::npos) << glitch.note;
  expectEstimatesGoOn(&session, 102.0, 20);
  EXPECT_EQ(session.statistics().resets, 0);
  EXPECT_EQ(session.statistics().messages_off_the_time_line, 1);
  EXPECT_LT(session.state().position_map.norm(), 1.0);  // the glitch's 500 m never applied
  // A second glitch once the data has gone on is one of its own, not the first's confirmation
  // (the first one's stamp was kept for ever, and the second reset the filter).
  EXPECT_FALSE(session.addFix(fixAt(5000.0, 500.0)).reset);
  for (int k = 1; k <= 15; ++k) {
    EXPECT_FALSE(session.addImu(restingImu(104.0 + 0.1 * k)).reset) << k;
  }
  EXPECT_EQ(session.statistics().resets, 0);
  EXPECT_EQ(session.statistics().messages_off_the_time_line, 2);
  // A real jump forward (a player seeking on) shows in a second message and is followed; beyond
  // session.restart_after_imu_gap_s it starts the session over there, its first message
  // included.
  EXPECT_FALSE(session.addImu(restingImu(500.0)).new_estimate);
  const LocalizationSession::Update followed = session.addImu(restingImu(500.1));
  EXPECT_TRUE(followed.reset) << followed.note;
  EXPECT_NE(followed.note.find("time jumped forward"), std::string::npos) << followed.note;
  EXPECT_EQ(session.statistics().messages_off_the_time_line, 2);
  EXPECT_EQ(session.statistics().messages_held_for_a_jump, 1);
}

// A single stamp far behind (a driver's zero stamp, a fix from a stale buffer) reset a healthy
// filter as a bag loop, and the next 2 s of data were then dropped as the old time line's. It is
// held back like a jump forward, and dropped when no second message confirms it.
TEST(LocalizationSession, OneStampFarBehindDoesNotResetAHealthyFilter) {
  LocalizationSession session(originConfig());
  standStill(&session, 100.0, 2.0);
  ASSERT_TRUE(session.started());
  const LocalizationSession::Update zero = session.addImu(restingImu(0.0));
  EXPECT_FALSE(zero.reset);
  EXPECT_NE(zero.note.find("behind the newest"), std::string::npos) << zero.note;
  EXPECT_FALSE(session.addFix(fixAt(50.0, 500.0)).reset);  // another, far from the first
  expectEstimatesGoOn(&session, 102.0, 20);
  session.addFix(fixAt(104.0));
  EXPECT_EQ(session.statistics().resets, 0);
  EXPECT_EQ(session.statistics().messages_off_the_time_line, 2);
  EXPECT_EQ(session.statistics().messages_of_previous_time_line, 0);
  EXPECT_EQ(session.statistics().filter.gps_used, 4);   // 100..102 s and 104 s: none dropped
  EXPECT_LT(session.state().position_map.norm(), 1.0);  // the stale fix's 500 m never applied
}

// Found by review: an IMU glitch stamped 1.05-2 s ahead was let through as soon as the data came
// within time_jump_back_s of it, after the sample that brought it there: the filter bridged a
// second to the glitch and dropped every real sample up to it. A held message goes through only
// once the data reaches its stamp, before the sample that does; one the data passes by more
// than time_jump_back_s first is dropped.
TEST(LocalizationSession, AnImuStampAheadGoesThroughOnlyWhereTheDataReachesIt) {
  struct Case {
    double ahead_s;
    bool early_fix;  // a fix of 103.1 s arriving before its IMU sample (fix_wait_for_imu_s)
    bool reached;
  };
  // 1.05 s: reached by the sample of 103.1 s, it goes through just before it. 1.55 s: passed by
  // more than time_jump_back_s first. Found by review: the early fix reached the glitch's stamp
  // first and let it through before the samples up to it; the IMU must reach it.
  for (const Case c :
       {Case{1.05, false, true}, Case{1.55, false, false}, Case{1.05, true, false}}) {
    SCOPED_TRACE(testing::Message() << c.ahead_s << (c.early_fix ? " early fix" : ""));
    LocalizationSession session(originConfig());
    standStill(&session, 100.0, 2.0);
    ASSERT_TRUE(session.started());
    EXPECT_FALSE(session.addImu(restingImu(102.0 + c.ahead_s)).new_estimate);
    for (int k = 1; k <= 30; ++k) {
      if (c.early_fix && k == 8) session.addFix(fixAt(103.1));
      const LocalizationSession::Update next = session.addImu(restingImu(102.0 + 0.1 * k));
      EXPECT_TRUE(next.new_estimate) << k << ": " << next.note;
      EXPECT_EQ(next.imu_status, Localizer::ImuStatus::kUsed) << k << ": " << next.note;
      EXPECT_EQ(next.held_estimates.size(), c.reached && k == 11 ? 1u : 0u) << k;
    }
    EXPECT_EQ(session.statistics().filter.imu_dropped, 0);
    EXPECT_EQ(session.statistics().filter.imu_gaps, 0);
    EXPECT_EQ(session.statistics().messages_held_for_a_jump, c.reached ? 1 : 0);
    EXPECT_EQ(session.statistics().messages_off_the_time_line, c.reached ? 0 : 1);
  }
}

// Found by review: a GPS connection stalled for 1.5 s delivers its backlog, or runs 1.05 s late
// for good; its second late fix confirmed a "jump back", and the filter reset (16 times in 20 s
// of a steady 1.05 s latency) and dropped the IMU as the old time line's. A GPS message late by
// up to gps.fix_history_s is late, not a jump: the filter applies it at its own time.
TEST(LocalizationSession, AGpsStreamLateByLessThanTheFixHistoryIsNotAJump) {
  for (const double latency_s : {1.05, 1.5}) {
    SCOPED_TRACE(latency_s);
    LocalizationSession session(originConfig());
    standStill(&session, 100.0, 1.0);
    ASSERT_TRUE(session.started());
    for (int k = 11; k <= 200; ++k) {  // IMU at 10 Hz; fix and velocity latency_s late
      const double t = 100.0 + 0.1 * k;
      EXPECT_FALSE(session.addImu(restingImu(t)).reset) << t;
      if (k % 5 == 0) {
        session.addGpsVelocity(stillAt(t - latency_s));
        const LocalizationSession::Update fix = session.addFix(fixAt(t - latency_s));
        EXPECT_FALSE(fix.reset) << fix.note;
      }
    }
    EXPECT_EQ(session.statistics().resets, 0);
    EXPECT_EQ(session.statistics().messages_of_previous_time_line, 0);
    EXPECT_EQ(session.statistics().messages_off_the_time_line, 0);
    EXPECT_FALSE(session.gpsClockOffset().has_value());
    EXPECT_GE(session.statistics().filter.gps_used, 30);
  }
}

// Found by review: the GPS alone confirmed jumps back. A backlog of fixes 2.5 s late (beyond
// gps.fix_history_s), or the GPS's leftovers from before a seek forward, reset the filter and
// the IMU was then dropped as the old time line's. The IMU's stamps are the filter's time line:
// a jump the GPS shows needs an IMU sample to confirm it.
TEST(LocalizationSession, TheGpsAloneConfirmsNoJump) {
  LocalizationSession session(originConfig());
  standStill(&session, 100.0, 2.0);
  ASSERT_TRUE(session.started());
  for (const double late : {99.5, 99.6}) {  // a stalled connection's backlog, 2.5 s late
    session.addGpsVelocity(stillAt(late));
    EXPECT_FALSE(session.addFix(fixAt(late)).reset);
  }
  expectEstimatesGoOn(&session, 102.0, 20);
  // A seek forward by 5 s (bridged) with the GPS 0.3 s behind: its leftovers from before the
  // seek come after the first samples of the new place.
  for (int k = 0; k <= 5; ++k) session.addImu(restingImu(109.0 + 0.1 * k));
  for (const double leftover : {103.8, 103.9}) {
    session.addGpsVelocity(stillAt(leftover));
    EXPECT_FALSE(session.addFix(fixAt(leftover)).reset);
  }
  for (int k = 6; k <= 20; ++k) EXPECT_FALSE(session.addImu(restingImu(109.0 + 0.1 * k)).reset);
  EXPECT_EQ(session.statistics().resets, 0);
  EXPECT_EQ(session.statistics().messages_of_previous_time_line, 0);
  EXPECT_TRUE(session.started());
}

// A stream stuck at one stamp far behind (the IMU silent, the receiver repeating a stale fix):
// what is held for the jump stays bounded, and is dropped once the data goes on.
TEST(LocalizationSession, MessagesHeldForAJumpAreBounded) {
  LocalizationSession session(originConfig());
  standStill(&session, 100.0, 2.0);
  ASSERT_TRUE(session.started());
  for (int k = 0; k < 200; ++k) EXPECT_FALSE(session.addFix(fixAt(10.0, 500.0)).reset);
  EXPECT_EQ(session.statistics().messages_off_the_time_line, 200 - 32);
  for (int k = 1; k <= 15; ++k) session.addImu(restingImu(102.0 + 0.1 * k));
  EXPECT_EQ(session.statistics().messages_off_the_time_line, 200);
  EXPECT_EQ(session.statistics().resets, 0);
}

// A GPS stamped in GPS time and an IMU in UTC (18 s apart), interleaved as they arrive: each fix
// was taken for a jump forward and the next IMU sample for a jump back, resetting the filter every
// few seconds, and it never started. The GPS alone confirms no jump, and the steady offset is
// named (after 5 s of it) and the GPS dropped until a fix agrees with the IMU again; then the
// filter starts.
TEST(LocalizationSession, AGpsOnAnotherClockIsNamedNotTakenForJumps) {
  LocalizationSession session(originConfig());
  std::string named;
  for (int k = 0; k < 150; ++k) {  // 15 s: IMU at 10 Hz, a fix and a velocity at each sample
    const double t = 100.0 + 0.1 * k;
    session.addImu(restingImu(t));
    session.addGpsVelocity(stillAt(t + 18.0));
    const LocalizationSession::Update fix = session.addFix(fixAt(t + 18.0));
    if (fix.note.find("different clocks") != std::string::npos) named = fix.note;
  }
  EXPECT_NE(named.find("18.000 s ahead of the IMU's"), std::string::npos) << named;
  ASSERT_TRUE(session.gpsClockOffset().has_value());
  EXPECT_NEAR(*session.gpsClockOffset(), 18.0, 0.2);
  EXPECT_EQ(session.statistics().resets, 0);  // the GPS alone confirms no jump
  const std::int64_t resets = session.statistics().resets;
  EXPECT_GT(session.statistics().gps_messages_off_the_imu_clock, 100);
  EXPECT_FALSE(session.started());
  // The receiver set to UTC: the first fix that agrees ends it, and the filter starts.
  for (int k = 150; k < 160; ++k) {
    const double t = 100.0 + 0.1 * k;
    session.addImu(restingImu(t));
    session.addGpsVelocity(stillAt(t));
    session.addFix(fixAt(t));
  }
  EXPECT_FALSE(session.gpsClockOffset().has_value());
  EXPECT_TRUE(session.started());
  EXPECT_EQ(session.statistics().resets, resets);
}

// A jump beyond the restart limit whose fix (and GPS velocity) arrive before the IMU sample of
// the same instant: they are held, the IMU sample confirms the jump, and they go through first,
// so that the filter starts at that fix with that velocity. The fix used to be dropped with the
// jump's first message, and the start waited for the next fix.
TEST(LocalizationSession, AJumpWhoseFixComesFirstStartsAtThatFix) {
  LocalizationSession session(originConfig());
  standStill(&session, 100.0, 2.0);
  ASSERT_TRUE(session.started());
  EXPECT_FALSE(session.addFix(fixAt(120.0, 7.0)).reset);
  GpsVelocityEvent moving = stillAt(120.0);
  moving.velocity = Eigen::Vector3d(2.0, 0.0, 0.0);
  EXPECT_FALSE(session.addGpsVelocity(moving).reset);  // the same sensor: not a confirmation
  const LocalizationSession::Update confirmed = session.addImu(restingImu(120.0));
  EXPECT_TRUE(confirmed.reset) << confirmed.note;
  EXPECT_TRUE(confirmed.started) << confirmed.note;
  ASSERT_TRUE(session.started());
  EXPECT_NEAR(session.state().stamp_s, 120.0, 1e-9);
  EXPECT_NEAR(session.state().position_map.x(), 7.0, 1e-6);
  EXPECT_TRUE(session.state().velocity_map.isApprox(moving.velocity));
  EXPECT_EQ(session.statistics().messages_held_for_a_jump, 2);
  EXPECT_EQ(session.statistics().resets, 1);
}

// A fix stamped a little more than time_jump_back_s ahead (jitter, a receiver's latency) is held;
// once the IMU catches up with it, it goes through and is applied at its instant.
TEST(LocalizationSession, AHeldFixTheDataCatchesUpWithIsApplied) {
  LocalizationSession session(originConfig());
  standStill(&session, 100.0, 2.0);
  ASSERT_TRUE(session.started());
  const std::int64_t used = session.statistics().filter.gps_used;
  EXPECT_NE(session.addFix(fixAt(103.05)).note.find("held until"), std::string::npos);
  for (int k = 1; k <= 15; ++k) {
    EXPECT_FALSE(session.addImu(restingImu(102.0 + 0.1 * k)).reset) << k;
  }
  EXPECT_EQ(session.statistics().filter.gps_used, used + 1);
  EXPECT_EQ(session.statistics().messages_held_for_a_jump, 1);
  EXPECT_EQ(session.statistics().messages_off_the_time_line, 0);
}

// Found by review: one receiver glitch stamps the fix and its velocity alike; the velocity was
// taken for the jump's confirmation and the next IMU sample reset the filter. Before the start, a
// fix waiting from before a jump of an hour started the filter there and bridged the hour.
TEST(LocalizationSession, AGlitchOnAFixAndItsVelocityIsOneMessage) {
  LocalizationSession session(originConfig());
  standStill(&session, 100.0, 2.0);
  ASSERT_TRUE(session.started());
  for (const double ahead_s : {5.0, 1000.0}) {
    EXPECT_FALSE(session.addFix(fixAt(session.state().stamp_s + ahead_s, 500.0)).reset);
    GpsVelocityEvent glitch = stillAt(session.state().stamp_s + ahead_s);
    EXPECT_FALSE(session.addGpsVelocity(glitch).reset);
    const double t = session.state().stamp_s;
    for (int k = 1; k <= 15; ++k) {
      const LocalizationSession::Update next = session.addImu(restingImu(t + 0.1 * k));
      EXPECT_FALSE(next.reset) << ahead_s << ": " << next.note;
    }
  }
  EXPECT_EQ(session.statistics().resets, 0);
  EXPECT_EQ(session.statistics().messages_off_the_time_line, 4);

  LocalizationSession waiting(originConfig());
  waiting.addFix(fixAt(100.0));
  waiting.addGpsVelocity(stillAt(100.0));
  for (int k = 0; k <= 5; ++k) waiting.addImu(restingImu(3700.0 + 0.1 * k));
  EXPECT_FALSE(waiting.started());  // not from the fix of an hour before
  waiting.addFix(fixAt(3700.5, 3.0));
  ASSERT_TRUE(waiting.addGpsVelocity(stillAt(3700.5)).started);
  EXPECT_NEAR(waiting.state().stamp_s, 3700.5, 1e-9);
  EXPECT_GE(waiting.errorCovariance().diagonal().minCoeff(), 0.0);
}

// A jump beyond the restart limit that lands on a fix's instant: the IMU sample goes first and is
// dropped, the GPS velocity confirms the jump and restarts the session, and the fix of that
// instant starts it (the restart used to come at the next IMU sample and drop the queued fix
// with it: one GPS period without a pose).
TEST(LocalizationSession, AJumpForwardLandingOnAFixRestartsAtThatFix) {
  LocalizationSession session(originConfig());
  standStill(&session, 100.0, 2.0);
  ASSERT_TRUE(session.started());
  EXPECT_FALSE(session.addImu(restingImu(118.0)).reset);  // dropped: not confirmed yet
  EXPECT_TRUE(session.addGpsVelocity(stillAt(118.0)).reset);
  const LocalizationSession::Update fix = session.addFix(fixAt(118.0, 7.0));
  const LocalizationSession::Update imu = session.addImu(restingImu(118.1));
  EXPECT_TRUE(fix.started || imu.started) << fix.note << " / " << imu.note;
  ASSERT_TRUE(session.started());
  ASSERT_TRUE((fix.started ? fix : imu).start_estimate.has_value());
  EXPECT_NEAR((fix.started ? fix : imu).start_estimate->state.stamp_s, 118.0, 1e-9);
  EXPECT_NEAR(session.state().position_map.x(), 7.0, 1e-6);
  EXPECT_EQ(session.statistics().resets, 1);
}

// A jump back, then a seek forward into the old time line's span (a player restarted further on):
// its first 2 s of stamps are taken for leftovers, then the stream is followed; it must not stay
// dropped for good.
TEST(LocalizationSession, ASeekForwardAfterAJumpBackIsFollowed) {
  LocalizationSession session(originConfig());
  for (int k = 0; k <= 100; ++k) session.addImu(restingImu(100.0 + 0.1 * k));
  EXPECT_FALSE(session.addImu(restingImu(100.0)).reset);  // held: the jump's first message
  EXPECT_TRUE(session.addImu(restingImu(100.1)).reset);
  for (int k = 0; k <= 30; ++k) session.addImu(restingImu(105.0 + 0.1 * k));
  EXPECT_EQ(session.statistics().messages_of_previous_time_line, 21);  // 105.0 .. 107.0
  session.addGpsVelocity(stillAt(108.1));
  EXPECT_TRUE(session.addFix(fixAt(108.1)).started);
}

// Found by review: a clock jumping an hour forward was bridged in one propagation; the covariance
// lost its positive definiteness (variances below zero) and every later fix was rejected. A gap
// longer than restart_after_imu_gap_s starts over instead; a shorter one is still bridged.
TEST(LocalizationSession, AnImuGapLongerThanTheRestartLimitStartsOverAtTheNextFix) {
  LocalizationSession session(originConfig());
  session.setGpsVelocityExpected(false);
  for (int i = 0; i <= 20; ++i) {
    session.addImu(restingImu(10.0 + 0.1 * i));
    if (i % 10 == 0) session.addFix(fixAt(10.0 + 0.1 * i));
  }
  ASSERT_TRUE(session.started());
  // A jump forward is taken at its second message (the first is dropped: one bad stamp alone
  // must not move the session's time).
  EXPECT_FALSE(session.addImu(restingImu(17.0)).new_estimate);  // 5 s gap
  const LocalizationSession::Update bridged = session.addImu(restingImu(17.1));
  EXPECT_FALSE(bridged.reset) << bridged.note;
  EXPECT_TRUE(bridged.new_estimate);
  // The held first sample went through first, bridging the gap, with an estimate of its own.
  EXPECT_NE(bridged.note.find("17.000 s after a gap: bridged"), std::string::npos) << bridged.note;
  ASSERT_EQ(bridged.held_estimates.size(), 1u);
  EXPECT_NEAR(bridged.held_estimates[0].state.stamp_s, 17.0, 1e-9);
  EXPECT_NEAR(session.state().stamp_s, 17.1, 1e-9);

  EXPECT_FALSE(session.addImu(restingImu(17.0 + 3600.0)).reset);
  const LocalizationSession::Update jumped = session.addImu(restingImu(17.1 + 3600.0));
  EXPECT_TRUE(jumped.reset);
  EXPECT_FALSE(jumped.new_estimate);
  EXPECT_NE(jumped.note.find("time jumped forward"), std::string::npos) << jumped.note;
  EXPECT_FALSE(session.started());
  EXPECT_EQ(session.statistics().resets, 1);
  // The next fix starts the filter again, at that fix, with a sound covariance.
  const LocalizationSession::Update restarted = session.addFix(fixAt(3617.0, 5.0));
  ASSERT_TRUE(restarted.started) << restarted.note;
  EXPECT_NEAR(session.state().position_map.x(), 5.0, 1e-6);
  EXPECT_GE(session.errorCovariance().diagonal().minCoeff(), 0.0);
  // The IMU silent while the fixes go on (1 Hz, no jump in the stamps): its next sample, 12 s
  // after the state, is not bridged either.
  for (int k = 1; k <= 12; ++k) session.addFix(fixAt(3617.0 + k, 5.0));
  const LocalizationSession::Update silent = session.addImu(restingImu(3629.05));
  EXPECT_TRUE(silent.reset);
  EXPECT_NE(silent.note.find("IMU silent"), std::string::npos) << silent.note;
  EXPECT_EQ(session.statistics().resets, 2);
}

// A short drive: a car accelerating east at 1 m/s^2 from 5 m/s, IMU at 10 Hz, a fix every 5th
// sample. One entry per sample, in stamp order: the IMU sample, then its fix if any.
struct DriveStep {
  ImuEvent imu;
  std::optional<GeodeticFixEvent> fix;
};

std::vector<DriveStep> accelerateEast(double t0, int samples) {
  std::vector<DriveStep> steps;
  for (int k = 0; k < samples; ++k) {
    const double t = 0.1 * k;
    DriveStep step;
    step.imu = restingImu(t0 + t);
    step.imu.orientation = Eigen::Matrix3d::Identity();
    step.imu.sample.specific_force.x() = 1.0;
    if (k % 5 == 0) step.fix = fixAt(t0 + t, 5.0 * t + 0.5 * t * t + 0.3 * std::sin(7.0 * k));
    steps.push_back(step);
  }
  return steps;
}

// The published trajectory: the state after every IMU event that made a new estimate. Frame
// 0's velocity follows its IMU sample. With wheel_speeds, each IMU sample is followed by a wheel
// speed of its instant (accelerateEast's speed, 0.2 m/s high).
std::vector<NavState> play(LocalizationSession* session, const std::vector<DriveStep>& steps,
                           int fix_delay_samples = 0, bool wheel_speeds = false) {
  std::vector<NavState> published;
  std::vector<std::pair<std::size_t, GeodeticFixEvent>> delayed;
  for (std::size_t k = 0; k < steps.size(); ++k) {
    if (session->addImu(steps[k].imu).new_estimate) published.push_back(session->state());
    if (wheel_speeds) {
      const double t = steps[k].imu.sample.stamp_s;
      session->addWheelSpeed({t, 5.2 + (t - steps[0].imu.sample.stamp_s), 0.05});
    }
    if (k == 0) {
      GpsVelocityEvent velocity;
      velocity.stamp_s = steps[0].imu.sample.stamp_s;
      velocity.velocity = Eigen::Vector3d(5.0, 0.0, 0.0);
      session->addGpsVelocity(velocity);
    }
    if (steps[k].fix) {
      // The first fix starts the filter; the later ones arrive fix_delay_samples late.
      delayed.emplace_back(k == 0 ? k : k + fix_delay_samples, *steps[k].fix);
    }
    while (!delayed.empty() && delayed.front().first <= k) {
      session->addFix(delayed.front().second);
      delayed.erase(delayed.begin());
    }
  }
  for (const auto& entry : delayed) session->addFix(entry.second);
  return published;
}

TEST(LocalizationSession, LateFixesGiveTheInOrderEstimate) {
  const std::vector<DriveStep> steps = accelerateEast(100.0, 60);
  LocalizationSession in_order(originConfig()), late(originConfig());
  play(&in_order, steps);
  // 0.7 s late: older than gps.max_fix_age_s, within gps.fix_history_s (the rostest's fault).
  play(&late, steps, /*fix_delay_samples=*/7);
  EXPECT_GT(late.statistics().filter.gps_applied_late, 8);
  EXPECT_EQ(late.statistics().filter.gps_rejected, 0);
  EXPECT_EQ(late.statistics().filter.gps_used, in_order.statistics().filter.gps_used);
  EXPECT_LT((late.state().position_map - in_order.state().position_map).norm(), 1e-6);
  EXPECT_LT((late.state().velocity_map - in_order.state().velocity_map).norm(), 1e-6);
}

// A late fix's replay applies the wheel speeds of the steps it replays again, once each: the
// estimate is the in-order one, and the wheel speeds do move it.
TEST(LocalizationSession, LateFixesWithWheelSpeedsGiveTheInOrderEstimate) {
  const std::vector<DriveStep> steps = accelerateEast(100.0, 60);
  LocalizationSession in_order(originConfig()), late(originConfig()), without(originConfig());
  play(&in_order, steps, 0, true);
  play(&late, steps, /*fix_delay_samples=*/7, true);
  play(&without, steps, 0, false);
  EXPECT_GT(late.statistics().filter.gps_applied_late, 8);
  EXPECT_EQ(late.statistics().filter.wheel_speed_used, 59);  // all but the one before the start
  EXPECT_EQ(late.statistics().filter.wheel_speed_ignored, 1);
  EXPECT_EQ(in_order.statistics().filter.wheel_speed_used, 59);
  EXPECT_LT((late.state().position_map - in_order.state().position_map).norm(), 1e-6);
  EXPECT_LT((late.state().velocity_map - in_order.state().velocity_map).norm(), 1e-6);
  EXPECT_GT((in_order.state().velocity_map - without.state().velocity_map).norm(), 0.05);
}

// A wheel speed further than wheel_speed.max_age_s from the filter's time (another clock, a
// message from before a jump) is counted and noted once, never applied; one in time is used
// again, and the next stale one is noted again. With wheel_speed.enabled false none is used.
TEST(LocalizationSession, StaleOrDisabledWheelSpeedsAreCountedNotApplied) {
  const std::vector<DriveStep> steps = accelerateEast(100.0, 20);
  LocalizationSession session(originConfig());
  play(&session, steps);
  const double now = session.state().stamp_s;
  const NavState before = session.state();
  const LocalizationSession::Update first = session.addWheelSpeed({now - 0.5, 7.0, 0.05});
  EXPECT_NE(first.note.find("stale"), std::string::npos) << first.note;
  EXPECT_TRUE(session.addWheelSpeed({now + 0.5, 7.0, 0.05}).note.empty());
  EXPECT_EQ(session.statistics().filter.wheel_speed_stale, 2);
  EXPECT_EQ(session.state().velocity_map, before.velocity_map);
  EXPECT_TRUE(session.addWheelSpeed({now, 6.9, 0.05}).note.empty());
  EXPECT_EQ(session.statistics().filter.wheel_speed_used, 1);
  EXPECT_FALSE(session.addWheelSpeed({now + 1.0, 7.0, 0.05}).note.empty());
  // Not finite: rejected by the filter, the state kept.
  const NavState used = session.state();
  session.addWheelSpeed({now, std::nan(""), 0.05});
  EXPECT_EQ(session.statistics().filter.wheel_speed_rejected, 1);
  EXPECT_EQ(session.state().velocity_map, used.velocity_map);

  LocalizationSessionConfig config = originConfig();
  config.localizer.wheel_speed.enabled = false;
  LocalizationSession off(config);
  play(&off, steps, 0, true);
  EXPECT_EQ(off.statistics().filter.wheel_speed_used, 0);
  EXPECT_EQ(off.statistics().filter.wheel_speed_ignored, 20);
}

// IMU and GPS arrive on separate connections: a node may receive the fix of an instant before
// that instant's IMU sample. The estimate must not depend on which comes first (e2e_synthetic's
// ATE varied 2.2 .. 3.1 m with the load before fixes waited for their IMU sample).
TEST(LocalizationSession, AFixArrivingBeforeItsImuSampleGivesTheInOrderEstimate) {
  const std::vector<DriveStep> steps = accelerateEast(100.0, 60);
  // The state once both messages of each instant are in, for either arrival order.
  const auto run = [&steps](bool fix_first) {
    LocalizationSession session(originConfig());
    GpsVelocityEvent velocity = stillAt(steps[0].imu.sample.stamp_s);
    velocity.velocity = Eigen::Vector3d(5.0, 0.0, 0.0);
    std::vector<NavState> states;
    for (std::size_t k = 0; k < steps.size(); ++k) {
      if (k == 0) {
        session.addImu(steps[0].imu);
        session.addGpsVelocity(velocity);
        session.addFix(*steps[0].fix);
      } else if (steps[k].fix && fix_first) {
        EXPECT_FALSE(session.addFix(*steps[k].fix).correction)
            << "a fix ahead of the filter was applied at once, k=" << k;
        EXPECT_TRUE(session.addImu(steps[k].imu).correction) << "the IMU sample released it";
      } else {
        session.addImu(steps[k].imu);
        if (steps[k].fix) session.addFix(*steps[k].fix);
      }
      states.push_back(session.state());
    }
    EXPECT_EQ(session.statistics().fixes_waited_for_imu, fix_first ? 11 : 0);
    EXPECT_EQ(session.statistics().fixes_imu_never_came, 0);
    EXPECT_EQ(session.statistics().filter.gps_used, 12);
    return states;
  };
  const std::vector<NavState> in_order = run(false), fix_first = run(true);
  ASSERT_EQ(fix_first.size(), in_order.size());
  for (std::size_t k = 0; k < in_order.size(); ++k) {
    EXPECT_LT((fix_first[k].position_map - in_order[k].position_map).norm(), 1e-9) << k;
    EXPECT_LT((fix_first[k].velocity_map - in_order[k].velocity_map).norm(), 1e-9) << k;
  }
}

// When the IMU stops, a waiting fix is still used once newer data shows the IMU is not coming.
TEST(LocalizationSession, AFixWhoseImuNeverComesIsAppliedAfterTheWait) {
  LocalizationSession session(originConfig());
  session.addImu(restingImu(100.0));
  session.addGpsVelocity(stillAt(100.0));
  ASSERT_TRUE(session.addFix(fixAt(100.0)).started);
  EXPECT_FALSE(session.addFix(fixAt(100.1, 0.05)).correction);  // waits for IMU 100.1
  const LocalizationSession::Update later = session.addFix(fixAt(100.5, 0.1));
  ASSERT_TRUE(later.correction);  // 100.1 gave up (0.4 s > fix_wait_for_imu_s); 100.5 waits
  EXPECT_TRUE(later.correction->accepted);
  EXPECT_EQ(session.statistics().fixes_imu_never_came, 1);
  EXPECT_EQ(session.statistics().filter.gps_used, 2);
  // A time jump back (a bag loop) clears what waits: the fix of 100.5 s waiting in the old time
  // line is not applied when the replayed one reaches 100.5 s again.
  ASSERT_FALSE(session.addFix(fixAt(100.6, 0.1)).correction);
  EXPECT_FALSE(session.addImu(restingImu(99.0)).reset);  // held: the jump's first message
  EXPECT_TRUE(session.addImu(restingImu(99.5)).reset);
  session.addImu(restingImu(100.0));
  session.addGpsVelocity(stillAt(100.0));
  ASSERT_TRUE(session.addFix(fixAt(100.0)).started);
  for (int k = 1; k <= 7; ++k) session.addImu(restingImu(100.0 + 0.1 * k));
  EXPECT_EQ(session.statistics().filter.gps_used, 3);
}

TEST(LocalizationSession, ABagLoopResetsAndTheReplayLocalizesAsTheFirstPass) {
  const std::vector<DriveStep> steps = accelerateEast(100.0, 60);
  LocalizationSession session(originConfig());
  const std::vector<NavState> first = play(&session, steps);
  ASSERT_EQ(first.size(), steps.size() - 1);  // every sample after the start
  EXPECT_EQ(session.statistics().resets, 0);
  // The stream starts again from its beginning (time jumps back 6 s): reset, start over, and
  // the same data gives the same estimates.
  const std::vector<NavState> second = play(&session, steps);
  EXPECT_EQ(session.statistics().resets, 1);
  EXPECT_EQ(session.statistics().starts, 2);
  ASSERT_EQ(second.size(), first.size());
  for (std::size_t k = 0; k < second.size(); ++k) {
    EXPECT_LT((second[k].position_map - first[k].position_map).norm(), 1e-9) << k;
  }
  // The reset is reported with its cause, at the loop's second message.
  EXPECT_FALSE(session.addImu(steps[0].imu).reset);
  const LocalizationSession::Update loop = session.addImu(steps[1].imu);
  EXPECT_TRUE(loop.reset);
  EXPECT_NE(loop.note.find("time jumped back"), std::string::npos) << loop.note;
}

TEST(LocalizationSession, AfterALoopTheVelocityArrivingFirstStillServesTheStart) {
  LocalizationSession session(originConfig());
  session.addImu(restingImu(100.0));
  session.addGpsVelocity(stillAt(100.0));
  session.addFix(fixAt(100.0));
  session.addImu(restingImu(109.0));  // a jump forward, taken at its second message
  session.addImu(restingImu(109.1));
  ASSERT_TRUE(session.started());
  GpsVelocityEvent moving = stillAt(100.0);
  moving.velocity = Eigen::Vector3d(3.0, 0.0, 0.0);
  // The loop shows on the velocity first: held, it confirms the jump with the IMU and serves the
  // start.
  EXPECT_FALSE(session.addGpsVelocity(moving).reset);
  EXPECT_TRUE(session.addImu(restingImu(100.0)).reset);
  ASSERT_TRUE(session.addFix(fixAt(100.0)).started);
  EXPECT_TRUE(session.state().velocity_map.isApprox(moving.velocity));
}

TEST(LocalizationSession, ConfigReadsTheSessionSectionStrictly) {
  const LocalizationSessionConfig config =
      LocalizationSessionConfig::fromYamlFile(test::repoPath("config/inekf.yaml"));
  const LocalizationSessionConfig defaults;
  EXPECT_EQ(config.start_max_wait_s, defaults.start_max_wait_s);
  EXPECT_EQ(config.default_fix_sigma_horizontal_m, defaults.default_fix_sigma_horizontal_m);
  EXPECT_EQ(config.default_fix_sigma_vertical_m, defaults.default_fix_sigma_vertical_m);
  EXPECT_EQ(config.time_jump_back_s, defaults.time_jump_back_s);
  EXPECT_EQ(config.restart_after_imu_gap_s, defaults.restart_after_imu_gap_s);
  EXPECT_EQ(config.fix_wait_for_imu_s, defaults.fix_wait_for_imu_s);
  EXPECT_EQ(config.localizer.min_gps_sigma_m, defaults.localizer.min_gps_sigma_m);

  const std::string dir = test::makeTempDir("session_config");
  const std::string path = dir + "/bad.yaml";
  std::ofstream(path) << "filter: left\nsession:\n  time_jump_back_sec: 2.0\n";
  try {
    LocalizationSessionConfig::fromYamlFile(path);
    FAIL() << "an unknown session key was accepted";
  } catch (const std::exception& error) {
    EXPECT_NE(std::string(error.what()).find("session.time_jump_back_sec"), std::string::npos)
        << error.what();
  }
  std::ofstream(path) << "session:\n  default_fix_sigma_vertical_m: 0\n";
  EXPECT_ANY_THROW(LocalizationSessionConfig::fromYamlFile(path));
  // A restart limit within imu.max_gap_s would restart the filter at ordinary steps.
  std::ofstream(path) << "imu:\n  max_gap_s: 0.5\nsession:\n  restart_after_imu_gap_s: 0.3\n";
  try {
    LocalizationSessionConfig::fromYamlFile(path);
    ADD_FAILURE() << "a restart limit below imu.max_gap_s was accepted";
  } catch (const std::exception& error) {
    EXPECT_NE(std::string(error.what()).find("session.restart_after_imu_gap_s"), std::string::npos)
        << error.what();
  }
  // Finite but absurd values are refused with their key: the filter squares them (1e200 made
  // every state non-finite), and a heading sigma beyond 180 deg means nothing more.
  const std::pair<const char*, const char*> absurd[] = {
      {"initial_sigma:\n  rotation_deg: 1.0e200\n",
       "initial_sigma.rotation_deg' must be in (0, 180]"},
      {"imu_noise:\n  gyro_noise_density: 1.0e200\n",
       "imu_noise.gyro_noise_density' must be in (0, 1e+06]"},
      {"heading:\n  align_above_sigma_deg: 200\n", "heading.align_above_sigma_deg' must be in"},
      {"session:\n  time_jump_back_s: -2\n", "session.time_jump_back_s' must be in (0, 1e+06]"},
  };
  for (const auto& [yaml, message] : absurd) {
    std::ofstream(path) << yaml;
    try {
      LocalizationSessionConfig::fromYamlFile(path);
      ADD_FAILURE() << "accepted: " << yaml;
    } catch (const std::exception& error) {
      EXPECT_NE(std::string(error.what()).find(message), std::string::npos) << error.what();
    }
  }
  // A heading roughly known (unknown_yaw_deg 5, below the alignment's 10 deg): no alignment,
  // but the heading check still corrects it (test_localizer): a valid setup.
  std::ofstream(path) << "initial_sigma:\n  unknown_yaw_deg: 5\n";
  EXPECT_NO_THROW(LocalizationSessionConfig::fromYamlFile(path));
}

// The start's yaw sigma about the map z axis (deg).
double startYawSigmaDeg(const LocalizationSession& session) {
  const Eigen::Matrix3d& r = session.state().rotation;
  const Eigen::Matrix3d world =
      r * session.poseCovariance().bottomRightCorner<3, 3>() * r.transpose();
  return std::sqrt(world(2, 2)) * 180.0 / M_PI;
}

// An orientation is used only with the covariance its message states; where it states zeros
// (sensor_msgs: unknown) the configured sigma; no orientation: levelled, yaw unknown.
TEST(LocalizationSession, TheStartTakesTheOrientationsStatedCovarianceOrTheConfiguredSigma) {
  const double yaw_sigma_rad = 5.0 * M_PI / 180.0;
  struct Case {
    std::optional<Eigen::Matrix3d> covariance;
    bool with_orientation;
    double expected_yaw_sigma_deg;
    const char* start_note;  // what the start's note says of the sigma
  };
  const Case cases[] = {
      {Eigen::Vector3d(1e-4, 1e-4, yaw_sigma_rad * yaw_sigma_rad).asDiagonal().toDenseMatrix(),
       true, 5.0, "stated yaw sigma 5"},
      // stated as unknown: initial_sigma.yaw_deg
      {Eigen::Matrix3d::Zero(), true, 1.0, "no stated covariance"},
      {std::nullopt, true, 1.0, "no stated covariance"},
      // no orientation: initial_sigma.unknown_yaw_deg
      {std::nullopt, false, 180.0, ""},
      // Not a covariance: indefinite (made the filter's variances negative and every later fix
      // rejected), and finite but absurd (overflowed the start's covariance to NaN, which was
      // published): the configured sigma, and the note says so (it reported the stated one).
      {(Eigen::Matrix3d() << 1e-4, 1e-2, 0, 1e-2, 1e-4, 0, 0, 0, 1e-4).finished(), true, 1.0,
       "stated covariance not one"},
      {Eigen::Matrix3d::Constant(1e308), true, 1.0, "stated covariance not one"},
  };
  for (const Case& c : cases) {
    LocalizationSession session(originConfig());
    session.setGpsVelocityExpected(false);
    ImuEvent imu = restingImu(10.0, c.with_orientation);
    imu.orientation_covariance = c.covariance;
    session.addImu(imu);
    const LocalizationSession::Update start = session.addFix(fixAt(10.0));
    if (c.with_orientation) {  // without one the start waits for start_max_wait_s
      EXPECT_TRUE(start.start_estimate) << start.note;
      EXPECT_NE(start.note.find(c.start_note), std::string::npos) << start.note;
    }
    session.addImu(restingImu(10.3, c.with_orientation));
    ASSERT_TRUE(session.started());
    // Up to the 0.3 s of gyro noise propagated since the start.
    EXPECT_NEAR(startYawSigmaDeg(session), c.expected_yaw_sigma_deg,
                1e-3 * c.expected_yaw_sigma_deg);
    if (c.with_orientation) {
      const Eigen::Matrix3d error = session.state().rotation.transpose() * kHeading;
      EXPECT_LT(Eigen::AngleAxisd(error).angle(), 1e-9);
    }
  }
}

// A car on a gentle curve at 10 m/s, flat, exact IMU (sample k holds over (t_{k-1}, t_k]), and
// 1 Hz fixes with 1.5 m noise: what the heading monitor sees on a road.
struct CurveDrive {
  double t0 = 100.0, speed = 10.0, yaw0 = 2.3, yaw_rate = 0.02;
  double yaw(double t) const { return yaw0 + yaw_rate * (t - t0); }
  Eigen::Vector3d position(double t) const {
    const double r = speed / yaw_rate;
    return Eigen::Vector3d(r * (std::sin(yaw(t)) - std::sin(yaw0)),
                           -r * (std::cos(yaw(t)) - std::cos(yaw0)), 0.0);
  }
  Eigen::Matrix3d rotation(double t) const {
    return Eigen::AngleAxisd(yaw(t), Eigen::Vector3d::UnitZ()).toRotationMatrix();
  }
  Eigen::Vector3d velocity(double t) const {
    return speed * Eigen::Vector3d(std::cos(yaw(t)), std::sin(yaw(t)), 0.0);
  }
};

double wrapDeg(double deg) { return std::remainder(deg, 360.0); }

struct CurveRun {
  std::vector<std::string> heading_notes;
  double worst_yaw_error_after_deg = 0.0;  // after `settle_s`
  double worst_horizontal_error_after_m = 0.0;
  LocalizationSession::Statistics statistics;
  bool finite = true;
};

// The IMU's mounting on the car: turned by yaw_deg about the car's z axis, then pitched by
// pitch_deg about the turned y axis (-90: the board upright, its x axis up), and whether the
// session is told (setImuMounting).
struct ImuMount {
  double yaw_deg = 0.0, pitch_deg = 0.0;
  bool told = true;
  Eigen::Matrix3d baseFromImu() const {
    return (Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()) *
            Eigen::AngleAxisd(pitch_deg * M_PI / 180.0, Eigen::Vector3d::UnitY()))
        .toRotationMatrix();
  }
};

// Runs `seconds` of the drive; with_orientation: the IMU reports the truth's yaw plus
// yaw_error_deg with a stated (1 deg)^2 yaw covariance (and the GPS velocity is given).
// From outlier_at_s on, `outliers` fixes in a row are outlier_m east of the truth. The yaw
// errors are of the car (base_link).
CurveRun runCurve(double seconds, bool with_orientation, double yaw_error_deg, double settle_s,
                  int outlier_at_s = -1, int outliers = 1, double outlier_m = 100.0,
                  const ImuMount& mount = ImuMount()) {
  const CurveDrive drive;
  const kitti::MercatorProjection projection(kLat0, kLon0, kAlt0);
  LocalizationSession session(originConfig());
  session.setGpsVelocityExpected(with_orientation);
  const Eigen::Matrix3d base_from_imu = mount.baseFromImu();
  if (mount.told) {
    EXPECT_TRUE(session.setImuMounting(base_from_imu));
  }
  std::mt19937 random(7);
  std::normal_distribution<double> noise(0.0, 1.5);
  CurveRun run;
  const int steps = static_cast<int>(seconds * 10.0);
  for (int k = 0; k <= steps; ++k) {
    const double t = drive.t0 + 0.1 * k;
    ImuEvent imu;
    imu.sample.stamp_s = t;
    imu.sample.angular_velocity =
        base_from_imu.transpose() * Eigen::Vector3d(0.0, 0.0, drive.yaw_rate);
    imu.sample.specific_force =
        base_from_imu.transpose() * Eigen::Vector3d(0.0, drive.yaw_rate * drive.speed, 9.81);
    if (with_orientation) {
      imu.orientation =
          Eigen::AngleAxisd(drive.yaw(t) + yaw_error_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ())
              .toRotationMatrix() *
          base_from_imu;
      const double s = M_PI / 180.0;
      imu.orientation_covariance = Eigen::Vector3d(0.25 * s * s, 0.25 * s * s, s * s).asDiagonal();
    }
    std::vector<LocalizationSession::Update> updates{session.addImu(imu)};
    if (with_orientation) {
      GpsVelocityEvent velocity;
      velocity.stamp_s = t;
      velocity.velocity = drive.velocity(t);
      updates.push_back(session.addGpsVelocity(velocity));
    }
    if (k % 10 == 0) {
      Eigen::Vector3d p = drive.position(t) + Eigen::Vector3d(noise(random), noise(random), 0.0);
      if (outlier_at_s >= 0 && k / 10 >= outlier_at_s && k / 10 < outlier_at_s + outliers) {
        p += Eigen::Vector3d(outlier_m, 0.0, 0.0);  // a receiver jump, or multipath
      }
      GeodeticFixEvent fix;
      fix.stamp_s = t;
      projection.toGeodetic(p, &fix.lat_deg, &fix.lon_deg, &fix.alt_m);
      fix.covariance_enu = Eigen::Vector3d(2.25, 2.25, 9.0).asDiagonal();
      updates.push_back(session.addFix(fix));
    }
    for (const auto& update : updates) {
      if (update.heading_event) run.heading_notes.push_back(update.note);
    }
    if (!session.started()) continue;
    run.finite = run.finite && session.state().rotation.allFinite() &&
                 session.state().position_map.allFinite() && session.poseCovariance().allFinite();
    const Eigen::Matrix3d r = session.state().rotation * base_from_imu.transpose();
    const double yaw_error = wrapDeg((std::atan2(r(1, 0), r(0, 0)) - drive.yaw(t)) * 180.0 / M_PI);
    if (t - drive.t0 >= settle_s) {
      run.worst_yaw_error_after_deg = std::max(run.worst_yaw_error_after_deg, std::abs(yaw_error));
      run.worst_horizontal_error_after_m =
          std::max(run.worst_horizontal_error_after_m,
                   (session.state().position_map - drive.position(t)).head<2>().norm());
    }
  }
  run.statistics = session.statistics();
  return run;
}

// Found by review: an IMU without an orientation (no INS) beside a receiver publishing a
// map-frame velocity: the start (levelled from gravity after session.start_max_wait_s) dropped
// the velocity and took zero at 15 m/s. A map-frame velocity needs no orientation; a body-frame
// one does, and without one the start takes zero, not knowing it.
TEST(LocalizationSession, AMapFrameVelocityServesAStartLevelledFromGravity) {
  for (const bool in_body_frame : {false, true}) {
    SCOPED_TRACE(in_body_frame ? "body frame" : "map frame");
    LocalizationSession session(originConfig());
    GpsVelocityEvent moving = stillAt(100.0);
    moving.velocity = Eigen::Vector3d(10.0, 0.0, 0.0);
    moving.in_body_frame = in_body_frame;
    session.addImu(restingImu(100.0, false));
    session.addFix(fixAt(100.0));
    session.addGpsVelocity(moving);
    session.addImu(restingImu(100.1, false));
    EXPECT_FALSE(session.started());  // its orientation may still come, within 0.2 s
    const LocalizationSession::Update update = session.addImu(restingImu(100.3, false));
    ASSERT_TRUE(update.started) << update.note;
    EXPECT_NE(update.note.find("levelled from gravity"), std::string::npos) << update.note;
    if (in_body_frame) {
      EXPECT_EQ(session.statistics().filter.starts_without_velocity, 1);
      EXPECT_LT(session.state().velocity_map.norm(), 1e-6);
    } else {
      EXPECT_EQ(session.statistics().filter.starts_without_velocity, 0);
      EXPECT_NE(update.note.find("velocity from the GPS velocity"), std::string::npos)
          << update.note;
      // Carried on at rest on the IMU: the velocity stays what the GPS said.
      EXPECT_LT((session.state().velocity_map - moving.velocity).norm(), 1e-6);
    }
  }
}

TEST(LocalizationSession, WithoutAnOrientationTheHeadingIsAlignedFromTheGpsTrack) {
  const CurveRun run = runCurve(60.0, false, 0.0, 30.0);
  EXPECT_TRUE(run.finite);
  EXPECT_EQ(run.statistics.filter.heading_alignments, 1);
  EXPECT_EQ(run.statistics.filter.heading_recoveries, 0);
  EXPECT_EQ(run.statistics.filter.heading_reopens, 0);
  ASSERT_EQ(run.heading_notes.size(), 1u);  // logged once, with its reason
  EXPECT_NE(run.heading_notes[0].find("aligned to the GPS track"), std::string::npos)
      << run.heading_notes[0];
  EXPECT_LT(run.worst_yaw_error_after_deg, 2.0);
  EXPECT_EQ(run.statistics.filter.gps_rejected, 0);
}

// Found by review: an IMU mounted turned (90 deg: its x axis the car's left; 180: backwards), tf
// saying so. The heading monitor and the land-vehicle constraint took the IMU's x axis for the
// car's and held the heading that far off. Told the mounting, the levelled start aligns right.
// Also a board mounted upright (its x axis up).
TEST(LocalizationSession, AnImuMountedTurnedIsAlignedToTheCarsHeading) {
  for (const auto& [mount_yaw_deg, mount_pitch_deg] :
       {std::pair{90.0, 0.0}, {180.0, 0.0}, {-120.0, 0.0}, {0.0, -90.0}}) {
    SCOPED_TRACE(std::to_string(mount_yaw_deg) + " / " + std::to_string(mount_pitch_deg));
    ImuMount mount;
    mount.yaw_deg = mount_yaw_deg;
    mount.pitch_deg = mount_pitch_deg;
    const CurveRun run = runCurve(60.0, false, 0.0, 30.0, -1, 1, 100.0, mount);
    EXPECT_TRUE(run.finite);
    EXPECT_EQ(run.statistics.filter.heading_alignments, 1);
    EXPECT_EQ(run.statistics.filter.heading_recoveries, 0);
    EXPECT_LT(run.worst_yaw_error_after_deg, 2.0);
    EXPECT_LT(run.worst_horizontal_error_after_m, 3.0);
    EXPECT_GT(run.statistics.filter.nonholonomic_used, 100);
    mount.told = false;  // as before: the IMU's x axis taken as the car's
    const CurveRun untold = runCurve(60.0, false, 0.0, 30.0, -1, 1, 100.0, mount);
    EXPECT_GT(untold.worst_yaw_error_after_deg, 45.0);
  }
  LocalizationSession session(originConfig());
  EXPECT_FALSE(session.setImuMounting(2.0 * Eigen::Matrix3d::Identity()));
  EXPECT_FALSE(session.setImuMounting(-Eigen::Matrix3d::Identity()));  // a reflection
}

// A reference heading 60 / 120 / 180 deg off claiming 1 deg: the fixes disagree, the monitor
// notices (logged and counted) and the heading is right again well within a minute.
TEST(LocalizationSession, AWrongReferenceHeadingIsNoticedAndRecovered) {
  for (double error_deg : {60.0, 120.0, 180.0}) {
    const CurveRun run = runCurve(90.0, true, error_deg, 40.0);
    EXPECT_TRUE(run.finite) << error_deg;
    const auto& f = run.statistics.filter;
    EXPECT_GE(f.heading_recoveries + f.heading_reopens, 1) << error_deg;
    EXPECT_EQ(static_cast<std::int64_t>(run.heading_notes.size()) > 0, true) << error_deg;
    EXPECT_LT(run.worst_yaw_error_after_deg, 2.0) << error_deg;
    std::printf(
        "[ HEADING  ] reference %.0f deg off: %lld recoveries, %lld re-opens, worst yaw "
        "error after 40 s %.2f deg; first note: %s\n",
        error_deg, static_cast<long long>(f.heading_recoveries),
        static_cast<long long>(f.heading_reopens), run.worst_yaw_error_after_deg,
        run.heading_notes.empty() ? "" : run.heading_notes[0].c_str());
  }
}

// The simulated MEMS IMU and receiver of the robot tests below: turn-on biases of 0.3 deg/s and
// 0.1 m/s^2, white noise of 1e-3 rad/s/sqrt(Hz) and 0.02 m/s^2/sqrt(Hz) at 100 Hz; fixes of a
// horizontal sigma (vertical twice it).
class MemsSensors {
 public:
  static constexpr double kRateHz = 100.0;
  const Eigen::Vector3d gyro_bias{0.004, -0.003, 0.005}, accel_bias{0.08, -0.06, 0.1};

  explicit MemsSensors(unsigned seed) : random_(seed) {}

  // The sample of a body turning at `rate` under the specific force `force` (body axes).
  ImuEvent imu(double stamp_s, const Eigen::Vector3d& rate, const Eigen::Vector3d& force) {
    ImuEvent event;
    event.sample.stamp_s = stamp_s;
    event.sample.angular_velocity = rate + gyro_bias + 1.0e-3 * std::sqrt(kRateHz) * noise();
    event.sample.specific_force = force + accel_bias + 0.02 * std::sqrt(kRateHz) * noise();
    return event;
  }
  // A fix of the point (x, y, 0) of the map.
  GeodeticFixEvent fix(double stamp_s, double x, double y, double sigma) {
    GeodeticFixEvent event;
    event.stamp_s = stamp_s;
    const Eigen::Vector3d p(x + sigma * unit_(random_), y + sigma * unit_(random_), 0.0);
    projection_.toGeodetic(p, &event.lat_deg, &event.lon_deg, &event.alt_m);
    const double v = sigma * sigma;
    event.covariance_enu = Eigen::Vector3d(v, v, 4.0 * v).asDiagonal();
    return event;
  }

 private:
  Eigen::Vector3d noise() {
    return Eigen::Vector3d(unit_(random_), unit_(random_), unit_(random_));
  }
  std::mt19937 random_;
  std::normal_distribution<double> unit_{0.0, 1.0};
  const kitti::MercatorProjection projection_{kLat0, kLon0, kAlt0};
};

// A robot with a MEMS IMU (no orientation; turn-on biases of 0.3 deg/s and 0.1 m/s^2, white
// noise) and 1 Hz fixes of 1.5 m, weaving along a 3 min drive at 4 or 1.5 m/s (at 1.5 m/s also
// after standing a minute): the robot template (config/robot_inekf.yaml, robot.launch's default)
// learns the gyro bias and holds the heading within 3 of its sigmas; KITTI's file, made for a
// tactical-grade INS, pins the bias near zero (the heading lags the turns by degrees) and at
// 1.5 m/s never aligns the heading.
struct MemsRun {
  double worst_yaw_error_after_deg = 0.0, rms_horizontal_after_m = 0.0;
  double gyro_bias_z_error = 0.0;              // rad/s, at the end
  double worst_yaw_sigmas_after = 0.0;         // the yaw error over its sigma, after settling
  std::int64_t standstill_updates_moving = 0;  // made while the robot drove faster than 0.3 m/s
  bool finite = true;
};

struct MemsDrive {
  double speed = 4.0;         // m/s once moving
  double standstill_s = 0.0;  // at the start (then up to speed at 0.5 m/s^2)
  double fix_sigma_m = 1.5;   // horizontal, 1 Hz
  double settle_s = 60.0;     // scored from this long after the robot starts moving
};

MemsRun runMemsDrive(LocalizationSessionConfig config, const MemsDrive& drive) {
  config.origin = GeodeticOrigin{kLat0, kLon0, kAlt0};
  LocalizationSession session(config);
  session.setGpsVelocityExpected(false);
  MemsSensors sensors(5);
  const double rate_hz = MemsSensors::kRateHz, dt = 1.0 / rate_hz;
  // Yaw rate: a slow weave, 0.15 rad/s peak over a 20 s period, once moving.
  const auto moving = [&](double t) { return t >= drive.standstill_s; };
  constexpr double kAcceleration = 0.5;  // after a standstill
  const auto speed_at = [&](double t) {
    if (!moving(t)) return 0.0;
    if (drive.standstill_s <= 0.0) return drive.speed;
    return std::min(drive.speed, kAcceleration * (t - drive.standstill_s));
  };
  const auto acceleration_at = [&](double t) {
    return moving(t) && speed_at(t) < drive.speed ? kAcceleration : 0.0;
  };
  const auto yaw_rate = [&](double t) {
    return moving(t) ? 0.15 * std::sin(2.0 * M_PI * (t - drive.standstill_s) / 20.0) : 0.0;
  };
  double yaw = 0.7, x = 0.0, y = 0.0, sum_sq = 0.0;
  int scored = 0;
  MemsRun run;
  const double t0 = 100.0;
  for (int k = 0; k <= static_cast<int>((drive.standstill_s + 180.0) * rate_hz); ++k) {
    const double t = k * dt;
    const double speed = speed_at(t);
    if (k > 0) {  // the truth over (t - dt, t]
      const double w = yaw_rate(t - 0.5 * dt);
      const double mid = yaw + 0.5 * w * dt;
      const double v = speed_at(t - 0.5 * dt);
      x += v * std::cos(mid) * dt;
      y += v * std::sin(mid) * dt;
      yaw += w * dt;
    }
    const std::int64_t standstill_before = session.statistics().filter.standstill_used;
    session.addImu(sensors.imu(t0 + t, Eigen::Vector3d(0.0, 0.0, yaw_rate(t)),
                               Eigen::Vector3d(acceleration_at(t), speed * yaw_rate(t), 9.81)));
    // Faster than the template's standstill.max_speed_mps (pulling away, the first 0.1 s of
    // 0.5 m/s^2 still fits the 0.5 s window's mean: an update at 0.05 m/s is expected).
    if (speed > 0.3) {
      run.standstill_updates_moving +=
          session.statistics().filter.standstill_used - standstill_before;
    }
    if (k % 100 == 0) session.addFix(sensors.fix(t0 + t, x, y, drive.fix_sigma_m));
    if (!session.started()) continue;
    const NavState& state = session.state();
    run.finite = run.finite && state.rotation.allFinite() && state.position_map.allFinite();
    const Eigen::Matrix3d& r = state.rotation;
    const double yaw_error_deg =
        std::abs(wrapDeg((std::atan2(r(1, 0), r(0, 0)) - yaw) * 180.0 / M_PI));
    // The yaw's sigma about the map z axis (the pose covariance's rotation block, body axes).
    const Eigen::Matrix3d rotation_covariance =
        r * session.poseCovariance().bottomRightCorner<3, 3>() * r.transpose();
    const double yaw_sigma_deg = std::sqrt(rotation_covariance(2, 2)) * 180.0 / M_PI;
    if (t < drive.standstill_s + drive.settle_s) continue;
    run.worst_yaw_error_after_deg = std::max(run.worst_yaw_error_after_deg, yaw_error_deg);
    run.worst_yaw_sigmas_after =
        std::max(run.worst_yaw_sigmas_after, yaw_error_deg / std::max(1e-9, yaw_sigma_deg));
    sum_sq += (state.position_map.head<2>() - Eigen::Vector2d(x, y)).squaredNorm();
    ++scored;
  }
  run.rms_horizontal_after_m = std::sqrt(sum_sq / std::max(1, scored));
  run.gyro_bias_z_error = session.state().gyro_bias.z() - sensors.gyro_bias.z();
  return run;
}

MemsRun runMemsDrive(const std::string& config_file, const MemsDrive& drive) {
  return runMemsDrive(LocalizationSessionConfig::fromYamlFile(config_file), drive);
}

TEST(LocalizationSession, TheRobotTemplateLearnsAMemsImusBiases) {
  for (const auto& [speed, standstill_s] : {std::pair{4.0, 0.0}, {1.5, 0.0}, {1.5, 60.0}}) {
    SCOPED_TRACE(std::to_string(speed) + " m/s after standing " + std::to_string(standstill_s));
    MemsDrive drive;
    drive.speed = speed;
    drive.standstill_s = standstill_s;
    const MemsRun robot = runMemsDrive(test::repoPath("config/robot_inekf.yaml"), drive);
    const MemsRun kitti = runMemsDrive(test::repoPath("config/inekf.yaml"), drive);
    std::printf(
        "[ MEMS     ] %.1f m/s, %.0f s standing: robot template: worst yaw %.2f deg (%.1f "
        "sigma), RMS %.2f m, gyro z bias error %.4f rad/s; KITTI's file: %.2f deg, %.2f m, "
        "%.4f rad/s\n",
        speed, standstill_s, robot.worst_yaw_error_after_deg, robot.worst_yaw_sigmas_after,
        robot.rms_horizontal_after_m, robot.gyro_bias_z_error, kitti.worst_yaw_error_after_deg,
        kitti.rms_horizontal_after_m, kitti.gyro_bias_z_error);
    EXPECT_TRUE(robot.finite);
    EXPECT_TRUE(kitti.finite);
    EXPECT_LT(robot.worst_yaw_error_after_deg, 5.0);
    EXPECT_LT(robot.worst_yaw_sigmas_after, 3.0);  // the yaw sigma it publishes covers its error
    EXPECT_LT(robot.rms_horizontal_after_m, 1.5);
    EXPECT_LT(std::abs(robot.gyro_bias_z_error), 1.5e-3);
    EXPECT_EQ(robot.standstill_updates_moving, 0);  // its IMU is as quiet as standing
    // What the template is for: KITTI's values on this IMU are far worse (at 1.5 m/s its 3 m/s
    // chords never align the heading).
    EXPECT_GT(kitti.worst_yaw_error_after_deg, 2.0 * robot.worst_yaw_error_after_deg);
  }
}

// A robot weaving at 1.5 m/s without vibration: its IMU looks as still as standing, and before
// its heading aligns the filter knows its velocity only to about 0.5 m/s. The fixes' track must
// veto the standstill, also where the heading monitor is off (the track was its only user).
TEST(LocalizationSession, TheStandstillUpdatesNeverFireWhileTheRobotDrives) {
  for (const bool heading_from_track : {true, false}) {
    LocalizationSessionConfig config =
        LocalizationSessionConfig::fromYamlFile(test::repoPath("config/robot_inekf.yaml"));
    config.localizer.heading_from_track = heading_from_track;
    MemsDrive drive;
    drive.speed = 1.5;
    const MemsRun run = runMemsDrive(config, drive);
    EXPECT_TRUE(run.finite);
    EXPECT_EQ(run.standstill_updates_moving, 0) << "heading_from_track " << heading_from_track;
  }
}

// A MEMS robot (MemsSensors) on a drive of segments (duration, acceleration along its
// heading, yaw rate), fixes (1.5 m once a second unless said otherwise) outside the outages: the
// standstill updates made while it drove faster than the template's standstill.max_speed_mps
// (0.3 m/s), its worst horizontal and yaw errors from `score_from_s` on and the heading
// monitor's events, with the updates or without.
struct Segment {
  double duration_s, acceleration, yaw_rate;
};
struct SegmentRun {
  std::int64_t updates_moving = 0;
  double worst_error_m = 0.0, worst_yaw_error_deg = 0.0;
  std::vector<std::string> heading_events;
  std::int64_t wheel_speed_suspensions = 0, wheel_speeds_used = 0;
};
struct FixStream {
  int every_samples = 100;  // of the 100 Hz IMU
  double sigma_m = 1.5;     // horizontal
};
// Wheel odometry: the true speed times (1 + scale_error) plus white noise of sigma_mps, and
// slip_mps more from slip_from_s to slip_to_s (a wheel spinning on ice or gravel).
struct WheelStream {
  int every_samples = 0;  // of the 100 Hz IMU; 0: none
  double sigma_mps = 0.05, scale_error = 0.0;
  double slip_from_s = 0.0, slip_to_s = 0.0, slip_mps = 0.0;
};
SegmentRun runMemsSegments(const std::vector<Segment>& segments, double initial_speed,
                           const std::vector<std::pair<double, double>>& outages,
                           double score_from_s, bool standstill, FixStream fixes = FixStream(),
                           WheelStream wheels = WheelStream()) {
  LocalizationSessionConfig config =
      LocalizationSessionConfig::fromYamlFile(test::repoPath("config/robot_inekf.yaml"));
  config.origin = GeodeticOrigin{kLat0, kLon0, kAlt0};
  config.localizer.standstill.enabled = standstill;
  LocalizationSession session(config);
  session.setGpsVelocityExpected(false);
  MemsSensors sensors(5);
  const auto segmentAt = [&](double t) {
    for (const Segment& s : segments) {
      if (t < s.duration_s) return s;
      t -= s.duration_s;
    }
    return Segment{0.0, 0.0, 0.0};
  };
  double total_s = 0.0;
  for (const Segment& s : segments) total_s += s.duration_s;
  const double rate_hz = MemsSensors::kRateHz, dt = 1.0 / rate_hz, t0 = 100.0;
  double yaw = 0.7, x = 0.0, y = 0.0, speed = initial_speed;
  std::mt19937 random(3);  // the wheels' own noise
  std::normal_distribution<double> noise(0.0, 1.0);
  SegmentRun run;
  for (int k = 0; k <= static_cast<int>(total_s * rate_hz); ++k) {
    const double t = k * dt;
    if (k > 0) {  // the truth over (t - dt, t]
      const Segment s = segmentAt(t - 0.5 * dt);
      const double before = speed;
      speed = std::max(0.0, speed + s.acceleration * dt);
      const double mid = yaw + 0.5 * s.yaw_rate * dt;
      x += 0.5 * (before + speed) * std::cos(mid) * dt;
      y += 0.5 * (before + speed) * std::sin(mid) * dt;
      yaw += s.yaw_rate * dt;
    }
    const Segment s = segmentAt(t);
    const std::int64_t before = session.statistics().filter.standstill_used;
    std::vector<LocalizationSession::Update> updates{
        session.addImu(sensors.imu(t0 + t, Eigen::Vector3d(0.0, 0.0, s.yaw_rate),
                                   Eigen::Vector3d(s.acceleration, speed * s.yaw_rate, 9.81)))};
    if (speed > 0.3) run.updates_moving += session.statistics().filter.standstill_used - before;
    bool out = false;
    for (const auto& [from, to] : outages) out = out || (t >= from && t < to);
    if (k % fixes.every_samples == 0 && !out) {
      updates.push_back(session.addFix(sensors.fix(t0 + t, x, y, fixes.sigma_m)));
    }
    if (wheels.every_samples > 0 && k % wheels.every_samples == 0) {
      const bool slipping = t >= wheels.slip_from_s && t < wheels.slip_to_s;
      const double measured = speed * (1.0 + wheels.scale_error) +
                              wheels.sigma_mps * noise(random) + (slipping ? wheels.slip_mps : 0.0);
      updates.push_back(session.addWheelSpeed({t0 + t, measured, wheels.sigma_mps}));
    }
    for (const auto& update : updates) {
      if (update.heading_event) run.heading_events.push_back(update.note);
    }
    if (!session.started() || t < score_from_s) continue;
    const NavState& state = session.state();
    const double error = (state.position_map.head<2>() - Eigen::Vector2d(x, y)).norm();
    run.worst_error_m = std::max(run.worst_error_m, error);
    const Eigen::Matrix3d& r = state.rotation;
    run.worst_yaw_error_deg =
        std::max(run.worst_yaw_error_deg,
                 std::abs(wrapDeg((std::atan2(r(1, 0), r(0, 0)) - yaw) * 180.0 / M_PI)));
  }
  run.wheel_speed_suspensions = session.statistics().filter.wheel_speed_suspensions;
  run.wheel_speeds_used = session.statistics().filter.wheel_speed_used;
  return run;
}

// Found by reviews: an IMU as quiet driving steadily as standing, and a filter that could not
// tell its speed from zero, held robots at zero velocity while they drove: 46 m off through a
// 30 s outage at 1.5 m/s, 9 m after a stop and go at 0.8 m/s, 41 m creeping at 0.4 m/s after
// pulling away gently (its first 0.2 s of acceleration still in a quiet window); then, with the
// filter's own pinned speed confirming the standstill, 12 m after a 40 s stop left at 0.3 m/s^2.
TEST(LocalizationSession, TheStandstillUpdatesNeverHoldADrivingRobot) {
  struct Case {
    const char* name;
    std::vector<Segment> segments;
    double initial_speed;
    std::vector<std::pair<double, double>> outages;
  };
  const std::vector<Case> cases = {
      {"straight at 1.5 m/s, 30 s without fixes", {{160.0, 0.0, 0.0}}, 1.5, {{60.0, 90.0}}},
      {"stop and go at 0.8 m/s",
       {{30.0, 0.0, 0.0},
        {1.6, 0.5, 0.0},
        {60.0, 0.0, 0.05},
        {1.6, -0.5, 0.0},
        {20.0, 0.0, 0.0},
        {1.6, 0.5, 0.0},
        {40.0, 0.0, 0.0}},
       0.0,
       {}},
      {"pulling away gently to 0.4 m/s",
       {{30.0, 0.0, 0.0}, {0.8, 0.5, 0.0}, {120.0, 0.0, 0.0}},
       0.0,
       {}},
      {"a 40 s stop, then 0.3 m/s^2 to 1.5 m/s",
       {{30.0, 0.0, 0.0},
        {3.0, 0.5, 0.0},
        {60.0, 0.0, 0.05},
        {3.0, -0.5, 0.0},
        {40.0, 0.0, 0.0},
        {5.0, 0.3, 0.0},
        {30.0, 0.0, 0.0}},
       0.0,
       {}},
  };
  for (const Case& c : cases) {
    const SegmentRun with = runMemsSegments(c.segments, c.initial_speed, c.outages, 40.0, true);
    const SegmentRun without = runMemsSegments(c.segments, c.initial_speed, c.outages, 40.0, false);
    std::printf("[ MEMS     ] %s: worst error %.2f m with the standstill updates, %.2f without\n",
                c.name, with.worst_error_m, without.worst_error_m);
    EXPECT_EQ(with.updates_moving, 0) << c.name;
    EXPECT_LT(with.worst_error_m, without.worst_error_m + 1.0) << c.name;
  }
}

// Found by review: a robot with 5 Hz fixes of 0.5 m that stops. A chord of the heading monitor
// spans up to 10 s, so the chords of the stop's first seconds end at the stop, where the
// filter's velocity is noise about zero; taken as the sign of the chord's direction, it said
// half of them were driven in reverse, and once the chords from before the stop had left the
// 20 s window those turned the heading round (180 deg, 19 s into the stop).
TEST(LocalizationSession, ARobotStoppingWithFrequentFixesKeepsItsHeading) {
  for (const double speed : {1.5, 4.0, 10.0}) {
    for (const bool standstill : {true, false}) {
      const double stop_s = 4.0;  // to a stop and back to speed, each
      const std::vector<Segment> segments = {{60.0, 0.0, 0.05},
                                             {stop_s, -speed / stop_s, 0.0},
                                             {60.0, 0.0, 0.0},
                                             {stop_s, speed / stop_s, 0.0},
                                             {30.0, 0.0, 0.0}};
      const SegmentRun run =
          runMemsSegments(segments, speed, {}, 40.0, standstill, FixStream{20, 0.5});
      char name[64];
      std::snprintf(name, sizeof(name), "%.1f m/s, standstill %s", speed,
                    standstill ? "on" : "off");
      // The start's alignment, and nothing after it.
      EXPECT_EQ(run.heading_events.size(), 1u)
          << name << (run.heading_events.size() > 1 ? ": " + run.heading_events[1] : std::string());
      EXPECT_LT(run.worst_yaw_error_deg, 6.0) << name;
    }
  }
}

// Wheel odometry through a GPS outage: the MEMS robot weaving at 4 m/s, 60 s without fixes.
// Without wheel speeds the unobserved accelerometer bias and velocity error integrate to tens of
// metres; with a 20 Hz wheel speed (0.05 m/s noise) the velocity along the robot stays known and
// only the heading's drift remains. Found by review: wheels 3 % off scale (a tyre's radius) taken
// as noise made the filter sure of a wrong speed: the returning fixes failed the gate, the
// heading was re-opened and realigned 81 deg off (now scale_sigma and min_interval_s: no event).
TEST(LocalizationSession, WheelSpeedsHoldAMemsRobotThroughAGpsOutage) {
  const std::vector<Segment> segments = {
      {60.0, 0.0, 0.1}, {20.0, 0.0, -0.1}, {40.0, 0.0, 0.05}, {40.0, 0.0, -0.05}};
  const std::vector<std::pair<double, double>> outage = {{90.0, 150.0}};
  const SegmentRun without = runMemsSegments(segments, 4.0, outage, 90.0, true);
  const SegmentRun with =
      runMemsSegments(segments, 4.0, outage, 90.0, true, FixStream(), WheelStream{5, 0.05, 0.0});
  const SegmentRun scaled =
      runMemsSegments(segments, 4.0, outage, 90.0, true, FixStream(), WheelStream{5, 0.05, 0.03});
  std::printf(
      "[ MEMS     ] 60 s outage at 4 m/s: worst error %.2f m without wheel speeds, %.2f with, "
      "%.2f (yaw %.1f deg) with 3 %% scale error\n",
      without.worst_error_m, with.worst_error_m, scaled.worst_error_m, scaled.worst_yaw_error_deg);
  EXPECT_GT(without.worst_error_m, 20.0);
  EXPECT_LT(with.worst_error_m, 0.25 * without.worst_error_m);
  EXPECT_LT(with.worst_yaw_error_deg, 5.0);
  EXPECT_LT(scaled.worst_error_m, 0.5 * without.worst_error_m);
  EXPECT_LT(scaled.worst_yaw_error_deg, 5.0);
  EXPECT_EQ(scaled.heading_events.size(), 1u)  // the start's alignment only
      << (scaled.heading_events.size() > 1 ? scaled.heading_events[1] : std::string());
}

// Found by review: a wheel slipping 1 m/s fast for 5 s inside an outage. Its speeds were rejected
// until the filter's sigma had grown, then taken, then the true speeds rejected: 34 m off, a
// heading re-open after it. Now each speed is gated on its own sigma (not the weaker one a speed
// of a fast stream is applied with), and five in a row rejected suspend them until a fix is
// accepted or five in a row agree with the filter again: better than without wheels.
TEST(LocalizationSession, ASlippingWheelIsSuspendedUntilItAgreesAgain) {
  const std::vector<Segment> segments = {
      {60.0, 0.0, 0.1}, {20.0, 0.0, -0.1}, {40.0, 0.0, 0.05}, {40.0, 0.0, -0.05}};
  const std::vector<std::pair<double, double>> outage = {{55.0, 115.0}};
  const SegmentRun without = runMemsSegments(segments, 4.0, outage, 55.0, true);
  WheelStream slipping{5, 0.05, 0.0};
  slipping.slip_from_s = 60.0;
  slipping.slip_to_s = 65.0;
  for (const double slip : {1.0, 3.0}) {
    slipping.slip_mps = slip;
    const SegmentRun run =
        runMemsSegments(segments, 4.0, outage, 55.0, true, FixStream(), slipping);
    std::printf(
        "[ MEMS     ] a %.0f m/s slip for 5 s in a 60 s outage: worst error %.2f m (%.2f "
        "without wheels)\n",
        slip, run.worst_error_m, without.worst_error_m);
    EXPECT_LT(run.worst_error_m, without.worst_error_m) << slip;
    EXPECT_EQ(run.heading_events.size(), 1u)
        << slip << (run.heading_events.size() > 1 ? ": " + run.heading_events[1] : std::string());
    EXPECT_GE(run.wheel_speed_suspensions, 1) << slip;
  }
}

// Found by review: wheels whose sign is wrong (an encoder wired reversed; or a robot backing out
// against a heading the track aligned forwards) on a robot at 1.5 m/s. After each alignment or
// re-open the filter's velocity sigma is 1 m/s: a -1.5 m/s speed passed the gate, turned the
// filter's velocity round and agreed with it from then on (25-35 heading re-opens in 150 s,
// 17-19 m off). Now after each of these the wheels' sign is checked against the filter's speed
// before they are taken: never here, as if there were no wheels.
TEST(LocalizationSession, WheelsWithTheWrongSignAreNeverTaken) {
  const std::vector<Segment> segments = {{60.0, 0.0, 0.05}, {60.0, 0.0, -0.05}, {30.0, 0.0, 0.0}};
  const SegmentRun without = runMemsSegments(segments, 1.5, {}, 40.0, true);
  WheelStream reversed{2, 0.05, -2.0};  // -1 times the speed, 50 Hz
  const SegmentRun run = runMemsSegments(segments, 1.5, {}, 40.0, true, FixStream(), reversed);
  std::printf(
      "[ MEMS     ] reversed wheels at 1.5 m/s: worst error %.2f m (%.2f without wheels), "
      "%zu heading events, %lld wheel speeds used\n",
      run.worst_error_m, without.worst_error_m, run.heading_events.size(),
      static_cast<long long>(run.wheel_speeds_used));
  EXPECT_EQ(run.heading_events.size(), 1u)
      << (run.heading_events.size() > 1 ? run.heading_events[1] : std::string());
  EXPECT_LT(run.worst_error_m, without.worst_error_m + 0.5);
  EXPECT_EQ(run.wheel_speeds_used, 0);
}

// A MEMS robot (MemsSensors) standing still for 2.5 min: fixes of
// 1.5 m once a second for the first 30 s, then none for 2 min (a garage, a covered yard). With
// the template's standstill updates it stays where it stands and learns its gyro bias (nothing
// else observes it before the robot drives); without them the accelerometer's bias, which tilt
// hides at rest, walks the position away and the heading turns with the unlearnt gyro bias.
struct MemsStand {
  double drift_m = 0.0;            // horizontal, at the end
  double yaw_change_deg = 0.0;     // over the outage (the truth does not turn)
  double gyro_bias_z_error = 0.0;  // rad/s, at the end
  double yaw_sigma_deg = 0.0;      // about the map z axis, at the end
  std::int64_t standstill_updates = 0;
  bool finite = true;
};

MemsStand runMemsStand(LocalizationSessionConfig config) {
  config.origin = GeodeticOrigin{kLat0, kLon0, kAlt0};
  LocalizationSession session(config);
  session.setGpsVelocityExpected(false);
  MemsSensors sensors(8);
  const double rate_hz = MemsSensors::kRateHz, t0 = 100.0, outage_from_s = 30.0;
  MemsStand stand;
  double yaw_at_outage = kNaN;
  const auto yawOf = [](const Eigen::Matrix3d& r) { return std::atan2(r(1, 0), r(0, 0)); };
  for (int k = 0; k <= static_cast<int>(150.0 * rate_hz); ++k) {
    const double t = k / rate_hz;
    session.addImu(sensors.imu(t0 + t, Eigen::Vector3d::Zero(), Eigen::Vector3d(0.0, 0.0, 9.81)));
    if (k % 100 == 0 && t < outage_from_s) session.addFix(sensors.fix(t0 + t, 0.0, 0.0, 1.5));
    if (!session.started()) continue;
    const NavState& state = session.state();
    stand.finite = stand.finite && state.rotation.allFinite() && state.position_map.allFinite();
    if (std::isnan(yaw_at_outage) && t >= outage_from_s) yaw_at_outage = yawOf(state.rotation);
  }
  const NavState& state = session.state();
  stand.drift_m = state.position_map.head<2>().norm();
  stand.yaw_change_deg = std::abs(wrapDeg((yawOf(state.rotation) - yaw_at_outage) * 180.0 / M_PI));
  stand.gyro_bias_z_error = state.gyro_bias.z() - sensors.gyro_bias.z();
  const Eigen::Matrix3d rotation_covariance = state.rotation *
                                              session.poseCovariance().bottomRightCorner<3, 3>() *
                                              state.rotation.transpose();
  stand.yaw_sigma_deg = std::sqrt(rotation_covariance(2, 2)) * 180.0 / M_PI;
  stand.standstill_updates = session.statistics().filter.standstill_used;
  return stand;
}

TEST(LocalizationSession, AMemsRobotStandingWithoutFixesStaysPutAndLearnsItsGyroBias) {
  LocalizationSessionConfig config =
      LocalizationSessionConfig::fromYamlFile(test::repoPath("config/robot_inekf.yaml"));
  ASSERT_TRUE(config.localizer.standstill.enabled);  // the template's
  const MemsStand with = runMemsStand(config);
  config.localizer.standstill.enabled = false;
  const MemsStand without = runMemsStand(config);
  std::printf(
      "[ MEMS     ] standing 2 min without fixes: with standstill updates (%lld) drift %.2f m, "
      "yaw turned %.2f deg, gyro z bias error %.5f rad/s, yaw sigma %.1f deg; without: %.2f m, "
      "%.2f deg, %.5f rad/s, %.1f deg\n",
      static_cast<long long>(with.standstill_updates), with.drift_m, with.yaw_change_deg,
      with.gyro_bias_z_error, with.yaw_sigma_deg, without.drift_m, without.yaw_change_deg,
      without.gyro_bias_z_error, without.yaw_sigma_deg);
  EXPECT_TRUE(with.finite);
  EXPECT_TRUE(without.finite);
  EXPECT_GT(with.standstill_updates, 1000);  // about 10 per second once still
  EXPECT_LT(with.drift_m, 2.0);              // the fixes' noise at the outage's start
  EXPECT_LT(with.yaw_change_deg, 1.0);
  EXPECT_LT(std::abs(with.gyro_bias_z_error), 2e-4);
  // Standing shows nothing of the heading: the updates must not claim one (linearised at the
  // estimate's velocity and with the yaw in them, they took its sigma to 2.6 deg), or the
  // land-vehicle constraint would hold whatever heading the robot happened to have.
  EXPECT_GT(with.yaw_sigma_deg, 10.0);
  EXPECT_EQ(without.standstill_updates, 0);
  EXPECT_GT(without.drift_m, 5.0 * with.drift_m);
  EXPECT_GT(without.yaw_change_deg, 10.0 * with.yaw_change_deg);
}

// A car that drives forward 20 s at 8 m/s east-north-east, stops, and reverses 33 s at 5 m/s
// (165 m; the heading monitor's 20 s window fills with chords pointing backwards). The IMU gives
// the true yaw (1 deg). Found by review: the track's chords (a land vehicle drives forward) said
// the heading was 180 deg off and the check turned it round.
TEST(LocalizationSession, ACarReversingKeepsItsHeading) {
  const double t0 = 100.0, yaw = 0.4;
  const kitti::MercatorProjection projection(kLat0, kLon0, kAlt0);
  const Eigen::Vector3d forward(std::cos(yaw), std::sin(yaw), 0.0);
  const Eigen::Matrix3d rotation = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).matrix();
  const auto acceleration = [](double t) {  // along the car's x axis, over (t - 0.1, t]
    if (t > 20.0 + 1e-9 && t <= 24.0 + 1e-9) return -2.0;        // 8 m/s to a stop
    if (t > 24.0 + 1e-9 && t <= 27.0 + 1e-9) return -5.0 / 3.0;  // to 5 m/s backwards
    return 0.0;
  };
  LocalizationSession session(originConfig());
  std::mt19937 random(11);
  std::normal_distribution<double> noise(0.0, 1.5);
  double speed = 8.0, along = 0.0, worst_yaw_error_deg = 0.0;
  std::vector<std::string> heading_notes;
  for (int k = 0; k <= 600; ++k) {
    const double t = 0.1 * k;
    if (k > 0) {
      const double a = acceleration(t);
      along += speed * 0.1 + 0.5 * a * 0.01;
      speed += a * 0.1;
    }
    ImuEvent imu;
    imu.sample.stamp_s = t0 + t;
    imu.sample.specific_force = Eigen::Vector3d(acceleration(t), 0.0, 9.81);
    imu.orientation = rotation;
    const double s = M_PI / 180.0;
    imu.orientation_covariance = Eigen::Vector3d(0.25 * s * s, 0.25 * s * s, s * s).asDiagonal();
    std::vector<LocalizationSession::Update> updates{session.addImu(imu)};
    GpsVelocityEvent velocity;
    velocity.stamp_s = t0 + t;
    velocity.velocity = speed * forward;
    updates.push_back(session.addGpsVelocity(velocity));
    if (k % 10 == 0) {
      const Eigen::Vector3d p =
          along * forward + Eigen::Vector3d(noise(random), noise(random), 0.0);
      GeodeticFixEvent fix;
      fix.stamp_s = t0 + t;
      projection.toGeodetic(p, &fix.lat_deg, &fix.lon_deg, &fix.alt_m);
      fix.covariance_enu = Eigen::Vector3d(2.25, 2.25, 9.0).asDiagonal();
      updates.push_back(session.addFix(fix));
    }
    for (const auto& update : updates) {
      if (update.heading_event) heading_notes.push_back(update.note);
    }
    if (!session.started()) continue;
    const Eigen::Matrix3d& r = session.state().rotation;
    worst_yaw_error_deg =
        std::max(worst_yaw_error_deg,
                 std::abs(wrapDeg((std::atan2(r(1, 0), r(0, 0)) - yaw) * 180.0 / M_PI)));
  }
  ASSERT_LT(speed, -4.9);
  const auto& f = session.statistics().filter;
  EXPECT_EQ(f.heading_recoveries + f.heading_reopens, 0)
      << (heading_notes.empty() ? "" : heading_notes.front());
  EXPECT_LT(worst_yaw_error_deg, 2.0);
  EXPECT_LT((session.state().position_map - along * forward).head<2>().norm(), 3.0);
}

// A real outlier is still rejected and touches neither the heading nor the monitor.
TEST(LocalizationSession, AHundredMetreJumpIsRejectedAndTheHeadingKept) {
  const CurveRun run = runCurve(60.0, true, 0.0, 0.0, 30);
  EXPECT_EQ(run.statistics.filter.gps_rejected, 1);
  EXPECT_EQ(run.statistics.filter.heading_recoveries, 0);
  EXPECT_EQ(run.statistics.filter.heading_reopens, 0);
  EXPECT_TRUE(run.heading_notes.empty());
  EXPECT_LT(run.worst_yaw_error_after_deg, 1.0);
}

// Found by review: two 30 m multipath fixes in a row. Both were counted in the heading monitor's
// NIS window (clipped at the gate), its mean passed 6, the heading was re-opened and the second
// outlier applied: a 25 m jump. Gated-out fixes are the rejected-in-a-row count's to judge.
TEST(LocalizationSession, TwoOutliersInARowAreRejectedAndTheHeadingKept) {
  const CurveRun run = runCurve(60.0, true, 0.0, 10.0, 30, 2, 30.0);
  EXPECT_EQ(run.statistics.filter.gps_rejected, 2);
  EXPECT_EQ(run.statistics.filter.heading_reopens, 0);
  EXPECT_TRUE(run.heading_notes.empty()) << run.heading_notes.front();
  EXPECT_LT(run.worst_yaw_error_after_deg, 1.0);
  EXPECT_LT(run.worst_horizontal_error_after_m, 5.0);
}

}  // namespace
}  // namespace estimation
}  // namespace inekf_semantic_mapping
