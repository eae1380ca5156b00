// The streaming filter front end under LocalizationSession (which inekf_offline and inekf_node
// both drive): stamp checks, gaps, stale and late fixes, gating, lazy initialization, statistics.
//
// Conventions and policies:
//  - An IMU sample stamped t_k propagates the state from the previous sample's stamp t_{k-1} to
//    t_k: the sample is held over the interval BEFORE it, (t_{k-1}, t_k]. On the real KITTI OXTS
//    data this fits the rotation far better than (t_k, t_{k+1}] (measured, see inekf.yaml).
//  - Out of order (t_k < t_{k-1}) or duplicate (|t_k - t_{k-1}| < 1 us) samples are dropped and
//    counted. A gap longer than max_imu_gap_s is bridged by propagating over it with the process
//    noise inflated by gap_noise_scale, the gyro's by at least gap_gyro_noise_scale_per_s times
//    the gap (the covariance grows honestly); the status says kGap.
//    A clock jumping back (bag loop) shows as kDroppedOutOfOrder: the session calls reset().
//  - A sample flagged `interpolated` propagates with the gyro/accel white noise inflated (see
//    interpolated_gyro_noise_scale_per_s / interpolated_accel_noise_scale).
//  - A fix OLDER than the state (it travelled slower than the IMU samples, e.g. on another ROS
//    connection) but within fix_history_s is applied at its own time: the filter is rewound to
//    the last IMU step at or before the fix, propagated to the fix's stamp, corrected there, and
//    the IMU samples since are propagated again (robot_localization's history idea); the result
//    equals the in-order one. Fixes are assumed to arrive in order among themselves: one older
//    than a fix already applied is not rewound (replaying would drop the newer one).
//  - Otherwise a fix whose stamp differs from the state's by at most max_fix_age_s is applied at
//    the state's (or rewound step's) time with its covariance inflated by (speed * age)^2 per
//    axis; older or newer ones are rejected ("stale fix"). Fix sigmas below min_gps_sigma_m are
//    raised to it.
//  - Any update that would produce a non-finite value is rejected; the last good state is kept.
//  - Re-acquisition: after max_consecutive_rejected_fixes fixes in a row fail the gate, the
//    filter's own position/velocity covariance is what is wrong (e.g. after a long outage or a
//    jump in the receiver's solution): the position and velocity covariance are inflated by the
//    innovation (in the map frame) and the fix is applied. Without this a diverged filter would
//    reject every later fix forever (KITTI 0028 frames 769..1202).
//  - The heading monitor. Every fix also goes into a GPS track: the chord from a fix to the
//    one after next, or to a later one until the chord is heading_track_min_chord_m long (a
//    slow car), of a car moving at heading_track_min_speed_mps or more, points along its
//    heading (base_link's x axis: setImuMounting) at the chord's middle instant (a land vehicle
//    drives forward; on a circular arc the chord is parallel to the tangent at its midpoint). Once
//    the track has confirmed the filter's heading, a chord along which the filter's own velocity
//    went backwards (its forward speed at the chord's fixes integrated: more than half the chord;
//    the car reversing, its yaw came continuously from a confirmed one) is turned by 180 deg;
//    before that (a start, an alignment, a re-open) the forward rule holds.
//    Against the filter's "gyro heading" (its yaw minus every change its corrections made to it)
//    each chord measures one constant offset; their robust weighted circular mean over
//    heading_track_window_s is the track's heading estimate for now. It is used three ways:
//      * alignment: while the filter's yaw sigma (about the map z axis) exceeds
//        heading_align_above_sigma_deg (a start levelled from gravity: 180 deg) and the track's
//        sigma is below heading_align_max_sigma_deg, the state is re-initialised from the track
//        (yaw and horizontal velocity; roll, pitch, position and biases kept);
//      * check: a filter whose heading differs from the track's by more than
//        heading_check_sigmas combined sigmas (and heading_check_min_deg) is re-initialised the
//        same way (a wrong attitude reference, a heading the constraint pinned wrongly);
//      * re-open: when heading_reopen_after_rejected_fixes fixes in a row fail the gate, or the
//        mean horizontal NIS of the last heading_nis_window_fixes fixes exceeds
//        heading_nis_window_max, the yaw variance about the map z axis is re-opened to
//        unknown_yaw_sigma_deg and the horizontal velocity and position variances are inflated
//        by the innovation, and the fix is tried again (the track then aligns it).
//    The yaw re-open is a world-frame perturbation (rotation about the map z axis through the
//    current position, velocity and position fixed in the map) mapped into the filter's own
//    error coordinates by fromWorldCovariance: for the left-invariant (body-frame) error it
//    adds sigma^2 u u^T to the rotation block with u = R^T e_z, for the right-invariant one it
//    also couples into position about the map origin. The land-vehicle constraint is not
//    applied while the last fix was gated out (it would hold a heading the fixes reject). Each
//    alignment, check and re-open is counted and reported once (takeHeadingEvent).
//    While the heading is unknown (yaw sigma above heading_align_above_sigma_deg: a levelled
//    start, a re-open) and heading_hold_unknown_yaw is set (off by default), each fix first drops
//    the yaw's cross-covariances (decorrelateYaw): the fixes correct position, velocity and biases
//    but do not rotate a heading the EKF's first-order update cannot find with a 180 deg sigma; the
//    track aligns it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "inekf_semantic_mapping/estimation/localizer_config.h"
#include "inekf_semantic_mapping/estimation/navigation_filter.h"
#include "inekf_semantic_mapping/estimation/types.h"

namespace inekf_semantic_mapping {
namespace estimation {

// The 2-dof chi-square gate with the tail probability of a 3-dof gate: P(chi2_2 > g2) =
// P(chi2_3 > g3), i.e. g2 = -2 ln(erfc(sqrt(g3 / 2)) + sqrt(2 g3 / pi) exp(-g3 / 2)). A fix
// without altitude is gated with it (30 -> 27.0; the 99.9 % quantiles 16.27 -> 13.82).
double twoDofGateOfSameTail(double gate_3dof);

class Localizer {
 public:
  // kRefused: the filter refused the propagation (it would have left non-finite values); the
  // state stays at its stamp and the sample counts with the drops.
  enum class ImuStatus {
    kUsed,
    kDroppedOutOfOrder,
    kDroppedDuplicate,
    kGap,
    kNotInitialized,
    kRefused
  };
  // Stamps closer than this are the same instant (a duplicate sample, a fix at a sample).
  static constexpr double kDuplicateStampS = 1e-6;
  // Wheel speeds: before their sign is checked (Localizer::addWheelSpeed), speeds up to this
  // are taken where the filter's forward-speed sigma is this or less; a suspension ends on
  // speeds within this Mahalanobis^2 of the filter's (1 dof, p = 0.05).
  static constexpr double kWheelSignSigmaFloorMps = 0.3;
  static constexpr double kWheelResumeMahalanobisSquared = 3.84;

  struct Statistics {
    std::int64_t imu_used = 0;
    std::int64_t imu_dropped = 0;
    std::int64_t imu_gaps = 0;
    std::int64_t gps_used = 0;
    std::int64_t gps_rejected = 0;
    std::int64_t gps_reacquisitions = 0;
    std::int64_t starts_without_velocity = 0;  // lazy starts with unknown_velocity_sigma_*
    std::int64_t gps_before_start = 0;         // fixes before any IMU sample: the start waits
    std::int64_t gps_applied_late = 0;         // fixes applied by rewinding to their own time
    std::int64_t nonholonomic_used = 0;        // land-vehicle constraint updates (per IMU step)
    std::int64_t nonholonomic_rejected = 0;
    std::int64_t nonholonomic_skipped = 0;    // heading too uncertain (see the config)
    std::int64_t nonholonomic_suspended = 0;  // the last fix was gated out
    std::int64_t standstill_used = 0;         // zero-velocity updates (a zero-rate one with each)
    std::int64_t standstill_rejected = 0;
    std::int64_t standstill_rate_rejected = 0;  // the zero-rate part alone
    std::int64_t wheel_speed_used = 0;          // forward speeds from wheel odometry
    std::int64_t wheel_speed_rejected = 0;      // gated out, or not finite
    std::int64_t wheel_speed_stale = 0;  // further than wheel_speed.max_age_s from the filter
    // Not tried: before the start, the heading or the wheels' sign unknown, suspended, disabled.
    std::int64_t wheel_speed_ignored = 0;
    std::int64_t wheel_speed_suspensions = 0;  // max_rejected_in_a_row reached (see the config)
    std::int64_t heading_alignments = 0;       // unknown heading set from the GPS track
    std::int64_t heading_recoveries = 0;       // a wrong heading re-initialised from the track
    std::int64_t heading_reopens = 0;          // yaw variance re-opened (fixes kept disagreeing)
    double last_mahalanobis_squared = 0.0;
  };

  explicit Localizer(LocalizerConfig config);

  // Explicit initialization at initial.stamp_s with the configured initial sigmas; the next IMU
  // sample propagates from initial.stamp_s.
  void initialize(const NavState& initial);
  // Same, with an explicit covariance in world-frame Euclidean coordinates (order rotation about
  // map axes, velocity, position, gyro bias, accel bias).
  void initialize(const NavState& initial, const ErrorCovariance& world_covariance);
  bool initialized() const { return initialized_; }

  // Lazy initialization: while not initialized, IMU samples are only remembered (kNotInitialized)
  // and the first valid fix initializes the state at the fix (rotation from the reference when
  // one was given and init_orientation_from_reference, else roll/pitch levelled from the latest
  // specific force, yaw 0 with unknown_yaw_sigma_deg; velocity from the reference's or
  // setInitialVelocity's, either way). Without a reference or
  // initial velocity the state starts at zero velocity with the unknown_velocity_sigma_*
  // uncertainty. A fix before any IMU sample and any reference does not start the filter (attitude
  // unknown): it is counted in gps_before_start and the next fix starts it. A later call replaces
  // the reference; velocity_map = nullopt means "not known". rotation_covariance: rad^2 about the
  // map axes (sensor_msgs/Imu); nullopt or zero diagonal entries: the configured initial sigmas.
  // One that is not a covariance (its symmetric part not positive semi-definite, or a variance
  // above pi^2) is not taken.
  void setInitialReference(
      const Eigen::Matrix3d& rotation, const std::optional<Eigen::Vector3d>& velocity_map,
      const std::optional<Eigen::Matrix3d>& rotation_covariance = std::nullopt);
  // The velocity (map frame) of a start without a reference rotation (levelled from gravity): a
  // GPS velocity needs no orientation. nullopt (or not finite): not known. setInitialReference
  // replaces it.
  void setInitialVelocity(const std::optional<Eigen::Vector3d>& velocity_map);
  // The stated rotation covariance the reference holds (symmetrized), nullopt when none was
  // given or it was not taken.
  const std::optional<Eigen::Matrix3d>& referenceRotationCovariance() const {
    return reference_rotation_covariance_;
  }

  ImuStatus addImu(const ImuSample& sample);
  CorrectionResult addPositionFix(const PositionFix& fix);
  // Wheel odometry: the vehicle's speed along its direction of travel at stamp_s (negative when
  // reversing), +- sigma_mps (NaN or not positive: wheel_speed.default_sigma_mps). Applied at the
  // filter's newest IMU time when stamp_s is within wheel_speed.max_age_s of it; the sigma floored
  // at min_sigma_mps, with scale_sigma times the speed and max_acceleration_mps2 times the age
  // added, and scaled up for speeds closer than min_interval_s to the previous one; kept with that
  // IMU step, so that a late fix's replay applies it again. Not applied before the start, while
  // the heading is unknown or the fixes reject it, after a start, alignment or re-open until a
  // speed's sign agrees with the filter's (slow speeds excepted), when stale, after
  // max_rejected_in_a_row gated out until a fix is accepted or they agree again, or with
  // wheel_speed.enabled false.
  CorrectionResult addWheelSpeed(double stamp_s, double speed_mps, double sigma_mps);

  // The IMU's mounting: its axes in base_link's (the rotation of tf base_link -> the IMU's frame;
  // identity by default: the IMU's x axis points forward). The land-vehicle constraint and the
  // heading monitor take the car's forward axis from it, and the configured
  // nonholonomic_vehicle_pitch/yaw_deg are then relative to base_link. Kept over reset().
  // False (nothing changed) for a matrix that is not a rotation.
  bool setImuMounting(const Eigen::Matrix3d& base_from_imu);
  const Eigen::Matrix3d& imuMounting() const { return base_from_imu_; }

  // Forgets the state (e.g. the bag looped); statistics are kept.
  void reset();

  // What the heading monitor did since the last call, for the log ("" when nothing): each
  // alignment, recovery and re-open with its reason, once.
  std::string takeHeadingEvent();
  // 1-sigma yaw uncertainty about the map z axis (rad).
  double yawSigma() const;

  const NavigationFilter& filter() const { return *filter_; }
  // State and covariance after the last IMU propagation, before that epoch's measurements (the
  // non-holonomic constraint): what a smoother takes as the prediction.
  const NavState& predictedState() const { return predicted_state_; }
  const ErrorCovariance& predictedCovariance() const { return predicted_covariance_; }
  const NavState& state() const { return filter_->state(); }
  Statistics statistics() const { return statistics_; }
  const LocalizerConfig& config() const { return config_; }

  // The initial world-frame covariance built from the configured sigmas.
  ErrorCovariance initialWorldCovariance() const;

 private:
  // One IMU sample held over dt, with the process-noise scales it is propagated with.
  struct ImuStep {
    ImuSample sample;
    double dt = 0.0;  // 0: the initial state (nothing to replay)
    double gyro_noise_scale = 1.0, accel_noise_scale = 1.0;
    // The standstill update after the step, decided when the sample arrived (a replay applies
    // the same one).
    std::optional<StandstillMeasurement> standstill;
    // The wheel speeds applied after the step (after the standstill and the constraint), in the
    // order they came.
    struct WheelSpeed {
      double speed_mps, sigma_mps, gate_sigma_mps;
    };
    std::vector<WheelSpeed> wheel_speeds;
  };
  // A step and the filter after it: what a rewind restores and replays.
  struct HistoryStep {
    ImuStep step;
    NavState state;
    ErrorCovariance covariance;
    double heading_correction_rad = 0.0;
  };
  // The GPS track's latest fix and the heading offsets its chords measured.
  struct TrackFix {
    double stamp_s = 0.0;
    Eigen::Vector2d position = Eigen::Vector2d::Zero();
    double variance = 0.0;  // horizontal, per axis (m^2)
    double gyro_heading_rad = 0.0;
    // The filter's speed along the vehicle's forward axis at the fix, once the track has
    // confirmed the heading (NaN before: a heading not yet checked may point backwards).
    double forward_speed_mps = std::numeric_limits<double>::quiet_NaN();
  };
  struct Chord {
    double stamp_s = 0.0;
    double offset_rad = 0.0;  // course minus the gyro heading at the chord's middle
    double variance = 0.0;    // rad^2
  };
  struct TrackHeading {
    bool valid = false;
    double offset_rad = 0.0, sigma_rad = 0.0;
    int chords = 0;
  };

  // The filter over one step (the same path for live and replayed samples); false when the
  // filter refused it (the state unchanged).
  bool propagate(const ImuStep& step);
  // propagate's land-vehicle constraint after a step.
  void constrainToVehicle(const ImuStep& step);
  // One wheel speed on the current state (counted unless replaying).
  CorrectionResult applyWheelSpeed(const ImuStep::WheelSpeed& speed);
  void recordStep(const ImuStep& step);
  void clearHistory();
  // The history step to rewind to for a fix stamped stamp_s (the last step at or before it), or
  // -1: not late, older than the history, or older than a fix already applied.
  std::ptrdiff_t lateFixStep(double stamp_s) const;
  // Rewinds to `step`, propagates to the fix's time (splitting the next step there), applies
  // the fix, and propagates the later steps again, updating the history.
  CorrectionResult applyFixInHistory(const PositionFix& fix, std::ptrdiff_t step);
  // Gate, stale check, re-acquisition and the correction, at the filter's current time.
  CorrectionResult applyFix(const PositionFix& fix);
  // The heading monitor's parts (see the class comment).
  void addToTrack(const PositionFix& fix);
  TrackHeading trackHeading() const;
  // The filter's distance driven forwards from track_fixes_[first] to `current`, from the speeds
  // the fixes recorded.
  double forwardDistance(std::size_t first, const TrackFix& current) const;
  // The track's velocity over its fixes of the last window_s (variance per axis, infinite when
  // fewer than two).
  Eigen::Vector2d trackVelocity(double window_s, double* variance) const;
  // What the current fixes of the last StandstillDetector::kFixesWindowS say: moving (faster than
  // the standstill's max_speed_mps by two sigmas), standing, or nothing.
  StandstillDetector::Fixes trackVerdict() const;
  void realignHeading(const TrackHeading& track, const std::string& why);
  void reopenHeading(const Eigen::Vector3d& innovation, const std::string& why);
  void noteHeadingEvent(const std::string& what);
  // Removes the cross-covariances of the yaw about the map z axis (the filter's marginals of the
  // yaw, the map-frame velocity and position and every other error kept), so that the next
  // correction cannot rotate the heading.
  void decorrelateYaw();
  // Accumulates the change a correction made to the filter's yaw since `heading_before_rad`.
  void noteHeadingChange(double heading_before_rad);
  // The azimuth of the car's forward axis (base_link's x) in the map frame.
  double vehicleHeading() const;
  // The map-frame horizontal velocity's sigma (m/s, the larger axis).
  double horizontalVelocitySigma() const;

  LocalizerConfig config_;
  Eigen::Matrix3d base_from_imu_ = Eigen::Matrix3d::Identity();  // setImuMounting
  Eigen::Vector3d forward_in_imu_ = Eigen::Vector3d::UnitX();    // base_link's x axis
  NonholonomicModel nonholonomic_model_;                         // from config_ and the mounting
  StandstillDetector standstill_;
  std::unique_ptr<NavigationFilter> filter_;
  bool initialized_ = false;
  std::optional<ImuSample> last_imu_;  // latest sample, also before initialization
  std::optional<Eigen::Matrix3d> reference_rotation_;
  std::optional<Eigen::Vector3d> reference_velocity_;
  std::optional<Eigen::Matrix3d> reference_rotation_covariance_;
  Statistics statistics_;
  NavState predicted_state_;
  ErrorCovariance predicted_covariance_ = ErrorCovariance::Identity();
  double interpolated_run_start_s_ = -1.0;  // < 0: not inside a run of interpolated samples
  int consecutive_rejected_fixes_ = 0;
  // Wheel speeds: gated out in a row, suspended until a fix is accepted, the last one's stamp.
  int consecutive_rejected_wheel_speeds_ = 0;
  bool wheel_speeds_suspended_ = false;
  int agreeing_wheel_speeds_ = 0;  // while suspended, in a row
  std::optional<double> wheel_agreement_since_s_;
  // Since the start, the last alignment or re-open: a wheel speed's sign was checked against the
  // filter's speed.
  bool wheel_sign_checked_ = false;
  std::optional<double> last_wheel_speed_stamp_s_;
  double last_accepted_fix_s_ = 0.0;
  // Where the last accepted fix (or the start) put the car: a fix farther from it than a car
  // moves in the time since is a jump of the receiver, wherever the filter has drifted.
  Eigen::Vector3d last_accepted_fix_position_ = Eigen::Vector3d::Zero();
  double last_fix_stamp_s_ = 0.0;  // newest fix that reached the correction
  // The steps of the last fix_history_s, oldest first, from history_[history_begin_] (the ones
  // before it expired and are erased in bulk).
  std::vector<HistoryStep> history_;
  std::size_t history_begin_ = 0;
  bool replaying_ = false;  // inside applyFixInHistory
  // The heading monitor.
  double heading_correction_rad_ = 0.0;  // sum of every yaw change the corrections made
  std::deque<TrackFix> track_fixes_;     // the window's fixes (the velocity fit)
  std::deque<Chord> chords_;
  std::deque<double> horizontal_nis_;
  // The track agreed with the filter's heading since its last (re)initialisation: its velocity
  // pointing backwards is then a car reversing, not a heading 180 deg off.
  bool heading_confirmed_ = false;
  std::string heading_event_;
};

}  // namespace estimation
}  // namespace inekf_semantic_mapping
