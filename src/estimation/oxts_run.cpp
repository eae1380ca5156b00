#include "inekf_semantic_mapping/estimation/oxts_run.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/estimation/smoother.h"
#include "inekf_semantic_mapping/kitti/mercator.h"
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

OxtsRunResult runLocalizerOnOxts(const std::vector<kitti::OxtsFrame>& frames,
                                 const OxtsRunOptions& options) {
  if (frames.empty()) throw std::invalid_argument("runLocalizerOnOxts: no OXTS frames");
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
  OxtsRunResult run;
  run.states.reserve(frames.size());
  run.pose_covariances.reserve(frames.size());
  run.truth.reserve(frames.size());
  for (const kitti::OxtsFrame& frame : frames) {
    run.truth.push_back(projection.poseInMap(frame.record));
  }
  run.first_estimated_frame = static_cast<int>(frames.size());

  const double t0 = frames.front().stampSeconds();
  for (std::size_t k = 0; k < frames.size(); ++k) {
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
    // Without a velocity in the frame there is none to wait for (the start does not wait).
    session.setGpsVelocityExpected(has_attitude);
    const bool started_before = session.started();
    const std::int64_t resets_before = session.statistics().resets;
    {
      ScopedTimer timer("oxts_run.propagate");
      const LocalizationSession::Update update = session.addImu(imu);
      if (update.heading_event || update.reset) run.heading_notes.push_back(update.note);
    }
    ForwardEpoch epoch;
    if (options.smooth && started_before && session.started() && !epochs.empty() &&
        session.statistics().resets == resets_before) {
      epoch = recordStep(epochs.back().filtered, imu.sample, session,
                         config.localizer.imu_noise.gravity_mps2);
      if (!epoch.has_step) ++run.smoother_breaks;
    }
    if (has_attitude) {
      GpsVelocityEvent velocity;
      velocity.stamp_s = stamp_s;
      velocity.velocity = Eigen::Vector3d(record.ve, record.vn, record.vu);
      session.addGpsVelocity(velocity);
    }
    if (const std::optional<kitti::GeodeticFix> geodetic =
            degrader.degrade(k, stamp_s - t0, frames[k].record)) {
      ScopedTimer timer("oxts_run.correct");
      ++run.fixes_offered;
      const GeodeticFixEvent event = fixEventFromDegraded(*geodetic, stamp_s);
      const bool was_started = session.started();
      const LocalizationSession::Update update = session.addFix(event);
      if (update.heading_event || update.reset) run.heading_notes.push_back(update.note);
      if (was_started && (!update.correction || update.correction->accepted)) {
        OxtsRunResult::Fix fix;  // the session's conversion, for the loop closure's GPS factors
        fix.frame = static_cast<int>(k);
        fix.fix.stamp_s = stamp_s;
        fix.fix.position_map = projection.toMap(event.lat_deg, event.lon_deg, event.alt_m);
        fix.fix.covariance_map = *event.covariance_enu;
        run.fixes.push_back(fix);
      }
    }
    if (!session.started()) continue;
    if (run.states.empty()) {
      // Frames before the start have no estimate of their own: they repeat the start's.
      run.first_estimated_frame = static_cast<int>(k);
      run.states.assign(k, session.state());
      run.pose_covariances.assign(k, session.poseCovariance());
    }
    run.states.push_back(session.state());
    run.pose_covariances.push_back(session.poseCovariance());
    if (options.smooth) {
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
  return run;
}

TrajectoryErrors compareWithTruth(const OxtsRunResult& run, int first, int last) {
  const int end = last < 0 ? static_cast<int>(run.states.size()) : last;
  TrajectoryErrors errors;
  int count = 0;
  for (int k = std::max(first, run.first_estimated_frame); k < end; ++k) {
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
