// Conversions between the ROS messages inekf_node receives/publishes and the estimation types.
// ROS-facing (src/ros): only nodes include this header.
#pragma once

#include <geometry_msgs/TwistStamped.h>
#include <nav_msgs/Odometry.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/NavSatFix.h>

#include <Eigen/Core>
#include <array>
#include <optional>

#include "inekf_semantic_mapping/estimation/types.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

// The IMU sample of a message (stamp from its header); nullopt when a rate or an acceleration
// is not finite.
std::optional<estimation::ImuSample> imuSampleFromMessage(const sensor_msgs::Imu& message);

// The message's orientation (body -> map, REP-103 ENU) when it carries one: covariance[0] is not
// -1 (the sensor_msgs/Imu "no orientation" marker), finite, and of unit-ish norm.
std::optional<Eigen::Matrix3d> imuOrientation(const sensor_msgs::Imu& message);

// A fix a filter may use: a GPS solution (status >= STATUS_FIX) with finite lat/lon/alt.
bool isUsableFix(const sensor_msgs::NavSatFix& fix);

// The fix covariance in the map frame (NavSatFix covariance is ENU, like `map`), symmetric, each
// axis' variance raised to at least min_sigma_m^2. Unknown or non-finite covariance -> the
// default sigmas (horizontal, vertical).
Eigen::Matrix3d fixCovarianceMap(const sensor_msgs::NavSatFix& fix, double min_sigma_m,
                                 double default_sigma_horizontal_m,
                                 double default_sigma_vertical_m);

// The velocity of a gps/vel message: kitti2bag publishes the OXTS body-frame velocity (vf, vl,
// vu) with frame_id imu_link/base_link; a message whose frame_id is the map frame is in the map
// frame. nullopt when not finite.
struct GpsVelocity {
  double stamp_s = 0.0;
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
  bool in_body_frame = true;
};
std::optional<GpsVelocity> gpsVelocity(const geometry_msgs::TwistStamped& message);

// geometry_msgs/PoseWithCovariance covariance (row-major 6x6: x y z, then rotation about the
// FIXED map axes x y z) from a filter's pose covariance (position in map, then body-frame
// rotation error R_true = R_est Exp(delta)). Since R Exp(delta) = Exp(R delta) R, the map-axes
// rotation error is R delta: the rotation blocks are rotated by R. Symmetrized.
std::array<double, 36> rosPoseCovariance(const Eigen::Matrix3d& body_to_map,
                                         const estimation::PoseCovariance& pose_covariance);

// Fills pose, twist (body-frame velocity and bias-corrected rate, as nav_msgs/Odometry asks for
// the twist in child_frame_id) and the pose covariance. Frames and stamp are set by the caller.
void fillOdometry(const estimation::NavState& state,
                  const estimation::PoseCovariance& pose_covariance,
                  const Eigen::Vector3d& latest_angular_velocity, nav_msgs::Odometry* odometry);

// True when every number of the state and the covariance is finite (nothing NaN is published).
bool isFinite(const estimation::NavState& state, const estimation::PoseCovariance& covariance);

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
