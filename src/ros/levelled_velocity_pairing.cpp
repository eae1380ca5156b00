#include "inekf_semantic_mapping/ros/levelled_velocity_pairing.h"

#include <cmath>
#include <limits>

#include "inekf_semantic_mapping/ros/kitti_bag_conventions.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

std::vector<geometry_msgs::TwistStamped> LevelledVelocityPairing::addOrientation(
    const ros::Time& stamp, const Eigen::Matrix3d& R_map_body) {
  if (!orientations_.empty() && stamp < orientations_.back().first) {
    // The bag looped (or the player restarted): the old orientations are of another time, and
    // velocities waiting from before the jump will never be reached.
    orientations_.clear();
    while (!pending_.empty() && pending_.front().header.stamp > stamp + ros::Duration(kLoopJumpS)) {
      pending_.pop_front();
    }
  }
  orientations_.emplace_back(stamp, R_map_body);
  while (orientations_.size() > kMaxOrientations) orientations_.pop_front();
  return release();
}

std::vector<geometry_msgs::TwistStamped> LevelledVelocityPairing::addVelocity(
    const geometry_msgs::TwistStamped& velocity) {
  if (!pending_.empty() && velocity.header.stamp < pending_.back().header.stamp) {
    pending_.clear();  // the bag looped: those wait for an IMU of another time
  }
  pending_.push_back(velocity);
  std::vector<geometry_msgs::TwistStamped> released = release();
  while (pending_.size() > kMaxPendingVelocities) {
    last_dropped_stamp_ = pending_.front().header.stamp;
    ++dropped_;
    pending_.pop_front();
  }
  return released;
}

std::vector<geometry_msgs::TwistStamped> LevelledVelocityPairing::release() {
  std::vector<geometry_msgs::TwistStamped> released;
  while (!pending_.empty() && !orientations_.empty() &&
         pending_.front().header.stamp <= orientations_.back().first) {
    const geometry_msgs::TwistStamped& velocity = pending_.front();
    const Eigen::Matrix3d* R_map_body = &orientations_.back().second;
    double nearest_s = std::numeric_limits<double>::infinity();
    for (const auto& [stamp, rotation] : orientations_) {
      const double gap_s = std::abs((stamp - velocity.header.stamp).toSec());
      if (gap_s < nearest_s) {
        nearest_s = gap_s;
        R_map_body = &rotation;
      }
    }
    released.push_back(velocityLevelledToMap(velocity, *R_map_body, map_frame_));
    pending_.pop_front();
  }
  return released;
}

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
