#include "inekf_semantic_mapping/kitti/mercator.h"

#include <cmath>

namespace inekf_semantic_mapping {
namespace kitti {
namespace {
constexpr double kPi = 3.14159265358979323846;
}

bool isGeodeticInRange(double lat_deg, double lon_deg, double alt_m) {
  return std::isfinite(alt_m) && std::abs(lat_deg) < 90.0 && std::abs(lon_deg) <= 180.0;
}

MercatorProjection::MercatorProjection(double lat0_deg, double lon0_deg, double alt0_m)
    : lat0_deg_(lat0_deg),
      lon0_deg_(lon0_deg),
      alt0_m_(alt0_m),
      scale_(std::cos(lat0_deg * kPi / 180.0)) {  // devkit latToScale
  origin_xy_ = mercator(lat0_deg, lon0_deg);
}

MercatorProjection MercatorProjection::atFirstFix(const OxtsRecord& first) {
  return MercatorProjection(first.lat, first.lon, first.alt);
}

// devkit latlonToMercator: mx = s*er*lon*pi/180, my = s*er*log(tan((90+lat)*pi/360)).
Eigen::Vector2d MercatorProjection::mercator(double lat_deg, double lon_deg) const {
  return {scale_ * kEarthRadiusM * lon_deg * kPi / 180.0,
          scale_ * kEarthRadiusM * std::log(std::tan((90.0 + lat_deg) * kPi / 360.0))};
}

Eigen::Vector3d MercatorProjection::toMap(double lat_deg, double lon_deg, double alt_m) const {
  const Eigen::Vector2d xy = mercator(lat_deg, lon_deg) - origin_xy_;
  return {xy.x(), xy.y(), alt_m - alt0_m_};
}

void MercatorProjection::toGeodetic(const Eigen::Vector3d& p_map, double* lat_deg, double* lon_deg,
                                    double* alt_m) const {
  const double mx = p_map.x() + origin_xy_.x();
  const double my = p_map.y() + origin_xy_.y();
  *lon_deg = mx * 180.0 / (kPi * scale_ * kEarthRadiusM);
  *lat_deg = std::atan(std::exp(my / (scale_ * kEarthRadiusM))) * 360.0 / kPi - 90.0;
  *alt_m = p_map.z() + alt0_m_;
}

Eigen::Matrix3d rotationFromRollPitchYaw(double roll, double pitch, double yaw) {
  return (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

Eigen::Isometry3d MercatorProjection::poseInMap(const OxtsRecord& record) const {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = rotationFromRollPitchYaw(record.roll, record.pitch, record.yaw);
  pose.translation() = toMap(record.lat, record.lon, record.alt);
  return pose;
}

}  // namespace kitti
}  // namespace inekf_semantic_mapping
