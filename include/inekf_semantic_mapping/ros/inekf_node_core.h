// What inekf_node does, in a class that a node's main holds: the ROS face of
// estimation::LocalizationSession (the same session inekf_offline drives: start, map origin, fix
// policy, time-jump reset and statistics live there). Subscribes the IMU, the GPS fix and the GPS
// velocity (kitti_player / kitti2bag topics by default, remappable), and publishes
// nav_msgs/Odometry, nav_msgs/Path, tf map -> base_link and FilterStatus. Poses: the start's at the
// first used fix's stamp, then one per IMU sample.
//
// Parameters (private):
//   config_file (string, default $(find inekf_semantic_mapping)/config/inekf.yaml)
//   filter (string, left | right | ekf; overrides the config file; filter_type is refused)
//   init_orientation_from_imu (bool; overrides init_orientation_from_reference)
//   origin_lat, origin_lon, origin_alt (double; all three or none: the map origin, else the first
//     usable fix)
//   default_fix_sigma_horizontal_m, default_fix_sigma_vertical_m, time_jump_back_s (override the
//     config's session.*); min_fix_sigma_m (overrides gps.min_sigma_m, the one fix floor)
//   publish_tf (true), map_frame (map), base_frame (base_link)
//   tf_max_heading_sigma_deg (10; <= 0: off): tf waits while the heading is more uncertain
//   imu_frame (string, default: the IMU messages' frame_id): the filter estimates this frame's
//     pose; odometry and tf are of base_frame, through the static base_frame -> imu_frame of tf
//     (identity, with one warning, while tf has none: a bag whose IMU is the body). Its rotation
//     gives the car's forward axis (base_frame's x) to the land-vehicle constraint and the heading
//     monitor; tf imu_frame -> a fix's frame_id gives the GPS antenna's lever arm.
//   max_path_length (5000 poses), path_publish_period_s (1.0)
//   diagnostics/* (over the config file's node.diagnostics.*, ros/localization_diagnostics.h)
// /diagnostics: one status at 1 Hz (filter state, input rates, fix age and rejections, sigmas).
// Any other private parameter, or one of the wrong type, stops the node naming it
// (ros/node_parameters.h).
// ROS-facing (src/ros): only nodes include this header.
#pragma once

#include <ros/node_handle.h>

#include <memory>

namespace inekf_semantic_mapping {
namespace ros_conversions {

class InekfNodeCore {
 public:
  // Throws (std::exception) on a bad parameter or config file.
  InekfNodeCore(ros::NodeHandle nh, ros::NodeHandle private_nh);
  ~InekfNodeCore();  // logs the timing report
  InekfNodeCore(const InekfNodeCore&) = delete;
  InekfNodeCore& operator=(const InekfNodeCore&) = delete;

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
