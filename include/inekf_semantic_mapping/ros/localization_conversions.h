// Conversions between the ROS messages inekf_node receives/publishes and the estimation types.
// ROS-facing (src/ros): only nodes include this header.
#pragma once

#include <geometry_msgs/TransformStamped.h>
#include <geometry_msgs/TwistStamped.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <ros/node_handle.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/NavSatFix.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cstddef>
#include <optional>
#include <string>

#include "inekf_semantic_mapping/FilterStatus.h"
#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/estimation/localization_session.h"
#include "inekf_semantic_mapping/estimation/types.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

// The session's configuration from a node's private parameters (a reader of them,
// ros/node_parameters.h): ~config_file (else default_file, else the built-in defaults;
// *config_file says which), then ~filter (left | right | ekf; ~filter_type is refused, naming
// ~filter), ~init_orientation_from_imu, ~min_fix_sigma_m (gps.min_sigma_m),
// ~default_fix_sigma_horizontal_m / _vertical_m, ~time_jump_back_s override it, and
// ~origin_lat/lon/alt (all three or none) set the map origin. Throws common::ConfigError on a
// bad file, value or origin.
estimation::LocalizationSessionConfig sessionConfigFromParameters(common::YamlReader* reader,
                                                                  const std::string& default_file,
                                                                  std::string* config_file);

// The IMU sample of a message (stamp from its header); nullopt when a rate or an acceleration
// is not finite.
std::optional<estimation::ImuSample> imuSampleFromMessage(const sensor_msgs::Imu& message);

// The message's orientation (body -> map, REP-103 ENU) when it carries one: covariance[0] is not
// -1 (the sensor_msgs/Imu "no orientation" marker), finite, and of unit-ish norm.
std::optional<Eigen::Matrix3d> imuOrientation(const sensor_msgs::Imu& message);

// A fix a filter may use: a GPS solution (status >= STATUS_FIX) with finite lat/lon/alt.
bool isUsableFix(const sensor_msgs::NavSatFix& fix);

// The receiver's covariance (NavSatFix covariance is ENU, like `map`); nullopt when it is
// unknown, not finite or not positive on the diagonal (the session uses its default sigmas).
// Not floored: the floor is the Localizer's gps.min_sigma_m.
std::optional<Eigen::Matrix3d> fixCovarianceEnu(const sensor_msgs::NavSatFix& fix);

// The velocity of a gps/vel message: kitti2bag and kitti_player publish the OXTS (ve, vn, vu)
// with frame_id map; any other frame_id (e.g. imu_link: body-frame vf, vl, vu) is taken as the
// body frame. nullopt when not finite.
std::optional<estimation::GpsVelocityEvent> gpsVelocity(const geometry_msgs::TwistStamped& message);

// Wheel odometry (nav_msgs/Odometry): the speed along base_link's x axis of the twist's linear
// velocity, which the message gives in its child_frame_id; `base_from_child` turns that frame's
// axes into base_link's (identity when the child frame is base_link). Its variance along that
// axis from the twist covariance's linear block, NaN when not positive and finite (the session's
// default applies). nullopt when the velocity is not finite.
std::optional<estimation::WheelSpeedEvent> wheelSpeed(const nav_msgs::Odometry& message,
                                                      const Eigen::Matrix3d& base_from_child);

// The session's events, unfiltered: the session counts and drops unusable ones.
estimation::ImuEvent imuEvent(const sensor_msgs::Imu& message);
estimation::GeodeticFixEvent fixEvent(const sensor_msgs::NavSatFix& message);

// geometry_msgs/PoseWithCovariance covariance (row-major 6x6: x y z, then rotation about the
// FIXED map axes x y z) from a filter's pose covariance (position in map, then body-frame
// rotation error R_true = R_est Exp(delta)). Since R Exp(delta) = Exp(R delta) R, the map-axes
// rotation error is R delta: the rotation blocks are rotated by R. Symmetrized.
std::array<double, 36> rosPoseCovariance(const Eigen::Matrix3d& body_to_map,
                                         const estimation::PoseCovariance& pose_covariance);

// Fills pose, twist (body-frame velocity and bias-corrected rate, as nav_msgs/Odometry asks for
// the twist in child_frame_id) and both covariances. Frames and stamp are set by the caller.
void fillOdometry(const estimation::LocalizationSession::Estimate& estimate,
                  const Eigen::Vector3d& latest_angular_velocity, nav_msgs::Odometry* odometry);

// Appends the odometry's pose to the path, keeping the newest max_length poses (trimmed in
// chunks: a long drive does not pay an O(n) erase on every sample).
void appendToPath(const nav_msgs::Odometry& odometry, std::size_t max_length, nav_msgs::Path* path);

// The odometry of base_frame from that of the IMU (the filter's body) and the static
// T_base_imu (tf base_link -> imu_link): pose T_map_imu * T_base_imu^-1; twist of the base
// point in base axes, R_bi (v_imu + w x r) with r the base origin in imu axes, rate R_bi w;
// pose covariance carried through the lever arm (position + rotation x R r, rotation blocks
// unchanged: they are about the fixed map axes). With T_base_imu identity, the input unchanged
// but for child_frame_id.
nav_msgs::Odometry odometryOfBase(const nav_msgs::Odometry& imu_odometry,
                                  const Eigen::Isometry3d& T_base_imu,
                                  const std::string& base_frame);

// The map -> base transform of an odometry message (its header and child frame, its pose).
geometry_msgs::TransformStamped transformOfOdometry(const nav_msgs::Odometry& odometry);
// REP-105's map -> odom when another node (the wheel odometry) publishes odom -> base:
// T_map_odom = T_map_base T_odom_base^-1, stamped as the odometry, so that map -> odom -> base
// is the odometry's pose and base keeps one parent.
geometry_msgs::TransformStamped mapToOdomTransform(const nav_msgs::Odometry& odometry,
                                                   const Eigen::Isometry3d& T_odom_base,
                                                   const std::string& odom_frame);

// The session's FilterStatus (biases once started, counts, last innovation); stamp and frame
// are set by the caller.
FilterStatus filterStatus(const estimation::LocalizationSession& session);

// True when every number of the state and the covariance is finite (nothing NaN is published).
bool isFinite(const estimation::NavState& state, const estimation::PoseCovariance& covariance);

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
