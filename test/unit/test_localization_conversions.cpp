// inekf_node's message conversions (src/ros/localization_conversions.cpp).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <limits>

#include "inekf_semantic_mapping/ros/kitti_bag_conventions.h"
#include "inekf_semantic_mapping/ros/localization_conversions.h"
#include "inekf_semantic_mapping/ros/localization_diagnostics.h"
#include "inekf_semantic_mapping/ros/names.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

Eigen::Matrix3d yawRotation(double yaw) {
  return Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
}

Eigen::Matrix<double, 6, 6> asMatrix(const std::array<double, 36>& values) {
  return Eigen::Map<const Eigen::Matrix<double, 6, 6, Eigen::RowMajor>>(values.data());
}

TEST(RosPoseCovariance, RotationBlockIsExpressedAboutTheMapAxes) {
  // Heading north (yaw 90 deg): the body x axis is the map y axis, body y is map -x.
  estimation::PoseCovariance body = estimation::PoseCovariance::Zero();
  body.topLeftCorner<3, 3>() = Eigen::Vector3d(1.0, 2.0, 3.0).asDiagonal();
  body.bottomRightCorner<3, 3>() = Eigen::Vector3d(0.01, 0.04, 0.09).asDiagonal();
  body(0, 3) = body(3, 0) = 0.05;  // position x with the body-x rotation (roll)
  const Eigen::Matrix<double, 6, 6> ros = asMatrix(rosPoseCovariance(yawRotation(M_PI / 2), body));

  const Eigen::Matrix3d position_block = ros.topLeftCorner<3, 3>();
  EXPECT_TRUE(position_block.isApprox(body.topLeftCorner(3, 3)));
  EXPECT_NEAR(ros(3, 3), 0.04, 1e-12);  // about map x = about body -y
  EXPECT_NEAR(ros(4, 4), 0.01, 1e-12);  // about map y = about body x
  EXPECT_NEAR(ros(5, 5), 0.09, 1e-12);
  EXPECT_NEAR(ros(0, 4), 0.05, 1e-12);  // the roll correlation moved to the map-y rotation
  EXPECT_NEAR(ros(0, 3), 0.0, 1e-12);
  EXPECT_TRUE(ros.isApprox(ros.transpose()));
}

TEST(RosPoseCovariance, MatchesTheFirstOrderMapErrorOfSampledBodyErrors) {
  // R Exp(delta) = Exp(R delta) R: a body error delta is the map error R delta.
  const Eigen::Matrix3d rotation =
      (Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized())).toRotationMatrix();
  estimation::PoseCovariance body = estimation::PoseCovariance::Identity() * 1e-4;
  body(3, 4) = body(4, 3) = 5e-5;
  const Eigen::Matrix<double, 6, 6> ros = asMatrix(rosPoseCovariance(rotation, body));
  const Eigen::Vector3d delta(1e-3, -2e-3, 0.5e-3);
  const Eigen::Matrix3d perturbed =
      rotation * Eigen::AngleAxisd(delta.norm(), delta.normalized()).toRotationMatrix();
  const Eigen::AngleAxisd map_error(perturbed * rotation.transpose());
  EXPECT_TRUE((map_error.angle() * map_error.axis()).isApprox(rotation * delta, 1e-6));
  const Eigen::Matrix3d rotation_block = ros.bottomRightCorner(3, 3);
  const Eigen::Matrix3d expected = rotation * body.bottomRightCorner(3, 3) * rotation.transpose();
  EXPECT_TRUE(rotation_block.isApprox(expected));
}

TEST(FixCovariance, KeepsTheReceiversCovarianceUnfloored) {
  sensor_msgs::NavSatFix fix;
  fix.position_covariance = {0.01, 0.002, 0, 0.002, 4.0, 0, 0, 0, 9.0};
  fix.position_covariance_type = sensor_msgs::NavSatFix::COVARIANCE_TYPE_KNOWN;
  const auto covariance = fixCovarianceEnu(fix);
  ASSERT_TRUE(covariance.has_value());
  EXPECT_NEAR((*covariance)(0, 0), 0.01, 1e-12);  // the Localizer floors it, once
  EXPECT_NEAR((*covariance)(1, 1), 4.0, 1e-12);
  EXPECT_NEAR((*covariance)(0, 1), 0.002, 1e-12);
  EXPECT_NEAR(fixEvent(fix).covariance_enu->coeff(2, 2), 9.0, 1e-12);
}

TEST(FixCovariance, UnknownOrNonFiniteCovarianceIsNone) {
  sensor_msgs::NavSatFix fix;
  fix.position_covariance_type = sensor_msgs::NavSatFix::COVARIANCE_TYPE_UNKNOWN;
  fix.position_covariance = {4, 0, 0, 0, 4, 0, 0, 0, 4};
  EXPECT_FALSE(fixCovarianceEnu(fix).has_value());
  fix.position_covariance_type = sensor_msgs::NavSatFix::COVARIANCE_TYPE_DIAGONAL_KNOWN;
  EXPECT_TRUE(fixCovarianceEnu(fix).has_value());
  fix.position_covariance[4] = kNaN;
  EXPECT_FALSE(fixCovarianceEnu(fix).has_value());
}

TEST(FixEvent, CarriesTheFixAndWhetherItIsASolution) {
  sensor_msgs::NavSatFix fix;
  fix.header.stamp = ros::Time(12, 500000000);
  fix.latitude = 49.0;
  fix.longitude = 8.4;
  fix.altitude = 110.0;
  fix.status.status = sensor_msgs::NavSatStatus::STATUS_FIX;
  estimation::GeodeticFixEvent event = fixEvent(fix);
  EXPECT_DOUBLE_EQ(event.stamp_s, 12.5);
  EXPECT_DOUBLE_EQ(event.lat_deg, 49.0);
  EXPECT_DOUBLE_EQ(event.alt_m, 110.0);
  EXPECT_TRUE(event.has_solution);
  EXPECT_FALSE(event.covariance_enu.has_value());
  fix.status.status = sensor_msgs::NavSatStatus::STATUS_NO_FIX;
  EXPECT_FALSE(fixEvent(fix).has_solution);
  // A solution with a value off the map projection goes to the session, which says why it is
  // ignored (LocalizationSession.MapOriginIsTheFirstUsableFixUnlessConfigured).
  fix.status.status = sensor_msgs::NavSatStatus::STATUS_FIX;
  fix.latitude = 95.0;
  EXPECT_TRUE(fixEvent(fix).has_solution);
  EXPECT_DOUBLE_EQ(fixEvent(fix).lat_deg, 95.0);
}

TEST(UsableFix, RejectsNoFixAndNaN) {
  sensor_msgs::NavSatFix fix;
  fix.latitude = 49.0;
  fix.longitude = 8.4;
  fix.altitude = 110.0;
  fix.status.status = sensor_msgs::NavSatStatus::STATUS_FIX;
  EXPECT_TRUE(isUsableFix(fix));
  fix.status.status = sensor_msgs::NavSatStatus::STATUS_NO_FIX;
  EXPECT_FALSE(isUsableFix(fix));
  fix.status.status = sensor_msgs::NavSatStatus::STATUS_GBAS_FIX;
  fix.longitude = kNaN;
  EXPECT_FALSE(isUsableFix(fix));
  fix.longitude = 8.4;
  fix.latitude = 90.0;  // the Mercator projection's pole
  EXPECT_FALSE(isUsableFix(fix));
  fix.latitude = 49.0;
  fix.longitude = 181.0;
  EXPECT_FALSE(isUsableFix(fix));
}

TEST(SessionParameters, AnOriginOffTheProjectionIsAnErrorNamingTheParameter) {
  const auto error = [](const std::string& yaml) {
    common::YamlReader reader("ROS parameters of /inekf_node", YAML::Load(yaml));
    std::string config_file;
    try {
      sessionConfigFromParameters(&reader, "/nonexistent/inekf.yaml", &config_file);
    } catch (const common::ConfigError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_EQ(error("{origin_lat: 49.0, origin_lon: 8.4, origin_alt: 110}"), "no error");
  EXPECT_NE(error("{origin_lat: 95.0, origin_lon: 8.4, origin_alt: 110}").find("origin_lat"),
            std::string::npos);
  EXPECT_NE(error("{origin_lat: 49.0, origin_lon: 200, origin_alt: 110}").find("origin_lon"),
            std::string::npos);
}

// The origin an earlier run of the node kept on the parameter server: resumed unless one is
// configured (a strict reader that refused the key would have stopped the restarted node).
TEST(SessionParameters, AnEarlierRunsOriginIsReadForAResumeUnlessOneIsConfigured) {
  const auto config = [](const std::string& yaml) {
    common::YamlReader reader("ROS parameters of /inekf_node", YAML::Load(yaml));
    std::string config_file;
    estimation::LocalizationSessionConfig read =
        sessionConfigFromParameters(&reader, "/nonexistent/inekf.yaml", &config_file);
    reader.rejectUnknown();
    return read;
  };
  const auto resumed = config("{map_origin_in_use: {lat: 49.0, lon: 8.4, alt: 110}}");
  ASSERT_TRUE(resumed.resume_origin);
  EXPECT_EQ(resumed.resume_origin->lon_deg, 8.4);
  EXPECT_FALSE(resumed.origin);
  const auto configured = config(
      "{origin_lat: 48.0, origin_lon: 8.0, origin_alt: 100, map_origin_in_use: {lat: 49.0, lon: "
      "8.4, alt: 110}}");
  EXPECT_FALSE(configured.resume_origin);
  ASSERT_TRUE(configured.origin);
  EXPECT_EQ(configured.origin->lat_deg, 48.0);
}

TEST(Velocity, MapFrameOrBodyFrameByFrameId) {
  geometry_msgs::TwistStamped message;
  message.header.stamp = ros::Time(12, 500000000);
  message.twist.linear.x = 10.0;
  message.header.frame_id = "map";
  auto velocity = gpsVelocity(message);
  ASSERT_TRUE(velocity.has_value());
  EXPECT_EQ(velocity->velocity, Eigen::Vector3d(10, 0, 0));
  EXPECT_FALSE(velocity->in_body_frame);
  EXPECT_DOUBLE_EQ(velocity->stamp_s, 12.5);
  message.header.frame_id = "imu_link";  // kitti2bag: vf, vl, vu
  velocity = gpsVelocity(message);
  ASSERT_TRUE(velocity.has_value());
  EXPECT_TRUE(velocity->in_body_frame);
  message.twist.linear.y = kNaN;
  EXPECT_FALSE(gpsVelocity(message).has_value());
}

// nav_msgs/Odometry's twist is in its child frame: the speed is along base_link's x axis, turned
// from the child frame's, its variance along that axis from the twist covariance.
TEST(WheelOdometry, ForwardSpeedAlongBaseLinkAndItsVariance) {
  nav_msgs::Odometry message;
  message.header.stamp = ros::Time(20, 250000000);
  message.twist.twist.linear.x = 3.0;
  message.twist.twist.linear.y = 0.4;
  message.twist.covariance[0] = 0.01;  // x
  message.twist.covariance[7] = 0.04;  // y
  auto speed = wheelSpeed(message, Eigen::Matrix3d::Identity());
  ASSERT_TRUE(speed.has_value());
  EXPECT_DOUBLE_EQ(speed->stamp_s, 20.25);
  EXPECT_DOUBLE_EQ(speed->speed_mps, 3.0);
  EXPECT_DOUBLE_EQ(speed->sigma_mps, 0.1);
  // A child frame turned -90 deg about base_link's z (its y axis is base_link's x): the speed
  // and the variance are its y's.
  const Eigen::Matrix3d base_from_child = yawRotation(-M_PI / 2.0);
  speed = wheelSpeed(message, base_from_child);
  ASSERT_TRUE(speed.has_value());
  EXPECT_NEAR(speed->speed_mps, 0.4, 1e-12);
  EXPECT_NEAR(speed->sigma_mps, 0.2, 1e-12);
  // No variance stated: NaN (the session's default sigma applies); a NaN velocity: none.
  message.twist.covariance[0] = 0.0;
  EXPECT_TRUE(std::isnan(wheelSpeed(message, Eigen::Matrix3d::Identity())->sigma_mps));
  message.twist.twist.linear.z = kNaN;
  EXPECT_FALSE(wheelSpeed(message, Eigen::Matrix3d::Identity()).has_value());
}

TEST(Imu, SampleAndOrientation) {
  sensor_msgs::Imu message;
  message.header.stamp = ros::Time(1317386425, 663884440);
  message.angular_velocity.z = 0.1;
  message.linear_acceleration.z = 9.8;
  message.orientation.w = std::cos(0.25);
  message.orientation.z = std::sin(0.25);  // yaw 0.5 rad
  const auto sample = imuSampleFromMessage(message);
  ASSERT_TRUE(sample.has_value());
  EXPECT_NEAR(sample->stamp_s, 1317386425.663884440, 1e-6);
  EXPECT_DOUBLE_EQ(sample->angular_velocity.z(), 0.1);
  EXPECT_DOUBLE_EQ(sample->specific_force.z(), 9.8);
  const auto orientation = imuOrientation(message);
  ASSERT_TRUE(orientation.has_value());
  EXPECT_TRUE(orientation->isApprox(yawRotation(0.5), 1e-12));

  message.orientation_covariance[0] = -1.0;  // sensor_msgs/Imu: "no orientation"
  EXPECT_FALSE(imuOrientation(message).has_value());
  message.orientation_covariance[0] = 0.0;
  message.orientation.w = message.orientation.z = 0.0;
  EXPECT_FALSE(imuOrientation(message).has_value());
  message.linear_acceleration.x = kNaN;
  EXPECT_FALSE(imuSampleFromMessage(message).has_value());
  // The session's event is unfiltered: the session counts the invalid sample.
  EXPECT_TRUE(std::isnan(imuEvent(message).sample.specific_force.x()));
}

TEST(Odometry, TwistIsInTheBodyFrameAndBiasCorrected) {
  estimation::NavState state;
  state.rotation = yawRotation(M_PI / 2);
  state.velocity_map = Eigen::Vector3d(0.0, 5.0, 0.0);  // driving north, forward
  state.position_map = Eigen::Vector3d(1.0, 2.0, 3.0);
  state.gyro_bias = Eigen::Vector3d(0.0, 0.0, 0.01);
  nav_msgs::Odometry odometry;
  estimation::LocalizationSession::Estimate estimate{state, estimation::PoseCovariance::Identity(),
                                                     estimation::TwistCovariance::Zero()};
  estimate.twist_covariance(0, 3) = estimate.twist_covariance(3, 0) = 0.25;
  estimate.twist_covariance(5, 5) = 0.5;
  fillOdometry(estimate, Eigen::Vector3d(0, 0, 0.11), &odometry);
  EXPECT_NEAR(odometry.twist.twist.linear.x, 5.0, 1e-12);
  EXPECT_NEAR(odometry.twist.twist.linear.y, 0.0, 1e-12);
  EXPECT_NEAR(odometry.twist.twist.angular.z, 0.10, 1e-12);
  EXPECT_DOUBLE_EQ(odometry.pose.pose.position.z, 3.0);
  EXPECT_NEAR(odometry.pose.pose.orientation.z, std::sin(M_PI / 4), 1e-12);
  EXPECT_NEAR(odometry.pose.covariance[0], 1.0, 1e-12);
  // The twist covariance row-major, as given (it was all zero: "perfectly known" to a consumer).
  EXPECT_EQ(odometry.twist.covariance[3], 0.25);
  EXPECT_EQ(odometry.twist.covariance[18], 0.25);
  EXPECT_EQ(odometry.twist.covariance[35], 0.5);

  EXPECT_TRUE(isFinite(state, estimation::PoseCovariance::Identity()));
  state.position_map.x() = kNaN;
  EXPECT_FALSE(isFinite(state, estimation::PoseCovariance::Identity()));
}

TEST(Path, KeepsTheNewestPosesTrimmedInChunks) {
  nav_msgs::Path path;
  nav_msgs::Odometry odometry;
  for (int k = 0; k < 11; ++k) {
    odometry.pose.pose.position.x = k;
    appendToPath(odometry, 10, &path);
  }
  EXPECT_EQ(path.poses.size(), 11u);  // within the chunk of 10 % above the limit
  odometry.pose.pose.position.x = 11;
  appendToPath(odometry, 10, &path);
  ASSERT_EQ(path.poses.size(), 10u);
  EXPECT_DOUBLE_EQ(path.poses.back().pose.position.x, 11.0);
}

TEST(Transform, IsTheOdometrysPoseBetweenItsFrames) {
  nav_msgs::Odometry odometry;
  odometry.header.frame_id = "map";
  odometry.child_frame_id = "base_link";
  odometry.pose.pose.position.y = 2.0;
  odometry.pose.pose.orientation.w = 1.0;
  const geometry_msgs::TransformStamped transform = transformOfOdometry(odometry);
  EXPECT_EQ(transform.header.frame_id, "map");
  EXPECT_EQ(transform.child_frame_id, "base_link");
  EXPECT_DOUBLE_EQ(transform.transform.translation.y, 2.0);
  EXPECT_DOUBLE_EQ(transform.transform.rotation.w, 1.0);
}

// With a wheel odometry publishing odom -> base_link, the filter publishes map -> odom: the chain
// map -> odom -> base_link is the filter's pose of base_link (REP-105), whatever odom says.
TEST(Transform, MapToOdomComposesWithOdomToBaseIntoTheOdometrysPose) {
  nav_msgs::Odometry odometry;
  odometry.header.frame_id = "map";
  odometry.header.stamp = ros::Time(12.5);
  odometry.child_frame_id = "base_link";
  const Eigen::Quaterniond map_yaw(Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()));
  odometry.pose.pose.position.x = 10.0;
  odometry.pose.pose.position.y = -4.0;
  odometry.pose.pose.position.z = 0.5;
  odometry.pose.pose.orientation.w = map_yaw.w();
  odometry.pose.pose.orientation.z = map_yaw.z();
  Eigen::Isometry3d T_odom_base = Eigen::Isometry3d::Identity();
  T_odom_base.translate(Eigen::Vector3d(3.0, 1.0, 0.0));
  T_odom_base.rotate(Eigen::AngleAxisd(-0.4, Eigen::Vector3d::UnitZ()));
  const geometry_msgs::TransformStamped map_odom =
      mapToOdomTransform(odometry, T_odom_base, "odom");
  EXPECT_EQ(map_odom.header.frame_id, "map");
  EXPECT_EQ(map_odom.child_frame_id, "odom");
  EXPECT_EQ(map_odom.header.stamp, ros::Time(12.5));
  const Eigen::Isometry3d T_map_base = toIsometry(map_odom.transform) * T_odom_base;
  EXPECT_TRUE(T_map_base.translation().isApprox(Eigen::Vector3d(10.0, -4.0, 0.5), 1e-12));
  EXPECT_TRUE(Eigen::Quaterniond(T_map_base.rotation()).isApprox(map_yaw, 1e-12));
}

TEST(FilterStatus, CountsTheSessionsDropsWithTheFiltersOwn) {
  estimation::LocalizationSession session{estimation::LocalizationSessionConfig()};
  estimation::ImuEvent bad;
  bad.sample.specific_force.x() = kNaN;
  session.addImu(bad);
  estimation::GeodeticFixEvent no_fix;
  no_fix.has_solution = false;
  session.addFix(no_fix);
  const FilterStatus status = filterStatus(session);
  EXPECT_EQ(status.filter_type, "left");  // the name of the filter parameter and config key
  EXPECT_EQ(status.imu_samples_dropped, 1u);
  EXPECT_EQ(status.gps_fixes_rejected, 1u);
  EXPECT_EQ(status.gps_fixes_used, 0u);
}

// inekf_node's /diagnostics: IMU without fixes turns the status WARN, then ERROR, after the
// configured data time; fixes that are accepted bring it back to OK.
estimation::ImuEvent stillImu(double stamp_s) {
  estimation::ImuEvent event;
  event.sample.stamp_s = stamp_s;
  event.sample.angular_velocity.setZero();
  event.sample.specific_force = Eigen::Vector3d(0, 0, 9.81);
  event.orientation = Eigen::Matrix3d::Identity();
  event.orientation_covariance = Eigen::Matrix3d::Identity() * 1e-6;
  return event;
}

std::string valueOf(const diagnostic_updater::DiagnosticStatusWrapper& status,
                    const std::string& key) {
  for (const auto& value : status.values) {
    if (value.key == key) return value.value;
  }
  return "(missing)";
}

// A frame_id with a leading slash (older drivers' "/gps") names the frame tf2 knows without it.
TEST(Frames, ALeadingSlashIsNotPartOfTheTfFrame) {
  EXPECT_EQ(frames::tfFrameId("/gps"), "gps");
  EXPECT_EQ(frames::tfFrameId("gps"), "gps");
  EXPECT_EQ(frames::tfFrameId(""), "");
}

TEST(LocalizationMonitor, WithoutFixesTheStatusTurnsWarnThenError) {
  LocalizationDiagnosticsOptions options;
  options.fix_warn_after_s = 2.0;
  options.fix_error_after_s = 4.0;
  estimation::LocalizationSession session{estimation::LocalizationSessionConfig{}};
  LocalizationMonitor monitor(options);
  using diagnostic_msgs::DiagnosticStatus;
  const auto levelAt = [&](double until_s, double* t) {
    for (; *t <= until_s + 1e-9; *t += 0.1) {
      session.addImu(stillImu(*t));
      monitor.noteImu(*t, /*wall_s=*/*t, session);
    }
    diagnostic_updater::DiagnosticStatusWrapper status;
    monitor.fill(session, /*wall_s=*/*t, &status);
    EXPECT_GE(status.values.size(), 3u);
    EXPECT_EQ(valueOf(status, "state"), "waiting");
    return status.level;
  };
  double t = 100.0;
  EXPECT_EQ(levelAt(101.0, &t), DiagnosticStatus::OK);
  EXPECT_EQ(levelAt(102.5, &t), DiagnosticStatus::WARN);
  EXPECT_EQ(levelAt(104.5, &t), DiagnosticStatus::ERROR);
  // The IMU rate is of the stamps, whatever the wall clock did.
  diagnostic_updater::DiagnosticStatusWrapper status;
  monitor.fill(session, t, &status);
  EXPECT_NEAR(std::stod(valueOf(status, "IMU rate (Hz)")), 10.0, 0.1);
  EXPECT_EQ(valueOf(status, "filter"), "left");
  // The IMU stops: on the wall clock that is a WARN of its own (the fix ERROR stays).
  diagnostic_updater::DiagnosticStatusWrapper later;
  monitor.fill(session, t + 10.0, &later);
  EXPECT_EQ(later.level, DiagnosticStatus::ERROR);
}

// The fix windows are of data time up to the newest IMU stamp: a GPS that goes quiet reads no
// rate and no fixes in the window once its last fix is a window old (they showed the last
// window's figures for good).
TEST(LocalizationMonitor, AQuietGpsLeavesTheFixWindowsEmpty) {
  LocalizationDiagnosticsOptions options;
  options.window_s = 10.0;
  estimation::LocalizationSession session{estimation::LocalizationSessionConfig{}};
  LocalizationMonitor monitor(options);
  double t = 100.0;
  for (; t < 106.0; t += 0.1) {
    session.addImu(stillImu(t));
    monitor.noteImu(t, t, session);
    if (std::fmod(t - 100.0 + 1e-6, 1.0) < 0.05) monitor.noteFix(t, t, session);  // 1 Hz
  }
  diagnostic_updater::DiagnosticStatusWrapper with_fixes;
  monitor.fill(session, t, &with_fixes);
  EXPECT_NEAR(std::stod(valueOf(with_fixes, "fix rate (Hz)")), 1.0, 0.05);
  for (; t < 125.0; t += 0.1) {  // the GPS is silent from 105 s
    session.addImu(stillImu(t));
    monitor.noteImu(t, t, session);
  }
  diagnostic_updater::DiagnosticStatusWrapper quiet;
  monitor.fill(session, t, &quiet);
  EXPECT_EQ(valueOf(quiet, "fix rate (Hz)"), "0.00");
  EXPECT_EQ(valueOf(quiet, "fixes accepted in window"), "0");
  EXPECT_EQ(valueOf(quiet, "fixes rejected in window"), "0");
}

// A GPS on another clock than the IMU: the status says so (ERROR), not only that no fix came.
TEST(LocalizationMonitor, AGpsOnAnotherClockIsAnErrorNamingIt) {
  estimation::LocalizationSession session{estimation::LocalizationSessionConfig{}};
  LocalizationMonitor monitor(LocalizationDiagnosticsOptions{});
  for (double t = 100.0; t <= 107.0 + 1e-9; t += 0.1) {
    session.addImu(stillImu(t));
    monitor.noteImu(t, t, session);
    estimation::GeodeticFixEvent fix;
    fix.stamp_s = t - 18.0;  // the IMU on GPS time, the receiver on UTC
    fix.lat_deg = 49.0;
    fix.lon_deg = 8.4;
    session.addFix(fix);
  }
  ASSERT_TRUE(session.gpsClockOffset().has_value());
  diagnostic_updater::DiagnosticStatusWrapper status;
  monitor.fill(session, 107.0, &status);
  EXPECT_EQ(status.level, diagnostic_msgs::DiagnosticStatus::ERROR);
  EXPECT_NE(status.message.find("GPS stamps 18.0 s behind the IMU's"), std::string::npos)
      << status.message;
}

// A looping bag resets the filter at every loop: "re-initialised" for a window after each reset,
// then "running" (it read "re-initialised" for good after the first loop).
TEST(LocalizationMonitor, TheStateSaysReinitialisedForAWindowAfterAReset) {
  estimation::LocalizationSession session{estimation::LocalizationSessionConfig{}};
  LocalizationDiagnosticsOptions options;
  options.window_s = 5.0;
  LocalizationMonitor monitor(options);
  const auto stateAfter = [&](double from_s, double to_s) {
    for (double t = from_s; t <= to_s + 1e-9; t += 0.1) {
      session.addImu(stillImu(t));
      monitor.noteImu(t, t, session);
      if (std::fmod(t + 1e-6, 1.0) < 0.05) {
        estimation::GeodeticFixEvent fix;
        fix.stamp_s = t;
        fix.lat_deg = 49.0;
        fix.lon_deg = 8.4;
        fix.alt_m = 100.0;
        session.addFix(fix);
        monitor.noteFix(t, t, session);
      }
    }
    diagnostic_updater::DiagnosticStatusWrapper status;
    monitor.fill(session, to_s, &status);
    return valueOf(status, "state");
  };
  EXPECT_EQ(stateAfter(100.0, 110.0), "running");
  EXPECT_EQ(stateAfter(50.0, 52.0), "re-initialised");  // the loop back: reset, started again
  EXPECT_EQ(session.statistics().resets, 1);
  EXPECT_EQ(stateAfter(52.1, 60.0), "running");
}

TEST(LocalizationMonitor, OptionsAreCheckedNamingTheKey) {
  LocalizationDiagnosticsOptions options;
  common::YamlReader reader("test", YAML::Load("diagnostics: {fix_warn_after_s: 9, "
                                               "fix_error_after_s: 3}"));
  try {
    readLocalizationDiagnosticsOptions(&reader, "diagnostics.", &options);
    FAIL() << "an error timeout below the warning one was accepted";
  } catch (const common::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("diagnostics.fix_error_after_s"), std::string::npos);
  }
}

}  // namespace
}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
