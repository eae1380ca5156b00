#include "inekf_semantic_mapping/ros/localization_conversions.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <string>

#include "inekf_semantic_mapping/ros/names.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

namespace {

Eigen::Vector3d toEigen(const geometry_msgs::Vector3& v) { return {v.x, v.y, v.z}; }

}  // namespace

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
         std::isfinite(fix.latitude) && std::isfinite(fix.longitude) && std::isfinite(fix.altitude);
}

Eigen::Matrix3d fixCovarianceMap(const sensor_msgs::NavSatFix& fix, double min_sigma_m,
                                 double default_sigma_horizontal_m,
                                 double default_sigma_vertical_m) {
  Eigen::Matrix3d covariance = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(
      fix.position_covariance.data());
  const bool known =
      fix.position_covariance_type != sensor_msgs::NavSatFix::COVARIANCE_TYPE_UNKNOWN &&
      covariance.allFinite() && covariance.diagonal().minCoeff() > 0.0;
  if (!known) {
    covariance = Eigen::Vector3d(default_sigma_horizontal_m * default_sigma_horizontal_m,
                                 default_sigma_horizontal_m * default_sigma_horizontal_m,
                                 default_sigma_vertical_m * default_sigma_vertical_m)
                     .asDiagonal();
  }
  covariance = 0.5 * (covariance + covariance.transpose()).eval();
  // A receiver's optimistic covariance (or a perfect-truth fix) must not make the filter
  // overconfident: floor each axis' variance.
  const double floor = min_sigma_m * min_sigma_m;
  for (int axis = 0; axis < 3; ++axis) {
    covariance(axis, axis) = std::max(covariance(axis, axis), floor);
  }
  return covariance;
}

std::optional<GpsVelocity> gpsVelocity(const geometry_msgs::TwistStamped& message) {
  GpsVelocity velocity;
  velocity.stamp_s = message.header.stamp.toSec();
  velocity.velocity = toEigen(message.twist.linear);
  velocity.in_body_frame = message.header.frame_id != frames::kMap;
  if (!velocity.velocity.allFinite()) return std::nullopt;
  return velocity;
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

void fillOdometry(const estimation::NavState& state,
                  const estimation::PoseCovariance& pose_covariance,
                  const Eigen::Vector3d& latest_angular_velocity, nav_msgs::Odometry* odometry) {
  const Eigen::Quaterniond q(state.rotation);
  odometry->pose.pose.position.x = state.position_map.x();
  odometry->pose.pose.position.y = state.position_map.y();
  odometry->pose.pose.position.z = state.position_map.z();
  odometry->pose.pose.orientation.w = q.w();
  odometry->pose.pose.orientation.x = q.x();
  odometry->pose.pose.orientation.y = q.y();
  odometry->pose.pose.orientation.z = q.z();
  const std::array<double, 36> covariance = rosPoseCovariance(state.rotation, pose_covariance);
  std::copy(covariance.begin(), covariance.end(), odometry->pose.covariance.begin());

  const Eigen::Vector3d velocity_body = state.rotation.transpose() * state.velocity_map;
  const Eigen::Vector3d rate_body = latest_angular_velocity - state.gyro_bias;
  odometry->twist.twist.linear.x = velocity_body.x();
  odometry->twist.twist.linear.y = velocity_body.y();
  odometry->twist.twist.linear.z = velocity_body.z();
  odometry->twist.twist.angular.x = rate_body.x();
  odometry->twist.twist.angular.y = rate_body.y();
  odometry->twist.twist.angular.z = rate_body.z();
  // The filter's velocity covariance lives in filter-specific error coordinates: leave the twist
  // covariance unknown (all zero) rather than publish a wrong one.
}

bool isFinite(const estimation::NavState& state, const estimation::PoseCovariance& covariance) {
  return state.rotation.allFinite() && state.velocity_map.allFinite() &&
         state.position_map.allFinite() && state.gyro_bias.allFinite() &&
         state.accel_bias.allFinite() && covariance.allFinite();
}

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
