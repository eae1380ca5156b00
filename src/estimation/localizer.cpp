#include "inekf_semantic_mapping/estimation/localizer.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <stdexcept>

#include "inekf_semantic_mapping/estimation/imu_filters.h"
#include "inekf_semantic_mapping/lie/so3.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

constexpr double kDegToRad = M_PI / 180.0;
constexpr double kDuplicateStampS = Localizer::kDuplicateStampS;

double wrapRad(double angle) { return std::atan2(std::sin(angle), std::cos(angle)); }

// Azimuth of a map-frame direction.
double headingOf(const Eigen::Vector3d& direction_map) {
  return std::atan2(direction_map.y(), direction_map.x());
}

// The configured direction of travel is relative to base_link's axes, the constraint's model in
// the IMU's.
NonholonomicModel nonholonomicModel(const LocalizerConfig& config,
                                    const Eigen::Matrix3d& base_from_imu) {
  NonholonomicModel model;
  model.lateral_sigma_mps = config.nonholonomic_lateral_sigma_mps;
  model.vertical_sigma_mps = config.nonholonomic_vertical_sigma_mps;
  model.imu_from_vehicle = base_from_imu.transpose() *
                           vehicleFrameInImu(config.nonholonomic_vehicle_pitch_deg * kDegToRad,
                                             config.nonholonomic_vehicle_yaw_deg * kDegToRad);
  return model;
}

}  // namespace

double twoDofGateOfSameTail(double gate_3dof) {
  if (!(gate_3dof > 0.0) || !std::isfinite(gate_3dof)) return gate_3dof;
  const double tail = std::erfc(std::sqrt(0.5 * gate_3dof)) +
                      std::sqrt(2.0 * gate_3dof / M_PI) * std::exp(-0.5 * gate_3dof);
  // Beyond ~1500 the tail underflows to 0; the quantiles there differ by a negligible 2 ln g.
  return tail > 0.0 ? -2.0 * std::log(tail) : gate_3dof;
}

Localizer::Localizer(LocalizerConfig config)
    : config_(std::move(config)),
      nonholonomic_model_(nonholonomicModel(config_, base_from_imu_)),
      standstill_(config_.standstill),
      filter_(makeFilter(config_.filter_type, config_.imu_noise)) {}

bool Localizer::setImuMounting(const Eigen::Matrix3d& base_from_imu) {
  const bool rotation = base_from_imu.allFinite() &&
                        (base_from_imu.transpose() * base_from_imu - Eigen::Matrix3d::Identity())
                                .cwiseAbs()
                                .maxCoeff() < 1e-6 &&
                        base_from_imu.determinant() > 0.0;
  if (!rotation) return false;
  if (base_from_imu.isApprox(base_from_imu_, 1e-12)) return true;
  base_from_imu_ = base_from_imu;
  forward_in_imu_ = base_from_imu.transpose().col(0);
  nonholonomic_model_ = nonholonomicModel(config_, base_from_imu_);
  // The track's headings were of the old axis.
  track_fixes_.clear();
  chords_.clear();
  heading_confirmed_ = false;
  return true;
}

double Localizer::vehicleHeading() const {
  return headingOf(filter_->state().rotation * forward_in_imu_);
}

ErrorCovariance Localizer::initialWorldCovariance() const {
  Eigen::Matrix<double, 15, 1> sigma;
  const double tilt = config_.initial_rotation_sigma_deg * kDegToRad;
  sigma << tilt, tilt, config_.initial_yaw_sigma_deg * kDegToRad,
      Eigen::Vector3d::Constant(config_.initial_velocity_sigma_mps),
      Eigen::Vector3d::Constant(config_.initial_position_sigma_m),
      Eigen::Vector3d::Constant(config_.initial_gyro_bias_sigma_radps),
      Eigen::Vector3d::Constant(config_.initial_accel_bias_sigma_mps2);
  return sigma.cwiseAbs2().asDiagonal();
}

void Localizer::initialize(const NavState& initial) {
  initialize(initial, initialWorldCovariance());
}

void Localizer::initialize(const NavState& initial, const ErrorCovariance& world_covariance) {
  filter_->initialize(initial, filter_->fromWorldCovariance(initial, world_covariance));
  filter_->setProcessNoiseScale(1.0, 1.0);
  predicted_state_ = filter_->state();
  predicted_covariance_ = filter_->covariance();
  initialized_ = true;
  consecutive_rejected_fixes_ = 0;
  consecutive_rejected_wheel_speeds_ = 0;
  wheel_speeds_suspended_ = false;
  agreeing_wheel_speeds_ = 0;
  wheel_agreement_since_s_.reset();
  wheel_sign_checked_ = false;
  last_wheel_speed_stamp_s_.reset();
  last_accepted_fix_s_ = initial.stamp_s;
  last_accepted_fix_position_ = initial.position_map;
  clearHistory();
  last_fix_stamp_s_ = -std::numeric_limits<double>::infinity();
  heading_correction_rad_ = 0.0;
  track_fixes_.clear();
  chords_.clear();
  horizontal_nis_.clear();
  heading_confirmed_ = false;
  standstill_.reset();
  recordStep(ImuStep());  // the initial state: dt 0, nothing to replay
}

bool Localizer::propagate(const ImuStep& step) {
  const double stamp_before = filter_->state().stamp_s;
  filter_->setProcessNoiseScale(step.gyro_noise_scale, step.accel_noise_scale);
  filter_->propagate(step.sample, step.dt);
  filter_->setProcessNoiseScale(1.0, 1.0);
  // A propagation the filter refused (it would have left non-finite values) leaves the state
  // where it was, stamp included.
  if (step.dt > 0.0 && filter_->state().stamp_s == stamp_before) return false;
  // The smoother needs the pure prediction; the constraint is a measurement of this epoch. Here,
  // not in addImu, so that a late fix's replay of the history applies it again.
  predicted_state_ = filter_->state();
  predicted_covariance_ = filter_->covariance();
  if (step.standstill) {
    // A vehicle that stands still shows nothing of its heading, but the update would take some
    // from the estimate's own errors (the horizontal specific force an unlearnt accelerometer
    // bias leaves couples the yaw into the velocity): until the track has aligned it, the yaw
    // is kept out of the update (its sigma 180 -> 3 deg in 10 s of standing without this).
    if (!(yawSigma() <= config_.heading_align_above_sigma_deg * kDegToRad)) decorrelateYaw();
    const double heading_before = vehicleHeading();
    const double gate = config_.standstill.gate_mahalanobis_squared;
    // Each part on its own: a gyro shaken beyond its configured noise must not take the zero
    // velocity down with the rate (a 3x noisier gyro: 9.2 km of drift with one 6-dof update).
    const CorrectionResult velocity =
        filter_->correctZeroVelocity(step.standstill->velocity_sigma_mps, gate);
    const CorrectionResult rate = filter_->correctZeroRate(
        step.standstill->mean_angular_velocity, step.standstill->angular_velocity_variance, gate);
    if (!replaying_) {  // counted once, when the sample came (a late fix replays it)
      ++(velocity.accepted ? statistics_.standstill_used : statistics_.standstill_rejected);
      if (!rate.accepted) ++statistics_.standstill_rate_rejected;
    }
    if (velocity.accepted || rate.accepted) noteHeadingChange(heading_before);
  }
  constrainToVehicle(step);
  for (const ImuStep::WheelSpeed& speed : step.wheel_speeds) applyWheelSpeed(speed);
  return true;
}

void Localizer::constrainToVehicle(const ImuStep& step) {
  if (config_.nonholonomic && step.dt > 0.0) {
    // About the map's z axis: the pose covariance's (5, 5) is about the IMU's own z, horizontal
    // for an IMU board mounted upright (the constraint ran with the heading unknown and pinned
    // it 19 deg off).
    const double heading_sigma_rad = yawSigma();
    if (!(heading_sigma_rad <= config_.nonholonomic_max_heading_sigma_deg * kDegToRad)) {
      ++statistics_.nonholonomic_skipped;
      return;
    }
    if (consecutive_rejected_fixes_ > 0) {
      // The fixes reject this heading: the constraint would only hold it.
      ++statistics_.nonholonomic_suspended;
      return;
    }
    const double heading_before = vehicleHeading();
    // The same information per second from a fast IMU's short steps.
    NonholonomicModel model = nonholonomic_model_;
    if (step.dt < config_.nonholonomic_min_step_s) {
      const double scale = std::sqrt(config_.nonholonomic_min_step_s / step.dt);
      model.lateral_sigma_mps *= scale;
      model.vertical_sigma_mps *= scale;
    }
    const CorrectionResult result =
        filter_->correctNonholonomic(model, config_.nonholonomic_gate_mahalanobis_squared);
    ++(result.accepted ? statistics_.nonholonomic_used : statistics_.nonholonomic_rejected);
    if (result.accepted) noteHeadingChange(heading_before);
  }
}

CorrectionResult Localizer::addWheelSpeed(double stamp_s, double speed_mps, double sigma_mps) {
  CorrectionResult result;
  const LocalizerConfig::WheelSpeedOptions& options = config_.wheel_speed;
  if (!options.enabled || !initialized_) {
    ++statistics_.wheel_speed_ignored;
    result.reason = options.enabled ? "the filter has not started" : "wheel_speed.enabled is false";
    return result;
  }
  const double age_s = std::abs(filter_->state().stamp_s - stamp_s);
  if (!(age_s <= options.max_age_s)) {
    ++statistics_.wheel_speed_stale;
    char text[160];
    std::snprintf(text, sizeof(text),
                  "stale: stamped %.3f s from the filter's time (wheel_speed.max_age_s %.3f)",
                  filter_->state().stamp_s - stamp_s, options.max_age_s);
    result.reason = text;
    return result;
  }
  // As the constraint: with the heading unknown the body velocity's direction is a guess, and a
  // speed along it would turn the heading as much as correct the speed (a MEMS robot aligned
  // 86 deg off with every wheel speed applied from its start); while the fixes reject the
  // heading, it would hold the wrong one.
  if (!(yawSigma() <= config_.nonholonomic_max_heading_sigma_deg * kDegToRad) ||
      consecutive_rejected_fixes_ > 0) {
    ++statistics_.wheel_speed_ignored;
    result.reason = "the heading is not known yet (or the fixes reject it)";
    return result;
  }
  const double stated =
      sigma_mps > 0.0 && std::isfinite(sigma_mps) ? sigma_mps : options.default_sigma_mps;
  const double floor = std::max(stated, options.min_sigma_mps);
  ImuStep::WheelSpeed speed{speed_mps, 0.0, 0.0};
  speed.gate_sigma_mps = std::sqrt(floor * floor + std::pow(options.scale_sigma * speed_mps, 2) +
                                   std::pow(options.max_acceleration_mps2 * age_s, 2));
  double predicted_variance = 0.0;
  const double predicted = filter_->predictedForwardSpeed(nonholonomic_model_, &predicted_variance);
  // After a start, an alignment or a re-open (the velocity sigma 1 m/s or more) the wheels' sign
  // is checked against the filter's own speed before they are taken: a reversed encoder's (or a
  // robot's backing out against a heading aligned forwards) -1.5 m/s passed the gate, turned the
  // filter's velocity round and agreed with it from then on (25-35 heading re-opens in 150 s).
  // Until then only slow speeds (whose sign does not matter) go in, and only where the filter
  // knows its own speed as well; a faster one checks the sign when the filter's speed is clear of
  // zero by two sigmas, on the same side.
  const double predicted_sigma = std::sqrt(predicted_variance);
  bool checks_sign = false;
  if (!wheel_sign_checked_) {
    const bool slow = std::abs(speed_mps) <= kWheelSignSigmaFloorMps &&
                      predicted_sigma <= kWheelSignSigmaFloorMps;
    const bool agrees = predicted * speed_mps > 0.0 && std::abs(predicted) >= 2.0 * predicted_sigma;
    if (!slow && !agrees) {
      ++statistics_.wheel_speed_ignored;
      result.reason = "the wheels' sign is not checked against the filter's speed yet";
      return result;
    }
    checks_sign = agrees;
  }
  const double d2 = (speed_mps - predicted) * (speed_mps - predicted) /
                    (predicted_variance + speed.gate_sigma_mps * speed.gate_sigma_mps);
  if (wheel_speeds_suspended_) {
    // Until a fix is accepted, or they agree closely with the filter (p = 0.05) for
    // min_interval_s and max_rejected_in_a_row speeds: 5 speeds at the gate's edge (0.1 s at
    // 50 Hz) let a long slip back in.
    if (!(d2 <= kWheelResumeMahalanobisSquared)) {
      agreeing_wheel_speeds_ = 0;
      wheel_agreement_since_s_.reset();
    } else {
      ++agreeing_wheel_speeds_;
      if (!wheel_agreement_since_s_) wheel_agreement_since_s_ = stamp_s;
    }
    if (agreeing_wheel_speeds_ < options.max_rejected_in_a_row || !wheel_agreement_since_s_ ||
        stamp_s - *wheel_agreement_since_s_ < options.min_interval_s) {
      ++statistics_.wheel_speed_ignored;
      last_wheel_speed_stamp_s_ = stamp_s;
      result.mahalanobis_squared = d2;
      result.reason = "suspended after " + std::to_string(options.max_rejected_in_a_row) +
                      " gated out in a row, until a fix is accepted or they agree again";
      return result;
    }
    wheel_speeds_suspended_ = false;
  }
  // Speeds faster than one per min_interval_s carry, together, the information of one: their
  // errors (slip, bumps, the scale) are shared, not independent. Each is still gated on its own
  // sigma: weakened, a slip's speeds passed the gate one by one and pulled the filter.
  const double interval_s = last_wheel_speed_stamp_s_
                                ? std::abs(stamp_s - *last_wheel_speed_stamp_s_)
                                : options.min_interval_s;
  last_wheel_speed_stamp_s_ = stamp_s;
  speed.sigma_mps = speed.gate_sigma_mps;
  if (interval_s < options.min_interval_s) {
    speed.sigma_mps *= std::sqrt(options.min_interval_s / std::max(interval_s, 1e-3));
  }
  result = applyWheelSpeed(speed);
  if (result.accepted) {
    consecutive_rejected_wheel_speeds_ = 0;
    if (checks_sign) wheel_sign_checked_ = true;
  } else if (result.mahalanobis_squared > options.gate_mahalanobis_squared &&
             options.max_rejected_in_a_row > 0 &&
             ++consecutive_rejected_wheel_speeds_ >= options.max_rejected_in_a_row) {
    // The wheels and the filter keep disagreeing: a slip, or a wrong scale or sign. Taken on,
    // they would pull the filter once its sigma had grown enough (then reject the true speeds).
    wheel_speeds_suspended_ = true;
    consecutive_rejected_wheel_speeds_ = 0;
    agreeing_wheel_speeds_ = 0;
    wheel_agreement_since_s_.reset();
    ++statistics_.wheel_speed_suspensions;
    result.reason += "; " + std::to_string(options.max_rejected_in_a_row) +
                     " in a row: wheel speeds suspended until a fix is accepted or they agree "
                     "again";
  }
  if (result.accepted && !history_.empty()) {
    // Kept with the step it followed: a late fix's replay applies it again after that step.
    HistoryStep& newest = history_.back();
    newest.step.wheel_speeds.push_back(speed);
    newest.state = filter_->state();
    newest.covariance = filter_->covariance();
    newest.heading_correction_rad = heading_correction_rad_;
  }
  return result;
}

CorrectionResult Localizer::applyWheelSpeed(const ImuStep::WheelSpeed& speed) {
  const double heading_before = vehicleHeading();
  const CorrectionResult result = filter_->correctForwardSpeed(
      nonholonomic_model_, speed.speed_mps, speed.sigma_mps, speed.gate_sigma_mps,
      config_.wheel_speed.gate_mahalanobis_squared);
  if (!replaying_)
    ++(result.accepted ? statistics_.wheel_speed_used : statistics_.wheel_speed_rejected);
  if (result.accepted) noteHeadingChange(heading_before);
  return result;
}

void Localizer::recordStep(const ImuStep& step) {
  if (!(config_.fix_history_s > 0.0)) return;
  history_.push_back({step, filter_->state(), filter_->covariance(), heading_correction_rad_});
  const double oldest_kept_s = history_.back().state.stamp_s - config_.fix_history_s;
  // Keep the newest step at or before the horizon: a fix exactly fix_history_s late rewinds to it.
  while (history_.size() - history_begin_ > 1 &&
         history_[history_begin_ + 1].state.stamp_s <= oldest_kept_s) {
    ++history_begin_;
  }
  // Drop the expired steps in bulk (amortized O(1) per step): the vector's storage is reused,
  // so recording allocates nothing per IMU sample once it has grown to the window.
  if (history_begin_ > history_.size() / 2) {
    history_.erase(history_.begin(),
                   history_.begin() + static_cast<std::ptrdiff_t>(history_begin_));
    history_begin_ = 0;
  }
}

void Localizer::clearHistory() {
  history_.clear();
  history_begin_ = 0;
}

std::ptrdiff_t Localizer::lateFixStep(double stamp_s) const {
  const auto begin = static_cast<std::ptrdiff_t>(history_begin_);
  const auto newest = static_cast<std::ptrdiff_t>(history_.size()) - 1;
  if (newest - begin < 1) return -1;
  if (stamp_s >= history_.back().state.stamp_s - kDuplicateStampS) return -1;  // not late
  // Replaying past an applied fix would drop it: a fix older than the last one is not rewound.
  if (stamp_s < last_fix_stamp_s_ - kDuplicateStampS) return -1;
  std::ptrdiff_t step = newest;
  while (step >= begin && history_[step].state.stamp_s > stamp_s + kDuplicateStampS) --step;
  return step >= begin ? step : -1;  // -1: older than the history
}

CorrectionResult Localizer::applyFixInHistory(const PositionFix& fix, std::ptrdiff_t step) {
  replaying_ = true;
  filter_->initialize(history_[step].state, history_[step].covariance);
  heading_correction_rad_ = history_[step].heading_correction_rad;
  const double into_next = fix.stamp_s - history_[step].state.stamp_s;
  if (into_next > kDuplicateStampS) {
    // The fix falls inside the next step: split that step at the fix's time (its sample holds
    // over the whole interval, so the two parts integrate to the same as the whole).
    ImuStep first_part = history_[step + 1].step;
    first_part.dt = into_next;
    first_part.standstill.reset();    // it belongs to the end of the step, kept by the rest
    first_part.wheel_speeds.clear();  // as do these
    propagate(first_part);
    history_[step + 1].step.dt -= into_next;
    history_.insert(history_.begin() + step + 1,
                    {first_part, filter_->state(), filter_->covariance(), heading_correction_rad_});
    ++step;
  }
  const CorrectionResult result = applyFix(fix);
  history_[step].state = filter_->state();
  history_[step].covariance = filter_->covariance();
  history_[step].heading_correction_rad = heading_correction_rad_;
  for (std::size_t k = static_cast<std::size_t>(step) + 1; k < history_.size(); ++k) {
    propagate(history_[k].step);
    history_[k].state = filter_->state();
    history_[k].covariance = filter_->covariance();
    history_[k].heading_correction_rad = heading_correction_rad_;
  }
  replaying_ = false;
  return result;
}

void Localizer::setInitialReference(const Eigen::Matrix3d& rotation,
                                    const std::optional<Eigen::Vector3d>& velocity_map,
                                    const std::optional<Eigen::Matrix3d>& rotation_covariance) {
  if (!rotation.allFinite()) return;
  reference_rotation_ = lie::normalizeRotation(rotation);
  reference_velocity_.reset();
  reference_rotation_covariance_.reset();
  if (velocity_map && velocity_map->allFinite()) reference_velocity_ = *velocity_map;
  if (rotation_covariance) {
    // Only a covariance: symmetric positive semi-definite, and no wider than a rotation can be
    // wrong (an indefinite one made the filter's covariance indefinite, its variances negative
    // and every later fix rejected; an absurd one overflowed it).
    const Eigen::Matrix3d stated = 0.5 * (*rotation_covariance + rotation_covariance->transpose());
    if (stated.allFinite()) {
      const Eigen::Vector3d eigenvalues =
          Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(stated, Eigen::EigenvaluesOnly)
              .eigenvalues();
      const double widest = M_PI * M_PI;
      if (eigenvalues.minCoeff() >= -1e-12 * std::max(1.0, eigenvalues.maxCoeff()) &&
          stated.diagonal().maxCoeff() <= widest) {
        reference_rotation_covariance_ = stated;
      }
    }
  }
}

void Localizer::setInitialVelocity(const std::optional<Eigen::Vector3d>& velocity_map) {
  reference_velocity_.reset();
  if (velocity_map && velocity_map->allFinite()) reference_velocity_ = *velocity_map;
}

Localizer::ImuStatus Localizer::addImu(const ImuSample& sample) {
  if (!std::isfinite(sample.stamp_s) || !sample.angular_velocity.allFinite() ||
      !sample.specific_force.allFinite() ||
      !(sample.angular_velocity.cwiseAbs().maxCoeff() <= config_.max_angular_rate_radps) ||
      !(sample.specific_force.cwiseAbs().maxCoeff() <= config_.max_specific_force_mps2)) {
    ++statistics_.imu_dropped;
    return ImuStatus::kDroppedDuplicate;  // unusable; counted with the drops
  }
  if (!initialized_) {
    last_imu_ = sample;
    return ImuStatus::kNotInitialized;
  }
  const double dt = sample.stamp_s - filter_->state().stamp_s;
  if (std::abs(dt) < kDuplicateStampS) {
    ++statistics_.imu_dropped;
    return ImuStatus::kDroppedDuplicate;
  }
  if (dt < 0.0) {
    ++statistics_.imu_dropped;
    return ImuStatus::kDroppedOutOfOrder;
  }
  const bool gap = dt > config_.max_imu_gap_s;
  double gyro_scale = 1.0, accel_scale = 1.0;
  if (gap) {
    // The heading change inside a gap is unknown (a car turns up to 20-30 deg/s): the gyro's
    // noise grows with the gap's length, as over an interpolated run.
    gyro_scale =
        std::max({gyro_scale, config_.gap_noise_scale, config_.gap_gyro_noise_scale_per_s * dt});
    accel_scale = std::max(accel_scale, config_.gap_noise_scale);
  }
  if (sample.interpolated) {
    // The run began at the last real sample, the start of this sample's interval.
    if (interpolated_run_start_s_ < 0.0) interpolated_run_start_s_ = filter_->state().stamp_s;
    const double run_s = sample.stamp_s - interpolated_run_start_s_;
    gyro_scale = std::max(gyro_scale, config_.interpolated_gyro_noise_scale_per_s * run_s);
    accel_scale = std::max(accel_scale, config_.interpolated_accel_noise_scale);
  } else {
    interpolated_run_start_s_ = -1.0;
  }
  ImuStep step{sample, dt, gyro_scale, accel_scale, std::nullopt, {}};
  if (config_.standstill.enabled) {
    // Not across a gap or an interpolated sample (the IMU did not see that time), nor while the
    // fixes reject the estimate.
    if (gap || sample.interpolated || consecutive_rejected_fixes_ > 0) {
      standstill_.reset();
    } else {
      StandstillDetector::Context context;
      context.velocity_sigma_mps = horizontalVelocitySigma();
      context.gyro_bias_sigma_radps =
          std::sqrt(std::max(0.0, filter_->covariance().block<3, 3>(9, 9).trace()));
      context.fixes = trackVerdict();
      context.gyro_noise_density = config_.imu_noise.gyro_noise_density;
      step.standstill = standstill_.add(sample, dt, filter_->state(), context);
    }
  }
  if (!propagate(step)) {
    // Not an estimate at this stamp: reported as such (it was kUsed, and the node published the
    // old state under the new stamp).
    ++statistics_.imu_dropped;
    return ImuStatus::kRefused;
  }
  recordStep(step);
  last_imu_ = sample;
  ++statistics_.imu_used;
  if (gap) {
    ++statistics_.imu_gaps;
    return ImuStatus::kGap;
  }
  return ImuStatus::kUsed;
}

CorrectionResult Localizer::addPositionFix(const PositionFix& fix) {
  CorrectionResult result;
  if (!std::isfinite(fix.stamp_s) || !fix.position_map.allFinite() ||
      !fix.covariance_map.allFinite() || !fix.antenna_in_imu.allFinite()) {
    result.reason = "non-finite fix";
    ++statistics_.gps_rejected;
    return result;
  }
  PositionFix used = fix;
  // Floor the fix's uncertainty: a receiver claiming centimetres must not freeze the filter.
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(
      0.5 * (fix.covariance_map + fix.covariance_map.transpose()));
  const double floor = config_.min_gps_sigma_m * config_.min_gps_sigma_m;
  used.covariance_map = eigen.eigenvectors() * eigen.eigenvalues().cwiseMax(floor).asDiagonal() *
                        eigen.eigenvectors().transpose();

  if (!initialized_) {
    if (!last_imu_ && !(config_.init_orientation_from_reference && reference_rotation_)) {
      // No attitude information at all yet (neither a reference nor gravity): starting now would
      // claim yaw 0 to the configured sigma. In inekf_node the first fix and the first IMU
      // message race on separate connections; the next fix starts the filter properly.
      result.reason = "no IMU sample yet: the filter starts at a later fix";
      ++statistics_.gps_before_start;
      return result;
    }
    NavState initial;
    initial.stamp_s = fix.stamp_s;
    bool velocity_known = false;
    if (reference_velocity_) {
      initial.velocity_map = *reference_velocity_;
      velocity_known = true;
    }
    if (config_.init_orientation_from_reference && reference_rotation_) {
      initial.rotation = *reference_rotation_;
    } else if (last_imu_->specific_force.norm() > 1.0) {
      // Level from the specific force (gravity reaction), yaw 0.
      const Eigen::Vector3d f = last_imu_->specific_force.normalized();
      const double roll = std::atan2(f.y(), f.z());
      const double pitch = std::atan2(-f.x(), std::hypot(f.y(), f.z()));
      initial.rotation = (Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                          Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
                             .toRotationMatrix();
    }
    // The IMU sits at the antenna minus its lever arm, turned by the start's attitude.
    initial.position_map = fix.position_map - initial.rotation * fix.antenna_in_imu;
    ErrorCovariance world = initialWorldCovariance();
    world.block<3, 3>(6, 6) = used.covariance_map;
    const bool yaw_known = config_.init_orientation_from_reference && reference_rotation_;
    if (!yaw_known) {
      // A yaw of 0 guessed: the lever arm's horizontal part may point anywhere.
      const double lever2 = fix.antenna_in_imu.head<2>().squaredNorm();
      world(6, 6) += lever2;
      world(7, 7) += lever2;
    }
    if (yaw_known && reference_rotation_covariance_) {
      // The orientation's own stated covariance; an axis it states as 0 (sensor_msgs: "not
      // known") keeps the configured sigma.
      const Eigen::Matrix3d& stated = *reference_rotation_covariance_;
      for (int i = 0; i < 3; ++i) {
        if (!(stated(i, i) > 0.0)) continue;
        world(i, i) = stated(i, i);
        for (int j = 0; j < 3; ++j) {
          if (j != i && stated(j, j) > 0.0) world(i, j) = stated(i, j);
        }
      }
    }
    if (!yaw_known) {
      // Levelled from gravity: the yaw of 0 is a guess, not a measurement.
      const double yaw_sigma = config_.unknown_yaw_sigma_deg * kDegToRad;
      world(2, 2) = yaw_sigma * yaw_sigma;
    }
    if (!velocity_known) {
      world.block<3, 3>(3, 3) = Eigen::Vector3d(config_.unknown_velocity_sigma_horizontal_mps,
                                                config_.unknown_velocity_sigma_horizontal_mps,
                                                config_.unknown_velocity_sigma_vertical_mps)
                                    .cwiseAbs2()
                                    .asDiagonal();
      ++statistics_.starts_without_velocity;
    }
    initialize(initial, world);
    result.accepted = true;
    result.reason = "initialized";
    ++statistics_.gps_used;
    return result;
  }

  // A late fix (older than the state) goes to its own time when the history reaches back to it.
  const std::ptrdiff_t step = lateFixStep(used.stamp_s);
  if (step < 0) return applyFix(used);
  ++statistics_.gps_applied_late;
  return applyFixInHistory(used, step);
}

CorrectionResult Localizer::applyFix(const PositionFix& fix) {
  CorrectionResult result;
  PositionFix used = fix;
  const double age = filter_->state().stamp_s - fix.stamp_s;
  if (std::abs(age) > config_.max_fix_age_s) {
    // age < 0: the fix is ahead of the state (the IMU fell silent), not old.
    result.reason = (age > 0 ? "stale fix: " + std::to_string(age) + " s older than"
                             : "fix " + std::to_string(-age) + " s ahead of") +
                    std::string(" the state's time (more than gps.max_fix_age_s)");
    ++statistics_.gps_rejected;
    return result;
  }
  last_fix_stamp_s_ = std::max(last_fix_stamp_s_, fix.stamp_s);
  // Applied at the state's time: the car moved by about speed * age meanwhile.
  const double moved = filter_->state().velocity_map.norm() * std::abs(age);
  used.covariance_map += Eigen::Matrix3d::Identity() * moved * moved;
  used.stamp_s = filter_->state().stamp_s;
  // Where the fix puts the IMU (the antenna minus its lever arm at the filter's attitude now): the
  // heading monitor's track, the horizontal NIS and the jump check are of the IMU's position; the
  // filter's update models the lever arm itself.
  const auto imu_position = [this, &used] {
    return Eigen::Vector3d(used.position_map - filter_->state().rotation * used.antenna_in_imu);
  };

  // The heading monitor, before the correction: the track including this fix (kept for the
  // standstill too: trackVerdict).
  if (config_.heading_from_track || config_.standstill.enabled) {
    PositionFix at_imu = used;
    at_imu.position_map = imu_position();
    addToTrack(at_imu);
  }
  if (config_.heading_from_track) {
    const TrackHeading track = trackHeading();
    if (track.valid && track.sigma_rad <= config_.heading_align_max_sigma_deg * kDegToRad) {
      const double yaw_sigma = yawSigma();
      const double delta = wrapRad(track.offset_rad - heading_correction_rad_);
      char why[160];
      if (!(yaw_sigma <= config_.heading_align_above_sigma_deg * kDegToRad)) {
        std::snprintf(why, sizeof(why),
                      "heading unknown (sigma %.0f deg): aligned to the GPS track of %d chords "
                      "(%+.1f deg, sigma %.1f deg)",
                      yaw_sigma / kDegToRad, track.chords, delta / kDegToRad,
                      track.sigma_rad / kDegToRad);
        ++statistics_.heading_alignments;
        realignHeading(track, why);
      } else if (std::abs(delta) >
                 std::max(config_.heading_check_min_deg * kDegToRad,
                          config_.heading_check_sigmas * std::hypot(yaw_sigma, track.sigma_rad))) {
        std::snprintf(why, sizeof(why),
                      "heading %.1f deg off the GPS track's (%d chords, sigma %.1f deg; the "
                      "filter's sigma %.1f deg): re-initialised from the track",
                      -delta / kDegToRad, track.chords, track.sigma_rad / kDegToRad,
                      yaw_sigma / kDegToRad);
        ++statistics_.heading_recoveries;
        realignHeading(track, why);
      } else {
        heading_confirmed_ = true;
      }
    }
  }

  const bool hold_yaw = config_.heading_from_track && config_.heading_hold_unknown_yaw;
  if (hold_yaw && !(yawSigma() <= config_.heading_align_above_sigma_deg * kDegToRad)) {
    decorrelateYaw();
  }
  const Eigen::Vector3d fix_imu_position = imu_position();
  const Eigen::Vector3d innovation = fix_imu_position - filter_->state().position_map;
  double horizontal_nis = 0.0;
  {
    const Eigen::Matrix2d s =
        filter_->poseCovariance().topLeftCorner<2, 2>() + used.covariance_map.topLeftCorner<2, 2>();
    const Eigen::Vector2d e = innovation.head<2>();
    const Eigen::LLT<Eigen::Matrix2d> llt(s);
    if (llt.info() == Eigen::Success && e.allFinite()) horizontal_nis = e.dot(llt.solve(e));
  }
  double heading_before = vehicleHeading();
  const double gate = used.horizontal_only
                          ? twoDofGateOfSameTail(config_.gps_gate_mahalanobis_squared)
                          : config_.gps_gate_mahalanobis_squared;
  result = filter_->correctPosition(used, gate);
  bool gated_out = !result.accepted && result.mahalanobis_squared > gate;
  if (gated_out) ++consecutive_rejected_fixes_;
  // The fixes keep disagreeing: the heading (and with it velocity) may be what is wrong.
  std::string reopen_why;
  if (gated_out && config_.heading_reopen_after_rejected_fixes > 0 &&
      consecutive_rejected_fixes_ == config_.heading_reopen_after_rejected_fixes) {
    reopen_why = std::to_string(consecutive_rejected_fixes_) + " fixes in a row failed the gate";
  }
  // The fixes the filter took: a gated-out one is the rejected-in-a-row count's to judge. Counted
  // here (clipped at the gate) two outliers in a row made the mean of 10 exceed 6: the heading
  // was re-opened and the second outlier applied, a 25 m jump for a 30 m multipath.
  if (config_.heading_nis_window_fixes > 0 && !gated_out && std::isfinite(horizontal_nis)) {
    horizontal_nis_.push_back(std::min(horizontal_nis, config_.gps_gate_mahalanobis_squared));
    while (static_cast<int>(horizontal_nis_.size()) > config_.heading_nis_window_fixes) {
      horizontal_nis_.pop_front();
    }
    if (static_cast<int>(horizontal_nis_.size()) == config_.heading_nis_window_fixes) {
      double mean = 0.0;
      for (double d2 : horizontal_nis_) mean += d2;
      mean /= static_cast<double>(horizontal_nis_.size());
      if (mean > config_.heading_nis_window_max && reopen_why.empty()) {
        char why[128];
        std::snprintf(why, sizeof(why), "the last %d fixes' mean horizontal NIS is %.1f (> %.1f)",
                      config_.heading_nis_window_fixes, mean, config_.heading_nis_window_max);
        reopen_why = why;
      }
    }
  }
  const double since_last_fix_s = std::max(1.0, filter_->state().stamp_s - last_accepted_fix_s_);
  // Measured from the last accepted fix, not from the filter: a filter that runs away (a wrong
  // velocity from a bad start) would otherwise outrun this bound and refuse every fix for good.
  const double fix_jump_m = (fix_imu_position - last_accepted_fix_position_).norm();
  const bool receiver_jumped = fix_jump_m > config_.max_reacquisition_speed_mps * since_last_fix_s;
  if (!reopen_why.empty()) {
    if (receiver_jumped) {
      reopen_why.clear();  // a broken receiver, not a wrong heading: the gate keeps rejecting
    } else {
      if (result.accepted) {
        // Undo nothing: the accepted fix stands; re-open around the corrected state.
        noteHeadingChange(heading_before);
        heading_before = vehicleHeading();
      }
      reopenHeading(gated_out ? innovation : Eigen::Vector3d::Zero(), reopen_why);
      horizontal_nis_.clear();
      if (gated_out) {
        if (hold_yaw) decorrelateYaw();
        result = filter_->correctPosition(used, gate);
        gated_out = !result.accepted && result.mahalanobis_squared > gate;
      }
    }
  }
  if (gated_out && config_.max_consecutive_rejected_fixes > 0 &&
      consecutive_rejected_fixes_ >= config_.max_consecutive_rejected_fixes) {
    const NavState& state = filter_->state();
    if (receiver_jumped) {
      result.reason = "re-acquisition refused: the fix is " + std::to_string(fix_jump_m) +
                      " m from the last accepted one, more than a car moves in " +
                      std::to_string(since_last_fix_s) + " s";
      ++statistics_.gps_rejected;
      return result;
    }
    ErrorCovariance inflation = ErrorCovariance::Zero();
    inflation.block<3, 3>(3, 3).diagonal().setConstant(
        std::pow(innovation.norm() / since_last_fix_s, 2));
    inflation.block<3, 3>(6, 6).diagonal().setConstant(innovation.squaredNorm());
    filter_->initialize(state,
                        filter_->covariance() + filter_->fromWorldCovariance(state, inflation));
    result = filter_->correctPosition(used, gate);
    if (result.accepted) ++statistics_.gps_reacquisitions;
  }
  statistics_.last_mahalanobis_squared = result.mahalanobis_squared;
  if (result.accepted) {
    noteHeadingChange(heading_before);
    consecutive_rejected_fixes_ = 0;
    wheel_speeds_suspended_ = false;  // the fix anchors the velocity again
    last_accepted_fix_s_ = filter_->state().stamp_s;
    last_accepted_fix_position_ = fix_imu_position;
  }
  if (result.accepted) {
    ++statistics_.gps_used;
  } else {
    ++statistics_.gps_rejected;
  }
  return result;
}

void Localizer::noteHeadingChange(double heading_before_rad) {
  heading_correction_rad_ += wrapRad(vehicleHeading() - heading_before_rad);
}

void Localizer::decorrelateYaw() {
  // In the left-invariant error xi = [xi_R, xi_v, xi_p, ...] (X_true = X_est Exp(xi)) the yaw
  // about the map z axis is u^T xi_R with u = R^T e_z, and a rotation about the map z axis
  // through the current position that leaves the map velocity and position alone is the
  // direction w = [u; 0; 0]. With the projector Q = I - w w^T (w^T w = 1) the error splits into
  // w * yaw + Q xi; P' = Q P Q^T + (w^T P w) w w^T keeps the yaw's variance and the covariance
  // of Q xi (every map-frame velocity, position and bias error: none of them sees w) and drops
  // only their cross-covariance. A position fix (H w = 0) then has no gain on the yaw.
  const auto* base = dynamic_cast<const ImuFilterBase*>(filter_.get());
  if (!base) return;
  const NavState& state = filter_->state();
  const Matrix15d to_left = base->leftFromError(state);
  const Matrix15d from_left = base->errorFromLeft(state);
  const ErrorCovariance left = to_left * filter_->covariance() * to_left.transpose();
  Eigen::Matrix<double, 15, 1> w = Eigen::Matrix<double, 15, 1>::Zero();
  w.head<3>() = state.rotation.transpose() * Eigen::Vector3d::UnitZ();
  const Matrix15d q = Matrix15d::Identity() - w * w.transpose();
  const double yaw_variance = w.dot(left * w);
  ErrorCovariance held = q * left * q.transpose() + yaw_variance * w * w.transpose();
  held = from_left * held * from_left.transpose();
  held = 0.5 * (held + held.transpose());
  if (!held.allFinite()) return;
  filter_->initialize(state, held);
}

void Localizer::noteHeadingEvent(const std::string& what) {
  if (!heading_event_.empty()) heading_event_ += "; ";
  heading_event_ += what;
}

std::string Localizer::takeHeadingEvent() {
  std::string event;
  event.swap(heading_event_);
  return event;
}

StandstillDetector::Fixes Localizer::trackVerdict() const {
  // The fixes of the last kFixesWindowS, while they are current: a robot that drove into a garage
  // and stopped there is not moving; fixes that have stopped coming say nothing.
  using Fixes = StandstillDetector::Fixes;
  constexpr double kWindowS = StandstillDetector::kFixesWindowS, kCurrentS = 2.5;
  constexpr int kMinFixes = 5;
  if (track_fixes_.empty() ||
      !(filter_->state().stamp_s - track_fixes_.back().stamp_s <= kCurrentS)) {
    return Fixes::kUnknown;
  }
  double variance = 0.0;
  const double speed = trackVelocity(kWindowS, &variance).norm();
  if (!std::isfinite(variance)) return Fixes::kUnknown;
  const double sigma = std::sqrt(variance), max_speed = config_.standstill.max_speed_mps;
  if (speed - 2.0 * sigma > max_speed) return Fixes::kMoving;
  // Standing: a track over (most of) the window, slower than the limit by two of its sigmas.
  const double newest = track_fixes_.back().stamp_s;
  int fixes = 0;
  double oldest = newest;
  for (const TrackFix& f : track_fixes_) {
    if (f.stamp_s < newest - kWindowS - kDuplicateStampS) continue;
    ++fixes;
    oldest = std::min(oldest, f.stamp_s);
  }
  const bool covers = fixes >= kMinFixes && newest - oldest >= 0.8 * kWindowS;
  return covers && speed + 2.0 * sigma <= max_speed ? Fixes::kStanding : Fixes::kUnknown;
}

double Localizer::horizontalVelocitySigma() const {
  // The body velocity's covariance (its first block of the twist) turned into the map.
  const Eigen::Matrix3d& r = filter_->state().rotation;
  const Eigen::Matrix3d map = r * filter_->twistCovariance().topLeftCorner<3, 3>() * r.transpose();
  return std::sqrt(std::max({0.0, map(0, 0), map(1, 1)}));
}

double Localizer::yawSigma() const {
  if (!initialized_) return std::numeric_limits<double>::infinity();
  const Eigen::Matrix3d& r = filter_->state().rotation;
  const Eigen::Matrix3d world =
      r * filter_->poseCovariance().bottomRightCorner<3, 3>() * r.transpose();
  return std::sqrt(std::max(0.0, world(2, 2)));
}

void Localizer::addToTrack(const PositionFix& fix) {
  TrackFix current;
  current.stamp_s = fix.stamp_s;
  current.position = fix.position_map.head<2>();
  current.variance = 0.5 * fix.covariance_map.topLeftCorner<2, 2>().trace();
  current.gyro_heading_rad = vehicleHeading() - heading_correction_rad_;
  if (heading_confirmed_) {
    const NavState& now = filter_->state();
    current.forward_speed_mps = now.velocity_map.dot(now.rotation * forward_in_imu_);
  }
  if (!current.position.allFinite() || !std::isfinite(current.variance)) return;
  // A chord from an earlier fix to this one, at least two fix intervals and
  // heading_track_min_chord_m long (1.5 m fixes: a 12 m chord is worth ~10 deg, a 6 m one ~20;
  // a slow car gets longer chords in time), within heading_track_max_chord_s, against the gyro
  // heading at its middle instant (on a circular arc driven at constant speed the chord is
  // parallel to the tangent there), interpolated between the fixes around it.
  const double floor = config_.heading_track_chord_floor_deg * kDegToRad;
  for (std::size_t k = track_fixes_.size(); k >= 2; --k) {
    const TrackFix& start = track_fixes_[k - 2];
    const double dt = current.stamp_s - start.stamp_s;
    if (!(dt <= config_.heading_track_max_chord_s)) break;
    const Eigen::Vector2d chord = current.position - start.position;
    const double length = chord.norm();
    if (length < config_.heading_track_min_chord_m) continue;
    // Not across an outage (no gap over 3 s), of a car moving but not impossibly fast.
    const bool two_intervals = k == track_fixes_.size();
    bool gap = two_intervals && dt > 3.0;
    for (std::size_t j = k - 1; j <= track_fixes_.size() && !gap; ++j) {
      const double next_s = j < track_fixes_.size() ? track_fixes_[j].stamp_s : current.stamp_s;
      gap = next_s - track_fixes_[j - 1].stamp_s > 3.0;
    }
    if (gap || !(dt > kDuplicateStampS) || length < config_.heading_track_min_speed_mps * dt ||
        length > config_.max_reacquisition_speed_mps * dt) {
      break;
    }
    double middle_heading = 0.0, turn = 0.0;
    if (two_intervals) {
      // The fix between them must be the chord's middle (evenly spaced fixes).
      const TrackFix& middle = track_fixes_.back();
      if (std::abs(middle.stamp_s - start.stamp_s - 0.5 * dt) > 0.15 * dt) break;
      middle_heading = middle.gyro_heading_rad;
    } else {
      const double middle_s = start.stamp_s + 0.5 * dt;
      middle_heading = current.gyro_heading_rad;
      for (std::size_t j = k - 2; j < track_fixes_.size(); ++j) {
        const TrackFix& a = track_fixes_[j];
        const TrackFix& b = j + 1 < track_fixes_.size() ? track_fixes_[j + 1] : current;
        if (b.stamp_s >= middle_s) {
          const double f =
              b.stamp_s > a.stamp_s ? (middle_s - a.stamp_s) / (b.stamp_s - a.stamp_s) : 0.0;
          middle_heading =
              a.gyro_heading_rad + f * wrapRad(b.gyro_heading_rad - a.gyro_heading_rad);
          break;
        }
      }
      // A turn along a long chord: the tangent-at-the-middle rule holds only on a circle.
      turn = wrapRad(current.gyro_heading_rad - start.gyro_heading_rad);
      if (std::abs(turn) > config_.heading_track_max_turn_deg * kDegToRad) break;
    }
    Chord c;
    c.stamp_s = current.stamp_s;
    c.offset_rad = wrapRad(std::atan2(chord.y(), chord.x()) - middle_heading);
    // Reversing: the filter's velocity along the confirmed heading, integrated over the chord's
    // fixes, went backwards most of its length. Not the velocity at its last fix alone: a chord
    // may end at a stop (it spans up to heading_track_max_chord_s), where that velocity is
    // noise about zero, and half the chords of the stop's first seconds would point backwards;
    // once the chords before the stop left the window, they turned the heading round.
    if (forwardDistance(k - 2, current) < -0.5 * length)
      c.offset_rad = wrapRad(c.offset_rad + M_PI);
    c.variance = (start.variance + current.variance) / (length * length) + floor * floor +
                 std::pow(config_.heading_track_turn_weight * turn, 2);
    chords_.push_back(c);
    break;
  }
  track_fixes_.push_back(current);
  // The standstill's verdict reads the fixes of its own window too.
  const double kept_s = config_.standstill.enabled ? std::max(config_.heading_track_window_s,
                                                              StandstillDetector::kFixesWindowS)
                                                   : config_.heading_track_window_s;
  const double oldest = current.stamp_s - kept_s;
  while (!track_fixes_.empty() && track_fixes_.front().stamp_s < oldest) track_fixes_.pop_front();
  while (!chords_.empty() && chords_.front().stamp_s < oldest) chords_.pop_front();
}

double Localizer::forwardDistance(std::size_t first, const TrackFix& current) const {
  // The trapezoid rule over the fixes from track_fixes_[first] to `current`; 0 when a speed is
  // unknown (the heading was not confirmed at a fix): the chord counts as driven forwards.
  double distance = 0.0;
  for (std::size_t j = first; j < track_fixes_.size(); ++j) {
    const TrackFix& a = track_fixes_[j];
    const TrackFix& b = j + 1 < track_fixes_.size() ? track_fixes_[j + 1] : current;
    const double step = 0.5 * (a.forward_speed_mps + b.forward_speed_mps) * (b.stamp_s - a.stamp_s);
    if (!std::isfinite(step)) return 0.0;
    distance += step;
  }
  return distance;
}

Localizer::TrackHeading Localizer::trackHeading() const {
  TrackHeading track;
  if (static_cast<int>(chords_.size()) < config_.heading_track_min_chords) return track;
  // Weighted circular mean, then once more without the chords more than 3 sigma from it (a
  // receiver jump, a stretch driven in reverse).
  const auto mean = [this](const double* centre, int* used, double* information) {
    double s = 0.0, c = 0.0;
    *used = 0;
    *information = 0.0;
    for (const Chord& chord : chords_) {
      if (centre &&
          std::abs(wrapRad(chord.offset_rad - *centre)) > 3.0 * std::sqrt(chord.variance)) {
        continue;
      }
      const double w = 1.0 / chord.variance;
      s += w * std::sin(chord.offset_rad);
      c += w * std::cos(chord.offset_rad);
      *information += w;
      ++*used;
    }
    return std::atan2(s, c);
  };
  int used = 0;
  double information = 0.0;
  const double first = mean(nullptr, &used, &information);
  const double offset = mean(&first, &used, &information);
  if (used < config_.heading_track_min_chords || !(information > 0.0)) return track;
  // Most chords must agree: otherwise the car reversed or the track is not a heading.
  if (2 * used <= static_cast<int>(chords_.size())) return track;
  double chi2 = 0.0;
  for (const Chord& chord : chords_) {
    const double r = wrapRad(chord.offset_rad - offset);
    if (std::abs(r) <= 3.0 * std::sqrt(chord.variance)) chi2 += r * r / chord.variance;
  }
  if (chi2 > 3.0 * used) return track;
  track.valid = std::isfinite(offset);
  track.offset_rad = offset;
  track.sigma_rad = 1.0 / std::sqrt(information);
  track.chords = used;
  return track;
}

Eigen::Vector2d Localizer::trackVelocity(double window_s, double* variance) const {
  // Least-squares slope of the fixes of the last window_s (constant velocity).
  *variance = std::numeric_limits<double>::infinity();
  if (track_fixes_.size() < 2) return Eigen::Vector2d::Zero();
  const double newest = track_fixes_.back().stamp_s;
  double t_mean = 0.0, n = 0.0, noise = 0.0;
  Eigen::Vector2d p_mean = Eigen::Vector2d::Zero();
  for (const TrackFix& f : track_fixes_) {
    if (f.stamp_s < newest - window_s - kDuplicateStampS) continue;
    t_mean += f.stamp_s;
    p_mean += f.position;
    noise = std::max(noise, f.variance);
    n += 1.0;
  }
  if (n < 2.0) return Eigen::Vector2d::Zero();
  t_mean /= n;
  p_mean /= n;
  double stt = 0.0;
  Eigen::Vector2d stp = Eigen::Vector2d::Zero();
  for (const TrackFix& f : track_fixes_) {
    if (f.stamp_s < newest - window_s - kDuplicateStampS) continue;
    stt += (f.stamp_s - t_mean) * (f.stamp_s - t_mean);
    stp += (f.stamp_s - t_mean) * (f.position - p_mean);
  }
  if (!(stt > 1e-6)) return Eigen::Vector2d::Zero();
  *variance = noise / stt;
  return stp / stt;
}

void Localizer::realignHeading(const TrackHeading& track, const std::string& why) {
  wheel_sign_checked_ = false;  // the velocity is re-initialised: check the wheels' sign again
  const NavState before = filter_->state();
  const double delta = wrapRad(track.offset_rad - heading_correction_rad_);
  const Eigen::Matrix3d turn =
      Eigen::AngleAxisd(delta, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  NavState state = before;
  state.rotation = lie::normalizeRotation(turn * before.rotation);
  // The world-frame covariance of the re-initialised state: the variances of roll, pitch,
  // position and biases as the filter had them, yaw from the track, the horizontal velocity from
  // the fixes of the last seconds (the dead-reckoned one was integrated with the wrong heading).
  // Their cross-covariances are dropped on purpose: they were built along the wrong heading.
  // Keeping them (the tilt's with the biases, turned with the body) makes a filter whose heading
  // was right about a third less overconfident in attitude and gyro bias in simulation, but on
  // the real drives with IMU + GPS only it cost 0071 in 5 of 6 GPS seeds (5.91 -> 6.20 m, 9.55 ->
  // 12.60 m) and changed nothing elsewhere (docs/localization.md, "Realigning the heading").
  const PoseCovariance pose = filter_->poseCovariance();
  const ErrorCovariance old = filter_->covariance();
  ErrorCovariance world = ErrorCovariance::Zero();
  world.block<3, 3>(0, 0) =
      before.rotation * pose.bottomRightCorner<3, 3>() * before.rotation.transpose();
  world.block<1, 3>(2, 0).setZero();
  world.block<3, 1>(0, 2).setZero();
  world(2, 2) = track.sigma_rad * track.sigma_rad;
  double velocity_variance = 0.0;
  const Eigen::Vector2d velocity = trackVelocity(3.0, &velocity_variance);
  const double floor = 1.0;  // m/s: the car's acceleration over the fitted seconds
  if (std::isfinite(velocity_variance)) {
    state.velocity_map.head<2>() = velocity;
    world.block<2, 2>(3, 3) = Eigen::Matrix2d::Identity() * (velocity_variance + floor * floor);
  } else {
    state.velocity_map = turn * before.velocity_map;
    const double v2 = before.velocity_map.head<2>().squaredNorm() + floor * floor;
    world.block<2, 2>(3, 3) = Eigen::Matrix2d::Identity() * v2;
  }
  world(5, 5) = std::max(floor * floor,
                         config_.initial_velocity_sigma_mps * config_.initial_velocity_sigma_mps);
  world.block<3, 3>(6, 6) = pose.topLeftCorner<3, 3>();
  world.block<6, 6>(9, 9) = old.block<6, 6>(9, 9);  // bias errors: additive in every filter
  if (!world.allFinite() || !state.rotation.allFinite() || !state.velocity_map.allFinite()) return;
  filter_->initialize(state, filter_->fromWorldCovariance(state, world));
  heading_correction_rad_ += delta;
  heading_confirmed_ = false;
  // The rejected fixes are still counted: a heading realigned from the track does not mend an
  // error the track cannot see (altitude, speed), and zeroing the count here kept re-acquisition
  // from ever firing (each re-open made the heading unknown, the next fix realigned it).
  horizontal_nis_.clear();
  noteHeadingEvent(why);
}

void Localizer::reopenHeading(const Eigen::Vector3d& innovation, const std::string& why) {
  wheel_sign_checked_ = false;
  const NavState& state = filter_->state();
  const double since_last_fix_s = std::max(1.0, state.stamp_s - last_accepted_fix_s_);
  // A rotation about the map z axis through the current position, in the filter's own error
  // coordinates (left-invariant: sigma^2 u u^T on the rotation block, u = R^T e_z); the map
  // velocity may be off by as much as the car's speed, the position by the innovation.
  ErrorCovariance world = ErrorCovariance::Zero();
  const double yaw_sigma = config_.unknown_yaw_sigma_deg * kDegToRad;
  world(2, 2) = yaw_sigma * yaw_sigma;
  const double speed2 = state.velocity_map.head<2>().squaredNorm() +
                        std::pow(innovation.head<2>().norm() / since_last_fix_s, 2);
  world(3, 3) = world(4, 4) = speed2;
  world(6, 6) = world(7, 7) = innovation.head<2>().squaredNorm();
  const ErrorCovariance inflated =
      filter_->covariance() + filter_->fromWorldCovariance(state, world);
  if (!inflated.allFinite()) return;
  filter_->initialize(state, inflated);
  heading_confirmed_ = false;
  ++statistics_.heading_reopens;
  char text[64];
  std::snprintf(text, sizeof(text), " at t=%.2f s", state.stamp_s);
  noteHeadingEvent(why + ": heading re-opened (sigma " +
                   std::to_string(static_cast<int>(config_.unknown_yaw_sigma_deg)) + " deg)" +
                   text);
}

void Localizer::reset() {
  initialized_ = false;
  last_imu_.reset();
  reference_rotation_.reset();
  reference_velocity_.reset();
  reference_rotation_covariance_.reset();
  interpolated_run_start_s_ = -1.0;
  filter_ = makeFilter(config_.filter_type, config_.imu_noise);
  standstill_.reset();
  clearHistory();
}

}  // namespace estimation
}  // namespace inekf_semantic_mapping
