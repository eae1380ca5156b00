// LocalizationSession: the whole streaming localization behind inekf_node and inekf_offline (one
// pipeline, two faces). It takes timestamped events (IMU samples, geodetic fixes, GPS velocities)
// in arrival order and owns every policy between them and the Localizer:
//  - the start: at the newest usable fix, with the orientation of the latest IMU sample that has
//    one (and only with the covariance it states; the configured initial sigmas where it states
//    zeros) and the GPS velocity of the fix's instant, once they have arrived or a message
//    start.max_wait_s newer shows that they are not coming (LazyStart). Without an orientation
//    the filter levels roll and pitch from gravity and starts with an unknown yaw (sigma
//    initial_sigma.unknown_yaw_deg), which the Localizer's heading monitor aligns from the GPS
//    track once the car has moved; without a GPS velocity it starts at zero speed with the
//    unknown_velocity sigmas;
//  - heading alignments, recoveries and re-opens (the Localizer's heading monitor) are noted
//    once each in the Update and counted in the statistics;
//  - the map origin: the configured one, else Mercator (KITTI devkit) at the first usable fix;
//  - fix covariance: the receiver's, or the default sigmas when it gives none; the only floor is
//    the Localizer's gps.min_sigma_m;
//  - fixes newer than the filter (their IMU sample has not arrived: IMU and GPS travel on
//    separate connections) wait for it, up to fix_wait_for_imu_s of data time, so the estimate
//    does not depend on which of the two messages of one instant a node receives first;
//  - a time jump is taken on the second message that shows it: a message stamped more than
//    time_jump_back_s off the newest stamp, behind or ahead, is held back until another one
//    within time_jump_back_s of it arrives from the other sensor, or a later IMU sample (a fix and
//    its velocity, stamped alike by the receiver, are one sensor; the GPS alone never confirms a
//    jump: a backlog or the leftovers after a seek reset the filter), and then goes through
//    first; it is dropped when the data goes on by more than time_jump_back_s without one (one
//    bad stamp, a receiver's or a driver's glitch, would otherwise reset a healthy filter, or
//    become the newest stamp and make the next ordinary message a jump back). A held message
//    that the data reaches goes through then. A GPS message late by up to the filter's
//    gps.fix_history_s is late, not a jump (the filter applies it at its own time);
//  - a jump back means a bag loop or a restarted player: the state is meaningless in the new
//    time line, start over (the map origin is kept: the same place keeps the same coordinates).
//    The stamps decide, not the clock: a loop shows in both on separate connections, in either
//    order (each reset once a loop 2-3 times), and stamps may run ahead of the clock (GPS time).
//    After the jump, a message of the old time line still in a queue (stamped in its span, ahead
//    of the new one) is dropped, not taken as the newest stamp;
//  - a jump forward beyond restart_after_imu_gap_s starts the session over before its first
//    message goes through (before the start: forgets the fix waiting from before the jump);
//  - the GPS on another clock: fixes stamped more than time_jump_back_s ahead of the IMU's latest
//    stamp, or later than gps.fix_history_s behind it, by a steady offset (within time_jump_back_s)
//    for kClockOffsetConfirmS of their stamps, with the IMU sending between them, are two clocks
//    (GPS time against UTC: 18 s), not a time jump: GPS messages at that offset are dropped, the
//    note names it (gpsClockOffset()), until a fix agrees with the IMU again. Taken for jumps, they
//    reset the filter every few seconds and it never started;
//  - a gap in the IMU stream longer than restart_after_imu_gap_s (the clock jumped forward, the
//    IMU was silent) is not bridged: dead reckoning over it is a guess that only grows, and one
//    over an hour broke the covariance; the session starts over at the next fix;
//  - an unsound state (a value not finite or a variance below zero: never expected, the filter
//    rejects such updates and the inputs are checked) is never reported, the start estimate
//    included: the session resets instead;
//  - statistics.
// Estimates are made at IMU stamps: an IMU event whose Update says `new_estimate` leaves state()
// at that sample's stamp (a node publishes it then). A fix corrects the current estimate. The
// start is an estimate too, at the start fix's stamp: whichever event completes it (the fix, its
// IMU sample or its GPS velocity, in whatever order they arrive), the Update carries it, so that
// a node publishes a pose from the first fix's instant on and not only from the next IMU sample
// (a map node looking up a scan between the two would find no pose).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "inekf_semantic_mapping/estimation/lazy_start.h"
#include "inekf_semantic_mapping/estimation/localizer.h"
#include "inekf_semantic_mapping/kitti/mercator.h"

namespace inekf_semantic_mapping {
namespace estimation {

using GeodeticOrigin = kitti::GeodeticOrigin;

struct LocalizationSessionConfig {
  LocalizerConfig localizer;
  // Start timing; whether the start takes the IMU orientation and GPS velocity follows
  // localizer.init_orientation_from_reference.
  double start_max_wait_s = 0.2;
  double start_max_velocity_age_s = 0.2;
  std::optional<GeodeticOrigin> origin;  // nullopt: the first usable fix
  // Without `origin`: the origin an earlier run of the same node took (inekf_node keeps it on the
  // parameter server), taken again when the first usable fix is within resume_origin_max_m of
  // it, so that a restarted node keeps the map frame the map and rviz hold. Further away (another
  // drive): the fix, and a note says why.
  std::optional<GeodeticOrigin> resume_origin;
  double resume_origin_max_m = 10000.0;
  // For fixes that carry no covariance.
  double default_fix_sigma_horizontal_m = 1.5;
  double default_fix_sigma_vertical_m = 3.0;
  double time_jump_back_s = 1.0;
  // An IMU gap longer than this starts the session over instead of being bridged. 0: always
  // bridge.
  double restart_after_imu_gap_s = 10.0;
  // A fix ahead of the filter waits this long (data time) for the IMU to reach its stamp; then
  // it is applied at the filter's time as the Localizer does (the IMU has stopped). 0: never wait.
  double fix_wait_for_imu_s = 0.3;

  // config/inekf.yaml: the Localizer's keys plus the `session:` section (keys named as the
  // members above). Throws std::runtime_error naming the file and the key.
  static LocalizationSessionConfig fromYamlFile(const std::string& path);
};

// An IMU sample; orientation (body -> map), when the sensor reports one, is used for the start,
// with orientation_covariance (rad^2 about the map axes, sensor_msgs/Imu's; nullopt or zeros:
// not stated, the configured initial sigmas). No orientation: the start levels from gravity with
// an unknown yaw.
struct ImuEvent {
  ImuSample sample;
  std::optional<Eigen::Matrix3d> orientation;
  std::optional<Eigen::Matrix3d> orientation_covariance;
};

struct GeodeticFixEvent {
  double stamp_s = 0.0;
  double lat_deg = 0.0, lon_deg = 0.0, alt_m = 0.0;
  // East-north-up (= map axes), m^2; nullopt: the receiver gives none (the default sigmas).
  std::optional<Eigen::Matrix3d> covariance_enu;
  bool has_solution = true;  // false: the receiver has no fix (never used)
  // m, the antenna in the IMU frame (inekf_node: tf IMU frame -> the fix's frame); zero: the
  // fix is of the IMU.
  Eigen::Vector3d antenna_in_imu = Eigen::Vector3d::Zero();
};

struct GpsVelocityEvent {
  double stamp_s = 0.0;
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
  bool in_body_frame = false;  // else in the map frame
};

// Wheel odometry: the vehicle's speed along its direction of travel (base_link's x axis, up to
// nonholonomic.vehicle_pitch/yaw_deg), negative when reversing.
struct WheelSpeedEvent {
  double stamp_s = 0.0;
  double speed_mps = 0.0;
  double sigma_mps = std::numeric_limits<double>::quiet_NaN();  // NaN: wheel_speed.default_sigma
};

class LocalizationSession {
 public:
  struct Statistics {
    Localizer::Statistics filter;  // the Localizer's counts (fixes used/rejected/late, ...)
    std::int64_t imu_samples = 0;  // IMU events received
    std::int64_t imu_invalid = 0;  // non-finite ones (never reach the filter)
    std::int64_t fixes_received = 0;
    std::int64_t fixes_ignored = 0;          // no solution or non-finite (never reach the filter)
    std::int64_t fixes_horizontal_only = 0;  // without altitude (2D), used horizontally
    std::int64_t fixes_waited_for_imu = 0;   // arrived before their instant's IMU sample
    std::int64_t fixes_imu_never_came = 0;   // ... and were applied after fix_wait_for_imu_s
    std::int64_t starts = 0;
    std::int64_t resets = 0;  // time jumps back and non-finite states
    // Dropped after a time jump back: stamped in the old time line's span, ahead of the new one.
    std::int64_t messages_of_previous_time_line = 0;
    // Dropped: stamped more than time_jump_back_s off the newest stamp (behind or ahead), and no
    // second message confirmed the jump before the data went on.
    std::int64_t messages_off_the_time_line = 0;
    // Held back as the first of a jump until a second message confirmed it, then used.
    std::int64_t messages_held_for_a_jump = 0;
    // GPS messages (fixes, velocities) dropped while their stamps ran a steady offset from the
    // IMU's (gps_clock_offset_s).
    std::int64_t gps_messages_off_the_imu_clock = 0;
  };

  // A state and its pose covariance, e.g. the start's.
  struct Estimate {
    NavState state;
    PoseCovariance pose_covariance = PoseCovariance::Zero();
    TwistCovariance twist_covariance = TwistCovariance::Zero();
  };

  // What one event did.
  struct Update {
    bool new_estimate = false;  // state() is a fresh estimate at this IMU event's stamp
    bool started = false;       // the filter started during this event
    // With `started`: the estimate at the start fix's stamp (start_estimate->state.stamp_s), to
    // publish before new_estimate's. Absent when new_estimate is that very estimate (a start on
    // the IMU sample of the fix's stamp).
    std::optional<Estimate> start_estimate;
    // Estimates at the stamps of IMU samples held back as the first of a time jump and used
    // during this event (its second message confirmed the jump, or the data caught up with
    // them), in stamp order: to publish, like start_estimate, with new_estimate's.
    std::vector<Estimate> held_estimates;
    bool reset = false;                              // the session started over during this event
    std::optional<Localizer::ImuStatus> imu_status;  // IMU events that reached the filter
    std::optional<CorrectionResult> correction;      // fixes (and starts) that reached it
    // The heading monitor aligned, recovered or re-opened the heading (the note says why).
    bool heading_event = false;
    // For the log, "" when all went as expected: why it reset, how it started, or why a sample
    // or a fix was not used (dropped, gap bridged, rejected).
    std::string note;
  };

  explicit LocalizationSession(LocalizationSessionConfig config);

  Update addImu(const ImuEvent& event);
  Update addFix(const GeodeticFixEvent& event);
  Update addGpsVelocity(const GpsVelocityEvent& event);
  // Applied at the filter's newest IMU time (Localizer::addWheelSpeed), outside the ordering of
  // the other streams: a wheel speed too far from the filter's time (wheel_speed.max_age_s: a
  // jump, a loop, another clock) is stale and only counted, so it never moves the session's time.
  // The note says the first stale one after a used one.
  Update addWheelSpeed(const WheelSpeedEvent& event);
  // Starts over on request (a filter the user sees diverged), as a confirmed jump back does: the
  // filter and the held data are dropped and the next start waits for a fix; the map origin
  // stays. The Update says reset, with `why` as its note.
  Update restart(const std::string& why);
  // Whether a GPS velocity source exists (default true): without one the start does not wait.
  void setGpsVelocityExpected(bool expected) { gps_velocity_expected_ = expected; }
  // The IMU's axes in base_link's (Localizer::setImuMounting); false: not a rotation, not taken.
  bool setImuMounting(const Eigen::Matrix3d& base_from_imu) {
    return localizer_.setImuMounting(base_from_imu);
  }

  bool started() const { return localizer_.initialized(); }
  const NavState& state() const { return localizer_.state(); }
  PoseCovariance poseCovariance() const { return localizer_.filter().poseCovariance(); }
  TwistCovariance twistCovariance() const { return localizer_.filter().twistCovariance(); }
  // The state with its pose and twist covariances.
  Estimate estimate() const { return Estimate{state(), poseCovariance(), twistCovariance()}; }
  // 1-sigma yaw uncertainty about the map z axis (rad); infinite before the start.
  double yawSigma() const { return localizer_.yawSigma(); }
  // The filter's full 15x15 covariance in its own error coordinates (smoothing records it).
  ErrorCovariance errorCovariance() const { return localizer_.filter().covariance(); }
  // The last IMU step's prediction, before that epoch's constraint update (for the smoother).
  const NavState& predictedState() const { return localizer_.predictedState(); }
  const ErrorCovariance& predictedErrorCovariance() const {
    return localizer_.predictedCovariance();
  }
  // The map frame's origin; nullopt before the first usable fix (without a configured origin).
  // Taken from the first usable fix, or resume_origin near it (the update's note says which).
  const std::optional<kitti::MercatorProjection>& projection() const { return projection_; }
  Statistics statistics() const;
  // The steady offset of the GPS stamps from the IMU's (s; GPS minus IMU) while they run on two
  // clocks (e.g. GPS time against UTC: 18 s), nullopt while they agree.
  std::optional<double> gpsClockOffset() const { return gps_clock_offset_s_; }
  // The latest finite IMU rate (body frame, not bias-corrected): the twist a node publishes.
  const Eigen::Vector3d& latestAngularVelocity() const { return latest_angular_velocity_; }
  // One line for a periodic log: time, position and its sigma, the statistics.
  std::string summary() const;
  // The latest innovation's squared Mahalanobis distance (0 before any).
  double lastMahalanobisSquared() const { return last_mahalanobis_squared_; }
  // Its degrees of freedom: 3, or 2 for a fix without altitude (used horizontally).
  int lastInnovationDegreesOfFreedom() const { return last_innovation_dof_; }
  const LocalizationSessionConfig& config() const { return config_; }

 private:
  using Event = std::variant<ImuEvent, GeodeticFixEvent, GpsVelocityEvent>;
  // How long (s of fix stamps) a steady GPS-IMU offset must last to be taken for two clocks: a
  // bag loop or a seek shows on both sensors within a message or two.
  static constexpr double kClockOffsetConfirmS = 5.0;
  // The vertical variance given a fix without altitude (sigma 1 km): its weight in the height is
  // nil, its horizontal update that of a 3D fix.
  static constexpr double kHorizontalOnlyVarianceM2 = 1e6;
  // A message held back as the first of a time jump (more than time_jump_back_s off the newest
  // stamp), with the messages of its sensor and instant after it, until a second confirms it.
  struct HeldJump {
    double stamp_s = 0.0;
    double newest_s = 0.0;  // the newest stamp when it came
    bool from_gps = false;  // its sensor: the receiver (fix, velocity) or the IMU
    std::vector<Event> events;
  };

  // At most this many messages held for one jump (a stream stuck at one stamp stays bounded).
  static constexpr std::size_t kMaxHeldMessages = 32;

  // One message through the time checks (admit) and, where it passes, handle; messages held
  // back for a time jump go through before it (the jump confirmed, or reached by the data).
  Update process(double stamp_s, const Event& event);
  // The time checks: a confirmed jump back resets, one forward past the restart limit too. False
  // when the message is held back or dropped (the note says why); `held` are the held messages
  // to go through before this one.
  bool admit(double stamp_s, const Event& event, Update* update, std::vector<Event>* held);
  // How far behind the newest stamp a GPS message is late rather than a jump back:
  // time_jump_back_s, or the filter's gps.fix_history_s where longer (it applies such a fix at
  // its own time).
  double lateGpsWindow() const;
  // Gives up a held jump: its messages are dropped.
  void dropHeldJump();
  // Ends a held jump (confirmed, or reached by the data): its messages go through, into `held`.
  void takeHeldJump(std::vector<Event>* held);
  // The GPS on another clock than the IMU: false (the note says why) for a GPS message whose
  // stamp runs the steady offset from the IMU's latest that the fixes have shown for
  // kClockOffsetConfirmS.
  bool onTheImuClock(double stamp_s, bool is_fix, Update* update);
  void handle(const Event& event, Update* update);
  void handleImu(const ImuEvent& event, Update* update);
  void handleFix(const GeodeticFixEvent& event, Update* update);
  void handleGpsVelocity(const GpsVelocityEvent& event, Update* update);
  void reset(const std::string& why, Update* update);
  void tryStart(double now_s, Update* update);
  // Gives a fix to the started filter and records the result (and why it was not used).
  void correct(const PositionFix& fix, Update* update);
  // The map origin at the first usable fix: resume_origin when near it, else the fix.
  void takeOrigin(const GeodeticFixEvent& event);
  // Applies the waiting fixes the IMU has reached, and those it has not reached within
  // fix_wait_for_imu_s of the newest stamp, in stamp order.
  void releaseWaitingFixes(Update* update);
  // Resets if the state or its covariance is not finite.
  void guardSound(Update* update);

  LocalizationSessionConfig config_;
  Localizer localizer_;
  LazyStart lazy_start_;
  std::string origin_note_;  // whether resume_origin was taken, for the update's note
  std::optional<kitti::MercatorProjection> projection_;
  std::vector<PositionFix> waiting_fixes_;  // sorted by stamp
  std::optional<double> newest_stamp_s_;
  // After a jump back: the newest stamp of the time line before it, until the new one passes it.
  std::optional<double> old_timeline_end_s_;
  // The lowest stamp of the messages dropped in a row as the old time line's.
  std::optional<double> first_dropped_stamp_s_;
  // Until a second message confirms the jump, the data goes on more than time_jump_back_s past
  // its newest_s, or catches up with it.
  std::optional<HeldJump> held_jump_;
  // The GPS against the IMU clock: the latest IMU stamp received, whether one came since the
  // last fix, and the offset of the fixes from it (more than time_jump_back_s) since when.
  std::optional<double> latest_imu_stamp_s_;
  bool imu_since_last_fix_ = false;
  std::optional<double> offset_candidate_s_;
  double offset_candidate_since_s_ = 0.0;
  std::optional<double> gps_clock_offset_s_;  // confirmed: GPS messages at it are dropped
  bool gps_velocity_expected_ = true;
  bool wheel_speed_stale_noted_ = false;          // since the last wheel speed used
  std::optional<double> last_suspension_note_s_;  // data time of the last one noted
  Eigen::Vector3d latest_angular_velocity_ = Eigen::Vector3d::Zero();
  double last_mahalanobis_squared_ = 0.0;
  int last_innovation_dof_ = 3;
  Statistics statistics_;
};

}  // namespace estimation
}  // namespace inekf_semantic_mapping
