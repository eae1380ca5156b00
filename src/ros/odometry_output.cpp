#include "inekf_semantic_mapping/ros/odometry_output.h"

#include <ros/console.h>

#include <algorithm>
#include <cmath>
#include <iomanip>

#include "inekf_semantic_mapping/ros/kitti_bag_conventions.h"
#include "inekf_semantic_mapping/ros/localization_conversions.h"
#include "inekf_semantic_mapping/ros/names.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

OdometryOutputOptions readOdometryOutputOptions(common::YamlReader* reader) {
  OdometryOutputOptions options;
  reader->read("publish_tf", &options.publish_tf);
  reader->read("tf_max_heading_sigma_deg", &options.tf_max_heading_sigma_deg);
  reader->read("map_frame", &options.map_frame);
  reader->read("base_frame", &options.base_frame);
  reader->read("odom_frame", &options.odom_frame);
  reader->read("imu_frame", &options.imu_frame);
  reader->read("max_path_length", &options.max_path_length);
  reader->read("path_publish_period_s", &options.path_publish_period_s);
  return options;
}

OdometryOutput::OdometryOutput(ros::NodeHandle& nh, const OdometryOutputOptions& options)
    : publish_tf_(options.publish_tf),
      tf_max_heading_sigma_deg_(options.tf_max_heading_sigma_deg),
      base_frame_(frames::tfFrameId(options.base_frame)),
      odom_frame_(frames::tfFrameId(options.odom_frame)),
      imu_frame_(frames::tfFrameId(options.imu_frame)),
      max_path_length_(std::max(options.max_path_length, 1)),
      path_publish_period_s_(options.path_publish_period_s) {
  path_.header.frame_id = options.map_frame;
  odometry_publisher_ = nh.advertise<nav_msgs::Odometry>(topics::kOdometry, 50);
  path_publisher_ = nh.advertise<nav_msgs::Path>(topics::kPath, 1, /*latch=*/true);
}

void OdometryOutput::noteImuFrame(const std::string& frame_id) {
  if (imu_frame_.empty() && !frame_id.empty()) imu_frame_ = frames::tfFrameId(frame_id);
}

void OdometryOutput::publish(const ros::Time& stamp,
                             const estimation::LocalizationSession::Estimate& estimate,
                             const Eigen::Vector3d& angular_velocity) {
  nav_msgs::Odometry odometry;
  odometry.header.stamp = stamp;
  odometry.header.frame_id = path_.header.frame_id;
  odometry.child_frame_id = base_frame_;
  fillOdometry(estimate, angular_velocity, &odometry);
  if (const auto T_base_imu = baseFromImu()) {
    odometry = odometryOfBase(odometry, *T_base_imu, base_frame_);
  }
  odometry_publisher_.publish(odometry);
  if (publish_tf_ && !holdTf(odometry)) {
    if (odom_frame_.empty()) {
      tf_broadcaster_.sendTransform(transformOfOdometry(odometry));
    } else if (const auto T_odom_base = odomFromBase(stamp)) {
      tf_broadcaster_.sendTransform(mapToOdomTransform(odometry, *T_odom_base, odom_frame_));
    }
  }
  appendToPath(odometry, static_cast<std::size_t>(max_path_length_), &path_);
  if (last_path_publish_.isZero() || stamp < last_path_publish_ ||
      (stamp - last_path_publish_).toSec() >= path_publish_period_s_) {
    path_.header.stamp = stamp;
    path_publisher_.publish(path_);
    last_path_publish_ = stamp;
  }
}

bool OdometryOutput::holdTf(const nav_msgs::Odometry& odometry) {
  if (heading_known_ || !(tf_max_heading_sigma_deg_ > 0.0)) return false;
  // The yaw about the map's z axis (ROS order x y z roll pitch yaw).
  const double sigma_deg = std::sqrt(std::max(0.0, odometry.pose.covariance[35])) * 180.0 / M_PI;
  if (sigma_deg <= tf_max_heading_sigma_deg_) {
    heading_known_ = true;
    if (said_held_) {
      ROS_INFO_STREAM("inekf_node: heading known (sigma "
                      << std::fixed << std::setprecision(1) << sigma_deg << " deg): tf "
                      << path_.header.frame_id << " -> " << base_frame_ << " published");
    }
    return false;
  }
  if (!said_held_) {
    said_held_ = true;
    ROS_WARN_STREAM("inekf_node: tf " << path_.header.frame_id << " -> " << base_frame_
                                      << " held back: the heading's sigma is " << std::fixed
                                      << std::setprecision(0) << sigma_deg
                                      << " deg (above ~tf_max_heading_sigma_deg, "
                                      << tf_max_heading_sigma_deg_
                                      << "); without an IMU orientation the GPS track gives it "
                                         "once the car drives");
  }
  return true;
}

std::optional<Eigen::Isometry3d> OdometryOutput::odomFromBase(const ros::Time& stamp) {
  try {
    return toIsometry(tf_buffer_.lookupTransform(odom_frame_, base_frame_, stamp).transform);
  } catch (const tf2::TransformException&) {
  }
  std::string why;
  if (auto latest = latestTransform(odom_frame_, base_frame_, &why)) return latest;
  ROS_WARN_STREAM_THROTTLE(10, "inekf_node: no tf " << odom_frame_ << " -> " << base_frame_
                                                    << " (~odom_frame: the wheel odometry's), so "
                                                    << path_.header.frame_id << " -> "
                                                    << odom_frame_ << " is not published: " << why);
  return std::nullopt;
}

void OdometryOutput::clearPath() {
  heading_known_ = false;  // a new start: tf waits for its heading again
  said_held_ = false;
  path_.poses.clear();
  path_publisher_.publish(path_);
  last_path_publish_ = ros::Time();
}

std::optional<Eigen::Isometry3d> OdometryOutput::latestTransform(const std::string& target,
                                                                 const std::string& source,
                                                                 std::string* why) {
  try {
    return toIsometry(tf_buffer_.lookupTransform(target, source, ros::Time(0)).transform);
  } catch (const tf2::TransformException& error) {
    if (why) *why = error.what();
    return std::nullopt;
  }
}

std::optional<Eigen::Matrix3d> OdometryOutput::imuMounting() {
  if (imu_frame_.empty() || imu_frame_ == base_frame_) return Eigen::Matrix3d::Identity();
  const std::optional<Eigen::Isometry3d> base_from_imu = latestTransform(base_frame_, imu_frame_);
  if (!base_from_imu) return std::nullopt;  // baseFromImu says so once
  return base_from_imu->rotation();
}

std::optional<Eigen::Isometry3d> OdometryOutput::frameInImu(const std::string& frame_id) {
  const std::string frame = frames::tfFrameId(frame_id);
  if (frame.empty() || frame == imu_frame_) return Eigen::Isometry3d::Identity();
  if (imu_frame_.empty()) return std::nullopt;
  return latestTransform(imu_frame_, frame);
}

std::optional<Eigen::Isometry3d> OdometryOutput::baseFromImu() {
  if (imu_frame_.empty() || imu_frame_ == base_frame_) return std::nullopt;
  std::string why;
  const std::optional<Eigen::Isometry3d> base_from_imu =
      latestTransform(base_frame_, imu_frame_, &why);
  if (base_from_imu && !found_base_imu_) {
    found_base_imu_ = true;
    ROS_INFO_STREAM("inekf_node: the filter estimates "
                    << imu_frame_ << "; publishing " << base_frame_ << " through tf " << base_frame_
                    << " -> " << imu_frame_);
  } else if (!base_from_imu && !warned_no_base_imu_) {
    warned_no_base_imu_ = true;
    ROS_WARN_STREAM("inekf_node: no tf " << base_frame_ << " -> " << imu_frame_ << " yet (" << why
                                         << "): publishing the pose of " << imu_frame_ << " as "
                                         << base_frame_ << " until it comes");
  }
  return base_from_imu;
}

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
