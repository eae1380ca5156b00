// When and with what a streaming filter starts, when its first fix, the IMU orientation and the
// GPS velocity arrive on separate connections in any order (LocalizationSession, for inekf_node
// and inekf_offline alike): at the newest fix, with
// the orientation of the latest IMU message and the velocity of the fix's instant, once those
// have arrived, or once a message max_wait_s (data time) newer than the first waiting fix shows
// that they are not coming. Before this existed, a fix handled before any IMU message started the
// filter levelled with yaw 0 (CI: e2e_real_oxts ATE 9.6 m, yaw error 42 deg on a drive heading
// -44.5).
#pragma once

#include <Eigen/Core>
#include <optional>

#include "inekf_semantic_mapping/estimation/types.h"

namespace inekf_semantic_mapping {
namespace estimation {

class LazyStart {
 public:
  struct Config {
    double max_wait_s = 0.2;          // data time a start waits for its IMU and velocity
    double max_velocity_age_s = 0.2;  // a velocity further than this from the fix is not its own
    // false: start levelled from gravity, not waiting for an orientation (only for the GPS
    // velocity of the fix's instant where one is published).
    bool use_reference = true;
  };

  // What to start the Localizer with (Localizer::setInitialReference with an orientation, else
  // setInitialVelocity; then addPositionFix).
  struct Start {
    PositionFix fix;
    std::optional<Eigen::Matrix3d> orientation;  // body -> map
    // The orientation's stated covariance (rad^2, small angles about the map axes, as
    // sensor_msgs/Imu); nullopt or all zeros: not stated (the Localizer's configured sigmas).
    std::optional<Eigen::Matrix3d> orientation_covariance;
    // The GPS velocity of the fix's instant: a map-frame one with or without an orientation, a
    // body-frame one only with the orientation (rotated by it).
    std::optional<Eigen::Vector3d> velocity_map;
  };

  explicit LazyStart(Config config) : config_(config) {}

  // The newest fix replaces one still waiting; the wait is counted from the first (a GPS faster
  // than 1 / max_wait_s would otherwise restart it with every fix, and a start waiting for an
  // orientation the IMU does not publish would never come).
  void offerFix(const PositionFix& fix) {
    if (!pending_fix_) waiting_since_s_ = fix.stamp_s;
    pending_fix_ = fix;
  }
  // An IMU message arrived, with or without an orientation: once the wait is over, one without
  // is not waited for any longer (before any IMU message, the start still waits for one).
  void noteImu() { imu_seen_ = true; }
  // The orientation (body -> map) of the latest IMU message that has one, with its stated
  // covariance (nullopt: none stated).
  void offerOrientation(const Eigen::Matrix3d& body_to_map,
                        const std::optional<Eigen::Matrix3d>& covariance = std::nullopt);
  // A GPS velocity, in the map frame or, with in_body_frame, in the body frame (rotated by the
  // orientation the start is made with).
  void offerVelocity(double stamp_s, const Eigen::Vector3d& velocity, bool in_body_frame);

  // Called after each message (stamped now_s) while the filter has not started. Returns the
  // start to make now, and forgets the fix; nullopt while there is none or it still waits.
  // velocity_source_exists: a GPS velocity is being published (else there is nothing to wait
  // for).
  std::optional<Start> poll(double now_s, bool velocity_source_exists);

  bool waiting() const { return pending_fix_.has_value(); }
  // Forgets everything (the filter was reset).
  void reset();

 private:
  std::optional<Eigen::Vector3d> velocityForPendingFix() const;
  bool velocityArrivedForPendingFix() const;

  Config config_;
  std::optional<PositionFix> pending_fix_;
  double waiting_since_s_ = 0.0;  // the stamp of the first fix of this wait
  bool imu_seen_ = false;
  std::optional<Eigen::Matrix3d> orientation_;
  std::optional<Eigen::Matrix3d> orientation_covariance_;
  std::optional<double> velocity_stamp_s_;
  Eigen::Vector3d velocity_ = Eigen::Vector3d::Zero();
  bool velocity_in_body_frame_ = false;
};

}  // namespace estimation
}  // namespace inekf_semantic_mapping
