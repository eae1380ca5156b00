// Plain data types shared by the navigation filters, the Localizer, inekf_offline and inekf_node.
// Frames: `map` (x east, y north, z up, gravity along -z) and the body = IMU frame (x forward,
// y left, z up). All times in seconds, all quantities SI.
#pragma once

#include <Eigen/Core>
#include <string>

namespace inekf_semantic_mapping {
namespace estimation {

struct ImuSample {
  double stamp_s = 0.0;
  Eigen::Vector3d angular_velocity = Eigen::Vector3d::Zero();  // rad/s, body frame
  // m/s^2, body frame, includes the gravity reaction: about +9.81 along z at rest.
  Eigen::Vector3d specific_force = Eigen::Vector3d::Zero();
  // True where the sample is not a real measurement (KITTI posmode -1 frames are interpolated
  // by the dataset): the Localizer inflates the process noise over such a sample.
  bool interpolated = false;
};

struct PositionFix {
  double stamp_s = 0.0;
  // m, map frame: the antenna's position, position + R * antenna_in_imu of the IMU's pose.
  Eigen::Vector3d position_map = Eigen::Vector3d::Zero();
  Eigen::Matrix3d covariance_map = Eigen::Matrix3d::Identity();  // m^2, map frame
  // m, the GPS antenna in the IMU frame (its lever arm); zero: the fix is of the IMU.
  Eigen::Vector3d antenna_in_imu = Eigen::Vector3d::Zero();
  // A fix without altitude (a receiver in a 2D mode): position_map.z() is the filter's own height
  // and covariance_map gives it a nil weight, so the innovation has 2 degrees of freedom, not 3
  // (the Localizer gates it at the same tail probability; diagnostics normalise by 2).
  bool horizontal_only = false;
};

struct NavState {
  double stamp_s = 0.0;
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  // body -> map
  Eigen::Vector3d velocity_map = Eigen::Vector3d::Zero();
  Eigen::Vector3d position_map = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();   // rad/s; true rate = measured - bias
  Eigen::Vector3d accel_bias = Eigen::Vector3d::Zero();  // m/s^2; true = measured - bias
};

// Continuous-time IMU noise densities (white noise and bias random walks).
struct ImuNoise {
  double gyro_noise_density = 7e-4;      // rad/s/sqrt(Hz)
  double accel_noise_density = 0.02;     // m/s^2/sqrt(Hz)
  double gyro_bias_random_walk = 1e-5;   // rad/s^2/sqrt(Hz)
  double accel_bias_random_walk = 1e-4;  // m/s^3/sqrt(Hz)
  double gravity_mps2 = 9.81;            // magnitude; the map frame's gravity is (0, 0, -g)
};

enum class FilterType { kLeftInvariant, kRightInvariant, kQuaternionEskf };

// "left" | "right" | "ekf"; throws std::invalid_argument naming the text otherwise.
FilterType filterTypeFromString(const std::string& text);
std::string toString(FilterType type);  // "left" | "right" | "ekf"

struct CorrectionResult {
  bool accepted = false;
  double mahalanobis_squared = 0.0;  // of the innovation (0 when not computed)
  std::string reason;                // why it was rejected ("" when accepted)
};

// Error-state covariance; block order rotation, velocity, position, gyro bias, accel bias, each
// in the owning filter's own error coordinates (see NavigationFilter).
using ErrorCovariance = Eigen::Matrix<double, 15, 15>;
using PoseCovariance = Eigen::Matrix<double, 6, 6>;
// Body-frame twist covariance, geometry_msgs TwistWithCovariance order: linear velocity (m/s),
// then angular velocity (rad/s).
using TwistCovariance = Eigen::Matrix<double, 6, 6>;

}  // namespace estimation
}  // namespace inekf_semantic_mapping
