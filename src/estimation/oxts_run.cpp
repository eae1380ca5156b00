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

OxtsRunResult runLocalizerOnOxts(const std::vector<kitti::OxtsFrame>& frames,
                                 const OxtsRunOptions& options) {
  if (frames.empty()) throw std::invalid_argument("runLocalizerOnOxts: no OXTS frames");
  const kitti::MercatorProjection projection =
      kitti::MercatorProjection::atFirstFix(frames.front().record);
  kitti::GpsDegrader degrader(options.gps);
  Localizer localizer(options.config);
  OxtsRunResult run;
  run.states.reserve(frames.size());
  run.pose_covariances.reserve(frames.size());
  run.truth.reserve(frames.size());
  for (const kitti::OxtsFrame& frame : frames) {
    run.truth.push_back(projection.poseInMap(frame.record));
  }

  const double t0 = frames.front().stampSeconds();
  auto fixOf = [&](std::size_t k) -> std::optional<PositionFix> {
    const kitti::OxtsRecord& record = frames[k].record;
    const std::optional<kitti::GeodeticFix> geodetic =
        degrader.degrade(k, frames[k].stampSeconds() - t0, record);
    if (!geodetic) return std::nullopt;
    ++run.fixes_offered;
    PositionFix fix;
    fix.stamp_s = frames[k].stampSeconds();
    fix.position_map = projection.toMap(geodetic->lat_deg, geodetic->lon_deg, geodetic->alt_m);
    const double h2 = geodetic->sigma_horizontal_m * geodetic->sigma_horizontal_m;
    const double v2 = geodetic->sigma_vertical_m * geodetic->sigma_vertical_m;
    fix.covariance_map = Eigen::Vector3d(h2, h2, v2).asDiagonal();
    return fix;
  };

  // Frame 0: attitude and world velocity from the OXTS solution, position from its fix.
  {
    ScopedTimer timer("oxts_run.initialize");
    const kitti::OxtsRecord& first = frames.front().record;
    NavState initial;
    initial.stamp_s = frames.front().stampSeconds();
    initial.rotation = kitti::rotationFromRollPitchYaw(
        first.roll, first.pitch, first.yaw + options.init_yaw_error_deg * kDegToRad);
    initial.velocity_map = Eigen::Vector3d(first.ve, first.vn, first.vu);
    ErrorCovariance world = localizer.initialWorldCovariance();
    const std::optional<PositionFix> first_fix = fixOf(0);
    if (first_fix) {
      initial.position_map = first_fix->position_map;
      world.block<3, 3>(6, 6) = first_fix->covariance_map.cwiseMax(options.config.min_gps_sigma_m *
                                                                   options.config.min_gps_sigma_m *
                                                                   Eigen::Matrix3d::Identity());
    }
    localizer.initialize(initial, world);
    run.states.push_back(localizer.state());
    run.pose_covariances.push_back(localizer.filter().poseCovariance());
  }

  for (std::size_t k = 1; k < frames.size(); ++k) {
    const kitti::OxtsRecord& record = frames[k].record;
    ImuSample sample;
    sample.stamp_s = frames[k].stampSeconds();
    sample.angular_velocity = Eigen::Vector3d(record.wx, record.wy, record.wz);
    sample.specific_force = Eigen::Vector3d(record.ax, record.ay, record.az);
    // The interval (k-1, k] touches an interpolated frame at either end.
    sample.interpolated = record.posmode < 0 || frames[k - 1].record.posmode < 0;
    {
      ScopedTimer timer("oxts_run.propagate");
      localizer.addImu(sample);
    }
    const std::optional<PositionFix> fix = fixOf(k);
    if (fix) {
      ScopedTimer timer("oxts_run.correct");
      localizer.addPositionFix(*fix);
    }
    run.states.push_back(localizer.state());
    run.pose_covariances.push_back(localizer.filter().poseCovariance());
  }
  run.statistics = localizer.statistics();
  return run;
}

TrajectoryErrors compareWithTruth(const OxtsRunResult& run, int first, int last) {
  const int end = last < 0 ? static_cast<int>(run.states.size()) : last;
  TrajectoryErrors errors;
  int count = 0;
  for (int k = std::max(first, 0); k < end; ++k) {
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
