// Standstill from the IMU, the filter's own velocity and the GPS track: while a vehicle stands
// still its velocity is zero and its gyro reads its own bias, two measurements a MEMS IMU needs
// (at rest an accelerometer bias of 0.1 m/s^2 walks the position 20 m in a minute without fixes,
// and nothing else observes the gyro bias before the vehicle drives). Eigen only, no ROS.
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
  // (bias-corrected, gravity removed: the acceleration) below max_acceleration_mps2, and its mean
  // bias-corrected rate below max_rate_degps plus three sigmas of the gyro bias (a turn-on bias
  // not yet learnt; at most three times max_rate_degps in all). A car or robot leaving a
  // standstill accelerates at 0.3-3 m/s^2.
  double window_s = 0.5;
  double max_acceleration_mps2 = 0.2;
  double max_rate_degps = 1.0;
  // An IMU cannot tell a vehicle driving steadily on a smooth road from one standing still; the
  // filter's velocity and the fixes can. Still needs either the filter's horizontal speed below
  // max_speed_mps by two of its sigmas (and the fixes not saying it moves; a start without a
  // velocity waits), or the fixes of the last kFixesWindowS standing (their track slower than
  // max_speed_mps by two of its sigmas) with the IMU steady all that time: a MEMS robot standing
  // with 1.5 m fixes knows its own velocity only to 0.5-1 m/s, its estimate wandering over 1 m/s.
  double max_speed_mps = 0.3;
  // Applied at most once per update_interval_s (the same information per second at any IMU
  // rate): the velocity is zero up to velocity_sigma_mps; the mean gyro over the interval is the
  // bias, its variance the larger of the noise density's over the interval and the samples' own
  // scatter (vibration). Each part is gated on its own 3 dof.
  double velocity_sigma_mps = 0.02;
  double update_interval_s = 0.1;
  double gate_mahalanobis_squared = 16.3;  // 3 dof: chi2 p = 1e-3
};

// Throws std::invalid_argument naming the option when one is out of range.
void validate(const StandstillOptions& options);

class StandstillDetector {
 public:
  // How long the GPS track must have stood (and the IMU been steady) for a vague velocity.
  // 20 s of 1.5 m fixes once a second: the track's speed to 0.05 m/s (10 s: 0.14, which let
  // robots creeping at 0.4-0.8 m/s pass for standing now and then).
  static constexpr double kFixesWindowS = 20.0;
  // How long the raw readings must have been steady before the filter's own speed may say still.
  static constexpr double kSettleS = 2.0;

  // What the fixes of the last kFixesWindowS say (the caller's fit of the GPS track).
  enum class Fixes { kUnknown, kStanding, kMoving };

  // What the filter and the fixes say besides the IMU sample.
  struct Context {
    double velocity_sigma_mps = 0.0;     // the map-frame horizontal velocity's (larger axis)
    double gyro_bias_sigma_radps = 0.0;  // the gyro bias's (norm over the axes)
    Fixes fixes = Fixes::kUnknown;
    double gyro_noise_density = 0.0;  // rad/s/sqrt(Hz)
  };

  explicit StandstillDetector(const StandstillOptions& options);

  // Forgets the window (a gap, an interpolated sample, a reset of the filter).
  void reset();

  // One IMU sample held over dt, with the filter's state before it. Returns the measurement to
  // apply after this step when the vehicle has stood still over the whole window and
  // update_interval_s has passed since the last one.
  std::optional<StandstillMeasurement> add(const ImuSample& sample, double dt,
                                           const NavState& state, const Context& context);

  // The last sample's verdict (diagnostics, tests).
  bool still() const { return still_; }

 private:
  struct WindowSample {
    double dt = 0.0;
    Eigen::Vector2d acceleration = Eigen::Vector2d::Zero();  // levelled, horizontal
    Eigen::Vector3d rate = Eigen::Vector3d::Zero();          // bias-corrected
    Eigen::Vector3d raw_force = Eigen::Vector3d::Zero(), raw_rate = Eigen::Vector3d::Zero();
  };

  StandstillOptions options_;
  std::deque<WindowSample> window_;
  Eigen::Vector2d acceleration_sum_ = Eigen::Vector2d::Zero();  // dt-weighted over the window
  Eigen::Vector3d rate_sum_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d raw_force_sum_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d raw_rate_sum_ = Eigen::Vector3d::Zero();
  double window_duration_s_ = 0.0;
  // How long the raw readings' window mean has stayed near its value when they became steady.
  double steady_s_ = 0.0;
  Eigen::Vector3d steady_force_ = Eigen::Vector3d::Zero(), steady_rate_ = Eigen::Vector3d::Zero();
  // Since the last measurement, while still: the raw gyro's dt-weighted sum, its samples and the
  // time they span.
  Eigen::Vector3d raw_rate_integral_ = Eigen::Vector3d::Zero();
  int raw_rate_count_ = 0;
  double still_duration_s_ = 0.0;
  bool still_ = false;
};

}  // namespace estimation
}  // namespace inekf_semantic_mapping
