#include "inekf_semantic_mapping/estimation/localization_session.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

#include "inekf_semantic_mapping/common/yaml_reader.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

LazyStart::Config startConfig(const LocalizationSessionConfig& config) {
  LazyStart::Config start;
  start.max_wait_s = config.start_max_wait_s;
  start.max_velocity_age_s = config.start_max_velocity_age_s;
  start.use_reference = config.localizer.init_orientation_from_reference;
  return start;
}

// Why the state cannot be reported, or "" when it can.
std::string unsoundness(const NavState& state, const ErrorCovariance& covariance) {
  if (!(state.rotation.allFinite() && state.velocity_map.allFinite() &&
        state.position_map.allFinite() && state.gyro_bias.allFinite() &&
        state.accel_bias.allFinite() && covariance.allFinite())) {
    return "non-finite state";
  }
  if (!(covariance.diagonal().minCoeff() >= 0.0)) return "negative variance in the state";
  return "";
}

}  // namespace

LocalizationSessionConfig LocalizationSessionConfig::fromYamlFile(const std::string& path) {
  common::YamlReader reader = common::YamlReader::fromFile(path);
  LocalizationSessionConfig config;
  config.localizer = LocalizerConfig::fromYaml(&reader);
  reader.allow("node.*");
  const auto positive = [&reader](const std::string& key, double* out) {
    reader.readInRange(key, out, 0.0, 1e6, true);
  };
  positive("session.start_max_wait_s", &config.start_max_wait_s);
  positive("session.start_max_velocity_age_s", &config.start_max_velocity_age_s);
  positive("session.default_fix_sigma_horizontal_m", &config.default_fix_sigma_horizontal_m);
  positive("session.default_fix_sigma_vertical_m", &config.default_fix_sigma_vertical_m);
  positive("session.time_jump_back_s", &config.time_jump_back_s);
  positive("session.resume_origin_max_m", &config.resume_origin_max_m);
  reader.read("session.restart_after_imu_gap_s", &config.restart_after_imu_gap_s);
  if (!(config.restart_after_imu_gap_s >= 0.0) ||
      (config.restart_after_imu_gap_s > 0.0 &&
       config.restart_after_imu_gap_s <= config.localizer.max_imu_gap_s)) {
    // Below imu.max_gap_s a normal step would restart the filter.
    reader.fail("session.restart_after_imu_gap_s", "must be 0 or more than imu.max_gap_s");
  }
  reader.read("session.fix_wait_for_imu_s", &config.fix_wait_for_imu_s);
  if (!(config.fix_wait_for_imu_s >= 0.0)) {
    reader.fail("session.fix_wait_for_imu_s", "must be a number >= 0");
  }
  reader.rejectUnknown();
  return config;
}

LocalizationSession::LocalizationSession(LocalizationSessionConfig config)
    : config_(std::move(config)), localizer_(config_.localizer), lazy_start_(startConfig(config_)) {
  if (config_.origin) {
    const GeodeticOrigin& o = *config_.origin;
    if (!kitti::isGeodeticInRange(o.lat_deg, o.lon_deg, o.alt_m)) {
      throw std::invalid_argument("map origin (" + std::to_string(o.lat_deg) + ", " +
                                  std::to_string(o.lon_deg) + ", " + std::to_string(o.alt_m) +
                                  "): latitude must be in (-90, 90) deg, longitude in "
                                  "[-180, 180] deg, altitude finite");
    }
    projection_.emplace(config_.origin->lat_deg, config_.origin->lon_deg, config_.origin->alt_m);
  }
}

LocalizationSession::Statistics LocalizationSession::statistics() const {
  Statistics statistics = statistics_;
  statistics.filter = localizer_.statistics();
  return statistics;
}

std::string LocalizationSession::summary() const {
  const Statistics s = statistics();
  std::ostringstream line;
  line << std::fixed << std::setprecision(2);
  if (started()) {
    const Eigen::Vector3d& p = state().position_map;
    line << "t=" << state().stamp_s << " s position (" << std::setprecision(1) << p.x() << ", "
         << p.y() << ", " << p.z() << ") m, sigma " << std::setprecision(2)
         << std::sqrt(poseCovariance().topLeftCorner<3, 3>().trace()) << " m; ";
  } else {
    line << "not started; ";
  }
  line << "IMU " << s.filter.imu_used << " used / " << s.filter.imu_dropped + s.imu_invalid
       << " dropped / " << s.filter.imu_gaps << " gaps; GPS " << s.filter.gps_used << " used ("
       << s.filter.gps_applied_late << " late";
  if (s.fixes_horizontal_only > 0) line << ", " << s.fixes_horizontal_only << " 2D";
  line << ") / " << s.filter.gps_rejected << " rejected / " << s.fixes_ignored << " ignored; ";
  if (s.filter.nonholonomic_used + s.filter.nonholonomic_rejected + s.filter.nonholonomic_skipped >
      0) {
    line << "vehicle constraint " << s.filter.nonholonomic_used << " used / "
         << s.filter.nonholonomic_rejected << " rejected / " << s.filter.nonholonomic_skipped
         << " waiting for the heading; ";
  }
  if (s.filter.standstill_used + s.filter.standstill_rejected > 0) {
    line << "standstill " << s.filter.standstill_used << " used / " << s.filter.standstill_rejected
         << " rejected (zero rate " << s.filter.standstill_rate_rejected << " rejected); ";
  }
  if (s.filter.wheel_speed_used + s.filter.wheel_speed_rejected + s.filter.wheel_speed_stale > 0) {
    line << "wheel speed " << s.filter.wheel_speed_used << " used / "
         << s.filter.wheel_speed_rejected << " rejected (" << s.filter.wheel_speed_suspensions
         << " suspensions) / " << s.filter.wheel_speed_stale << " stale; ";
  }
  const std::int64_t heading_events =
      s.filter.heading_alignments + s.filter.heading_recoveries + s.filter.heading_reopens;
  if (heading_events > 0) {
    line << "heading " << s.filter.heading_alignments << " aligned / "
         << s.filter.heading_recoveries << " recovered / " << s.filter.heading_reopens
         << " re-opened; ";
  }
  line << s.resets << " resets";
  if (s.messages_of_previous_time_line > 0) {
    line << " (" << s.messages_of_previous_time_line
         << " messages of the time line before a jump dropped)";
  }
  if (s.gps_messages_off_the_imu_clock > 0) {
    line << " (" << s.gps_messages_off_the_imu_clock
         << " GPS messages dropped: stamped on another clock than the IMU's)";
  }
  if (s.messages_off_the_time_line > 0) {
    line << " (" << s.messages_off_the_time_line
         << " messages off the time line dropped: no second message confirmed their jump)";
  }
  return line.str();
}

void LocalizationSession::reset(const std::string& why, Update* update) {
  localizer_.reset();
  lazy_start_.reset();
  waiting_fixes_.clear();
  newest_stamp_s_.reset();
  if (held_jump_) dropHeldJump();
  ++statistics_.resets;
  update->reset = true;
  update->note = why;
}

LocalizationSession::Update LocalizationSession::restart(const std::string& why) {
  Update update;
  reset(why, &update);
  return update;
}

void LocalizationSession::dropHeldJump() {
  statistics_.messages_off_the_time_line += static_cast<std::int64_t>(held_jump_->events.size());
  held_jump_.reset();
}

void LocalizationSession::takeHeldJump(std::vector<Event>* held) {
  *held = std::move(held_jump_->events);
  statistics_.messages_held_for_a_jump += static_cast<std::int64_t>(held->size());
  held_jump_.reset();
}

namespace {

const char* sourceName(const std::variant<ImuEvent, GeodeticFixEvent, GpsVelocityEvent>& event) {
  if (std::holds_alternative<ImuEvent>(event)) return "IMU";
  return std::holds_alternative<GeodeticFixEvent>(event) ? "GPS fix" : "GPS velocity";
}

// What a later event of the same message did, added to what came before it.
void fold(const LocalizationSession::Update& later, LocalizationSession::Update* update) {
  update->new_estimate = update->new_estimate || later.new_estimate;
  update->started = update->started || later.started;
  if (later.start_estimate) update->start_estimate = later.start_estimate;
  update->reset = update->reset || later.reset;
  if (later.imu_status) update->imu_status = later.imu_status;
  if (later.correction) update->correction = later.correction;
  update->heading_event = update->heading_event || later.heading_event;
  if (!later.note.empty()) {
    update->note = update->note.empty() ? later.note : update->note + "; " + later.note;
  }
}

}  // namespace

bool LocalizationSession::admit(double stamp_s, const Event& event, Update* update,
                                std::vector<Event>* held) {
  if (!std::isfinite(stamp_s)) return true;
  const char* source = sourceName(event);
  const double tolerance = config_.time_jump_back_s;
  // After a jump back, a message stamped in the old time line's span and ahead of the new one is
  // one of the old time line still in a queue (IMU, fixes and velocities travel on separate
  // connections): taken, it would become the newest stamp and the new time line's next message
  // a second jump. Such leftovers are the last of the old line, within a moment of each other:
  // once the dropped stamps span more than 2 time_jump_back_s, the stream has really moved there
  // (a seek forward) and is followed.
  bool moved_forward = false;  // confirmed by the old time line's dropped messages
  if (old_timeline_end_s_ && newest_stamp_s_ && stamp_s > *newest_stamp_s_ + tolerance &&
      stamp_s <= *old_timeline_end_s_ + tolerance) {
    if (!first_dropped_stamp_s_) first_dropped_stamp_s_ = stamp_s;
    first_dropped_stamp_s_ = std::min(*first_dropped_stamp_s_, stamp_s);
    if (stamp_s - *first_dropped_stamp_s_ <= 2.0 * tolerance) {
      std::ostringstream why;
      why << std::fixed << std::setprecision(3) << source << " stamp " << stamp_s
          << " s is of the time line before the jump back (now " << *newest_stamp_s_
          << " s): dropped";
      update->note = why.str();
      ++statistics_.messages_of_previous_time_line;
      return false;
    }
    old_timeline_end_s_.reset();
    moved_forward = true;
  }
  first_dropped_stamp_s_.reset();
  // A time jump: taken once a second message shows it (see the header). The second must be near
  // the first, and from the other sensor or a later IMU sample: a receiver stamps a fix and its
  // velocity alike, one glitch on both is still one, and the IMU's stamps are the filter's time
  // line (a GPS backlog, or the GPS's leftovers after a seek, confirmed jumps back alone).
  const bool from_gps = !std::holds_alternative<ImuEvent>(event);
  const bool ahead = newest_stamp_s_ && stamp_s > *newest_stamp_s_ + tolerance;
  // A GPS message is late, not a jump, as long as the filter can still apply it at its own time
  // (a receiver's latency, a stalled connection's backlog).
  const bool behind =
      newest_stamp_s_ && stamp_s + (from_gps ? lateGpsWindow() : tolerance) < *newest_stamp_s_;
  const bool near_held = held_jump_ && std::abs(stamp_s - held_jump_->stamp_s) <= tolerance;
  const bool confirms =
      near_held && (from_gps != held_jump_->from_gps ||
                    (!from_gps && stamp_s > held_jump_->stamp_s + Localizer::kDuplicateStampS));
  if (((ahead && !moved_forward) || behind) && !confirms) {
    // A first message off the time line, or one more of the same sensor and instant: held back.
    if (!near_held) {
      if (held_jump_) dropHeldJump();
      held_jump_ = HeldJump{stamp_s, *newest_stamp_s_, from_gps, {}};
    }
    if (held_jump_->events.size() < kMaxHeldMessages) {
      held_jump_->events.push_back(event);
    } else {
      ++statistics_.messages_off_the_time_line;  // a stream stuck at one stamp: kept bounded
    }
    std::ostringstream why;
    why << std::fixed << std::setprecision(3) << source << " stamp " << stamp_s << " s is "
        << std::abs(stamp_s - *newest_stamp_s_) << " s " << (ahead ? "ahead of" : "behind")
        << " the newest (" << *newest_stamp_s_
        << " s): held until another message confirms the time jump";
    update->note = why.str();
    return false;
  }
  // The jump's first stamp: the held message's when this one confirms it.
  double jump_s = stamp_s;
  if ((ahead || behind) && confirms) {
    jump_s = std::min(stamp_s, held_jump_->stamp_s);
    takeHeldJump(held);
  }
  if (ahead && started() && config_.restart_after_imu_gap_s > 0.0 &&
      jump_s - state().stamp_s > config_.restart_after_imu_gap_s) {
    // Beyond what the IMU may be bridged over: the session starts over before the jump's first
    // message, so that a fix of the jump's instant already serves the new start.
    std::ostringstream why;
    why << std::fixed << std::setprecision(3) << "time jumped forward (" << source << " stamp "
        << stamp_s << " s, the filter at " << state().stamp_s
        << " s: more than session.restart_after_imu_gap_s): the filter starts again at the next "
           "fix";
    reset(why.str(), update);
  } else if (ahead && !started() && config_.restart_after_imu_gap_s > 0.0 &&
             jump_s - *newest_stamp_s_ > config_.restart_after_imu_gap_s) {
    // Before the start: a fix (and orientation, velocity) waiting from before the jump would
    // start the filter there and bridge the whole gap.
    lazy_start_.reset();
    waiting_fixes_.clear();
  }
  if (behind) {
    std::ostringstream why;
    why << std::fixed << std::setprecision(3) << "time jumped back (" << source << " stamp "
        << stamp_s << " s, newest " << *newest_stamp_s_ << " s: a bag loop, a restarted player?)";
    const double old_end = *newest_stamp_s_;
    reset(why.str(), update);
    old_timeline_end_s_ = old_end;
  }
  const double newest = std::max(stamp_s, jump_s);
  newest_stamp_s_ = newest_stamp_s_ ? std::max(*newest_stamp_s_, newest) : newest;
  // Past the old time line's end its messages can no longer be told from the new one's.
  if (old_timeline_end_s_ && *newest_stamp_s_ > *old_timeline_end_s_) old_timeline_end_s_.reset();
  if (held_jump_) {
    // An IMU sample only where the IMU reaches it (a fix arriving early must not let it before
    // the samples up to it).
    const bool held_ahead = held_jump_->stamp_s > held_jump_->newest_s;
    if (held_ahead && (held_jump_->from_gps || !from_gps) &&
        *newest_stamp_s_ + Localizer::kDuplicateStampS >= held_jump_->stamp_s) {
      // Reached by the data (a message stamped early, data with jitter): in line now, it goes
      // through before this message (an IMU glitch a second ahead, let through as soon as the
      // data came within time_jump_back_s, made the filter bridge a second and drop the samples
      // up to it).
      takeHeldJump(held);
    } else if (*newest_stamp_s_ > held_jump_->newest_s + tolerance) {
      dropHeldJump();  // not confirmed while the data went on: a glitch
    }
  }
  return true;
}

double LocalizationSession::lateGpsWindow() const {
  return std::max(config_.time_jump_back_s, config_.localizer.fix_history_s);
}

bool LocalizationSession::onTheImuClock(double stamp_s, bool is_fix, Update* update) {
  const double tolerance = config_.time_jump_back_s;
  if (!std::isfinite(stamp_s) || !latest_imu_stamp_s_) return true;
  const double offset = stamp_s - *latest_imu_stamp_s_;
  if (is_fix) {
    // Late within what the filter applies at its own time: a latency, not another clock.
    if (offset <= tolerance && -offset <= lateGpsWindow()) {
      if (gps_clock_offset_s_) {
        std::ostringstream note;
        note << std::fixed << std::setprecision(3) << "GPS fix at " << stamp_s
             << " s agrees with the IMU clock again: GPS used";
        update->note = note.str();
      }
      offset_candidate_s_.reset();
      gps_clock_offset_s_.reset();
    } else if (imu_since_last_fix_) {  // both sensors sending: the offset is between clocks
      if (!offset_candidate_s_ || std::abs(offset - *offset_candidate_s_) > tolerance) {
        offset_candidate_s_ = offset;
        offset_candidate_since_s_ = stamp_s;
      } else if (stamp_s - offset_candidate_since_s_ >= kClockOffsetConfirmS) {
        gps_clock_offset_s_ = offset;
      }
    }
    imu_since_last_fix_ = false;
  }
  if (!gps_clock_offset_s_ || std::abs(offset - *gps_clock_offset_s_) > tolerance) return true;
  ++statistics_.gps_messages_off_the_imu_clock;
  std::ostringstream note;
  note << std::fixed << std::setprecision(3) << "GPS stamps run " << std::abs(offset) << " s "
       << (offset > 0.0 ? "ahead of" : "behind") << " the IMU's (GPS " << stamp_s << " s, IMU "
       << *latest_imu_stamp_s_
       << " s): the two are on different clocks (GPS time against UTC?); GPS messages dropped "
          "until they agree";
  update->note = note.str();
  return false;
}

LocalizationSession::Update LocalizationSession::process(double stamp_s, const Event& event) {
  Update update;
  if (std::holds_alternative<ImuEvent>(event)) {
    if (std::isfinite(stamp_s)) latest_imu_stamp_s_ = stamp_s;
    imu_since_last_fix_ = true;
  } else if (!onTheImuClock(stamp_s, std::holds_alternative<GeodeticFixEvent>(event), &update)) {
    return update;
  }
  std::vector<Event> held;
  if (!admit(stamp_s, event, &update, &held)) return update;
  // Held messages go through first; an estimate of theirs is at their own stamp: published from
  // held_estimates, this message's own as new_estimate.
  for (const Event& earlier : held) {
    Update part;
    handle(earlier, &part);
    if (part.new_estimate) {
      update.held_estimates.push_back(estimate());
      part.new_estimate = false;
    }
    fold(part, &update);
  }
  Update own;
  handle(event, &own);
  fold(own, &update);
  return update;
}

void LocalizationSession::handle(const Event& event, Update* update) {
  if (const auto* imu = std::get_if<ImuEvent>(&event)) {
    handleImu(*imu, update);
  } else if (const auto* fix = std::get_if<GeodeticFixEvent>(&event)) {
    handleFix(*fix, update);
    if (!origin_note_.empty()) {  // after the start's own note
      Update origin;
      origin.note = origin_note_;
      origin_note_.clear();
      fold(origin, update);
    }
  } else {
    handleGpsVelocity(std::get<GpsVelocityEvent>(event), update);
  }
}

void LocalizationSession::guardSound(Update* update) {
  if (!started()) return;
  const std::string unsound = unsoundness(state(), localizer_.filter().covariance());
  if (unsound.empty()) return;
  std::ostringstream why;
  why << std::fixed << std::setprecision(3) << unsound << " at " << state().stamp_s << " s";
  reset(why.str(), update);
  update->new_estimate = false;
  update->start_estimate.reset();
}

LocalizationSession::Update LocalizationSession::addImu(const ImuEvent& event) {
  ++statistics_.imu_samples;
  return process(event.sample.stamp_s, event);
}

LocalizationSession::Update LocalizationSession::addFix(const GeodeticFixEvent& event) {
  ++statistics_.fixes_received;
  return process(event.stamp_s, event);
}

LocalizationSession::Update LocalizationSession::addGpsVelocity(const GpsVelocityEvent& event) {
  // Checked like the others: after a bag loop the velocity may be the first message back.
  return process(event.stamp_s, event);
}

LocalizationSession::Update LocalizationSession::addWheelSpeed(const WheelSpeedEvent& event) {
  Update update;
  const std::int64_t stale_before = localizer_.statistics().wheel_speed_stale;
  const std::int64_t suspensions_before = localizer_.statistics().wheel_speed_suspensions;
  const CorrectionResult result =
      localizer_.addWheelSpeed(event.stamp_s, event.speed_mps, event.sigma_mps);
  // No new_estimate: the estimate is at the last IMU sample's stamp, already published; the
  // next sample's carries the correction.
  const std::int64_t suspensions = localizer_.statistics().wheel_speed_suspensions;
  if (suspensions > suspensions_before &&
      (!last_suspension_note_s_ || event.stamp_s - *last_suspension_note_s_ >= 60.0 ||
       event.stamp_s < *last_suspension_note_s_)) {
    // The first, then at most one a minute: wheels whose sign is wrong are suspended again after
    // every fix that lifts it.
    last_suspension_note_s_ = event.stamp_s;
    std::ostringstream note;
    note << std::fixed << std::setprecision(3) << "wheel speed at " << event.stamp_s
         << " s: " << result.reason << " (a slip, or the wheels' scale or sign wrong; "
         << suspensions << " suspensions so far)";
    update.note = note.str();
  } else if (result.accepted) {
    wheel_speed_stale_noted_ = false;
  } else if (localizer_.statistics().wheel_speed_stale > stale_before &&
             !wheel_speed_stale_noted_) {
    wheel_speed_stale_noted_ = true;
    std::ostringstream note;
    note << std::fixed << std::setprecision(3) << "wheel speed at " << event.stamp_s
         << " s not used: " << result.reason << "; later stale ones are counted until one is used";
    update.note = note.str();
  }
  guardSound(&update);
  return update;
}

void LocalizationSession::handleImu(const ImuEvent& event, Update* out) {
  Update& update = *out;
  const ImuSample& sample = event.sample;
  if (!std::isfinite(sample.stamp_s) || !sample.angular_velocity.allFinite() ||
      !sample.specific_force.allFinite()) {
    ++statistics_.imu_invalid;
    // Said, not only counted: an IMU whose every message has a NaN never starts the filter.
    std::ostringstream note;
    note << std::fixed << std::setprecision(3) << "IMU sample at " << sample.stamp_s
         << " s dropped: "
         << (!std::isfinite(sample.stamp_s)         ? "its stamp"
             : !sample.angular_velocity.allFinite() ? "its angular velocity"
                                                    : "its linear acceleration")
         << " is not finite (NaN or Inf); " << statistics_.imu_invalid << " dropped so far";
    update.note = note.str();
    return;
  }
  if (started() && config_.restart_after_imu_gap_s > 0.0 &&
      sample.stamp_s - state().stamp_s > config_.restart_after_imu_gap_s) {
    std::ostringstream why;
    why << std::fixed << std::setprecision(3) << "IMU silent from " << state().stamp_s << " s to "
        << sample.stamp_s << " s (more than session.restart_after_imu_gap_s): not bridged, the "
        << "filter starts again at the next fix";
    reset(why.str(), &update);
  }
  latest_angular_velocity_ = sample.angular_velocity;
  if (!started()) {
    lazy_start_.noteImu();
    if (event.orientation) {
      lazy_start_.offerOrientation(*event.orientation, event.orientation_covariance);
    }
  }
  Localizer::ImuStatus status = localizer_.addImu(sample);
  if (status == Localizer::ImuStatus::kNotInitialized) {
    tryStart(sample.stamp_s, &update);
    if (!started()) return;
    // The start is at the waiting fix's stamp: a later sample carries the state on to its own.
    const double ahead_s = sample.stamp_s - state().stamp_s;
    if (ahead_s >= Localizer::kDuplicateStampS) status = localizer_.addImu(sample);
    update.new_estimate = std::abs(sample.stamp_s - state().stamp_s) < Localizer::kDuplicateStampS;
    // A sample at the fix's stamp makes the start estimate new_estimate itself: not twice.
    if (update.new_estimate && update.start_estimate &&
        std::abs(update.start_estimate->state.stamp_s - state().stamp_s) <
            Localizer::kDuplicateStampS) {
      update.start_estimate.reset();
    }
  } else {
    update.new_estimate =
        status == Localizer::ImuStatus::kUsed || status == Localizer::ImuStatus::kGap;
  }
  // Fixes of this instant that arrived first are applied before the estimate is published.
  if (started()) releaseWaitingFixes(&update);
  update.imu_status = status;
  const bool dropped = status == Localizer::ImuStatus::kDroppedDuplicate ||
                       status == Localizer::ImuStatus::kDroppedOutOfOrder ||
                       status == Localizer::ImuStatus::kRefused;
  if ((dropped || status == Localizer::ImuStatus::kGap) && update.note.empty()) {
    std::ostringstream note;
    note << std::fixed << std::setprecision(3) << "IMU sample at " << sample.stamp_s << " s "
         << (status == Localizer::ImuStatus::kGap       ? "after a gap: bridged with inflated noise"
             : status == Localizer::ImuStatus::kRefused ? "refused by the filter (its propagation "
                                                          "would not be finite): dropped"
                                                        : "duplicate or out of order: dropped");
    update.note = note.str();
  }
  guardSound(&update);
}

void LocalizationSession::handleFix(const GeodeticFixEvent& event, Update* out) {
  Update& update = *out;
  if (!event.has_solution || !std::isfinite(event.stamp_s)) {
    ++statistics_.fixes_ignored;
    std::ostringstream note;
    note << std::fixed << std::setprecision(3) << "GPS fix at " << event.stamp_s << " s ignored: "
         << (event.has_solution ? "its stamp is not finite"
                                : "the receiver reports no solution (status: no fix)");
    update.note = note.str();
    return;
  }
  // A receiver in a 2D mode gives no altitude (NavSatFix: NaN). Once the filter runs such a fix
  // still says where the car is on the ground: it is used horizontally (below).
  const bool horizontal_only = !std::isfinite(event.alt_m) && started() &&
                               kitti::isGeodeticInRange(event.lat_deg, event.lon_deg, 0.0);
  if (!horizontal_only && !kitti::isGeodeticInRange(event.lat_deg, event.lon_deg, event.alt_m)) {
    ++statistics_.fixes_ignored;
    std::ostringstream note;
    note << std::fixed << std::setprecision(3) << "GPS fix at " << event.stamp_s
         << " s ignored: latitude " << std::setprecision(9) << event.lat_deg << ", longitude "
         << event.lon_deg << ", altitude " << std::setprecision(3) << event.alt_m;
    if (!std::isfinite(event.alt_m)) {
      note << " (no altitude, a receiver in a 2D mode: the filter starts from a 3D fix; once "
              "started it uses such fixes horizontally)";
    } else {
      note << " (latitude must be in (-90, 90) deg, longitude in [-180, 180] deg)";
    }
    update.note = note.str();
    return;
  }
  if (!projection_) takeOrigin(event);
  PositionFix fix;
  fix.stamp_s = event.stamp_s;
  fix.antenna_in_imu = event.antenna_in_imu;
  if (horizontal_only) {
    // The filter's own height (now: the fix may wait for its IMU sample) as the measured one,
    // with a variance that makes its weight nil (a gain of ~1e-6 on an innovation near zero): the
    // update is the horizontal one. Its d^2 has 2 degrees of freedom (horizontal_only: gated and
    // normalised as such).
    fix.position_map = projection_->toMap(event.lat_deg, event.lon_deg, 0.0);
    fix.position_map.z() = state().position_map.z() + (state().rotation * event.antenna_in_imu).z();
    fix.horizontal_only = true;
    ++statistics_.fixes_horizontal_only;
  } else {
    fix.position_map = projection_->toMap(event.lat_deg, event.lon_deg, event.alt_m);
  }
  const bool known = event.covariance_enu && event.covariance_enu->allFinite() &&
                     event.covariance_enu->diagonal().minCoeff() > 0.0;
  if (known) {
    fix.covariance_map = 0.5 * (*event.covariance_enu + event.covariance_enu->transpose());
  } else {
    const double h = config_.default_fix_sigma_horizontal_m;
    const double v = config_.default_fix_sigma_vertical_m;
    fix.covariance_map = Eigen::Vector3d(h * h, h * h, v * v).asDiagonal();
  }
  if (horizontal_only) {
    fix.covariance_map.row(2).setZero();
    fix.covariance_map.col(2).setZero();
    fix.covariance_map(2, 2) = kHorizontalOnlyVarianceM2;
  }
  // The floor (gps.min_sigma_m) is the Localizer's: the one place it is applied.
  if (!started()) {
    // The newest fix waits (briefly) for its instant's IMU orientation and GPS velocity.
    lazy_start_.offerFix(fix);
    tryStart(event.stamp_s, &update);
    return;
  }
  if (config_.fix_wait_for_imu_s > 0.0 &&
      fix.stamp_s > state().stamp_s + Localizer::kDuplicateStampS) {
    ++statistics_.fixes_waited_for_imu;
    const auto later = std::upper_bound(
        waiting_fixes_.begin(), waiting_fixes_.end(), fix.stamp_s,
        [](double stamp_s, const PositionFix& waiting) { return stamp_s < waiting.stamp_s; });
    waiting_fixes_.insert(later, fix);
  } else {
    correct(fix, &update);
  }
  releaseWaitingFixes(&update);
  guardSound(&update);
}

void LocalizationSession::takeOrigin(const GeodeticFixEvent& event) {
  if (config_.resume_origin) {
    const GeodeticOrigin& o = *config_.resume_origin;
    const kitti::MercatorProjection earlier(o.lat_deg, o.lon_deg, o.alt_m);
    const double distance_m =
        earlier.toMap(event.lat_deg, event.lon_deg, event.alt_m).head<2>().norm();
    std::ostringstream note;
    note << std::fixed << std::setprecision(9) << "map origin (lat " << o.lat_deg << ", lon "
         << o.lon_deg << ", alt " << std::setprecision(3) << o.alt_m << ") ";
    if (std::isfinite(distance_m) && distance_m <= config_.resume_origin_max_m) {
      projection_ = earlier;
      note << "resumed from an earlier run: the first fix is " << std::setprecision(0) << distance_m
           << " m from it";
      origin_note_ = note.str();
      return;
    }
    note << "of an earlier run not resumed: the first fix is " << std::setprecision(0)
         << distance_m / 1000.0 << " km from it (session.resume_origin_max_m)";
    origin_note_ = note.str();
  }
  projection_.emplace(event.lat_deg, event.lon_deg, event.alt_m);
}

void LocalizationSession::correct(const PositionFix& fix, Update* update) {
  update->correction = localizer_.addPositionFix(fix);
  last_mahalanobis_squared_ = update->correction->mahalanobis_squared;
  last_innovation_dof_ = fix.horizontal_only ? 2 : 3;
  std::ostringstream note;
  if (!update->correction->accepted) {
    note << std::fixed << std::setprecision(3) << "GPS fix at " << fix.stamp_s
         << " s rejected: " << update->correction->reason << " (d^2 = " << std::setprecision(1)
         << last_mahalanobis_squared_ << ")";
  }
  // The heading monitor's alignments, recoveries and re-opens: once each, with the reason.
  const std::string heading = localizer_.takeHeadingEvent();
  if (!heading.empty()) {
    if (!note.str().empty()) note << "; ";
    note << std::fixed << std::setprecision(3) << "GPS fix at " << fix.stamp_s << " s: " << heading;
    update->heading_event = true;
  }
  if (!note.str().empty()) update->note = note.str();
}

void LocalizationSession::releaseWaitingFixes(Update* update) {
  while (!waiting_fixes_.empty() && started()) {
    const PositionFix& oldest = waiting_fixes_.front();
    const bool reached = oldest.stamp_s <= state().stamp_s + Localizer::kDuplicateStampS;
    const bool given_up =
        newest_stamp_s_ && *newest_stamp_s_ - oldest.stamp_s >= config_.fix_wait_for_imu_s;
    if (!reached && !given_up) return;
    if (!reached) ++statistics_.fixes_imu_never_came;
    const PositionFix fix = oldest;
    waiting_fixes_.erase(waiting_fixes_.begin());
    correct(fix, update);
  }
}

void LocalizationSession::handleGpsVelocity(const GpsVelocityEvent& event, Update* update) {
  if (started()) return;  // only the start uses it
  lazy_start_.offerVelocity(event.stamp_s, event.velocity, event.in_body_frame);
  tryStart(event.stamp_s, update);
}

void LocalizationSession::tryStart(double now_s, Update* update) {
  if (started()) return;
  const std::optional<LazyStart::Start> start = lazy_start_.poll(now_s, gps_velocity_expected_);
  if (!start) return;
  if (start->orientation) {
    localizer_.setInitialReference(*start->orientation, start->velocity_map,
                                   start->orientation_covariance);
  } else {
    localizer_.setInitialVelocity(start->velocity_map);
  }
  update->correction = localizer_.addPositionFix(start->fix);
  last_mahalanobis_squared_ = update->correction->mahalanobis_squared;
  last_innovation_dof_ = start->fix.horizontal_only ? 2 : 3;
  std::ostringstream note;
  note << std::fixed << std::setprecision(3);
  if (!started()) {
    note << "GPS fix at " << start->fix.stamp_s << " s not used: " << update->correction->reason;
    update->note = note.str();
    return;
  }
  ++statistics_.starts;
  update->started = true;
  // The filter's estimate at the start fix's instant: the fix's position, the orientation and
  // velocity of that instant's IMU message and GPS velocity. A node publishes it whichever of
  // the three messages completed the start.
  update->start_estimate = estimate();
  const double yaw_deg = std::atan2(state().rotation(1, 0), state().rotation(0, 0)) * 180.0 / M_PI;
  note << "started at t=" << state().stamp_s << " s, position " << state().position_map.transpose()
       << " m, yaw " << std::setprecision(1) << yaw_deg << " deg (";
  if (start->orientation) {
    note << "orientation from the IMU";
    // The covariance the filter took, not the one the message stated.
    const std::optional<Eigen::Matrix3d>& stated = localizer_.referenceRotationCovariance();
    const bool given =
        start->orientation_covariance && start->orientation_covariance->diagonal().maxCoeff() > 0.0;
    if (stated && stated->diagonal().maxCoeff() > 0.0) {
      note << ", stated yaw sigma " << std::setprecision(2)
           << (stated->diagonal()(2) > 0.0 ? std::sqrt(stated->diagonal()(2)) * 180.0 / M_PI
                                           : config_.localizer.initial_yaw_sigma_deg)
           << " deg" << std::setprecision(1);
    } else if (given) {
      note << ", stated covariance not one (not positive semi-definite, not finite or wider than "
              "180 deg): yaw sigma "
           << config_.localizer.initial_yaw_sigma_deg << " deg";
    } else {
      note << ", no stated covariance: yaw sigma " << config_.localizer.initial_yaw_sigma_deg
           << " deg";
    }
  } else {
    note << "levelled from gravity, yaw unknown (sigma " << config_.localizer.unknown_yaw_sigma_deg
         << " deg)";
  }
  if (start->velocity_map) {
    note << ", velocity from the GPS velocity)";
  } else {
    note << ", no GPS velocity: speed unknown (sigma "
         << config_.localizer.unknown_velocity_sigma_horizontal_mps << " m/s))";
  }
  update->note = note.str();
  // Whichever event completed the start (a fix, a GPS velocity, an IMU sample), its estimate is
  // published only when it is sound.
  guardSound(update);
}

}  // namespace estimation
}  // namespace inekf_semantic_mapping
