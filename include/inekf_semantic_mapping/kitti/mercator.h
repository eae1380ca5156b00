// Geodetic -> `map` frame exactly as the KITTI raw devkit (latToScale, latlonToMercator,
// convertOxtsToPose): Mercator scaled by cos(lat0) with origin at the first fix, z = alt - alt0,
// x east, y north, z up. This `map` frame is the project's world frame everywhere.
#pragma once

#include <Eigen/Geometry>

#include "inekf_semantic_mapping/kitti/oxts.h"

namespace inekf_semantic_mapping {
namespace kitti {

constexpr double kEarthRadiusM = 6378137.0;  // the devkit's er

// A place on the Earth (WGS84): a map frame's origin (the localization's, and a saved map's).
struct GeodeticOrigin {
  double lat_deg = 0.0, lon_deg = 0.0, alt_m = 0.0;
};

// A place the projection can take: finite, |latitude| < 90 deg (it diverges at the poles),
// |longitude| <= 180 deg. A first fix outside it would make the origin, and so every later
// fix, not finite.
bool isGeodeticInRange(double lat_deg, double lon_deg, double alt_m);

class MercatorProjection {
 public:
  explicit MercatorProjection(double lat0_deg, double lon0_deg, double alt0_m);
  static MercatorProjection atFirstFix(const OxtsRecord& first);

  Eigen::Vector3d toMap(double lat_deg, double lon_deg, double alt_m) const;
  // The exact inverse of toMap (for the synthetic generator and the GPS degradation).
  void toGeodetic(const Eigen::Vector3d& p_map, double* lat_deg, double* lon_deg,
                  double* alt_m) const;
  // T_map_imu: translation toMap(lat, lon, alt), rotation Rz(yaw) Ry(pitch) Rx(roll).
  Eigen::Isometry3d poseInMap(const OxtsRecord& record) const;

  double scale() const { return scale_; }
  double lat0Deg() const { return lat0_deg_; }
  double lon0Deg() const { return lon0_deg_; }
  double alt0M() const { return alt0_m_; }

 private:
  // Unshifted devkit Mercator coordinates of a fix (mx, my) at this projection's scale.
  Eigen::Vector2d mercator(double lat_deg, double lon_deg) const;

  double lat0_deg_, lon0_deg_, alt0_m_;
  double scale_;
  Eigen::Vector2d origin_xy_;
};

// Rz(yaw) Ry(pitch) Rx(roll), the devkit's rotation of the OXTS body in the map frame.
Eigen::Matrix3d rotationFromRollPitchYaw(double roll, double pitch, double yaw);

}  // namespace kitti
}  // namespace inekf_semantic_mapping
