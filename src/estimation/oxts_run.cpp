#include "inekf_semantic_mapping/estimation/oxts_run.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <limits>
#include <memory>
#include <optional>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/estimation/smoother.h"
#include "inekf_semantic_mapping/kitti/mercator.h"
#include "inekf_semantic_mapping/kitti/timestamps.h"
#include "inekf_semantic_mapping/lie/so3.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

constexpr double kDegToRad = M_PI / 180.0;

double wrapDeg(double deg) {
  deg = std::fmod(deg + 180.0, 360.0);
  if (deg <= 0.0) deg += 360.0;
  return deg - 180.0;
}

// A heading sigma at or below this is known (tf's tf_max_heading_sigma_deg, 10 deg).
constexpr double kKnownHeadingSigmaDeg = 10.0;

// Heading of the body x axis in the map frame.
double headingDeg(const Eigen::Matrix3d& r) { return std::atan2(r(1, 0), r(0, 0)) / kDegToRad; }

// The IMU step the filter just made from `previous` (the last reported state) to the session's
// state, for the smoother: the prediction before any fix and the step's transition. A step the
// filter did not make with this one sample (a dropped or duplicate sample, a bridged gap) is
// not reproduced exactly: has_step stays false and the smoother restarts there.
ForwardEpoch recordStep(const NavState& previous, const ImuSample& sample,
                        const LocalizationSession& session, double gravity_mps2) {
  ForwardEpoch epoch;
  const NavState& predicted = session.predictedState();
  const double dt = predicted.stamp_s - previous.stamp_s;
  if (!(dt > 0.0)) return epoch;
  const NavState replay =
      integrateImu(previous, sample.angular_velocity, sample.specific_force, gravity_mps2, dt);
  if ((replay.position_map - predicted.position_map).norm() > 1e-6 ||
      (replay.velocity_map - predicted.velocity_map).norm() > 1e-6) {
    return epoch;
  }
  epoch.has_step = true;
  epoch.predicted = predicted;
  epoch.predicted_covariance = session.predictedErrorCovariance();
  epoch.transition = leftErrorTransition(sample.angular_velocity - previous.gyro_bias,
                                         sample.specific_force - previous.accel_bias, dt);
  return epoch;
}

}  // namespace

GeodeticFixEvent fixEventFromDegraded(const kitti::GeodeticFix& fix, double stamp_s) {
  GeodeticFixEvent event;
  event.stamp_s = stamp_s;
  event.lat_deg = fix.lat_deg;
  event.lon_deg = fix.lon_deg;
  event.alt_m = fix.alt_m;
  const double h2 = fix.sigma_horizontal_m * fix.sigma_horizontal_m;
  const double v2 = fix.sigma_vertical_m * fix.sigma_vertical_m;
  event.covariance_enu = Eigen::Matrix3d(Eigen::Vector3d(h2, h2, v2).asDiagonal());
  return event;
}

namespace {

// A start orientation for the frames up to the start (the second pass): per frame, with the
// covariance it is stated with (rad^2 about the map axes; a zero axis keeps the configured sigma).
struct GivenStart {
  std::vector<Eigen::Matrix3d> rotations;  // frames 0 .. the start frame
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
};

// One pass and what the second-pass decision needs of it: per frame, the causal (filtered) state
// and yaw sigma, the gyro-bias z sigma; the frames of the heading events; how the start was made.
struct Pass {
  OxtsRunResult run;
  std::vector<NavState> filtered;
  std::vector<double> filtered_yaw_sigma_rad, gyro_bias_z_sigma_radps;
  std::vector<int> heading_event_frames;
  bool started_without_attitude = false;
};

Pass runPass(const std::vector<kitti::OxtsFrame>& frames, const OxtsRunOptions& options,
             const GivenStart* given);

}  // namespace

OxtsRunResult runLocalizerOnOxts(const std::vector<kitti::OxtsFrame>& frames,
                                 const OxtsRunOptions& options) {
  if (frames.empty()) throw std::invalid_argument("runLocalizerOnOxts: no OXTS frames");
  Pass first = runPass(frames, options, nullptr);
  if (!options.smooth || !options.second_pass || first.filtered.empty()) {
    return std::move(first.run);
  }
  // Only a start whose heading was not known: none stated, or a stated one the monitor replaced.
  const int start = first.run.first_estimated_frame;
  int earliest = -1;
  if (first.started_without_attitude) {
    earliest = start;
  } else if (first.run.statistics.filter.heading_recoveries +
                 first.run.statistics.filter.heading_alignments >
             0) {
    // A stated heading the monitor re-initialised, or re-opened and then aligned.
    earliest = first.heading_event_frames.empty() ? start : first.heading_event_frames.front();
  } else {
    return std::move(first.run);
  }
  // The first frame from which the causal yaw sigma stays settled for 30 s (or to the end of a
  // shorter drive) without a heading event: its heading is the one to carry back.
  const int n = static_cast<int>(frames.size());
  const double settled = options.settled_yaw_sigma_deg * kDegToRad;
  int reference = -1;
  for (int k = std::max(earliest, start); k < n && reference < 0; ++k) {
    if (!(first.filtered_yaw_sigma_rad[k] <= settled)) continue;
    const double t0 = frames[k].stampSeconds();
    bool holds = true;
    int j = k;
    for (; j < n && frames[j].stampSeconds() - t0 <= 30.0; ++j) {
      if (!(first.filtered_yaw_sigma_rad[j] <= settled)) {
        holds = false;
        break;
      }
    }
    if (!holds) {
      k = j;  // no frame before j can hold either
      continue;
    }
    for (int e : first.heading_event_frames) holds = holds && !(e > k && e < j);
    if (holds) reference = k;
  }
  std::ostringstream note;
  note << std::fixed << std::setprecision(1);
  if (reference < 0) {
    note << "no second pass: the heading never settled (causal yaw sigma <= "
         << options.settled_yaw_sigma_deg << " deg for 30 s or to the end)";
    first.run.heading_notes.insert(first.run.heading_notes.begin(), note.str());
    return std::move(first.run);
  }
  // Back from the reference through the gyro: the step k-1 -> k is the sample at k's.
  GivenStart given;
  given.rotations.assign(static_cast<std::size_t>(start) + 1, Eigen::Matrix3d::Identity());
  const Eigen::Vector3d bias = first.filtered[reference].gyro_bias;
  Eigen::Matrix3d rotation = first.filtered[reference].rotation;
  for (int k = reference; k > 0; --k) {
    if (k <= start) given.rotations[k] = rotation;
    const double dt = frames[k].stampSeconds() - frames[k - 1].stampSeconds();
    const kitti::OxtsRecord& r = frames[k].record;
    rotation = rotation * lie::expSO3(-(Eigen::Vector3d(r.wx, r.wy, r.wz) - bias) * dt);
  }
  given.rotations[0] = rotation;
  const double span_s = frames[reference].stampSeconds() - frames[start].stampSeconds();
  const double drift = first.gyro_bias_z_sigma_radps[reference] * span_s;
  // No surer than the configured start's sigma, but a stated 180 deg (heading unknown) is no
  // floor: the carried-back heading would start the second pass as unknown as the first.
  const double floor_deg =
      std::min(options.config.localizer.initial_yaw_sigma_deg, kKnownHeadingSigmaDeg);
  const double sigma =
      std::max(floor_deg * kDegToRad, std::hypot(first.filtered_yaw_sigma_rad[reference], drift));
  given.covariance(2, 2) = sigma * sigma;
  // A stated heading with a sigma above "known" says little: its agreement below would hold for
  // any offset (3 x 180 deg; an 85 deg error was kept, 5.4 deg rotation RMSE against 0.7).
  const bool stated_heading_known =
      options.config.localizer.initial_yaw_sigma_deg <= kKnownHeadingSigmaDeg;
  if (!first.started_without_attitude && stated_heading_known) {
    // A stated start the carried-back heading agrees with was right: the monitor's events came
    // later (e.g. a re-open over bad fixes); the first pass stands.
    const double off_deg =
        wrapDeg(headingDeg(given.rotations[start]) - headingDeg(first.filtered[start].rotation));
    const double combined_deg = std::hypot(sigma, first.filtered_yaw_sigma_rad[start]) / kDegToRad;
    if (std::abs(off_deg) <= 3.0 * combined_deg) {
      note << "no second pass: the start's stated heading agrees with the settled one carried "
              "back to it ("
           << std::setprecision(2) << off_deg << " deg, sigma " << combined_deg << " deg)";
      first.run.heading_notes.insert(first.run.heading_notes.begin(), note.str());
      return std::move(first.run);
    }
  }
  Pass second = runPass(frames, options, &given);
  note << "second pass: the heading settled at t=" << frames[reference].stampSeconds() << " s "
       << "(frame " << reference << ", yaw sigma " << std::setprecision(2)
       << first.filtered_yaw_sigma_rad[reference] / kDegToRad << " deg), carried back "
       << std::setprecision(1) << span_s << " s through the gyro to the start: yaw "
       << headingDeg(given.rotations[start]) << " deg, sigma " << std::setprecision(2)
       << sigma / kDegToRad << " deg (the first pass started at " << std::setprecision(1)
       << headingDeg(first.filtered[start].rotation) << " deg)";
  second.run.heading_notes.insert(second.run.heading_notes.begin(), note.str());
  second.run.second_pass = true;
  second.run.second_pass_reference_frame = reference;
  second.run.second_pass_yaw_sigma_deg = sigma / kDegToRad;
  return std::move(second.run);
}

namespace {

Pass runPass(const std::vector<kitti::OxtsFrame>& frames, const OxtsRunOptions& options,
             const GivenStart* given) {
  Pass pass;
  const kitti::OxtsRecord& origin = frames.front().record;
  LocalizationSessionConfig config = options.config;
  // The truth's map frame, so that the estimate compares with it directly.
  config.origin = GeodeticOrigin{origin.lat, origin.lon, origin.alt};
  if (options.smooth && config.localizer.filter_type != FilterType::kLeftInvariant) {
    throw std::invalid_argument(
        "smoothing runs on the left-invariant filter's error (filter: left), not on " +
        toString(config.localizer.filter_type));
  }
  LocalizationSession session(config);
  const kitti::MercatorProjection& projection = *session.projection();
  std::vector<ForwardEpoch> epochs;  // one per reported frame from the start on (smoothing)
  kitti::GpsDegrader degrader(options.gps);
  std::mt19937_64 wheel_random(options.gps.seed + 1);  // its own stream: the fixes stay the same
  std::normal_distribution<double> wheel_noise(0.0, 1.0);
  OxtsRunResult& run = pass.run;
  pass.filtered.reserve(frames.size());
  run.states.reserve(frames.size());
  run.pose_covariances.reserve(frames.size());
  run.truth.reserve(frames.size());
  for (const kitti::OxtsFrame& frame : frames) {
    run.truth.push_back(projection.poseInMap(frame.record));
  }
  run.first_estimated_frame = static_cast<int>(frames.size());

  const double t0 = frames.front().stampSeconds();
  // A bad line of timestamps.txt stamps the frame's IMU sample, fix and velocity alike: fed,
  // the session took the frame for a jump back (its second message confirmed it), reset, and the
  // drive was lost (ATE 7 m for 0.03 m). Such frames (a few lines in a row at most) are left out:
  // each holds the last estimate.
  std::vector<std::int64_t> stamps_ns;
  stamps_ns.reserve(frames.size());
  for (const kitti::OxtsFrame& frame : frames) stamps_ns.push_back(frame.stamp_ns);
  const std::vector<bool> misstamped = kitti::isolatedMisstampedFrames(stamps_ns);
  for (std::size_t k = 0; k < frames.size(); ++k) {
    if (misstamped[k]) {
      run.misstamped_frames.push_back(static_cast<int>(k));
      if (run.states.empty()) continue;  // before the start: the start's state repeats for it
      run.held_frames.push_back(static_cast<int>(k));
      run.states.push_back(run.states.back());
      run.pose_covariances.push_back(run.pose_covariances.back());
      pass.filtered.push_back(pass.filtered.back());
      pass.filtered_yaw_sigma_rad.push_back(pass.filtered_yaw_sigma_rad.back());
      pass.gyro_bias_z_sigma_radps.push_back(pass.gyro_bias_z_sigma_radps.back());
      if (options.smooth && !epochs.empty()) {
        // An identity step (no time passes for the filter): the smoother carries what the later
        // frames know across the glitch instead of ending a segment there.
        ForwardEpoch held;
        held.filtered = epochs.back().filtered;
        held.filtered_covariance = epochs.back().filtered_covariance;
        held.has_step = true;
        held.predicted = held.filtered;
        held.predicted_covariance = held.filtered_covariance;
        held.transition = Matrix15d::Identity();
        epochs.push_back(held);
      }
      continue;
    }
    const kitti::OxtsRecord record =
        options.imu_gps_only ? kitti::withoutAttitude(frames[k].record) : frames[k].record;
    const bool has_attitude = kitti::carriesAttitude(record);
    const double stamp_s = frames[k].stampSeconds();
    ImuEvent imu;
    imu.sample.stamp_s = stamp_s;
    imu.sample.angular_velocity = Eigen::Vector3d(record.wx, record.wy, record.wz);
    imu.sample.specific_force = Eigen::Vector3d(record.ax, record.ay, record.az);
    // The interval (k-1, k] touches an interpolated frame at either end.
    imu.sample.interpolated = record.posmode < 0 || (k > 0 && frames[k - 1].record.posmode < 0);
    if (has_attitude) {
      imu.orientation = kitti::rotationFromRollPitchYaw(
          record.roll, record.pitch, record.yaw + options.init_yaw_error_deg * kDegToRad);
    }
    if (given && k < given->rotations.size() && !session.started()) {
      imu.orientation = given->rotations[k];  // the second pass's start, stated with its sigma
      imu.orientation_covariance = given->covariance;
    }
    // Without a velocity in the frame there is none to wait for (the start does not wait).
    session.setGpsVelocityExpected(has_attitude);
    const bool started_before = session.started();
    const std::int64_t resets_before = session.statistics().resets;
    bool heading_moved = false;  // by the monitor during this frame: not a step of the filter
    // A heading the filter was sure of (sigma <= 10 deg, tf's "heading known") before the frame.
    const bool heading_was_known =
        started_before && session.yawSigma() <= kKnownHeadingSigmaDeg * kDegToRad;
    // Whichever of the frame's messages reset or started the session, or moved the heading (a
    // time jump is confirmed, and reset, by the frame's second message).
    const auto note = [&](const LocalizationSession::Update& update) {
      if (update.heading_event || update.reset) run.heading_notes.push_back(update.note);
      if (update.heading_event) {
        pass.heading_event_frames.push_back(static_cast<int>(k));
        heading_moved = true;
      }
      if (update.started) pass.started_without_attitude = !imu.orientation;
    };
    {
      ScopedTimer timer("oxts_run.propagate");
      note(session.addImu(imu));
    }
    ForwardEpoch epoch;
    if (options.smooth && started_before && session.started() && !epochs.empty() &&
        session.statistics().resets == resets_before) {
      epoch = recordStep(epochs.back().filtered, imu.sample, session,
                         config.localizer.imu_noise.gravity_mps2);
      const NavState& before = epochs.back().filtered;
      if (!epoch.has_step && session.state().stamp_s == before.stamp_s &&
          session.state().position_map == before.position_map &&
          session.state().velocity_map == before.velocity_map) {
        // The session dropped this frame's sample (a duplicate stamp): the filter did not move,
        // an identity step, as for a misstamped frame; the smoother restarted here before.
        epoch.has_step = true;
        epoch.predicted = before;
        epoch.predicted_covariance = epochs.back().filtered_covariance;
        epoch.transition = Matrix15d::Identity();
      }
      if (!epoch.has_step) ++run.smoother_breaks;
    }
    if (options.wheel_speed_sigma_mps > 0.0) {
      const double sigma = options.wheel_speed_sigma_mps;
      note(session.addWheelSpeed(
          {stamp_s, frames[k].record.vf + sigma * wheel_noise(wheel_random), sigma}));
    }
    if (has_attitude) {
      GpsVelocityEvent velocity;
      velocity.stamp_s = stamp_s;
      velocity.velocity = Eigen::Vector3d(record.ve, record.vn, record.vu);
      note(session.addGpsVelocity(velocity));
    }
    if (const std::optional<kitti::GeodeticFix> geodetic =
            degrader.degrade(k, stamp_s - t0, frames[k].record)) {
      ScopedTimer timer("oxts_run.correct");
      ++run.fixes_offered;
      const GeodeticFixEvent event = fixEventFromDegraded(*geodetic, stamp_s);
      const bool was_started = session.started();
      const LocalizationSession::Update update = session.addFix(event);
      note(update);
      if (was_started && (!update.correction || update.correction->accepted)) {
        OxtsRunResult::Fix fix;  // the session's conversion, for the loop closure's GPS factors
        fix.frame = static_cast<int>(k);
        fix.fix.stamp_s = stamp_s;
        fix.fix.position_map = projection.toMap(event.lat_deg, event.lon_deg, event.alt_m);
        fix.fix.covariance_map = *event.covariance_enu;
        run.fixes.push_back(fix);
      }
    }
    if (!session.started()) {
      if (run.states.empty()) continue;
      // Reset after the start and not yet restarted: the frame keeps its place (every later
      // state stays at its own frame) with the last estimate, and is left out of the scores
      // (held).
      run.held_frames.push_back(static_cast<int>(k));
      run.states.push_back(run.states.back());
      run.pose_covariances.push_back(run.pose_covariances.back());
      pass.filtered.push_back(pass.filtered.back());
      pass.filtered_yaw_sigma_rad.push_back(std::numeric_limits<double>::infinity());
      pass.gyro_bias_z_sigma_radps.push_back(std::numeric_limits<double>::infinity());
      if (options.smooth) {  // no step: a segment of its own, the smoother keeps it as it is
        ForwardEpoch held;
        held.filtered = epochs.back().filtered;
        held.filtered_covariance = epochs.back().filtered_covariance;
        epochs.push_back(held);
      }
      continue;
    }
    if (run.states.empty()) {
      // Frames before the start have no estimate of their own: they repeat the start's.
      run.first_estimated_frame = static_cast<int>(k);
      run.states.assign(k, session.state());
      run.pose_covariances.assign(k, session.poseCovariance());
      pass.filtered.assign(k, session.state());
      pass.filtered_yaw_sigma_rad.assign(k, std::numeric_limits<double>::infinity());
      pass.gyro_bias_z_sigma_radps.assign(k, std::numeric_limits<double>::infinity());
    }
    // A frame whose IMU sample the session dropped (the first of a jump forward) keeps the last
    // estimate: not its own, so not scored either.
    if (std::abs(session.state().stamp_s - stamp_s) > 1e-3) {
      run.held_frames.push_back(static_cast<int>(k));
    }
    run.states.push_back(session.state());
    run.pose_covariances.push_back(session.poseCovariance());
    pass.filtered.push_back(session.state());
    pass.filtered_yaw_sigma_rad.push_back(session.yawSigma());
    pass.gyro_bias_z_sigma_radps.push_back(
        std::sqrt(std::max(0.0, session.errorCovariance()(11, 11))));
    if (options.smooth) {
      // A heading the filter was sure of and the monitor re-initialised or re-opened is a reset
      // of the state or its covariance, not a measurement: a segment starts here (the smoother
      // carried a 15 deg re-initialisation back over every earlier frame, 6.6 -> 13.3 deg
      // rotation RMSE). An alignment of a heading not yet known is within its prior: carried
      // back, it gives the frames before it their heading.
      if (heading_moved && heading_was_known) epoch.has_step = false;
      epoch.filtered = session.state();
      epoch.filtered_covariance = session.errorCovariance();
      epochs.push_back(epoch);
    }
  }
  if (options.smooth && !epochs.empty()) {
    ScopedTimer timer("oxts_run.smooth");
    const std::vector<SmoothedEpoch> smoothed = smoothLeftInvariant(epochs);
    // The pose covariance a filter reports for a state and covariance: one definition.
    const std::unique_ptr<NavigationFilter> reporter =
        makeFilter(FilterType::kLeftInvariant, config.localizer.imu_noise);
    const std::size_t first = static_cast<std::size_t>(run.first_estimated_frame);
    run.smoothed_covariances.assign(run.states.size(), smoothed.front().covariance);
    run.smoother_gains.assign(run.states.size(), Matrix15d::Zero());
    for (std::size_t i = 0; i < smoothed.size(); ++i) {
      reporter->initialize(smoothed[i].state, smoothed[i].covariance);
      run.states[first + i] = smoothed[i].state;
      run.pose_covariances[first + i] = reporter->poseCovariance();
      run.smoothed_covariances[first + i] = smoothed[i].covariance;
      run.smoother_gains[first + i] = smoothed[i].gain;
    }
    for (std::size_t k = 0; k < first; ++k) {  // frames before the start repeat it
      run.states[k] = run.states[first];
      run.pose_covariances[k] = run.pose_covariances[first];
    }
    run.smoothed = true;
  }
  if (run.states.empty()) {  // never started: nothing to report but the (unstarted) defaults
    run.states.assign(frames.size(), session.state());
    run.pose_covariances.assign(frames.size(), session.poseCovariance());
  }
  run.statistics = session.statistics();
  return pass;
}

}  // namespace

TrajectoryErrors compareWithTruth(const OxtsRunResult& run, int first, int last) {
  const int end = last < 0 ? static_cast<int>(run.states.size()) : last;
  TrajectoryErrors errors;
  int count = 0;
  for (int k = std::max(first, run.first_estimated_frame); k < end; ++k) {
    if (std::binary_search(run.held_frames.begin(), run.held_frames.end(), k)) continue;
    const NavState& s = run.states[k];
    const Eigen::Isometry3d& truth = run.truth[k];
    errors.ate_m += (s.position_map - truth.translation()).squaredNorm();
    const double angle = lie::logSO3(s.rotation.transpose() * truth.linear()).norm() / kDegToRad;
    errors.rotation_rmse_deg += angle * angle;
    const double yaw = yawErrorDeg(run, k);
    errors.yaw_rmse_deg += yaw * yaw;
    ++count;
  }
  if (count == 0) return errors;
  errors.ate_m = std::sqrt(errors.ate_m / count);
  errors.rotation_rmse_deg = std::sqrt(errors.rotation_rmse_deg / count);
  errors.yaw_rmse_deg = std::sqrt(errors.yaw_rmse_deg / count);
  return errors;
}

FixErrorMean meanFixError(const OxtsRunResult& run) {
  FixErrorMean result;
  for (const OxtsRunResult::Fix& fix : run.fixes) {
    if (fix.frame < 0 || fix.frame >= static_cast<int>(run.truth.size())) continue;
    result.mean += fix.fix.position_map - run.truth[fix.frame].translation();
    ++result.fixes;
  }
  if (result.fixes > 0) result.mean /= result.fixes;
  return result;
}

double yawErrorDeg(const OxtsRunResult& run, int frame) {
  return wrapDeg(headingDeg(run.states[frame].rotation) - headingDeg(run.truth[frame].linear()));
}

kitti::GpsDegradationOptions protocolGps() {
  kitti::GpsDegradationOptions gps;
  gps.sigma_horizontal_m = 1.5;
  gps.sigma_vertical_m = 3.0;
  gps.every_n_frames = 10;
  gps.seed = 1;
  return gps;
}

TravelDirection travelDirectionInImu(const std::vector<NavState>& states, double min_speed_mps) {
  std::vector<double> pitches, yaws;
  for (const NavState& s : states) {
    const Eigen::Vector3d v = s.rotation.transpose() * s.velocity_map;
    if (!v.allFinite() || !(v.x() >= min_speed_mps)) continue;
    pitches.push_back(std::atan2(v.z(), v.x()) * 180.0 / M_PI);
    yaws.push_back(std::atan2(v.y(), v.x()) * 180.0 / M_PI);
  }
  TravelDirection direction;
  direction.samples = static_cast<int>(pitches.size());
  if (pitches.empty()) return direction;
  const auto median = [](std::vector<double>* values) {
    const auto middle = values->begin() + static_cast<std::ptrdiff_t>(values->size() / 2);
    std::nth_element(values->begin(), middle, values->end());
    return *middle;
  };
  direction.pitch_deg = median(&pitches);
  direction.yaw_deg = median(&yaws);
  return direction;
}

}  // namespace estimation
}  // namespace inekf_semantic_mapping
