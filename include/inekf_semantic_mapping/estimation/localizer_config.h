// LocalizerConfig: every parameter of the Localizer, read from the keys of config/inekf.yaml by
// one checked reader (inekf_node, inekf_offline and the localization session share it).
#pragma once

#include <string>

#include "inekf_semantic_mapping/estimation/standstill_detector.h"
#include "inekf_semantic_mapping/estimation/types.h"

namespace inekf_semantic_mapping {
namespace common {
class YamlReader;
}  // namespace common
namespace estimation {

// Defaults = config/inekf.yaml (tuned on KITTI, see the comments there).
struct LocalizerConfig {
  FilterType filter_type = FilterType::kLeftInvariant;
  ImuNoise imu_noise;

  // Initial 1-sigma uncertainties.
  double initial_rotation_sigma_deg = 0.5;  // roll and pitch (about the map x and y axes)
  double initial_yaw_sigma_deg = 1.0;       // about the map z axis
  double initial_velocity_sigma_mps = 0.5;
  // When the lazy start has no velocity reference (no GPS velocity message yet, or levelling
  // from the specific force) the state starts at zero velocity with this sigma, horizontal and
  // vertical: a car may already be driving at motorway speed. Zero +- 0.5 m/s there makes the
  // first fixes of a moving car fail the gate (gtest LazyStartWithoutAVelocity...).
  double unknown_velocity_sigma_horizontal_mps = 15.0;
  double unknown_velocity_sigma_vertical_mps = 2.0;
  // Yaw sigma of a lazy start levelled from gravity (no orientation reference): yaw 0 is a guess.
  double unknown_yaw_sigma_deg = 180.0;
  double initial_position_sigma_m = 2.0;
  double initial_gyro_bias_sigma_radps = 1e-4;
  double initial_accel_bias_sigma_mps2 = 0.03;

  double gps_gate_mahalanobis_squared = 30.0;  // 3 dof
  double min_gps_sigma_m = 0.3;
  double max_imu_gap_s = 0.5;
  double gap_noise_scale = 10.0;  // multiplies the noise densities over a gap
  // ... and the gyro's is at least this times the gap's length (s): the heading change inside a
  // gap is unknown (a 2.2 s gap in a turn of 2011_09_26_drive_0036 left the heading 20 deg off
  // with a stated sigma of 0.6 deg; the fixes took 15 s to bring it within 1 deg).
  double gap_gyro_noise_scale_per_s = 100.0;
  // Over a sample flagged `interpolated`: KITTI's linear interpolation of the gyro across a
  // dropout integrates to the wrong heading change (up to ~12 deg over a 1.4 s run, nothing
  // over one or two frames), so the gyro noise scale grows with the time spent inside the run:
  // scale = max(1, interpolated_gyro_noise_scale_per_s * seconds since the run began).
  double interpolated_gyro_noise_scale_per_s = 100.0;
  double interpolated_accel_noise_scale = 3.0;
  double max_fix_age_s = 0.5;
  double fix_history_s = 2.0;  // how late a fix may arrive and still be applied at its own time
  int max_consecutive_rejected_fixes = 5;  // then re-acquire (see above); <= 0: never
  // Re-acquisition moves the estimate to the fix: never faster than a car can move since the
  // last accepted fix (a fix 1000 km away is a broken receiver, not a wrong filter).
  double max_reacquisition_speed_mps = 70.0;
  // IMU samples beyond the sensor's range are faults, not motion: rejected like NaN samples.
  double max_angular_rate_radps = 35.0;    // 2000 deg/s, the widest common MEMS range
  double max_specific_force_mps2 = 160.0;  // 16 g

  // Land-vehicle constraint after every IMU step (NavigationFilter::correctNonholonomic): the
  // body velocity has no lateral / vertical component, up to these sigmas. Only for an IMU fixed
  // to a wheeled vehicle (this package's use: a car), its forward axis base_link's x
  // (Localizer::setImuMounting: inekf_node reads it from tf); false for anything else.
  bool nonholonomic = true;
  double nonholonomic_lateral_sigma_mps = 0.5;
  double nonholonomic_vertical_sigma_mps = 1.0;
  // The sigmas are per IMU step of at least this long; a shorter step's variances are scaled by
  // min_step / dt, so that a fast IMU holds the velocity at most as hard per second as steps of
  // this length (a 100 Hz IMU held it ten times as hard as KITTI's 10 Hz OXTS). 0.05 leaves
  // KITTI's steps (0.06 s and longer) as they were tuned; config/robot_inekf.yaml says 0.1.
  double nonholonomic_min_step_s = 0.05;
  // The direction of travel (NonholonomicModel::imu_from_vehicle): degrees above base_link's
  // x-y plane and from its x axis towards +y (the IMU's axes when it is mounted as base_link).
  // 0, 0: base_link's x axis is the car's. config/inekf.yaml holds KITTI's; inekf_offline --smooth
  // reports a drive's own.
  double nonholonomic_vehicle_pitch_deg = 0.0;
  double nonholonomic_vehicle_yaw_deg = 0.0;
  double nonholonomic_gate_mahalanobis_squared = 13.8;  // 2 dof: chi2 p = 1e-3
  // The constraint cannot tell forward from backward: with the heading this uncertain (1 sigma
  // about the body z axis) it would as soon turn the car around as converge. Skipped until then.
  double nonholonomic_max_heading_sigma_deg = 10.0;

  // Zero-velocity and zero-rate updates while the vehicle stands still (StandstillDetector).
  // Off by default: KITTI's OXTS holds its biases itself (config/robot_inekf.yaml turns it on).
  StandstillOptions standstill;

  // Wheel odometry's forward speed (Localizer::addWheelSpeed): the speed along the direction of
  // travel (the constraint's vehicle x axis), applied at the filter's newest IMU time.
  struct WheelSpeedOptions {
    bool enabled = true;             // off: every wheel speed is counted and ignored
    double default_sigma_mps = 0.1;  // where the message states no variance
    double min_sigma_mps = 0.02;     // the floor of every sigma
    // A fraction of the speed added to its sigma: the wheels' scale (tyre radius, load, a
    // calibration) is a bias, not noise, and a filter that took it for noise grew confident of a
    // wrong speed (a 3 % error: the returning fixes rejected, the heading re-opened, 81 deg off).
    double scale_sigma = 0.05;
    // Speeds closer together than this count together as one (their sigma scaled by
    // sqrt(min_interval_s / interval)): consecutive wheel speeds share their errors.
    double min_interval_s = 1.0;
    double max_age_s = 0.1;                  // from the filter's time, either way; older: stale
    double max_acceleration_mps2 = 3.0;      // an aged speed's sigma grows by this times its age
    double gate_mahalanobis_squared = 10.8;  // 1 dof: chi2 p = 1e-3
    // This many gated out in a row (slip, a wrong scale or sign): none is used until a fix is
    // accepted or as many in a row agree with the filter again (a slip let through once the
    // filter's sigma had grown, then the true speeds were rejected: 34 m off after a 5 s slip of
    // 1 m/s). 0: never suspended.
    int max_rejected_in_a_row = 5;
  } wheel_speed;

  // Lazy initialization (LocalizationSession's start): take rotation and velocity from
  // setInitialReference() (the orientation of the first Imu message that has one) instead of
  // levelling with yaw 0 and zero speed. The reference rotation's covariance is the one the
  // message states; where it states none (all zeros) initial_rotation_sigma_deg / _yaw_ apply.
  bool init_orientation_from_reference = true;

  // The heading monitor (see the class comment above).
  bool heading_from_track = true;
  double heading_track_window_s = 20.0;
  double heading_track_min_speed_mps = 3.0;
  double heading_track_min_chord_m = 8.0;   // a chord spans at least this far ...
  double heading_track_max_chord_s = 10.0;  // ... within this long (and two fix intervals)
  // A chord over more than two fix intervals whose gyro heading turns by more than this is left
  // out; its turn adds (turn_weight * turn)^2 to its variance (the tangent-at-the-middle rule is
  // exact only on a circle).
  double heading_track_max_turn_deg = 45.0;
  double heading_track_turn_weight = 0.1;
  double heading_track_chord_floor_deg = 2.0;  // per chord: sideslip, turns of varying rate
  int heading_track_min_chords = 3;
  double heading_align_above_sigma_deg = 10.0;
  double heading_align_max_sigma_deg = 5.0;
  double heading_check_sigmas = 4.0;
  double heading_check_min_deg = 5.0;
  int heading_reopen_after_rejected_fixes = 3;  // <= 0: never
  int heading_nis_window_fixes = 10;            // <= 0: no window check
  double heading_nis_window_max = 6.0;          // mean horizontal NIS (2 dof: expect 2)
  // While the yaw sigma exceeds heading_align_above_sigma_deg, the fixes do not rotate the
  // heading (its cross-covariances are removed before each fix): the track aligns it. Off by
  // default: on KITTI it leaves the smoothed IMU+GPS-only runs worse (0027: 1.16 m, 0.99 off).
  bool heading_hold_unknown_yaw = false;

  // Reads the YAML file (keys as in config/inekf.yaml; missing keys keep the defaults above; the
  // top-level `session:` section is LocalizationSessionConfig's, a `node:` one the node's).
  // Throws common::ConfigError (a std::invalid_argument) naming the file and the key on a bad
  // value or an unknown key.
  static LocalizerConfig fromYamlFile(const std::string& path);
  // Reads this config's keys through `reader` (which then knows them as read): the session reads
  // its own section through the same reader, so one file is parsed and checked once.
  static LocalizerConfig fromYaml(common::YamlReader* reader);
};

}  // namespace estimation
}  // namespace inekf_semantic_mapping
