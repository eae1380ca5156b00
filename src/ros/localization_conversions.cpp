#include "inekf_semantic_mapping/ros/localization_conversions.h"

#include <tf2_eigen/tf2_eigen.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <stdexcept>
#include <string>
#include <utility>

#include "inekf_semantic_mapping/kitti/mercator.h"
#include "inekf_semantic_mapping/ros/names.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

namespace {

Eigen::Vector3d toEigen(const geometry_msgs::Vector3& v) { return {v.x, v.y, v.z}; }

}  // namespace

estimation::LocalizationSessionConfig sessionConfigFromParameters(common::YamlReader* reader,
                                                                  const std::string& default_file,
                                                                  std::string* config_file) {
  // An explicitly given config file must load (a bad one is fatal: the error names the file and
  // the key); without the parameter a missing default file means the built-in defaults.
  estimation::LocalizationSessionConfig config;
  config_file->clear();
  reader->read("config_file", config_file);
  if (!config_file->empty() || std::ifstream(default_file).good()) {
    if (config_file->empty()) *config_file = default_file;
    config = estimation::LocalizationSessionConfig::fromYamlFile(*config_file);
  } else {
    *config_file = "built-in defaults (" + default_file + " not found)";
  }
  // One name for the filter, the config file's own key; filter_type is its old name.
  reader->renamed("filter_type", "filter");
  reader->readChoice("filter", estimation::filterTypeFromString, &config.localizer.filter_type);
  estimation::LocalizerConfig& localizer = config.localizer;
  reader->read("init_orientation_from_imu", &localizer.init_orientation_from_reference);
  // The file's checks for the same values (its gps.min_sigma_m and session.* keys).
  reader->readInRange("min_fix_sigma_m", &localizer.min_gps_sigma_m, 0.0, 1e6);
  reader->readInRange("default_fix_sigma_horizontal_m", &config.default_fix_sigma_horizontal_m, 0.0,
                      1e6, true);
  reader->readInRange("default_fix_sigma_vertical_m", &config.default_fix_sigma_vertical_m, 0.0,
                      1e6, true);
  reader->readInRange("time_jump_back_s", &config.time_jump_back_s, 0.0, 1e6, true);
  estimation::GeodeticOrigin origin;
  const int origin_parts =
      reader->has("origin_lat") + reader->has("origin_lon") + reader->has("origin_alt");
  reader->read("origin_lat", &origin.lat_deg);
  reader->read("origin_lon", &origin.lon_deg);
  reader->read("origin_alt", &origin.alt_m);
  if (origin_parts == 3) {
    if (!(std::abs(origin.lat_deg) < 90.0)) reader->fail("origin_lat", "must be in (-90, 90) deg");
    if (!(std::abs(origin.lon_deg) <= 180.0)) {
      reader->fail("origin_lon", "must be in [-180, 180] deg");
    }
    if (!std::isfinite(origin.alt_m)) reader->fail("origin_alt", "must be a finite number");
    config.origin = origin;
  } else if (origin_parts != 0) {
    reader->fail("origin_lat", "set all three of origin_lat, origin_lon, origin_alt or none");
  }
  // Written by an earlier run of this node (InekfNodeCore), for a restart.
  estimation::GeodeticOrigin earlier;
  if (reader->has("map_origin_in_use.lat") && reader->has("map_origin_in_use.lon") &&
      reader->has("map_origin_in_use.alt")) {
    reader->read("map_origin_in_use.lat", &earlier.lat_deg);
    reader->read("map_origin_in_use.lon", &earlier.lon_deg);
    reader->read("map_origin_in_use.alt", &earlier.alt_m);
    if (!config.origin &&
        kitti::isGeodeticInRange(earlier.lat_deg, earlier.lon_deg, earlier.alt_m)) {
      config.resume_origin = earlier;
    }
  }
  return config;
}

std::optional<estimation::ImuSample> imuSampleFromMessage(const sensor_msgs::Imu& message) {
  estimation::ImuSample sample;
  sample.stamp_s = message.header.stamp.toSec();
  sample.angular_velocity = toEigen(message.angular_velocity);
  sample.specific_force = toEigen(message.linear_acceleration);
  if (!sample.angular_velocity.allFinite() || !sample.specific_force.allFinite()) {
    return std::nullopt;
  }
  return sample;
}

std::optional<Eigen::Matrix3d> imuOrientation(const sensor_msgs::Imu& message) {
  if (message.orientation_covariance[0] == -1.0) return std::nullopt;
  const Eigen::Quaterniond q(message.orientation.w, message.orientation.x, message.orientation.y,
                             message.orientation.z);
  if (!q.coeffs().allFinite() || std::abs(q.norm() - 1.0) > 1e-3) return std::nullopt;
  return q.normalized().toRotationMatrix();
}

bool isUsableFix(const sensor_msgs::NavSatFix& fix) {
  return fix.status.status >= sensor_msgs::NavSatStatus::STATUS_FIX &&
         kitti::isGeodeticInRange(fix.latitude, fix.longitude, fix.altitude);
}

std::optional<Eigen::Matrix3d> fixCovarianceEnu(const sensor_msgs::NavSatFix& fix) {
  const Eigen::Matrix3d covariance = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(
      fix.position_covariance.data());
  if (fix.position_covariance_type == sensor_msgs::NavSatFix::COVARIANCE_TYPE_UNKNOWN ||
      !covariance.allFinite() || !(covariance.diagonal().minCoeff() > 0.0)) {
    return std::nullopt;
  }
  return covariance;
}

std::optional<estimation::GpsVelocityEvent> gpsVelocity(
    const geometry_msgs::TwistStamped& message) {
  estimation::GpsVelocityEvent velocity;
  velocity.stamp_s = message.header.stamp.toSec();
  velocity.velocity = toEigen(message.twist.linear);
  velocity.in_body_frame = message.header.frame_id != frames::kMap;
  if (!velocity.velocity.allFinite()) return std::nullopt;
  return velocity;
}

std::optional<estimation::WheelSpeedEvent> wheelSpeed(const nav_msgs::Odometry& message,
                                                      const Eigen::Matrix3d& base_from_child) {
  const Eigen::Vector3d velocity = base_from_child * toEigen(message.twist.twist.linear);
  if (!velocity.allFinite()) return std::nullopt;
  estimation::WheelSpeedEvent event;
  event.stamp_s = message.header.stamp.toSec();
  event.speed_mps = velocity.x();
  const Eigen::Matrix3d linear = Eigen::Map<const Eigen::Matrix<double, 6, 6, Eigen::RowMajor>>(
                                     message.twist.covariance.data())
                                     .topLeftCorner<3, 3>();
  const double variance = (base_from_child * linear * base_from_child.transpose())(0, 0);
  if (variance > 0.0 && std::isfinite(variance)) event.sigma_mps = std::sqrt(variance);
  return event;
}

estimation::ImuEvent imuEvent(const sensor_msgs::Imu& message) {
  estimation::ImuEvent event;
  event.sample.stamp_s = message.header.stamp.toSec();
  event.sample.angular_velocity = toEigen(message.angular_velocity);
  event.sample.specific_force = toEigen(message.linear_acceleration);
  event.orientation = imuOrientation(message);
  if (event.orientation) {
    event.orientation_covariance = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(
        message.orientation_covariance.data());
  }
  return event;
}

estimation::GeodeticFixEvent fixEvent(const sensor_msgs::NavSatFix& message) {
  estimation::GeodeticFixEvent event;
  event.stamp_s = message.header.stamp.toSec();
  event.lat_deg = message.latitude;
  event.lon_deg = message.longitude;
  event.alt_m = message.altitude;
  event.covariance_enu = fixCovarianceEnu(message);
  // The values are the session's to check: it says why a fix it cannot use is ignored.
  event.has_solution = message.status.status >= sensor_msgs::NavSatStatus::STATUS_FIX;
  return event;
}

std::array<double, 36> rosPoseCovariance(const Eigen::Matrix3d& body_to_map,
                                         const estimation::PoseCovariance& pose_covariance) {
  Eigen::Matrix<double, 6, 6> to_map = Eigen::Matrix<double, 6, 6>::Identity();
  to_map.bottomRightCorner<3, 3>() = body_to_map;
  Eigen::Matrix<double, 6, 6> ros = to_map * pose_covariance * to_map.transpose();
  ros = 0.5 * (ros + ros.transpose()).eval();
  std::array<double, 36> out;
  Eigen::Map<Eigen::Matrix<double, 6, 6, Eigen::RowMajor>>(out.data()) = ros;
  return out;
}

void fillOdometry(const estimation::LocalizationSession::Estimate& estimate,
                  const Eigen::Vector3d& latest_angular_velocity, nav_msgs::Odometry* odometry) {
  const estimation::NavState& state = estimate.state;
  const Eigen::Quaterniond q(state.rotation);
  odometry->pose.pose.position.x = state.position_map.x();
  odometry->pose.pose.position.y = state.position_map.y();
  odometry->pose.pose.position.z = state.position_map.z();
  odometry->pose.pose.orientation.w = q.w();
  odometry->pose.pose.orientation.x = q.x();
  odometry->pose.pose.orientation.y = q.y();
  odometry->pose.pose.orientation.z = q.z();
  const std::array<double, 36> covariance =
      rosPoseCovariance(state.rotation, estimate.pose_covariance);
  std::copy(covariance.begin(), covariance.end(), odometry->pose.covariance.begin());

  const Eigen::Vector3d velocity_body = state.rotation.transpose() * state.velocity_map;
  const Eigen::Vector3d rate_body = latest_angular_velocity - state.gyro_bias;
  odometry->twist.twist.linear.x = velocity_body.x();
  odometry->twist.twist.linear.y = velocity_body.y();
  odometry->twist.twist.linear.z = velocity_body.z();
  odometry->twist.twist.angular.x = rate_body.x();
  odometry->twist.twist.angular.y = rate_body.y();
  odometry->twist.twist.angular.z = rate_body.z();
  // Both in the body frame, as the twist: geometry_msgs' row-major 6x6.
  Eigen::Map<Eigen::Matrix<double, 6, 6, Eigen::RowMajor>>(odometry->twist.covariance.data()) =
      estimate.twist_covariance;
}

void appendToPath(const nav_msgs::Odometry& odometry, std::size_t max_length,
                  nav_msgs::Path* path) {
  geometry_msgs::PoseStamped pose;
  pose.header = odometry.header;
  pose.pose = odometry.pose.pose;
  path->poses.push_back(pose);
  max_length = std::max<std::size_t>(max_length, 1);
  if (path->poses.size() > max_length + max_length / 10) {
    path->poses.erase(path->poses.begin(), path->poses.end() - max_length);
  }
}

nav_msgs::Odometry odometryOfBase(const nav_msgs::Odometry& imu_odometry,
                                  const Eigen::Isometry3d& T_base_imu,
                                  const std::string& base_frame) {
  nav_msgs::Odometry out = imu_odometry;
  out.child_frame_id = base_frame;
  const geometry_msgs::Pose& pose = imu_odometry.pose.pose;
  Eigen::Isometry3d T_map_imu = Eigen::Isometry3d::Identity();
  T_map_imu.linear() = Eigen::Quaterniond(pose.orientation.w, pose.orientation.x,
                                          pose.orientation.y, pose.orientation.z)
                           .normalized()
                           .toRotationMatrix();
  T_map_imu.translation() = Eigen::Vector3d(pose.position.x, pose.position.y, pose.position.z);
  const Eigen::Isometry3d T_imu_base = T_base_imu.inverse();
  const Eigen::Isometry3d T_map_base = T_map_imu * T_imu_base;
  out.pose.pose = tf2::toMsg(T_map_base);

  // Twist: the base point moves with v_imu + w x r (r: base origin in imu axes).
  const Eigen::Vector3d r = T_imu_base.translation();
  const Eigen::Matrix3d R_base_imu = T_base_imu.linear();
  const Eigen::Vector3d w = toEigen(imu_odometry.twist.twist.angular);
  const Eigen::Vector3d v = toEigen(imu_odometry.twist.twist.linear);
  const Eigen::Vector3d v_base = R_base_imu * (v + w.cross(r));
  const Eigen::Vector3d w_base = R_base_imu * w;
  out.twist.twist.linear.x = v_base.x();
  out.twist.twist.linear.y = v_base.y();
  out.twist.twist.linear.z = v_base.z();
  out.twist.twist.angular.x = w_base.x();
  out.twist.twist.angular.y = w_base.y();
  out.twist.twist.angular.z = w_base.z();
  // d v_base = R (dv - r^ dw), d w_base = R dw.
  Eigen::Matrix3d r_hat;
  r_hat << 0, -r.z(), r.y(), r.z(), 0, -r.x(), -r.y(), r.x(), 0;
  Eigen::Matrix<double, 6, 6> twist_jacobian = Eigen::Matrix<double, 6, 6>::Zero();
  twist_jacobian.topLeftCorner<3, 3>() = R_base_imu;
  twist_jacobian.topRightCorner<3, 3>() = -R_base_imu * r_hat;
  twist_jacobian.bottomRightCorner<3, 3>() = R_base_imu;
  Eigen::Map<const Eigen::Matrix<double, 6, 6, Eigen::RowMajor>> twist_in(
      imu_odometry.twist.covariance.data());
  Eigen::Matrix<double, 6, 6> twist_out = twist_jacobian * twist_in * twist_jacobian.transpose();
  Eigen::Map<Eigen::Matrix<double, 6, 6, Eigen::RowMajor>>(out.twist.covariance.data()) =
      0.5 * (twist_out + twist_out.transpose());

  // p_base = p_imu + R r: a rotation error dtheta about the map axes moves it by
  // dtheta x (R r) = -[R r]x dtheta.
  const Eigen::Vector3d lever = T_map_imu.linear() * r;
  Eigen::Matrix3d skew;
  skew << 0, -lever.z(), lever.y(), lever.z(), 0, -lever.x(), -lever.y(), lever.x(), 0;
  Eigen::Matrix<double, 6, 6> J = Eigen::Matrix<double, 6, 6>::Identity();
  J.topRightCorner<3, 3>() = -skew;
  Eigen::Map<const Eigen::Matrix<double, 6, 6, Eigen::RowMajor>> C(
      imu_odometry.pose.covariance.data());
  Eigen::Matrix<double, 6, 6> moved = J * C * J.transpose();
  moved = 0.5 * (moved + moved.transpose()).eval();
  Eigen::Map<Eigen::Matrix<double, 6, 6, Eigen::RowMajor>>(out.pose.covariance.data()) = moved;
  return out;
}

geometry_msgs::TransformStamped transformOfOdometry(const nav_msgs::Odometry& odometry) {
  geometry_msgs::TransformStamped transform;
  transform.header = odometry.header;
  transform.child_frame_id = odometry.child_frame_id;
  transform.transform.translation.x = odometry.pose.pose.position.x;
  transform.transform.translation.y = odometry.pose.pose.position.y;
  transform.transform.translation.z = odometry.pose.pose.position.z;
  transform.transform.rotation = odometry.pose.pose.orientation;
  return transform;
}

geometry_msgs::TransformStamped mapToOdomTransform(const nav_msgs::Odometry& odometry,
                                                   const Eigen::Isometry3d& T_odom_base,
                                                   const std::string& odom_frame) {
  Eigen::Isometry3d T_map_base;
  tf2::fromMsg(odometry.pose.pose, T_map_base);
  geometry_msgs::TransformStamped transform =
      tf2::eigenToTransform(T_map_base * T_odom_base.inverse());
  transform.header = odometry.header;
  transform.child_frame_id = odom_frame;
  return transform;
}

FilterStatus filterStatus(const estimation::LocalizationSession& session) {
  const estimation::LocalizationSession::Statistics statistics = session.statistics();
  FilterStatus status;
  status.filter_type = estimation::toString(session.config().localizer.filter_type);
  if (session.started()) {
    const estimation::NavState& state = session.state();
    status.gyro_bias.x = state.gyro_bias.x();
    status.gyro_bias.y = state.gyro_bias.y();
    status.gyro_bias.z = state.gyro_bias.z();
    status.accel_bias.x = state.accel_bias.x();
    status.accel_bias.y = state.accel_bias.y();
    status.accel_bias.z = state.accel_bias.z();
  }
  const double d2 = session.lastMahalanobisSquared();
  status.last_innovation_mahalanobis = std::isfinite(d2) ? std::sqrt(std::max(0.0, d2)) : 0.0;
  status.gps_fixes_used = static_cast<uint32_t>(statistics.filter.gps_used);
  status.gps_fixes_rejected =
      static_cast<uint32_t>(statistics.filter.gps_rejected + statistics.fixes_ignored);
  status.imu_samples = static_cast<uint32_t>(statistics.filter.imu_used);
  status.imu_samples_dropped =
      static_cast<uint32_t>(statistics.filter.imu_dropped + statistics.imu_invalid);
  status.heading_alignments = static_cast<uint32_t>(statistics.filter.heading_alignments);
  status.heading_recoveries = static_cast<uint32_t>(statistics.filter.heading_recoveries +
                                                    statistics.filter.heading_reopens);
  status.resets = static_cast<uint32_t>(statistics.resets);
  return status;
}

bool isFinite(const estimation::NavState& state, const estimation::PoseCovariance& covariance) {
  return state.rotation.allFinite() && state.velocity_map.allFinite() &&
         state.position_map.allFinite() && state.gyro_bias.allFinite() &&
         state.accel_bias.allFinite() && covariance.allFinite();
}

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
