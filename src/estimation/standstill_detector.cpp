// StandstillDetector: a sliding window of the IMU's levelled acceleration and bias-corrected
// rate, gated by the filter's velocity and the GPS track.
#include "inekf_semantic_mapping/estimation/standstill_detector.h"

#include <algorithm>
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
  raw_force_sum_.setZero();
  raw_rate_sum_.setZero();
  window_duration_s_ = 0.0;
  steady_s_ = 0.0;
  raw_rate_integral_.setZero();
  raw_rate_count_ = 0;
  still_duration_s_ = 0.0;
  still_ = false;
}

std::optional<StandstillMeasurement> StandstillDetector::add(const ImuSample& sample, double dt,
                                                             const NavState& state,
                                                             const Context& context) {
  if (!(dt > 0.0) || !std::isfinite(dt)) return std::nullopt;
  WindowSample entry;
  entry.dt = dt;
  // At rest the bias-corrected specific force rotated into the map is gravity's reaction, (0, 0,
  // g): its horizontal part is the acceleration (and the filter's tilt error times g, which the
  // zero-velocity updates themselves remove).
  entry.acceleration = (state.rotation * (sample.specific_force - state.accel_bias)).head<2>();
  entry.rate = sample.angular_velocity - state.gyro_bias;
  entry.raw_force = sample.specific_force;
  entry.raw_rate = sample.angular_velocity;
  window_.push_back(entry);
  acceleration_sum_ += entry.acceleration * dt;
  rate_sum_ += entry.rate * dt;
  raw_force_sum_ += entry.raw_force * dt;
  raw_rate_sum_ += entry.raw_rate * dt;
  window_duration_s_ += dt;
  // Keep the newest samples that cover window_s (the oldest one dropped only while the rest
  // still cover it).
  while (window_.size() > 1 && window_duration_s_ - window_.front().dt >= options_.window_s) {
    const WindowSample& old = window_.front();
    acceleration_sum_ -= old.acceleration * old.dt;
    rate_sum_ -= old.rate * old.dt;
    raw_force_sum_ -= old.raw_force * old.dt;
    raw_rate_sum_ -= old.raw_rate * old.dt;
    window_duration_s_ -= old.dt;
    window_.pop_front();
  }
  const bool full = window_duration_s_ >= options_.window_s - 1e-9;
  // Widened by three sigmas of the gyro bias (a turn-on bias not yet learnt), at most to three
  // times the limit: beyond, a slow turn on the spot would be taken for the bias.
  const double limit = options_.max_rate_degps * kDegToRad;
  const double max_rate =
      limit + std::min(2.0 * limit, 3.0 * std::max(0.0, context.gyro_bias_sigma_radps));
  const bool not_turning = full && (rate_sum_ / window_duration_s_).norm() <= max_rate;
  const bool quiet = not_turning && (acceleration_sum_ / window_duration_s_).norm() <=
                                        options_.max_acceleration_mps2;
  // Steady: the raw readings' window mean stays near their mean since the steady time began (no
  // acceleration and no turn began, whatever the filter's tilt and biases, which make a MEMS
  // filter's own acceleration wander at rest), within the limits, or three sigmas of the window
  // mean's own noise where that is larger (the window's scatter: the IMU's noise, vibration).
  const Eigen::Vector3d force_mean = raw_force_sum_ / window_duration_s_;
  const Eigen::Vector3d rate_mean = raw_rate_sum_ / window_duration_s_;
  // Per axis, the samples' variance about the window mean.
  Eigen::Vector3d force_scatter = Eigen::Vector3d::Zero(), rate_scatter = force_scatter;
  const double n = static_cast<double>(window_.size());
  if (full && n >= 2.0) {
    for (const WindowSample& w : window_) {
      force_scatter += (w.raw_force - force_mean).cwiseAbs2();
      rate_scatter += (w.raw_rate - rate_mean).cwiseAbs2();
    }
    force_scatter /= n - 1.0;
    rate_scatter /= n - 1.0;
  }
  const bool steady =
      full && steady_s_ > 0.0 &&
      (force_mean - steady_force_).norm() <=
          std::max(options_.max_acceleration_mps2, 3.0 * std::sqrt(force_scatter.sum() / n)) &&
      (rate_mean - steady_rate_).norm() <=
          std::max(options_.max_rate_degps * kDegToRad, 3.0 * std::sqrt(rate_scatter.sum() / n));
  if (steady) {
    // The reference: the mean of the window means since the steady time began.
    steady_s_ += dt;
    steady_force_ += (force_mean - steady_force_) * (dt / steady_s_);
    steady_rate_ += (rate_mean - steady_rate_) * (dt / steady_s_);
  } else if (full) {
    steady_force_ = force_mean;
    steady_rate_ = rate_mean;
    steady_s_ = dt;  // begins now
  }
  const double speed = state.velocity_map.head<2>().norm();
  const double max_speed = options_.max_speed_mps;
  // The filter's speed is below the limit by two of its sigmas (and the fixes do not say it
  // moves); or the fixes have stood for their window and the IMU been steady as long. Standing
  // within the velocity's sigmas is no evidence: a robot driving steadily at 1.5 m/s through an
  // outage, its velocity sigma grown to 0.6 m/s, was held at zero for 46 m; a robot pulling away
  // gently to 0.4 m/s, its first 0.2 s of acceleration still in a quiet window, was held at zero
  // again by a speed estimate of 0.3 +- 0.05. The raw readings must have been steady for
  // kSettleS too: the filter's own speed and acceleration, which the updates pin, confirmed a
  // standstill after a gentle pull-away (0.3 m/s^2) and held the robot for 8 s, 12 m.
  const bool known_still = quiet && steady && steady_s_ >= kSettleS &&
                           speed + 2.0 * context.velocity_sigma_mps <= max_speed &&
                           context.fixes != Fixes::kMoving;
  const bool fixes_stood =
      not_turning && context.fixes == Fixes::kStanding && steady_s_ >= kFixesWindowS - 1e-9;
  still_ = known_still || fixes_stood;
  if (!still_) {
    raw_rate_integral_.setZero();
    raw_rate_count_ = 0;
    still_duration_s_ = 0.0;
    return std::nullopt;
  }
  raw_rate_integral_ += sample.angular_velocity * dt;
  ++raw_rate_count_;
  still_duration_s_ += dt;
  if (still_duration_s_ < options_.update_interval_s - 1e-9) return std::nullopt;
  StandstillMeasurement measurement;
  measurement.velocity_sigma_mps = options_.velocity_sigma_mps;
  measurement.mean_angular_velocity = raw_rate_integral_ / still_duration_s_;
  // White noise of density d averaged over T seconds: d^2 / T per axis. Vibration beyond the
  // configured density shows as the window's scatter (s^2 per sample, s^2 / n for the mean of the
  // interval's n samples); the larger of the two.
  const double density = context.gyro_noise_density;
  const Eigen::Vector3d variance = Eigen::Vector3d::Constant(density * density / still_duration_s_)
                                       .cwiseMax(rate_scatter / raw_rate_count_);
  measurement.angular_velocity_variance = variance;
  raw_rate_integral_.setZero();
  raw_rate_count_ = 0;
  still_duration_s_ = 0.0;
  return measurement;
}

}  // namespace estimation
}  // namespace inekf_semantic_mapping
