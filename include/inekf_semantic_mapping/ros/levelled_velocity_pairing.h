// The Python kitti2bag's gps/vel is levelled (vf, vl, vu): turning it into map axes needs the
// heading of its instant, which travels on the IMU's connection. rosbag play's messages of one
// instant arrive in either order, so a velocity that comes before the IMU message of its stamp
// waits for it (dropping it lost the first frame's velocity, and inekf_node's start came a frame
// later). This pairs them: velocities wait until an orientation at or after their stamp is
// there, then leave in map axes with the orientation nearest their stamp.
// ROS-facing (src/ros): only nodes and their tests include this header.
#pragma once

#include <geometry_msgs/TwistStamped.h>
#include <ros/time.h>

#include <Eigen/Core>
#include <cstddef>
#include <deque>
#include <string>
#include <utility>
#include <vector>

namespace inekf_semantic_mapping {
namespace ros_conversions {

class LevelledVelocityPairing {
 public:
  static constexpr std::size_t kMaxOrientations = 200;
  // Beyond this many waiting velocities (no IMU message comes at all) the oldest are dropped.
  static constexpr std::size_t kMaxPendingVelocities = 50;
  // Waiting velocities this much newer than an IMU message that jumped back: another loop.
  static constexpr double kLoopJumpS = 1.0;

  explicit LevelledVelocityPairing(std::string map_frame) : map_frame_(std::move(map_frame)) {}

  // The IMU orientation (body -> map) of `stamp`; returns the velocities it releases, in map axes.
  // A stamp before the previous one (the bag looped) forgets the old orientations and the
  // velocities that wait for another loop's time.
  std::vector<geometry_msgs::TwistStamped> addOrientation(const ros::Time& stamp,
                                                          const Eigen::Matrix3d& R_map_body);
  // A levelled velocity; returns the velocities released (it, when the IMU already reached its
  // stamp). Velocities dropped for want of any IMU message are counted in dropped().
  std::vector<geometry_msgs::TwistStamped> addVelocity(const geometry_msgs::TwistStamped& velocity);

  std::size_t pending() const { return pending_.size(); }
  std::size_t dropped() const { return dropped_; }
  // The stamp of the last velocity dropped (for the warning).
  const ros::Time& lastDroppedStamp() const { return last_dropped_stamp_; }

 private:
  std::vector<geometry_msgs::TwistStamped> release();

  std::string map_frame_;
  std::deque<std::pair<ros::Time, Eigen::Matrix3d>> orientations_;
  std::deque<geometry_msgs::TwistStamped> pending_;
  std::size_t dropped_ = 0;
  ros::Time last_dropped_stamp_;
};

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
