#include "inekf_semantic_mapping/estimation/imu_filters.h"

#include <Eigen/Cholesky>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

#include "inekf_semantic_mapping/lie/se23.h"
#include "inekf_semantic_mapping/lie/so3.h"

namespace inekf_semantic_mapping {
namespace estimation {

Eigen::Matrix3d vehicleFrameInImu(double pitch_rad, double yaw_rad) {
  // Yaw about z, then a rotation about y by -pitch: x = (1, 0, 0) goes to
  // (cos p cos y, cos p sin y, sin p).
  return lie::expSO3(Eigen::Vector3d(0.0, 0.0, yaw_rad)) *
         lie::expSO3(Eigen::Vector3d(0.0, -pitch_rad, 0.0));
}

namespace {

using Vector15d = Eigen::Matrix<double, 15, 1>;
using lie::ExtendedPose;

ErrorCovariance symmetrized(const ErrorCovariance& p) { return 0.5 * (p + p.transpose()); }

bool finiteState(const NavState& s) {
  return std::isfinite(s.stamp_s) && s.rotation.allFinite() && s.velocity_map.allFinite() &&
         s.position_map.allFinite() && s.gyro_bias.allFinite() && s.accel_bias.allFinite();
}

ExtendedPose extendedPose(const NavState& s) {
  ExtendedPose x;
  x.rotation = s.rotation;
  x.velocity = s.velocity_map;
  x.position = s.position_map;
  return x;
}

void setExtendedPose(const ExtendedPose& x, NavState* s) {
  s->rotation = x.rotation;
  s->velocity_map = x.velocity;
  s->position_map = x.position;
}

// t p t^T for the block-sparse coordinate maps (3x3 blocks; most are zero): skips the zero
// blocks, about a tenth of the work of two dense 15x15 products.
Matrix15d sandwich(const Matrix15d& t, const Matrix15d& p) {
  bool nonzero[5][5];
  for (int i = 0; i < 5; ++i) {
    for (int k = 0; k < 5; ++k) nonzero[i][k] = !t.block<3, 3>(3 * i, 3 * k).isZero(0.0);
  }
  Matrix15d tp = Matrix15d::Zero();
  for (int i = 0; i < 5; ++i) {
    for (int k = 0; k < 5; ++k) {
      if (nonzero[i][k]) {
        tp.middleRows<3>(3 * i).noalias() += t.block<3, 3>(3 * i, 3 * k) * p.middleRows<3>(3 * k);
      }
    }
  }
  Matrix15d out = Matrix15d::Zero();
  for (int j = 0; j < 5; ++j) {
    for (int k = 0; k < 5; ++k) {
      if (nonzero[j][k]) {
        out.middleCols<3>(3 * j).noalias() +=
            tp.middleCols<3>(3 * k) * t.block<3, 3>(3 * j, 3 * k).transpose();
      }
    }
  }
  return out;
}

Eigen::Matrix<double, 3, 15> positionJacobian() {
  Eigen::Matrix<double, 3, 15> h = Eigen::Matrix<double, 3, 15>::Zero();
  h.block<3, 3>(0, 6).setIdentity();
  return h;
}

}  // namespace

namespace {
CorrectionResult rejectNonFinite(CorrectionResult result) {
  result.accepted = false;
  result.reason = "update would produce a non-finite state";
  return result;
}
CorrectionResult rejectBadFix() {
  CorrectionResult result;
  result.reason = "non-finite fix";
  return result;
}
}  // namespace

// ---------------------------------------------------------------------------------------------
// ImuFilterBase

void ImuFilterBase::initialize(const NavState& state, const ErrorCovariance& covariance) {
  // A non-finite start would be kept, and every later step refused without a word.
  if (!state.rotation.allFinite() || !state.velocity_map.allFinite() ||
      !state.position_map.allFinite() || !state.gyro_bias.allFinite() ||
      !state.accel_bias.allFinite() || !std::isfinite(state.stamp_s)) {
    throw std::invalid_argument("filter initialised with a non-finite state");
  }
  if (!covariance.allFinite()) {
    throw std::invalid_argument("filter initialised with a non-finite covariance");
  }
  state_ = state;
  state_.rotation = lie::normalizeRotation(state.rotation);
  covariance_ = symmetrized(covariance);
}

void ImuFilterBase::propagate(const ImuSample& sample, double dt) {
  if (!(dt > 0.0) || !std::isfinite(dt) || !sample.angular_velocity.allFinite() ||
      !sample.specific_force.allFinite()) {
    return;
  }
  const Eigen::Vector3d w = sample.angular_velocity - state_.gyro_bias;
  const Eigen::Vector3d a = sample.specific_force - state_.accel_bias;
  const NavState next =
      integrateImu(state_, sample.angular_velocity, sample.specific_force, noise_.gravity_mps2, dt);
  const Matrix15d phi = leftErrorTransition(w, a, dt);
  const Matrix15d q =
      leftProcessNoise(w, a, noise_, gyro_noise_scale_, accel_noise_scale_, dt, phi);
  ErrorCovariance next_covariance;
  if (type() == FilterType::kLeftInvariant) {
    next_covariance = propagateLeftCovariance(phi, covariance_) + q;
  } else {
    const Matrix15d to_left = leftFromError(state_);
    const Matrix15d from_left = errorFromLeft(next);
    const Matrix15d left_next = propagateLeftCovariance(phi, sandwich(to_left, covariance_)) + q;
    next_covariance = sandwich(from_left, left_next);
  }
  if (commit(next, symmetrized(next_covariance))) last_dt_ = dt;
}

bool ImuFilterBase::commit(const NavState& state, const ErrorCovariance& covariance) {
  if (!finiteState(state) || !covariance.allFinite()) return false;
  state_ = state;
  state_.rotation = lie::normalizeRotation(state.rotation);
  covariance_ = covariance;
  return true;
}

PoseCovariance ImuFilterBase::poseCovariance() const {
  const Matrix15d to_left = leftFromError(state_);
  const ErrorCovariance left = sandwich(to_left, covariance_);
  Eigen::Matrix<double, 6, 15> j = Eigen::Matrix<double, 6, 15>::Zero();
  j.block<3, 3>(0, 6) = state_.rotation;  // dp_map = R xi_p
  j.block<3, 3>(3, 0).setIdentity();      // body small angle = xi_R
  const PoseCovariance pose = j * left * j.transpose();
  return 0.5 * (pose + pose.transpose());
}

TwistCovariance ImuFilterBase::twistCovariance() const {
  const Matrix15d to_left = leftFromError(state_);
  const ErrorCovariance left = sandwich(to_left, covariance_);
  // Left-invariant error: R_true^T v_true = v_b + xi_v + v_b^ xi_R; the true rate is the
  // measured one less b_true = b + xi_bg.
  const Eigen::Vector3d v_b = state_.rotation.transpose() * state_.velocity_map;
  Eigen::Matrix<double, 6, 15> j = Eigen::Matrix<double, 6, 15>::Zero();
  j.block<3, 3>(0, 0) = lie::hat(v_b);
  j.block<3, 3>(0, 3).setIdentity();
  j.block<3, 3>(3, 9) = -Eigen::Matrix3d::Identity();
  TwistCovariance twist = j * left * j.transpose();
  if (last_dt_ > 0.0) {  // a rate density over one sample's interval
    const double density = noise_.gyro_noise_density * gyro_noise_scale_;
    twist.bottomRightCorner<3, 3>() += Eigen::Matrix3d::Identity() * density * density / last_dt_;
  }
  return 0.5 * (twist + twist.transpose());
}

ErrorCovariance ImuFilterBase::fromWorldCovariance(const NavState& state,
                                                   const ErrorCovariance& world) const {
  Matrix15d world_to_left = Matrix15d::Identity();
  const Eigen::Matrix3d rt = state.rotation.transpose();
  for (int block = 0; block < 3; ++block) world_to_left.block<3, 3>(3 * block, 3 * block) = rt;
  const Matrix15d world_to_error = errorFromLeft(state) * world_to_left;
  return symmetrized(world_to_error * world * world_to_error.transpose());
}

template <int M>
CorrectionResult ImuFilterBase::kalmanUpdate(const Eigen::Matrix<double, M, 1>& innovation,
                                             const Eigen::Matrix<double, M, 15>& h,
                                             const Eigen::Matrix<double, M, M>& noise, double gate,
                                             Eigen::Matrix<double, 15, 1>* correction,
                                             ErrorCovariance* updated) const {
  CorrectionResult result;
  const Eigen::Matrix<double, 15, M> pht = covariance_ * h.transpose();
  const Eigen::Matrix<double, M, M> s = h * pht + noise;
  Eigen::LLT<Eigen::Matrix<double, M, M>> llt(s);
  if (!s.allFinite() || !innovation.allFinite() || llt.info() != Eigen::Success) {
    result.reason = "innovation covariance not positive definite or not finite";
    return result;
  }
  result.mahalanobis_squared = innovation.dot(llt.solve(innovation));
  if (!(result.mahalanobis_squared <= gate)) {
    char text[128];
    std::snprintf(text, sizeof(text), "outlier: Mahalanobis^2 %.1f > gate %.1f",
                  result.mahalanobis_squared, gate);
    result.reason = text;
    return result;
  }
  const Eigen::Matrix<double, 15, M> gain = llt.solve(pht.transpose()).transpose();
  *correction = gain * innovation;
  // Joseph form (I - KH) P (I - KH)^T + K N K^T: a sum of two congruences of positive
  // semi-definite matrices, so it stays one in floating point where P - KHP (and its expanded
  // algebra P - K (PH^T)^T - (PH^T) K^T + K S K^T) cancels to negative variances: a precise fix
  // on a prior of kilometres. Two 15x15 products per update, a few microseconds.
  const Matrix15d i_kh = Matrix15d::Identity() - gain * h;
  *updated = symmetrized(i_kh * covariance_ * i_kh.transpose() + gain * noise * gain.transpose());
  result.accepted = true;
  return result;
}

Eigen::Matrix<double, 3, 15> ImuFilterBase::vehicleVelocityJacobian(
    const NonholonomicModel& model, Eigen::Vector3d* vehicle_velocity) const {
  // Left-invariant error xi (X_true = X exp(xi)): R_true = R (I + xi_R^), v_true = v + R xi_v,
  // so the body velocity R_true^T v_true = v_b + xi_v + v_b^ xi_R to first order; the vehicle
  // frame's velocity is R_iv^T times that.
  const Eigen::Matrix3d vehicle_from_imu = model.imu_from_vehicle.transpose();
  const Eigen::Vector3d body_velocity = state_.rotation.transpose() * state_.velocity_map;
  *vehicle_velocity = vehicle_from_imu * body_velocity;
  Eigen::Matrix<double, 3, 15> h_left = Eigen::Matrix<double, 3, 15>::Zero();
  h_left.block<3, 3>(0, 0) = vehicle_from_imu * lie::hat(body_velocity);
  h_left.block<3, 3>(0, 3) = vehicle_from_imu;
  return h_left * leftFromError(state_);
}

CorrectionResult ImuFilterBase::correctNonholonomic(const NonholonomicModel& model, double gate) {
  CorrectionResult result;
  const double lateral = model.lateral_sigma_mps, vertical = model.vertical_sigma_mps;
  if (!(lateral > 0.0) || !(vertical > 0.0) || !std::isfinite(lateral) ||
      !std::isfinite(vertical) || !model.imu_from_vehicle.allFinite()) {
    result.reason = "non-holonomic sigmas must be positive and finite, the vehicle frame finite";
    return result;
  }
  Eigen::Vector3d vehicle_velocity;
  const Eigen::Matrix<double, 3, 15> jacobian = vehicleVelocityJacobian(model, &vehicle_velocity);
  const Eigen::Matrix<double, 2, 15> h = jacobian.bottomRows<2>();
  // Measured: 0 lateral, 0 vertical in the vehicle frame.
  const Eigen::Vector2d innovation = -vehicle_velocity.tail<2>();
  const Eigen::Matrix2d noise =
      Eigen::Vector2d(lateral * lateral, vertical * vertical).asDiagonal();
  Vector15d delta;
  ErrorCovariance updated;
  result = kalmanUpdate<2>(innovation, h, noise, gate, &delta, &updated);
  if (!result.accepted) return result;
  return applyCorrection(delta, updated) ? result : rejectNonFinite(result);
}

CorrectionResult ImuFilterBase::correctZeroVelocity(double sigma, double gate) {
  CorrectionResult result;
  if (!(sigma > 0.0) || !std::isfinite(sigma)) {
    result.reason = "the zero-velocity sigma must be positive and finite";
    return result;
  }
  // The body velocity R_true^T v_true = v_b + xi_v + v_b^ xi_R (as in correctNonholonomic),
  // measured 0, linearised at the velocity the measurement says is true, zero: there the
  // attitude does not enter (v_b^ = 0). Taken at the estimate's few tenths of a m/s of noise,
  // v_b^ xi_R let each update "observe" the yaw of a robot that had never moved (its sigma 180
  // -> 2.6 deg, gtest AMemsRobotStandingWithoutFixes...).
  NavState at_rest = state_;
  at_rest.velocity_map.setZero();
  Eigen::Matrix<double, 3, 15> h_left = Eigen::Matrix<double, 3, 15>::Zero();
  h_left.block<3, 3>(0, 3).setIdentity();
  const Eigen::Matrix<double, 3, 15> h = h_left * leftFromError(at_rest);
  const Eigen::Vector3d innovation = -(state_.rotation.transpose() * state_.velocity_map);
  const Eigen::Matrix3d noise = Eigen::Matrix3d::Identity() * sigma * sigma;
  Vector15d delta;
  ErrorCovariance updated;
  result = kalmanUpdate<3>(innovation, h, noise, gate, &delta, &updated);
  if (!result.accepted) return result;
  return applyCorrection(delta, updated) ? result : rejectNonFinite(result);
}

CorrectionResult ImuFilterBase::correctZeroRate(const Eigen::Vector3d& mean_rate,
                                                const Eigen::Vector3d& variance, double gate) {
  CorrectionResult result;
  if (!mean_rate.allFinite() || !variance.allFinite() || !(variance.minCoeff() > 0.0)) {
    result.reason = "the zero-rate measurement must be finite, its variances positive";
    return result;
  }
  // At rest the gyro reads w = b_g + noise; the bias error is additive (true - estimate).
  Eigen::Matrix<double, 3, 15> h_left = Eigen::Matrix<double, 3, 15>::Zero();
  h_left.block<3, 3>(0, 9).setIdentity();
  const Eigen::Matrix<double, 3, 15> h = h_left * leftFromError(state_);
  const Eigen::Vector3d innovation = mean_rate - state_.gyro_bias;
  const Eigen::Matrix3d noise = variance.asDiagonal();
  Vector15d delta;
  ErrorCovariance updated;
  result = kalmanUpdate<3>(innovation, h, noise, gate, &delta, &updated);
  if (!result.accepted) return result;
  return applyCorrection(delta, updated) ? result : rejectNonFinite(result);
}

CorrectionResult ImuFilterBase::correctForwardSpeed(const NonholonomicModel& model,
                                                    double speed_mps, double sigma_mps,
                                                    double gate_sigma_mps, double gate) {
  CorrectionResult result;
  if (!std::isfinite(speed_mps) || !(sigma_mps > 0.0) || !std::isfinite(sigma_mps) ||
      !(gate_sigma_mps > 0.0) || !(gate_sigma_mps <= sigma_mps) ||
      !model.imu_from_vehicle.allFinite()) {
    result.reason =
        "the forward speed must be finite, its sigmas positive and finite (the gate's at most "
        "the update's)";
    return result;
  }
  // The vehicle-frame velocity's x row. Along the direction of travel the attitude hardly enters
  // (v_b^ xi_R is perpendicular to v_b): the speed corrects the velocity's magnitude, the fixes
  // its direction.
  Eigen::Vector3d vehicle_velocity;
  const Eigen::Matrix<double, 3, 15> jacobian = vehicleVelocityJacobian(model, &vehicle_velocity);
  const Eigen::Matrix<double, 1, 15> h = jacobian.topRows<1>();
  const Eigen::Matrix<double, 1, 1> innovation(speed_mps - vehicle_velocity.x());
  // The gate: this measurement on its own noise.
  const double predicted_variance = (h * covariance_ * h.transpose())(0, 0);
  const double gated =
      innovation(0) * innovation(0) / (predicted_variance + gate_sigma_mps * gate_sigma_mps);
  if (!(gated <= gate)) {
    char text[128];
    std::snprintf(text, sizeof(text), "outlier: Mahalanobis^2 %.1f > gate %.1f", gated, gate);
    result.mahalanobis_squared = gated;
    result.reason = std::isfinite(gated) ? text : "innovation not finite";
    return result;
  }
  const Eigen::Matrix<double, 1, 1> noise(sigma_mps * sigma_mps);
  Vector15d delta;
  ErrorCovariance updated;
  result = kalmanUpdate<1>(innovation, h, noise, std::numeric_limits<double>::infinity(), &delta,
                           &updated);
  result.mahalanobis_squared = gated;
  if (!result.accepted) return result;
  return applyCorrection(delta, updated) ? result : rejectNonFinite(result);
}

double ImuFilterBase::predictedForwardSpeed(const NonholonomicModel& model,
                                            double* variance_m2ps2) const {
  Eigen::Vector3d vehicle_velocity;
  const Eigen::Matrix<double, 1, 15> h =
      vehicleVelocityJacobian(model, &vehicle_velocity).topRows<1>();
  *variance_m2ps2 = (h * covariance_ * h.transpose())(0, 0);
  return vehicle_velocity.x();
}

bool ImuFilterBase::finiteFix(const PositionFix& fix) {
  return std::isfinite(fix.stamp_s) && fix.position_map.allFinite() &&
         fix.covariance_map.allFinite() && fix.antenna_in_imu.allFinite();
}

// ---------------------------------------------------------------------------------------------
// LeftInvariantEkf

CorrectionResult LeftInvariantEkf::correctPosition(const PositionFix& fix, double gate) {
  if (!finiteFix(fix)) return rejectBadFix();
  // y = p + R l (l: the antenna in the IMU frame) is a left-invariant observation (Barrau &
  // Bonnabel 2017): with X = X_est Exp(xi), R_est^T (y - p_est) - l = xi_p - l^ xi_R.
  const Eigen::Matrix3d& r = state_.rotation;
  const Eigen::Vector3d& l = fix.antenna_in_imu;
  const Eigen::Vector3d innovation = r.transpose() * (fix.position_map - state_.position_map) - l;
  const Eigen::Matrix3d noise = r.transpose() * fix.covariance_map * r;
  Eigen::Matrix<double, 3, 15> h = positionJacobian();
  h.block<3, 3>(0, 0) = -lie::hat(l);
  Vector15d delta;
  ErrorCovariance updated;
  CorrectionResult result = kalmanUpdate<3>(innovation, h, noise, gate, &delta, &updated);
  if (!result.accepted) return result;
  return applyCorrection(delta, updated) ? result : rejectNonFinite(result);
}

bool LeftInvariantEkf::applyCorrection(const Vector15d& delta, const ErrorCovariance& covariance) {
  NavState next = state_;
  setExtendedPose(extendedPose(state_) * lie::expSE23(delta.head<9>()), &next);
  next.gyro_bias += delta.segment<3>(9);
  next.accel_bias += delta.segment<3>(12);
  return commit(next, covariance);
}

Matrix15d LeftInvariantEkf::errorFromLeft(const NavState&) const { return Matrix15d::Identity(); }
Matrix15d LeftInvariantEkf::leftFromError(const NavState&) const { return Matrix15d::Identity(); }

// ---------------------------------------------------------------------------------------------
// RightInvariantEkf

CorrectionResult RightInvariantEkf::correctPosition(const PositionFix& fix, double gate) {
  if (!finiteFix(fix)) return rejectBadFix();
  // With X = Exp(xi) X_est: y - (p_est + R_est l) = xi_p - (p_est + R_est l)^ xi_R.
  const Eigen::Vector3d antenna = state_.position_map + state_.rotation * fix.antenna_in_imu;
  const Eigen::Vector3d innovation = fix.position_map - antenna;
  Eigen::Matrix<double, 3, 15> h = positionJacobian();
  h.block<3, 3>(0, 0) = -lie::hat(antenna);
  Vector15d delta;
  ErrorCovariance updated;
  CorrectionResult result =
      kalmanUpdate<3>(innovation, h, fix.covariance_map, gate, &delta, &updated);
  if (!result.accepted) return result;
  return applyCorrection(delta, updated) ? result : rejectNonFinite(result);
}

bool RightInvariantEkf::applyCorrection(const Vector15d& delta, const ErrorCovariance& covariance) {
  NavState next = state_;
  setExtendedPose(lie::expSE23(delta.head<9>()) * extendedPose(state_), &next);
  next.gyro_bias += delta.segment<3>(9);
  next.accel_bias += delta.segment<3>(12);
  return commit(next, covariance);
}

Matrix15d RightInvariantEkf::errorFromLeft(const NavState& state) const {
  Matrix15d t = Matrix15d::Identity();
  t.block<9, 9>(0, 0) = extendedPose(state).adjoint();
  return t;
}

Matrix15d RightInvariantEkf::leftFromError(const NavState& state) const {
  Matrix15d t = Matrix15d::Identity();
  t.block<9, 9>(0, 0) = extendedPose(state).inverse().adjoint();
  return t;
}

// ---------------------------------------------------------------------------------------------
// QuaternionEskf

void QuaternionEskf::initialize(const NavState& state, const ErrorCovariance& covariance) {
  ImuFilterBase::initialize(state, covariance);
  attitude_ = Eigen::Quaterniond(state_.rotation).normalized();
}

void QuaternionEskf::propagate(const ImuSample& sample, double dt) {
  ImuFilterBase::propagate(sample, dt);
  attitude_ = Eigen::Quaterniond(state_.rotation).normalized();
}

CorrectionResult QuaternionEskf::correctPosition(const PositionFix& fix, double gate) {
  if (!finiteFix(fix)) return rejectBadFix();
  // The attitude error is local (R = R_est Exp(dtheta)): y - (p_est + R_est l) = dp - R_est l^
  // dtheta.
  const Eigen::Vector3d& l = fix.antenna_in_imu;
  const Eigen::Vector3d innovation = fix.position_map - state_.position_map - state_.rotation * l;
  Eigen::Matrix<double, 3, 15> h = positionJacobian();
  h.block<3, 3>(0, 0) = -state_.rotation * lie::hat(l);
  Vector15d delta;
  ErrorCovariance updated;
  CorrectionResult result =
      kalmanUpdate<3>(innovation, h, fix.covariance_map, gate, &delta, &updated);
  if (!result.accepted) return result;
  return applyCorrection(delta, updated) ? result : rejectNonFinite(result);
}

bool QuaternionEskf::applyCorrection(const Vector15d& delta, const ErrorCovariance& covariance) {
  NavState next = state_;
  const Eigen::Vector3d dtheta = delta.head<3>();
  const double angle = dtheta.norm();
  const Eigen::Quaterniond dq = angle > 0.0
                                    ? Eigen::Quaterniond(Eigen::AngleAxisd(angle, dtheta / angle))
                                    : Eigen::Quaterniond::Identity();
  const Eigen::Quaterniond attitude = (attitude_ * dq).normalized();
  next.rotation = attitude.toRotationMatrix();
  next.velocity_map += delta.segment<3>(3);
  next.position_map += delta.segment<3>(6);
  next.gyro_bias += delta.segment<3>(9);
  next.accel_bias += delta.segment<3>(12);
  if (!commit(next, covariance)) return false;
  attitude_ = attitude;
  return true;
}

Matrix15d QuaternionEskf::errorFromLeft(const NavState& state) const {
  Matrix15d t = Matrix15d::Identity();
  t.block<3, 3>(3, 3) = state.rotation;
  t.block<3, 3>(6, 6) = state.rotation;
  return t;
}

Matrix15d QuaternionEskf::leftFromError(const NavState& state) const {
  Matrix15d t = Matrix15d::Identity();
  t.block<3, 3>(3, 3) = state.rotation.transpose();
  t.block<3, 3>(6, 6) = state.rotation.transpose();
  return t;
}

// ---------------------------------------------------------------------------------------------

std::unique_ptr<NavigationFilter> makeFilter(FilterType type, const ImuNoise& noise) {
  switch (type) {
    case FilterType::kLeftInvariant:
      return std::make_unique<LeftInvariantEkf>(noise);
    case FilterType::kRightInvariant:
      return std::make_unique<RightInvariantEkf>(noise);
    case FilterType::kQuaternionEskf:
      return std::make_unique<QuaternionEskf>(noise);
  }
  throw std::invalid_argument("makeFilter: unknown filter type");
}

FilterType filterTypeFromString(const std::string& text) {
  if (text == "left") return FilterType::kLeftInvariant;
  if (text == "right") return FilterType::kRightInvariant;
  if (text == "ekf") return FilterType::kQuaternionEskf;
  throw std::invalid_argument("unknown filter type '" + text + "' (expected left, right or ekf)");
}

std::string toString(FilterType type) {
  switch (type) {
    case FilterType::kLeftInvariant:
      return "left";
    case FilterType::kRightInvariant:
      return "right";
    case FilterType::kQuaternionEskf:
      return "ekf";
  }
  return "unknown";
}

}  // namespace estimation
}  // namespace inekf_semantic_mapping
