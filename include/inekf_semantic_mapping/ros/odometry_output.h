// What inekf_node publishes for each estimate: nav_msgs/Odometry and tf map -> base_frame, and
// the nav_msgs/Path of them. The filter estimates the IMU's pose; the base pose goes through the
// static base_frame -> imu_frame of tf, so nothing assumes base_link = imu_link.
// ROS-facing (src/ros): only nodes include this header.
#pragma once

#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <ros/node_handle.h>
#include <ros/publisher.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>

#include <Eigen/Geometry>
#include <optional>
#include <string>

#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/estimation/localization_session.h"
#include "inekf_semantic_mapping/estimation/types.h"
#include "inekf_semantic_mapping/ros/names.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

struct OdometryOutputOptions {
  bool publish_tf = true;
  // After a start (and a reset), tf map -> base waits until the heading's sigma is first at or
  // below this (deg): a start without an IMU orientation knows no heading until the car moves,
  // and a map took its scans turned anywhere. The odometry (with its covariance) is published
  // meanwhile. Not again later in the run: tf2 interpolates over a gap in tf, so a pause there
  // would hold back nothing. <= 0: tf from the start.
  double tf_max_heading_sigma_deg = 10.0;
  std::string map_frame = frames::kMap;
  std::string base_frame = frames::kBaseLink;
  // REP-105: when another node publishes odom_frame -> base_frame (a wheel odometry, e.g.
  // diff_drive_controller), tf is map_frame -> odom_frame (base_frame had two parents and the
  // tree broke). Empty: map_frame -> base_frame.
  std::string odom_frame;
  std::string imu_frame;  // empty: the IMU messages' frame_id (see OdometryOutput::noteImuFrame)
  int max_path_length = 5000;  // poses
  double path_publish_period_s = 1.0;
};

// The private parameters publish_tf, tf_max_heading_sigma_deg, map_frame, base_frame, odom_frame,
// imu_frame, max_path_length and path_publish_period_s (defaults above).
OdometryOutputOptions readOdometryOutputOptions(common::YamlReader* reader);

class OdometryOutput {
 public:
  // Advertises the odometry and path topics on nh.
  OdometryOutput(ros::NodeHandle& nh, const OdometryOutputOptions& options);

  // The frame the filter estimates, from the first IMU message that names one (unless the
  // imu_frame parameter set it).
  void noteImuFrame(const std::string& frame_id);
  const std::string& baseFrame() const { return base_frame_; }
  const std::string& imuFrame() const { return imu_frame_; }

  // One estimate, stamped with the message's own stamp: a double stamp loses the nanoseconds,
  // and consumers match our poses to their data by exact stamp.
  void publish(const ros::Time& stamp, const estimation::LocalizationSession::Estimate& estimate,
               const Eigen::Vector3d& angular_velocity);

  // Empties the path and publishes the empty path (the filter was reset); tf waits for the new
  // start's heading (tf_max_heading_sigma_deg).
  void clearPath();

  // The rotation of the IMU's axes in base_frame's: identity when the IMU is the base (or its
  // messages name no frame), from tf otherwise; nullopt while tf has no such transform.
  std::optional<Eigen::Matrix3d> imuMounting();
  // A sensor frame's pose in the IMU's frame (tf IMU frame -> frame_id; a leading slash
  // dropped): identity when the message names no frame or the IMU's own; nullopt while the IMU
  // frame is not known yet or tf has no such transform. A GPS fix's frame: the antenna's lever
  // arm (its translation); a GPS velocity's: the rotation into the IMU's axes.
  std::optional<Eigen::Isometry3d> frameInImu(const std::string& frame_id);
  const std::string& mapFrame() const { return path_.header.frame_id; }

 private:
  // The static base_frame -> imu_frame from tf; nullopt (the IMU pose is published as the base
  // pose) when the IMU is the base or tf has no such transform (warned once). Looked up for
  // every estimate: it is cheap, and a transform that arrives late is picked up.
  std::optional<Eigen::Isometry3d> baseFromImu();
  // tf's latest target <- source, nullopt (and why) when it has none.
  std::optional<Eigen::Isometry3d> latestTransform(const std::string& target,
                                                   const std::string& source,
                                                   std::string* why = nullptr);
  // True until the odometry's heading sigma is first at or below tf_max_heading_sigma_deg after
  // a start (the wait and its end are said once).
  bool holdTf(const nav_msgs::Odometry& odometry);
  // tf odom_frame -> base_frame at `stamp`, else its latest (a wheel odometry a little behind the
  // IMU); nullopt while there is none (said once a while).
  std::optional<Eigen::Isometry3d> odomFromBase(const ros::Time& stamp);

  bool publish_tf_ = true;
  double tf_max_heading_sigma_deg_ = 10.0;
  bool heading_known_ = false;  // since the start: tf flows
  bool said_held_ = false;      // the wait was said
  std::string base_frame_, odom_frame_, imu_frame_;
  int max_path_length_ = 5000;
  double path_publish_period_s_ = 1.0;
  bool found_base_imu_ = false, warned_no_base_imu_ = false;
  nav_msgs::Path path_;
  ros::Time last_path_publish_;
  ros::Publisher odometry_publisher_, path_publisher_;
  tf2_ros::Buffer tf_buffer_;
  tf2_ros::TransformListener tf_listener_{tf_buffer_};
  tf2_ros::TransformBroadcaster tf_broadcaster_;
};

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
