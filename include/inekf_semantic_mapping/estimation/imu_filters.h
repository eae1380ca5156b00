// The three NavigationFilter implementations. They share the state propagation and the exact
// left-invariant transition (error_dynamics.h), mapped into each filter's error coordinates by
// errorFromLeft(); they differ in how the error is defined and how a fix corrects the state.
#pragma once

#include <Eigen/Geometry>

#include "inekf_semantic_mapping/estimation/error_dynamics.h"
#include "inekf_semantic_mapping/estimation/navigation_filter.h"

namespace inekf_semantic_mapping {
namespace estimation {

class ImuFilterBase : public NavigationFilter {
 public:
  explicit ImuFilterBase(const ImuNoise& noise) : noise_(noise) {}

  void initialize(const NavState& state, const ErrorCovariance& covariance) override;
  void propagate(const ImuSample& sample, double dt) override;
  void setProcessNoiseScale(double gyro_scale, double accel_scale) override {
    gyro_noise_scale_ = gyro_scale;
    accel_noise_scale_ = accel_scale;
  }
  const NavState& state() const override { return state_; }
  ErrorCovariance covariance() const override { return covariance_; }
  PoseCovariance poseCovariance() const override;
  TwistCovariance twistCovariance() const override;
  ErrorCovariance fromWorldCovariance(const NavState& state,
                                      const ErrorCovariance& world_covariance) const override;

  // Generic in the left-invariant error (H = R_iv^T [v_b^ I 0 0 0] rows y, z, with R_iv the
  // vehicle frame in the IMU's) mapped into this filter's coordinates through leftFromError().
  CorrectionResult correctNonholonomic(const NonholonomicModel& model, double gate) override;
  // Generic in the left-invariant error as well, like the constraint.
  CorrectionResult correctZeroVelocity(double sigma_mps, double gate) override;
  CorrectionResult correctZeroRate(const Eigen::Vector3d& mean_rate_radps,
                                   const Eigen::Vector3d& variance, double gate) override;
  // The constraint's row x (H = e_x^T R_iv^T [v_b^ I 0 0 0]), with a measured value.
  CorrectionResult correctForwardSpeed(const NonholonomicModel& model, double speed_mps,
                                       double sigma_mps, double gate_sigma_mps,
                                       double gate) override;
  double predictedForwardSpeed(const NonholonomicModel& model,
                               double* variance_m2ps2) const override;

  // Linear map from the left-invariant error at `state` to this filter's error (first order).
  virtual Matrix15d errorFromLeft(const NavState& state) const = 0;
  virtual Matrix15d leftFromError(const NavState& state) const = 0;

 protected:
  // The vehicle frame's velocity R_iv^T R^T v (the model's R_iv) and its Jacobian in this
  // filter's error coordinates: the constraint's and the forward speed's rows.
  Eigen::Matrix<double, 3, 15> vehicleVelocityJacobian(const NonholonomicModel& model,
                                                       Eigen::Vector3d* vehicle_velocity) const;
  // Accepts the candidate state and covariance if all finite; returns false otherwise.
  bool commit(const NavState& state, const ErrorCovariance& covariance);
  // Shared Kalman algebra: innovation nu (M), Jacobian H (Mx15), noise N (MxM). Fills the
  // correction delta and the Joseph-form covariance; returns the result (gate, finiteness).
  template <int M>
  CorrectionResult kalmanUpdate(const Eigen::Matrix<double, M, 1>& innovation,
                                const Eigen::Matrix<double, M, 15>& jacobian,
                                const Eigen::Matrix<double, M, M>& noise,
                                double gate_mahalanobis_squared,
                                Eigen::Matrix<double, 15, 1>* correction,
                                ErrorCovariance* updated_covariance) const;
  // The state corrected by `delta` (this filter's error coordinates) and committed with
  // `covariance`; false (state kept) if not finite.
  virtual bool applyCorrection(const Eigen::Matrix<double, 15, 1>& delta,
                               const ErrorCovariance& covariance) = 0;
  static bool finiteFix(const PositionFix& fix);

  ImuNoise noise_;
  double gyro_noise_scale_ = 1.0;
  double accel_noise_scale_ = 1.0;
  NavState state_;
  ErrorCovariance covariance_ = ErrorCovariance::Identity();
  double last_dt_ = 0.0;  // of the last propagation: the white noise of one gyro sample
};

// Left-invariant EKF: body-frame errors; the GPS fix is a left-invariant observation Y = X b,
// so H = [0 0 I 0 0] does not depend on the state: innovation R^T (y - p), noise R^T N R,
// update X <- X exp(K nu) (biases additive).
class LeftInvariantEkf : public ImuFilterBase {
 public:
  using ImuFilterBase::ImuFilterBase;
  FilterType type() const override { return FilterType::kLeftInvariant; }
  CorrectionResult correctPosition(const PositionFix& fix, double gate) override;
  Matrix15d errorFromLeft(const NavState& state) const override;
  Matrix15d leftFromError(const NavState& state) const override;

 protected:
  bool applyCorrection(const Eigen::Matrix<double, 15, 1>& delta,
                       const ErrorCovariance& covariance) override;
};

// Right-invariant EKF: map-frame errors (X_true = exp(xi) X_est). For a position fix
// H = [-p^ 0 I 0 0] (state dependent: GPS is not a right-invariant observation), update
// X <- exp(K nu) X.
class RightInvariantEkf : public ImuFilterBase {
 public:
  using ImuFilterBase::ImuFilterBase;
  FilterType type() const override { return FilterType::kRightInvariant; }
  CorrectionResult correctPosition(const PositionFix& fix, double gate) override;
  Matrix15d errorFromLeft(const NavState& state) const override;
  Matrix15d leftFromError(const NavState& state) const override;

 protected:
  bool applyCorrection(const Eigen::Matrix<double, 15, 1>& delta,
                       const ErrorCovariance& covariance) override;
};

// Conventional quaternion error-state EKF: R_true = R Exp(dtheta_body), v and p additive in the
// map frame; H = [0 0 I 0 0]; the attitude is kept as a unit quaternion.
class QuaternionEskf : public ImuFilterBase {
 public:
  using ImuFilterBase::ImuFilterBase;
  FilterType type() const override { return FilterType::kQuaternionEskf; }
  void initialize(const NavState& state, const ErrorCovariance& covariance) override;
  void propagate(const ImuSample& sample, double dt) override;
  CorrectionResult correctPosition(const PositionFix& fix, double gate) override;
  Matrix15d errorFromLeft(const NavState& state) const override;
  Matrix15d leftFromError(const NavState& state) const override;

 protected:
  bool applyCorrection(const Eigen::Matrix<double, 15, 1>& delta,
                       const ErrorCovariance& covariance) override;

 private:
  Eigen::Quaterniond attitude_ = Eigen::Quaterniond::Identity();
};

}  // namespace estimation
}  // namespace inekf_semantic_mapping
