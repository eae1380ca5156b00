// Standstill from the IMU and the filter's own velocity: while a vehicle stands still its
// velocity is zero and its gyro reads its own bias, two measurements a MEMS IMU needs (at rest
// an accelerometer bias of 0.1 m/s^2 walks the position 20 m in a minute without fixes, and
// nothing else observes the gyro bias before the vehicle drives). Eigen only, no ROS.
#pragma once

#include <Eigen/Core>
#include <deque>
#include <optional>

#include "inekf_semantic_mapping/estimation/navigation_filter.h"

namespace inekf_semantic_mapping {
namespace estimation {

struct StandstillOptions {
  bool enabled = false;
  // The IMU must have been quiet this long: the window's mean levelled horizontal specific force
  // (bias-corrected, gravity removed: the acceleration) and mean bias-corrected rate below
  // these. A car or robot leaving a standstill accelerates at 0.3-3 m/s^2.
  double window_s = 0.5;
  double max_acceleration_mps2 = 0.2;
  double max_rate_degps = 1.0;
  // An IMU cannot tell a car driving steadily on a smooth road from a car standing still; the
  // filter's velocity can: its horizontal speed and the speed's sigma both below max_speed_mps.
  // A MEMS robot standing with 1.5 m fixes knows its velocity only to about 0.5 m/s: then a
  // speed within max_speed_mps plus two sigmas, the sigma below max_velocity_sigma_mps, and the
  // recent fixes not moving (the caller's verdict) will do. A start without a velocity
  // (unknown_velocity_sigma_*) waits until the fixes have measured it.
  double max_speed_mps = 0.3;
  double max_velocity_sigma_mps = 1.0;
  // Applied at most once per update_interval_s (the same information per second at any IMU
  // rate): the velocity is zero up to velocity_sigma_mps; the mean gyro over the interval is
  // the bias, with the variance the gyro noise density gives over that time.
  double velocity_sigma_mps = 0.02;
  double update_interval_s = 0.1;
  double gate_mahalanobis_squared = 22.5;  // 6 dof: chi2 p = 1e-3
};

// Throws std::invalid_argument naming the option when one is out of range.
void validate(const StandstillOptions& options);

class StandstillDetector {
 public:
  explicit StandstillDetector(const StandstillOptions& options);

  // Forgets the window (a gap, an interpolated sample, a reset of the filter).
  void reset();

  // One IMU sample held over dt, with the filter's state before it, the horizontal velocity's
  // sigma (m/s, the larger axis) and whether the recent fixes move faster than max_speed_mps.
  // Returns the measurement to apply after this step when the vehicle has stood still over the
  // whole window and update_interval_s has passed since the last one; gyro_noise_density
  // (rad/s/sqrt(Hz)) gives the mean rate's variance.
  std::optional<StandstillMeasurement> add(const ImuSample& sample, double dt,
                                           const NavState& state, double velocity_sigma_mps,
                                           bool fixes_say_moving, double gyro_noise_density);

  // The last sample's verdict (diagnostics, tests).
  bool still() const { return still_; }

 private:
  struct WindowSample {
    double stamp_s = 0.0, dt = 0.0;
    Eigen::Vector2d acceleration = Eigen::Vector2d::Zero();  // levelled, horizontal
    Eigen::Vector3d rate = Eigen::Vector3d::Zero();          // bias-corrected
  };

  StandstillOptions options_;
  std::deque<WindowSample> window_;
  Eigen::Vector2d acceleration_sum_ = Eigen::Vector2d::Zero();  // dt-weighted over the window
  Eigen::Vector3d rate_sum_ = Eigen::Vector3d::Zero();
  double window_duration_s_ = 0.0;
  // Since the last measurement, while still: the raw gyro integrated and the time it spans.
  Eigen::Vector3d raw_rate_integral_ = Eigen::Vector3d::Zero();
  double still_duration_s_ = 0.0;
  bool still_ = false;
};

}  // namespace estimation
}  // namespace inekf_semantic_mapping
