// StandstillDetector: a sliding window of the IMU's levelled acceleration and bias-corrected
// rate, gated by the filter's velocity.
#include "inekf_semantic_mapping/estimation/standstill_detector.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

constexpr double kDegToRad = M_PI / 180.0;

void requirePositive(double value, const char* name) {
  if (!(value > 0.0) || !std::isfinite(value)) {
    throw std::invalid_argument(std::string("standstill.") + name +
                                " must be positive and finite, got " + std::to_string(value));
  }
}

}  // namespace

void validate(const StandstillOptions& options) {
  requirePositive(options.window_s, "window_s");
  requirePositive(options.max_acceleration_mps2, "max_acceleration_mps2");
  requirePositive(options.max_rate_degps, "max_rate_degps");
  requirePositive(options.max_speed_mps, "max_speed_mps");
  requirePositive(options.max_velocity_sigma_mps, "max_velocity_sigma_mps");
  requirePositive(options.velocity_sigma_mps, "velocity_sigma_mps");
  requirePositive(options.update_interval_s, "update_interval_s");
  requirePositive(options.gate_mahalanobis_squared, "gate_mahalanobis_squared");
}

StandstillDetector::StandstillDetector(const StandstillOptions& options) : options_(options) {
  validate(options_);
}

void StandstillDetector::reset() {
  window_.clear();
  acceleration_sum_.setZero();
  rate_sum_.setZero();
  window_duration_s_ = 0.0;
  raw_rate_integral_.setZero();
  still_duration_s_ = 0.0;
  still_ = false;
}

std::optional<StandstillMeasurement> StandstillDetector::add(const ImuSample& sample, double dt,
                                                             const NavState& state,
                                                             double velocity_sigma_mps,
                                                             bool fixes_say_moving,
                                                             double gyro_noise_density) {
  if (!(dt > 0.0) || !std::isfinite(dt)) return std::nullopt;
  WindowSample entry;
  entry.stamp_s = sample.stamp_s;
  entry.dt = dt;
  // At rest the bias-corrected specific force rotated into the map is gravity's reaction, (0, 0,
  // g): its horizontal part is the acceleration (and the filter's tilt error times g, which the
  // zero-velocity updates themselves remove).
  entry.acceleration =
      (state.rotation * (sample.specific_force - state.accel_bias)).head<2>();
  entry.rate = sample.angular_velocity - state.gyro_bias;
  window_.push_back(entry);
  acceleration_sum_ += entry.acceleration * dt;
  rate_sum_ += entry.rate * dt;
  window_duration_s_ += dt;
  // Keep the newest samples that cover window_s (the oldest one dropped only while the rest
  // still cover it).
  while (window_.size() > 1 && window_duration_s_ - window_.front().dt >= options_.window_s) {
    const WindowSample& old = window_.front();
    acceleration_sum_ -= old.acceleration * old.dt;
    rate_sum_ -= old.rate * old.dt;
    window_duration_s_ -= old.dt;
    window_.pop_front();
  }
  const double speed = state.velocity_map.head<2>().norm();
  const double max_speed = options_.max_speed_mps;
  // The filter knows the vehicle stands; or it cannot tell (standing is within two sigmas) and
  // the fixes do not say it moves.
  const bool known_still = speed <= max_speed && velocity_sigma_mps <= max_speed;
  const bool maybe_still = speed <= max_speed + 2.0 * velocity_sigma_mps &&
                           velocity_sigma_mps <= options_.max_velocity_sigma_mps &&
                           !fixes_say_moving;
  still_ = window_duration_s_ >= options_.window_s - 1e-9 &&
           (acceleration_sum_ / window_duration_s_).norm() <= options_.max_acceleration_mps2 &&
           (rate_sum_ / window_duration_s_).norm() <= options_.max_rate_degps * kDegToRad &&
           (known_still || maybe_still);
  if (!still_) {
    raw_rate_integral_.setZero();
    still_duration_s_ = 0.0;
    return std::nullopt;
  }
  raw_rate_integral_ += sample.angular_velocity * dt;
  still_duration_s_ += dt;
  if (still_duration_s_ < options_.update_interval_s - 1e-9) return std::nullopt;
  StandstillMeasurement measurement;
  measurement.velocity_sigma_mps = options_.velocity_sigma_mps;
  measurement.mean_angular_velocity = raw_rate_integral_ / still_duration_s_;
  // White noise of density d averaged over T seconds: variance d^2 / T per axis.
  measurement.angular_velocity_variance =
      Eigen::Vector3d::Constant(gyro_noise_density * gyro_noise_density / still_duration_s_);
  raw_rate_integral_.setZero();
  still_duration_s_ = 0.0;
  return measurement;
}

}  // namespace estimation
}  // namespace inekf_semantic_mapping
