// One interface for the three IMU + GPS filters (robot_localization's FilterBase idea), so the
// Localizer, inekf_offline and inekf_node run any of them unchanged.
//
// Error coordinates (15-dim: rotation, velocity, position, gyro bias, accel bias):
//  - kLeftInvariant:  eta = X_est^-1 X_true = exp(xi): rotation/velocity/position errors in the
//                     BODY frame (xi_v = R^T (v_true - v_est) to first order).
//  - kRightInvariant: eta = X_true X_est^-1 = exp(xi): errors in the MAP frame, position error
//                     about the map origin (xi_p = p_true - R_true R_est^T p_est).
//  - kQuaternionEskf: R_true = R_est Exp(dtheta) (body small angle), v/p errors additive in map.
// Bias errors are additive (true - estimate) in all three.
#pragma once

#include <memory>

#include "inekf_semantic_mapping/estimation/types.h"

namespace inekf_semantic_mapping {
namespace estimation {

// The land-vehicle constraint's measurement model (NavigationFilter::correctNonholonomic).
struct NonholonomicModel {
  // m/s: sideslip and the lever arm of the IMU from the rear axle in turns (lateral), suspension
  // travel (vertical).
  double lateral_sigma_mps = 0.5;
  double vertical_sigma_mps = 1.0;
  // The vehicle frame (x along the direction of travel, z up) in the IMU frame. An IMU is never
  // mounted exactly along the car's axis: on KITTI's rig the direction of travel points 0.65 deg
  // up in the IMU frame, so that "no vertical velocity" in the IMU's own axes at 10 m/s is a
  // 0.11 m/s error that the filter explains by tilting its attitude (vehicleFrameInImu).
  Eigen::Matrix3d imu_from_vehicle = Eigen::Matrix3d::Identity();
};

// What a standstill measures (NavigationFilter::correctStandstill, StandstillDetector): the
// body velocity is zero, and the gyro's mean over the still interval is its bias.
struct StandstillMeasurement {
  double velocity_sigma_mps = 0.02;
  Eigen::Vector3d mean_angular_velocity = Eigen::Vector3d::Zero();      // rad/s, raw, body frame
  Eigen::Vector3d angular_velocity_variance = Eigen::Vector3d::Zero();  // (rad/s)^2 per axis
};

// imu_from_vehicle for a direction of travel at `pitch_rad` above the IMU's x-y plane (towards
// +z) and `yaw_rad` from its x axis towards +y, with no roll between the two frames.
Eigen::Matrix3d vehicleFrameInImu(double pitch_rad, double yaw_rad);

class NavigationFilter {
 public:
  virtual ~NavigationFilter() = default;

  virtual FilterType type() const = 0;

  // Sets the state and its covariance, in this filter's own error coordinates (order above).
  // Throws std::invalid_argument on a non-finite state or covariance.
  virtual void initialize(const NavState& state, const ErrorCovariance& covariance) = 0;

  // Integrates one IMU sample held constant over dt seconds (closed form on SE_2(3) with the
  // bias-corrected sample) and propagates the covariance with the exact discrete transition.
  // The state's stamp advances by dt. Non-finite input or dt <= 0 is ignored (state kept).
  virtual void propagate(const ImuSample& sample, double dt) = 0;

  // Multiplies the white gyro/accel noise densities used by propagate() from now on (the bias
  // random walks stay: a gap says nothing about the biases); the Localizer raises it over gaps
  // and interpolated samples. 1 = nominal.
  virtual void setProcessNoiseScale(double gyro_scale, double accel_scale) = 0;

  // GPS position fix in the map frame: of the IMU, or of an antenna at fix.antenna_in_imu
  // (y = p + R l, the lever arm's attitude dependence in the Jacobian). Rejected (state unchanged)
  // when the squared Mahalanobis distance of the innovation exceeds gate_mahalanobis_squared, when
  // the input is not finite, or when the update would produce a non-finite state or covariance.
  virtual CorrectionResult correctPosition(const PositionFix& fix,
                                           double gate_mahalanobis_squared) = 0;

  // Land-vehicle (non-holonomic) constraint: the velocity has no lateral (y) and no vertical (z)
  // component in the vehicle frame, up to the model's standard deviations. It makes heading
  // observable on straight roads at constant speed, where GPS positions alone leave it to the
  // gyro's drift. Rejected as correctPosition is (gate on the 2-dof innovation, non-finite input
  // or result, sigmas not positive).
  virtual CorrectionResult correctNonholonomic(const NonholonomicModel& model,
                                               double gate_mahalanobis_squared) = 0;

  // At a standstill (StandstillDetector), two updates gated each on its own 3 dof and rejected
  // as correctPosition is. Zero velocity: the body velocity is 0 +- sigma (H = [0 I 0 0 0] in the
  // left-invariant error, linearised at the zero velocity it measures). Zero rate: the mean
  // measured rate over a still interval is the gyro bias (H = [0 0 0 I 0]).
  virtual CorrectionResult correctZeroVelocity(double sigma_mps,
                                               double gate_mahalanobis_squared) = 0;
  virtual CorrectionResult correctZeroRate(const Eigen::Vector3d& mean_rate_radps,
                                           const Eigen::Vector3d& variance,
                                           double gate_mahalanobis_squared) = 0;

  // Wheel odometry: the vehicle's speed along its direction of travel (the model's vehicle x
  // axis: lateral and vertical are the constraint's), measured `speed_mps` +- sigma_mps; negative
  // when reversing. Gated on its 1 dof with the measurement's own gate_sigma_mps (<= sigma_mps:
  // one of a stream of speeds that share their errors is weighed as a share of them, sigma_mps,
  // but tested as the measurement it is) and rejected as correctPosition is.
  virtual CorrectionResult correctForwardSpeed(const NonholonomicModel& model, double speed_mps,
                                               double sigma_mps, double gate_sigma_mps,
                                               double gate_mahalanobis_squared) = 0;
  // The filter's own speed along the model's vehicle x axis and its variance (first order): what
  // correctForwardSpeed gates a measured speed against.
  virtual double predictedForwardSpeed(const NonholonomicModel& model,
                                       double* variance_m2ps2) const = 0;

  virtual const NavState& state() const = 0;
  virtual ErrorCovariance covariance() const = 0;

  // Euclidean pose covariance for ROS (geometry_msgs PoseWithCovariance order): position error in
  // the map frame (m) first, then the rotation error as a BODY-frame small angle
  // (R_true = R_est Exp(delta), rad). Computed from covariance() to first order.
  virtual PoseCovariance poseCovariance() const = 0;
  // The body-frame twist's covariance (first order): the velocity R^T v and the bias-corrected
  // rate of the last IMU sample (the gyro bias's uncertainty and the sample's own white noise).
  virtual TwistCovariance twistCovariance() const = 0;

  // Maps a "world-frame Euclidean" error [dtheta_map (R_true = Exp(dtheta) R_est), dv_map,
  // dp_map, dbg, dba] into this filter's error coordinates at `state` (first order). Used to
  // build initial covariances (e.g. a yaw sigma about the map z axis) for any filter.
  virtual ErrorCovariance fromWorldCovariance(const NavState& state,
                                              const ErrorCovariance& world_covariance) const = 0;
};

std::unique_ptr<NavigationFilter> makeFilter(FilterType type, const ImuNoise& noise);

}  // namespace estimation
}  // namespace inekf_semantic_mapping
