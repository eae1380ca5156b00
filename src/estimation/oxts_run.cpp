#include "inekf_semantic_mapping/estimation/oxts_run.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>

#include "inekf_semantic_mapping/common/timing.h"
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
  LocalizationSession session(config);
  const kitti::MercatorProjection& projection = *session.projection();
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
    const kitti::OxtsRecord& record = frames[k].record;
    const double stamp_s = frames[k].stampSeconds();
    ImuEvent imu;
    imu.sample.stamp_s = stamp_s;
    imu.sample.angular_velocity = Eigen::Vector3d(record.wx, record.wy, record.wz);
    imu.sample.specific_force = Eigen::Vector3d(record.ax, record.ay, record.az);
    // The interval (k-1, k] touches an interpolated frame at either end.
    imu.sample.interpolated = record.posmode < 0 || (k > 0 && frames[k - 1].record.posmode < 0);
    imu.orientation = kitti::rotationFromRollPitchYaw(
        record.roll, record.pitch, record.yaw + options.init_yaw_error_deg * kDegToRad);
    {
      ScopedTimer timer("oxts_run.propagate");
      session.addImu(imu);
    }
    GpsVelocityEvent velocity;
    velocity.stamp_s = stamp_s;
    velocity.velocity = Eigen::Vector3d(record.ve, record.vn, record.vu);
    session.addGpsVelocity(velocity);
    if (const std::optional<kitti::GeodeticFix> geodetic =
            degrader.degrade(k, stamp_s - t0, record)) {
      ScopedTimer timer("oxts_run.correct");
      ++run.fixes_offered;
      session.addFix(fixEventFromDegraded(*geodetic, stamp_s));
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

double yawErrorDeg(const OxtsRunResult& run, int frame) {
  return wrapDeg(headingDeg(run.states[frame].rotation) - headingDeg(run.truth[frame].linear()));
}

}  // namespace estimation
}  // namespace inekf_semantic_mapping
