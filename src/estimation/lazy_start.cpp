#include "inekf_semantic_mapping/estimation/lazy_start.h"

#include <cmath>

namespace inekf_semantic_mapping {
namespace estimation {

void LazyStart::offerOrientation(const Eigen::Matrix3d& body_to_map,
                                 const std::optional<Eigen::Matrix3d>& covariance) {
  if (!body_to_map.allFinite()) return;
  orientation_ = body_to_map;
  orientation_covariance_ = covariance;
}

void LazyStart::offerVelocity(double stamp_s, const Eigen::Vector3d& velocity, bool in_body_frame) {
  if (!std::isfinite(stamp_s) || !velocity.allFinite()) return;
  velocity_stamp_s_ = stamp_s;
  velocity_ = velocity;
  velocity_in_body_frame_ = in_body_frame;
}

std::optional<Eigen::Vector3d> LazyStart::velocityForPendingFix() const {
  if (!pending_fix_ || !velocity_stamp_s_ ||
      std::abs(*velocity_stamp_s_ - pending_fix_->stamp_s) > config_.max_velocity_age_s) {
    return std::nullopt;
  }
  if (!velocity_in_body_frame_) return velocity_;
  // A body-frame velocity needs the orientation the start is made with.
  if (!config_.use_reference || !orientation_) return std::nullopt;
  return Eigen::Vector3d(*orientation_ * velocity_);
}

bool LazyStart::velocityArrivedForPendingFix() const {
  return pending_fix_ && velocity_stamp_s_ &&
         std::abs(*velocity_stamp_s_ - pending_fix_->stamp_s) <= config_.max_velocity_age_s;
}

std::optional<LazyStart::Start> LazyStart::poll(double now_s, bool velocity_source_exists) {
  if (!pending_fix_) return std::nullopt;
  const bool waiting_for_orientation = config_.use_reference && !orientation_;
  if (now_s - waiting_since_s_ <= config_.max_wait_s) {
    if (waiting_for_orientation) return std::nullopt;  // its IMU message
    // Its velocity: a map-frame one serves a start levelled from gravity too (it needs no
    // orientation; it was dropped there and the start took zero at 15 m/s).
    if (velocity_source_exists && !velocityArrivedForPendingFix()) return std::nullopt;
  } else if (waiting_for_orientation && !imu_seen_) {
    return std::nullopt;  // no IMU message yet: its first may bring the orientation
  }
  Start start;
  start.fix = *pending_fix_;
  start.velocity_map = velocityForPendingFix();
  pending_fix_.reset();
  if (config_.use_reference && orientation_) {
    start.orientation = orientation_;
    start.orientation_covariance = orientation_covariance_;
  }
  return start;
}

void LazyStart::reset() {
  pending_fix_.reset();
  imu_seen_ = false;
  orientation_.reset();
  orientation_covariance_.reset();
  velocity_stamp_s_.reset();
}

}  // namespace estimation
}  // namespace inekf_semantic_mapping
