// KITTI -> ROS conversions on values the tests build: IMU fields and orientation, stamps outside
// ROS time, NavSatFix status and covariance, twist, point cloud fields and rings, camera frame
// and info. kitti2bag itself: test/cli/test_kitti2bag.cpp.
#include <gtest/gtest.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <sys/wait.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_msgs/TFMessage.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <opencv2/imgcodecs.hpp>

#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/kitti/errors.h"
#include "inekf_semantic_mapping/ros/drive_publishers.h"
#include "inekf_semantic_mapping/ros/kitti_conversions.h"
#include "inekf_semantic_mapping/ros/names.h"
#include "synthetic_kitti_drive.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {
namespace {

namespace fs = std::filesystem;

using test_drive::oxtsLine;
using test_drive::recordAt;
using test_drive::syntheticScan;
using test_drive::writeFile;
using test_drive::writeSyntheticDrive;

TEST(KittiConversions, ImuUsesBodyFrameFieldsAndOrientation) {
  const kitti::OxtsRecord r = recordAt(3);
  const sensor_msgs::Imu imu = toImuMessage(r, ros::Time(5, 0));
  EXPECT_EQ(imu.header.frame_id, frames::kImu);
  EXPECT_EQ(imu.linear_acceleration.x, r.ax);
  EXPECT_EQ(imu.linear_acceleration.z, r.az);
  EXPECT_EQ(imu.angular_velocity.z, r.wz);
  Eigen::Quaterniond q;
  tf2::fromMsg(imu.orientation, q);
  EXPECT_TRUE(q.toRotationMatrix().isApprox(kitti::rotationFromRollPitchYaw(r.roll, r.pitch, r.yaw),
                                            1e-12));
  EXPECT_GT(imu.orientation_covariance[8], 0.0);
  EXPECT_GT(imu.linear_acceleration_covariance[0], 0.0);
}

// kitti_player's ~calib_dir, named and not there: an error naming it (the drive played without
// its camera, warned once).
TEST(KittiPlayerOptions, ANamedCalibrationFolderMustExist) {
  const auto read = [](const std::string& yaml) {
    common::YamlReader reader("ROS parameters of /kitti_player", YAML::Load(yaml));
    return readKittiPlayerOptions(&reader);
  };
  EXPECT_EQ(read("{drive_dir: /d, calib_dir: ''}").calib_dir, "");
  EXPECT_EQ(read("{drive_dir: /d, calib_dir: /tmp}").calib_dir, "/tmp");
  try {
    read("{drive_dir: /d, calib_dir: /nonexistent_calib}");
    ADD_FAILURE() << "a missing calib_dir was accepted";
  } catch (const common::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("calib_dir"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("/nonexistent_calib' is not a folder"), std::string::npos)
        << e.what();
  }
}

// ROS time is unsigned 32-bit seconds; roscpp's own error ("Time is out of dual 32-bit range")
// names neither the stamp nor the file.
TEST(KittiConversions, StampsOutsideRosTimeAreRefusedByDate) {
  EXPECT_TRUE(fitsRosTime(0));
  EXPECT_EQ(toRosTime(1317041067403000000LL).toNSec(), 1317041067403000000ULL);
  EXPECT_TRUE(fitsRosTime(4294967295LL * 1000000000LL));
  EXPECT_FALSE(fitsRosTime(4294967296LL * 1000000000LL));
  EXPECT_FALSE(fitsRosTime(-1));
  try {
    toRosTime(-86400LL * 1000000000LL);
    ADD_FAILURE() << "a 1969 stamp became a ROS time";
  } catch (const std::out_of_range& e) {
    EXPECT_NE(std::string(e.what()).find("1969-12-31"), std::string::npos) << e.what();
  }
  try {
    checkTimelineFitsRosTime("/data/2011_09_26_drive_0001_sync", 0, 4294967296LL * 1000000000LL);
    ADD_FAILURE() << "a 2106 stamp passed";
  } catch (const std::out_of_range& e) {
    EXPECT_NE(std::string(e.what()).find("2011_09_26_drive_0001_sync: timestamps.txt"),
              std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("2106-02-07"), std::string::npos) << e.what();
  }
}

TEST(KittiConversions, NavSatStatusAndCovariance) {
  kitti::OxtsRecord r = recordAt(0);
  EXPECT_EQ(navSatStatusFromOxts(r), sensor_msgs::NavSatStatus::STATUS_GBAS_FIX);
  r.posmode = 4;
  EXPECT_EQ(navSatStatusFromOxts(r), sensor_msgs::NavSatStatus::STATUS_SBAS_FIX);
  r.posmode = 3;
  EXPECT_EQ(navSatStatusFromOxts(r), sensor_msgs::NavSatStatus::STATUS_FIX);
  r.numsats = 3;
  EXPECT_EQ(navSatStatusFromOxts(r), sensor_msgs::NavSatStatus::STATUS_NO_FIX);
  r.numsats = 8;
  r.posmode = -1;
  EXPECT_EQ(navSatStatusFromOxts(r), sensor_msgs::NavSatStatus::STATUS_NO_FIX);

  kitti::GeodeticFix fix;
  fix.lat_deg = 1;
  fix.lon_deg = 2;
  fix.alt_m = 3;
  fix.sigma_horizontal_m = 2;
  fix.sigma_vertical_m = 5;
  r.posmode = 5;
  const sensor_msgs::NavSatFix with_fix = toNavSatFixMessage(r, fix, ros::Time(1, 0));
  EXPECT_EQ(with_fix.latitude, 1);
  EXPECT_EQ(with_fix.position_covariance[0], 4);
  EXPECT_EQ(with_fix.position_covariance[4], 4);
  EXPECT_EQ(with_fix.position_covariance[8], 25);
  EXPECT_EQ(with_fix.position_covariance_type,
            sensor_msgs::NavSatFix::COVARIANCE_TYPE_DIAGONAL_KNOWN);
  const sensor_msgs::NavSatFix no_fix = toNavSatFixMessage(r, std::nullopt, ros::Time(1, 0));
  EXPECT_EQ(no_fix.status.status, sensor_msgs::NavSatStatus::STATUS_NO_FIX);
  EXPECT_EQ(no_fix.position_covariance_type, sensor_msgs::NavSatFix::COVARIANCE_TYPE_UNKNOWN);
}

TEST(KittiConversions, GroundTruthTwistIsInTheBodyFrame) {
  kitti::OxtsRecord r = recordAt(0);
  r.roll = r.pitch = 0;
  r.yaw = M_PI / 2;  // facing north
  r.ve = 0;
  r.vn = 3;
  r.vu = 0;
  const nav_msgs::Odometry odom =
      toGroundTruthMessage(r, kitti::MercatorProjection::atFirstFix(r), ros::Time(1, 0));
  EXPECT_EQ(odom.header.frame_id, frames::kMap);
  EXPECT_EQ(odom.child_frame_id, frames::kBaseLink);
  EXPECT_NEAR(odom.twist.twist.linear.x, 3.0, 1e-12);  // forward
  EXPECT_NEAR(odom.twist.twist.linear.y, 0.0, 1e-12);
}

TEST(KittiConversions, PointCloudHasFieldsAndRings) {
  kitti::VelodyneScan scan;
  scan.xyzi = syntheticScan();
  const sensor_msgs::PointCloud2 cloud = toPointCloudMessage(scan, ros::Time(2, 0));
  ASSERT_EQ(cloud.fields.size(), 5u);
  EXPECT_EQ(cloud.fields[3].name, "intensity");
  EXPECT_EQ(cloud.fields[4].name, "ring");
  EXPECT_EQ(cloud.fields[4].datatype, sensor_msgs::PointField::UINT16);
  EXPECT_EQ(cloud.width * cloud.height, scan.size());
  EXPECT_EQ(cloud.header.frame_id, frames::kVelodyne);
  sensor_msgs::PointCloud2ConstIterator<float> x(cloud, "x"), intensity(cloud, "intensity");
  sensor_msgs::PointCloud2ConstIterator<std::uint16_t> ring(cloud, "ring");
  for (std::size_t i = 0; i < scan.size(); ++i, ++x, ++intensity, ++ring) {
    EXPECT_EQ(*x, scan.point(i)[0]);
    EXPECT_EQ(*intensity, scan.point(i)[3]);
    EXPECT_EQ(*ring, i / 36) << i;
  }
  EXPECT_TRUE(cloud.is_dense);
  // A point without finite coordinates is published as it is, and the cloud is not dense.
  scan.xyzi[4 * 5 + 1] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_FALSE(toPointCloudMessage(scan, ros::Time(2, 0)).is_dense);
}

TEST(KittiConversions, CameraFrameAndInfoReproduceTheDevkitProjection) {
  const std::string drive_dir = writeSyntheticDrive();
  const kitti::RawDrive drive(drive_dir);
  DriveMessageFactory factory(drive, kitti::GpsDegradationOptions{});
  ASSERT_TRUE(factory.hasCalibration());
  const auto transforms = factory.staticTransformMessages(ros::Time(1, 0));
  Eigen::Isometry3d T_velo_camera = Eigen::Isometry3d::Identity();
  bool found = false;
  for (const auto& t : transforms) {
    if (t.header.frame_id == frames::kVelodyne && t.child_frame_id == frames::kCameraColorLeft) {
      T_velo_camera = tf2::transformToEigen(t);
      found = true;
    }
  }
  ASSERT_TRUE(found);
  const auto [image, info] = factory.cameraMessages(2, 0);
  Eigen::Matrix<double, 3, 4> P;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) P(r, c) = info.P[4 * r + c];
  const kitti::CameraProjection devkit = factory.calibration()->projection(2);
  for (const Eigen::Vector3d& x_velo :
       {Eigen::Vector3d(10, 1, 0.5), Eigen::Vector3d(5, -2, -1), Eigen::Vector3d(30, 4, 2)}) {
    const Eigen::Vector3d ros_pixel = P * (T_velo_camera.inverse() * x_velo).homogeneous();
    const Eigen::Vector3d devkit_pixel = devkit.projectHomogeneous(x_velo);
    EXPECT_NEAR(ros_pixel.x() / ros_pixel.z(), devkit_pixel.x() / devkit_pixel.z(), 1e-9);
    EXPECT_NEAR(ros_pixel.y() / ros_pixel.z(), devkit_pixel.y() / devkit_pixel.z(), 1e-9);
  }
  // Camera 2 is 0.1 m to the left (-x) of rectified cam0: P_rect_02(0,3) = fx * 0.1.
  const Eigen::Isometry3d T_rect0_velo = Eigen::Isometry3d(devkit.R_rect) * devkit.T_cam0_velo;
  EXPECT_TRUE(
      (T_rect0_velo * T_velo_camera).translation().isApprox(Eigen::Vector3d(-0.1, 0, 0), 1e-9));
  EXPECT_THROW(readImageMessage("/nonexistent.png", true, "x", ros::Time()),
               kitti::KittiFormatError);
  fs::remove_all(fs::path(drive_dir).parent_path().parent_path());
}

}  // namespace
}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
