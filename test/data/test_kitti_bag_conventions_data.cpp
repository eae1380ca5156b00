// The Python kitti2bag's levelled IMU vectors, recomputed from real OXTS records of ../shared,
// come close to the body-frame ones after kitti_bag_adapter's conversion.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <string>

#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/ros/kitti_bag_conventions.h"
#include "inekf_semantic_mapping/ros/localization_conversions.h"
#include "python_kitti2bag_imu.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace {

namespace conv = ros_conversions;

using test_imu::pythonKitti2bagImu;
using test_imu::rpy;
using test_imu::setVector;
using test_imu::toEigen;

// The real OXTS records: af..au / wf..wu rotated back with the record's own roll and pitch come
// close to ax..az / wx..wz, not exactly: on 2011_09_26_drive_0013 the unit's levelled outputs
// differ from its body outputs rotated by its reported roll and pitch by up to 0.022 m/s^2 and
// 5.6e-5 rad/s (an attitude about 1e-3 rad off; measured here, all 50 frames). The exactness
// (1e-9) is checked above on vectors that are levelled exactly; here, that the conversion removes
// nearly all of the levelled/body difference.
TEST(KittiBagConventions, RealOxtsLevelledVectorsComeCloseToTheBodyOnes) {
  const std::string drive = "data/kitti_raw/2011_09_26/2011_09_26_drive_0013_sync/oxts/data";
  ISM_REQUIRE_SHARED(drive);
  int records = 0;
  double max_accel_residual = 0.0, max_rate_residual = 0.0, max_accel_unconverted = 0.0;
  for (const auto& entry : std::filesystem::directory_iterator(test::sharedPath(drive))) {
    const kitti::OxtsRecord r = kitti::readOxtsFile(entry.path().string());
    const auto body = conv::imuLevelledToBody(
        pythonKitti2bagImu(rpy(r.roll, r.pitch, r.yaw), {r.af, r.al, r.au}, {r.wf, r.wl, r.wu}));
    ASSERT_TRUE(body) << entry.path();
    const Eigen::Vector3d a_body(r.ax, r.ay, r.az);
    max_accel_residual =
        std::max(max_accel_residual, (toEigen(body->linear_acceleration) - a_body).norm());
    max_rate_residual =
        std::max(max_rate_residual,
                 (toEigen(body->angular_velocity) - Eigen::Vector3d(r.wx, r.wy, r.wz)).norm());
    max_accel_unconverted =
        std::max(max_accel_unconverted, (Eigen::Vector3d(r.af, r.al, r.au) - a_body).norm());
    ++records;
  }
  EXPECT_EQ(records, 50);
  EXPECT_LT(max_accel_residual, 0.03);
  EXPECT_LT(max_rate_residual, 1e-4);
  // Unconverted, the levelled vectors are off by 0.15 m/s^2 here (pitch up to 0.6 deg).
  EXPECT_GT(max_accel_unconverted, 5 * max_accel_residual);
}

}  // namespace
}  // namespace inekf_semantic_mapping
