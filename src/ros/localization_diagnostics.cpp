#include "inekf_semantic_mapping/ros/localization_diagnostics.h"

#include <cmath>
#include <iomanip>
#include <optional>
#include <sstream>

#include "inekf_semantic_mapping/ros/localization_conversions.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

namespace {
using diagnostic_msgs::DiagnosticStatus;
constexpr double kRadToDeg = 180.0 / M_PI;
}  // namespace

void readLocalizationDiagnosticsOptions(common::YamlReader* reader, const std::string& prefix,
                                        LocalizationDiagnosticsOptions* options) {
  LocalizationDiagnosticsOptions& o = *options;
  for (const auto& [key, value] : {std::pair{"expected_imu_rate_hz", &o.expected_imu_rate_hz},
                                   {"expected_fix_rate_hz", &o.expected_fix_rate_hz},
                                   {"fix_warn_after_s", &o.fix_warn_after_s},
                                   {"fix_error_after_s", &o.fix_error_after_s},
                                   {"window_s", &o.window_s},
                                   {"max_position_sigma_m", &o.max_position_sigma_m},
                                   {"max_heading_sigma_deg", &o.max_heading_sigma_deg},
                                   {"imu_stale_after_s", &o.imu_stale_after_s}}) {
    reader->read(prefix + key, value);
    if (!(*value > 0)) reader->fail(prefix + key, "must be > 0");
  }
  if (o.fix_error_after_s < o.fix_warn_after_s) {
    reader->fail(prefix + "fix_error_after_s", "must be >= fix_warn_after_s");
  }
}

LocalizationMonitor::LocalizationMonitor(LocalizationDiagnosticsOptions options)
    : options_(options),
      imu_(options.window_s),
      fixes_(options.window_s),
      accepted_(options.window_s),
      rejected_(options.window_s) {}

void LocalizationMonitor::noteCounters(double stamp_s,
                                       const estimation::LocalizationSession& session) {
  const estimation::LocalizationSession::Statistics statistics = session.statistics();
  if (statistics.resets != resets_) {  // a new timeline: its windows start empty
    resets_ = statistics.resets;
    imu_.clear();
    fixes_.clear();
    accepted_.clear();
    rejected_.clear();
    first_imu_s_ = stamp_s;
    last_accepted_s_ = -1.0;
  }
  if (statistics.filter.gps_used > used_) {
    const double d2 = session.lastMahalanobisSquared();
    const double dof = session.lastInnovationDegreesOfFreedom();
    accepted_.add(stamp_s, std::isfinite(d2) ? d2 / dof : 0.0);
    last_accepted_s_ = stamp_s;
  }
  const std::int64_t rejected = statistics.filter.gps_rejected + statistics.fixes_ignored;
  if (rejected > rejected_count_) rejected_.add(stamp_s);
  used_ = statistics.filter.gps_used;
  rejected_count_ = rejected;
}

void LocalizationMonitor::noteImu(double stamp_s, double wall_s,
                                  const estimation::LocalizationSession& session) {
  if (imu_.count() == 0 && last_imu_wall_s_ < 0) first_imu_s_ = stamp_s;
  if (stamp_s < newest_s_) first_imu_s_ = stamp_s;  // the data went back (bag loop)
  newest_s_ = stamp_s;
  last_imu_wall_s_ = wall_s;
  imu_.add(stamp_s);
  // The fix windows end at the newest data too: a GPS that went quiet showed its last window's
  // rate, counts and NIS for good.
  fixes_.expire(stamp_s);
  accepted_.expire(stamp_s);
  rejected_.expire(stamp_s);
  noteCounters(stamp_s, session);
}

void LocalizationMonitor::noteFix(double stamp_s, double wall_s,
                                  const estimation::LocalizationSession& session) {
  fixes_.add(stamp_s);
  noteCounters(stamp_s, session);
}

void LocalizationMonitor::fill(const estimation::LocalizationSession& session, double wall_s,
                               diagnostic_updater::DiagnosticStatusWrapper* status) const {
  const estimation::LocalizationSession::Statistics statistics = session.statistics();
  const estimation::Localizer::Statistics& filter = statistics.filter;
  // "re-initialised" for a window after a reset, then "running" again (a looping bag said
  // "re-initialised" for good after its first loop); the count of resets stays below.
  const bool recently_reset = statistics.resets > 0 && newest_s_ - first_imu_s_ < options_.window_s;
  const std::string state = !session.started() ? "waiting"
                            : recently_reset   ? "re-initialised"
                                               : "running";
  const double since_fix_s = newest_s_ - (last_accepted_s_ >= 0 ? last_accepted_s_ : first_imu_s_);
  double position_sigma_m = 0.0, heading_sigma_deg = 0.0;
  bool finite = true;
  if (session.started()) {
    const estimation::PoseCovariance covariance = session.poseCovariance();
    finite = isFinite(session.state(), covariance);
    const std::array<double, 36> ros = rosPoseCovariance(session.state().rotation, covariance);
    position_sigma_m = std::sqrt(std::max(0.0, ros[0] + ros[7]));
    heading_sigma_deg = std::sqrt(std::max(0.0, ros[35])) * kRadToDeg;
  }
  const bool has_imu = last_imu_wall_s_ >= 0;
  const double imu_silent_s = has_imu ? wall_s - last_imu_wall_s_ : 0.0;
  const double imu_rate = imu_.rateHz(), fix_rate = fixes_.rateHz();
  const bool window_full = newest_s_ - first_imu_s_ >= options_.window_s;

  // The worst condition names the status; ERROR before WARN before OK.
  std::ostringstream message;
  unsigned char level = DiagnosticStatus::OK;
  const auto raise = [&](unsigned char to, const std::string& why) {
    if (to < level) return;
    if (to > level) message.str("");
    if (!message.str().empty()) message << "; ";
    message << why;
    level = to;
  };
  if (!has_imu) {
    raise(DiagnosticStatus::OK, "waiting for IMU");
  } else {
    if (!finite) raise(DiagnosticStatus::ERROR, "state or covariance not finite");
    if (const std::optional<double> offset = session.gpsClockOffset()) {
      std::ostringstream why;
      why << "GPS stamps " << std::fixed << std::setprecision(1) << std::abs(*offset) << " s "
          << (*offset > 0.0 ? "ahead of" : "behind")
          << " the IMU's (another clock: GPS time against UTC?): GPS dropped";
      raise(DiagnosticStatus::ERROR, why.str());
    }
    if (since_fix_s > options_.fix_error_after_s) {
      raise(DiagnosticStatus::ERROR,
            "no accepted GPS fix for " + std::to_string(static_cast<int>(since_fix_s)) + " s");
    } else if (since_fix_s > options_.fix_warn_after_s) {
      raise(DiagnosticStatus::WARN,
            "no accepted GPS fix for " + std::to_string(static_cast<int>(since_fix_s)) + " s");
    }
    if (imu_silent_s > options_.imu_stale_after_s) {
      raise(DiagnosticStatus::WARN,
            "no IMU for " + std::to_string(static_cast<int>(imu_silent_s)) + " s");
    }
    if (window_full && imu_rate < 0.5 * options_.expected_imu_rate_hz) {
      raise(DiagnosticStatus::WARN, "IMU rate below half the expected");
    }
    if (rejected_.count() >= 2 && rejected_.count() > accepted_.count()) {
      raise(DiagnosticStatus::WARN, "most fixes rejected");
    }
    if (session.started() && position_sigma_m > options_.max_position_sigma_m) {
      raise(DiagnosticStatus::WARN, "position uncertain");
    }
    if (session.started() && heading_sigma_deg > options_.max_heading_sigma_deg) {
      raise(DiagnosticStatus::WARN, "heading uncertain (not yet observed by motion?)");
    }
    if (level == DiagnosticStatus::OK) raise(DiagnosticStatus::OK, state);
  }
  status->summary(level, message.str());
  status->add("filter", estimation::toString(session.config().localizer.filter_type));
  status->add("state", state);
  status->addf("IMU rate (Hz)", "%.2f", imu_rate);
  status->addf("IMU expected rate (Hz)", "%.2f", options_.expected_imu_rate_hz);
  status->addf("fix rate (Hz)", "%.2f", fix_rate);
  status->addf("fix expected rate (Hz)", "%.2f", options_.expected_fix_rate_hz);
  status->addf("since last accepted fix (s, data time)", "%.1f", has_imu ? since_fix_s : 0.0);
  status->add("fixes accepted in window", accepted_.count());
  status->add("fixes rejected in window", rejected_.count());
  status->addf("mean normalised innovation (NIS / dof)", "%.2f", accepted_.mean());
  status->addf("position sigma horizontal (m)", "%.2f", position_sigma_m);
  status->addf("heading sigma (deg)", "%.2f", heading_sigma_deg);
  status->add("fixes used", filter.gps_used);
  status->add("fixes rejected", filter.gps_rejected + statistics.fixes_ignored);
  status->add("land-vehicle constraint updates", filter.nonholonomic_used);
  status->add("land-vehicle constraint rejected / skipped / suspended",
              std::to_string(filter.nonholonomic_rejected) + " / " +
                  std::to_string(filter.nonholonomic_skipped) + " / " +
                  std::to_string(filter.nonholonomic_suspended));
  status->add("standstill updates used / rejected / zero-rate rejected",
              std::to_string(filter.standstill_used) + " / " +
                  std::to_string(filter.standstill_rejected) + " / " +
                  std::to_string(filter.standstill_rate_rejected));
  status->add("wheel speeds used / rejected / stale / ignored / suspensions",
              std::to_string(filter.wheel_speed_used) + " / " +
                  std::to_string(filter.wheel_speed_rejected) + " / " +
                  std::to_string(filter.wheel_speed_stale) + " / " +
                  std::to_string(filter.wheel_speed_ignored) + " / " +
                  std::to_string(filter.wheel_speed_suspensions));
  status->add("heading alignments", filter.heading_alignments);
  status->add("heading recoveries", filter.heading_recoveries + filter.heading_reopens);
  status->add("resets", statistics.resets);
}

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
