// The conversions kitti_bag_adapter applies to bags of the Python kitti2bag (tomas789), the
// detection of a bag's convention, and inekf_node's base_link-from-IMU odometry.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <random>
#include <string>

#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/ros/kitti_bag_conventions.h"
#include "inekf_semantic_mapping/ros/levelled_velocity_pairing.h"
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

TEST(KittiBagConventions, LevelledImuVectorsGoBackToTheBodyFrame) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> angle(-0.3, 0.3), heading(-M_PI, M_PI), value(-10, 10);
  for (int i = 0; i < 200; ++i) {
    const Eigen::Matrix3d R = rpy(angle(rng), angle(rng), heading(rng));
    const Eigen::Vector3d f(value(rng), value(rng), value(rng)),
        w(value(rng), value(rng), value(rng));
    const Eigen::Matrix3d R_level_body =
        Eigen::AngleAxisd(-std::atan2(R(1, 0), R(0, 0)), Eigen::Vector3d::UnitZ()) * R;
    const auto body =
        conv::imuLevelledToBody(pythonKitti2bagImu(R, R_level_body * f, R_level_body * w));
    ASSERT_TRUE(body);
    EXPECT_LT((toEigen(body->linear_acceleration) - f).norm(), 1e-9);
    EXPECT_LT((toEigen(body->angular_velocity) - w).norm(), 1e-9);
    EXPECT_EQ(body->header.frame_id, "imu_link");
  }
}

TEST(KittiBagConventions, LevelledFrameOfALevelBodyIsTheBody) {
  EXPECT_TRUE(conv::levelledFromBody(rpy(0, 0, 2.0)).isIdentity(1e-12));
  EXPECT_TRUE(conv::levelledFromBody(rpy(0.1, -0.2, 2.0)).isApprox(rpy(0.1, -0.2, 0), 1e-12));
}

TEST(KittiBagConventions, ImuWithoutOrientationIsNotConverted) {
  sensor_msgs::Imu imu = pythonKitti2bagImu(Eigen::Matrix3d::Identity(), {0, 0, 9.8}, {0, 0, 0});
  imu.orientation_covariance[0] = -1.0;
  EXPECT_FALSE(conv::imuLevelledToBody(imu));
  imu = pythonKitti2bagImu(Eigen::Matrix3d::Identity(), {0, 0, 9.8}, {0, 0, 0});
  imu.orientation.w = 0.0;  // not a rotation
  EXPECT_FALSE(conv::imuLevelledToBody(imu));
}

TEST(KittiBagConventions, LevelledVelocityGoesToTheMapAxes) {
  const Eigen::Matrix3d R = rpy(0.05, -0.07, 2.5);
  const Eigen::Vector3d v_map(3.0, -4.0, 0.2);
  geometry_msgs::TwistStamped velocity;
  velocity.header.frame_id = "imu_link";
  setVector(Eigen::AngleAxisd(-2.5, Eigen::Vector3d::UnitZ()) * v_map, &velocity.twist.linear);
  const geometry_msgs::TwistStamped out = conv::velocityLevelledToMap(velocity, R, "map");
  EXPECT_LT((toEigen(out.twist.linear) - v_map).norm(), 1e-12);
  EXPECT_EQ(out.header.frame_id, "map");
}

TEST(KittiBagConventions, CameraInfoIsTheRectifiedCameraWithTheBaselineOnce) {
  sensor_msgs::CameraInfo info;  // the real 2011_09_26 K_02, D_02, P_rect_02
  info.header.frame_id = "camera_color_left";
  info.width = 1242;
  info.height = 375;
  info.K = {959.791, 0, 696.0217, 0, 956.9251, 224.1806, 0, 0, 1};
  info.D = {-0.3691481, 0.1968681, 0.001353473, 0.0005677587, -0.06770705};
  info.R = {0.9998817,    0.01511453,  -0.002841595, -0.01511724, 0.9998853,
            -0.000933851, 0.002827154, 0.0009766976, 0.9999955};
  info.P = {721.5377, 0, 609.5593, 44.85728, 0, 721.5377, 172.854, 0.2163791, 0, 0, 1, 0.002745884};
  const sensor_msgs::CameraInfo out = conv::rectifiedCameraInfo(info);
  EXPECT_EQ(out.K[0], 721.5377);
  EXPECT_EQ(out.K[2], 609.5593);
  EXPECT_EQ(out.K[4], 721.5377);
  EXPECT_EQ(out.K[5], 172.854);
  EXPECT_EQ(out.K[8], 1.0);
  for (double d : out.D) EXPECT_EQ(d, 0.0);
  EXPECT_EQ(out.R[0] * out.R[4] * out.R[8], 1.0);
  EXPECT_EQ(out.P[3], 0.0);
  EXPECT_EQ(out.P[7], 0.0);
  EXPECT_EQ(out.P[11], 0.0);
  EXPECT_EQ(out.P[0], 721.5377);
  EXPECT_EQ(out.width, 1242u);
  info.P[10] = 0.0;
  EXPECT_THROW(conv::rectifiedCameraInfo(info), std::invalid_argument);
}

Eigen::Isometry3d isometry(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R;
  T.translation() = t;
  return T;
}

nav_msgs::Odometry odometryOf(const Eigen::Isometry3d& T) {
  nav_msgs::Odometry odometry;
  odometry.pose.pose.position.x = T.translation().x();
  odometry.pose.pose.position.y = T.translation().y();
  odometry.pose.pose.position.z = T.translation().z();
  const Eigen::Quaterniond q(T.linear());
  odometry.pose.pose.orientation.w = q.w();
  odometry.pose.pose.orientation.x = q.x();
  odometry.pose.pose.orientation.y = q.y();
  odometry.pose.pose.orientation.z = q.z();
  return odometry;
}

Eigen::Isometry3d poseOf(const nav_msgs::Odometry& odometry) {
  const auto& p = odometry.pose.pose;
  return isometry(
      Eigen::Quaterniond(p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z)
          .toRotationMatrix(),
      {p.position.x, p.position.y, p.position.z});
}

// The Python kitti2bag's base_link -> imu_link.
const Eigen::Isometry3d kBaseImu = isometry(Eigen::Matrix3d::Identity(), {-1.405, 0.32, 0.93});

TEST(KittiBagConventions, EstimateAndTruthOfBaseLinkAgree) {
  const Eigen::Isometry3d T_map_imu = isometry(rpy(0.02, -0.06, 1.9), {10.0, -3.0, 1.5});
  // inekf_node: the IMU estimate published as base_link through tf base_link -> imu_link.
  const nav_msgs::Odometry estimate =
      conv::odometryOfBase(odometryOf(T_map_imu), kBaseImu, "base_link");
  // kitti_bag_adapter: the bag's world -> base_link (the OXTS pose) as base_link truth.
  geometry_msgs::TransformStamped world_oxts;
  const nav_msgs::Odometry o = odometryOf(T_map_imu);
  world_oxts.transform.translation.x = o.pose.pose.position.x;
  world_oxts.transform.translation.y = o.pose.pose.position.y;
  world_oxts.transform.translation.z = o.pose.pose.position.z;
  world_oxts.transform.rotation = o.pose.pose.orientation;
  const nav_msgs::Odometry truth =
      conv::groundTruthOfBase(world_oxts, kBaseImu.inverse(), "map", "base_link");
  EXPECT_TRUE(poseOf(estimate).isApprox(poseOf(truth), 1e-12));
  EXPECT_EQ(estimate.child_frame_id, "base_link");
  EXPECT_EQ(truth.header.frame_id, "map");
  // base_link composed with base_link -> imu_link is the IMU pose again.
  EXPECT_TRUE((poseOf(estimate) * kBaseImu).isApprox(T_map_imu, 1e-12));
  // And base_link is where the lever arm says: 1.405 m ahead of the IMU, 0.93 m below.
  EXPECT_NEAR((poseOf(estimate).translation() - T_map_imu.translation()).norm(),
              kBaseImu.translation().norm(), 1e-12);
}

TEST(KittiBagConventions, BaseOdometryOfAnIdentityTransformIsTheImuOdometry) {
  nav_msgs::Odometry imu = odometryOf(isometry(rpy(0.1, 0.2, 0.3), {1, 2, 3}));
  imu.twist.twist.linear.x = 5.0;
  imu.twist.twist.angular.z = 0.3;
  for (int i = 0; i < 36; ++i) imu.pose.covariance[i] = (i % 7 == 0) ? 0.1 * (1 + i) : 0.0;
  const nav_msgs::Odometry base =
      conv::odometryOfBase(imu, Eigen::Isometry3d::Identity(), "base_link");
  EXPECT_TRUE(poseOf(base).isApprox(poseOf(imu), 1e-12));
  EXPECT_EQ(base.twist.twist.linear.x, 5.0);
  EXPECT_EQ(base.twist.twist.angular.z, 0.3);
  for (int i = 0; i < 36; ++i) EXPECT_NEAR(base.pose.covariance[i], imu.pose.covariance[i], 1e-15);
}

TEST(KittiBagConventions, BaseVelocityIncludesTheLeverArm) {
  nav_msgs::Odometry imu = odometryOf(Eigen::Isometry3d::Identity());
  imu.twist.twist.angular.z = 0.5;  // turning in place about the IMU
  const nav_msgs::Odometry base = conv::odometryOfBase(imu, kBaseImu, "base_link");
  // The base origin sits at r = (1.405, -0.32, -0.93) in IMU axes: it moves with w x r.
  const Eigen::Vector3d expected =
      Eigen::Vector3d(0, 0, 0.5).cross(Eigen::Vector3d(1.405, -0.32, -0.93));
  EXPECT_LT((toEigen(base.twist.twist.linear) - expected).norm(), 1e-12);
  EXPECT_NEAR(base.twist.twist.angular.z, 0.5, 1e-12);
  // A heading uncertainty moves the base sideways: its lateral position variance grows.
  imu.pose.covariance[35] = 0.01;  // yaw
  const nav_msgs::Odometry uncertain = conv::odometryOfBase(imu, kBaseImu, "base_link");
  EXPECT_NEAR(uncertain.pose.covariance[7], 0.01 * 1.405 * 1.405, 1e-12);  // y y
  // So does a yaw-rate uncertainty the base's lateral speed (v_base = v + w x r).
  imu.twist.covariance[35] = 0.04;  // wz wz
  imu.twist.covariance[0] = 0.25;   // vx vx
  const nav_msgs::Odometry twist = conv::odometryOfBase(imu, kBaseImu, "base_link");
  EXPECT_NEAR(twist.twist.covariance[7], 0.04 * 1.405 * 1.405, 1e-12);       // vy vy
  EXPECT_NEAR(twist.twist.covariance[0], 0.25 + 0.04 * 0.32 * 0.32, 1e-12);  // vx vx
  EXPECT_NEAR(twist.twist.covariance[35], 0.04, 1e-12);
}

conv::BagContents ismBag() {
  conv::BagContents bag;
  bag.path = "own.bag";
  bag.topic_types = {{"/kitti/oxts/imu", "sensor_msgs/Imu"},
                     {"/kitti/oxts/gps/fix", "sensor_msgs/NavSatFix"},
                     {"/tf_static", "tf2_msgs/TFMessage"}};
  bag.static_frames = {{"base_link", "imu_link"}, {"imu_link", "velo_link"}};
  return bag;
}

conv::BagContents pythonBag() {
  conv::BagContents bag = ismBag();
  bag.path = "tomas789.bag";
  bag.topic_types["/tf"] = "tf2_msgs/TFMessage";
  bag.dynamic_frames = {{"world", "base_link"}};
  return bag;
}

std::string errorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& error) {
    return error.what();
  }
  return "";
}

TEST(KittiBagConventions, DetectsEachConvention) {
  EXPECT_EQ(conv::detectBagConvention(ismBag()), conv::BagConvention::kIsm);
  EXPECT_EQ(conv::detectBagConvention(pythonBag()), conv::BagConvention::kKitti2bagPy);
  EXPECT_NO_THROW(conv::checkBagConvention(ismBag(), conv::BagConvention::kIsm));
  EXPECT_NO_THROW(conv::checkBagConvention(pythonBag(), conv::BagConvention::kKitti2bagPy));
  EXPECT_EQ(conv::bagConventionFromString("kitti2bag_py"), conv::BagConvention::kKitti2bagPy);
  EXPECT_EQ(conv::bagConventionName(conv::BagConvention::kIsm), "ism");
  EXPECT_THROW(conv::bagConventionFromString("rosbag"), std::invalid_argument);
}

TEST(KittiBagConventions, ABagOfNeitherConventionIsAClearError) {
  conv::BagContents no_imu = ismBag();
  no_imu.topic_types.erase("/kitti/oxts/imu");
  std::string error = errorOf([&] { conv::detectBagConvention(no_imu); });
  EXPECT_NE(error.find("own.bag"), std::string::npos) << error;
  EXPECT_NE(error.find("/kitti/oxts/imu (sensor_msgs/Imu)"), std::string::npos) << error;

  conv::BagContents wrong_type = ismBag();
  wrong_type.topic_types["/kitti/oxts/gps/fix"] = "geometry_msgs/PointStamped";
  error = errorOf([&] { conv::detectBagConvention(wrong_type); });
  EXPECT_NE(error.find("/kitti/oxts/gps/fix is geometry_msgs/PointStamped, expected "
                       "sensor_msgs/NavSatFix"),
            std::string::npos)
      << error;

  conv::BagContents no_frames = ismBag();
  no_frames.static_frames.clear();
  error = errorOf([&] { conv::detectBagConvention(no_frames); });
  EXPECT_NE(error.find("no base_link -> imu_link"), std::string::npos) << error;
  EXPECT_NE(error.find("tomas789/kitti2bag"), std::string::npos) << error;

  conv::BagContents odom = ismBag();
  odom.dynamic_frames = {{"odom", "base_link"}};
  error = errorOf([&] { conv::detectBagConvention(odom); });
  EXPECT_NE(error.find("/tf carries odom -> base_link"), std::string::npos) << error;

  error = errorOf([&] { conv::checkBagConvention(pythonBag(), conv::BagConvention::kIsm); });
  EXPECT_NE(error.find("world -> base_link"), std::string::npos) << error;
  error = errorOf([&] { conv::checkBagConvention(ismBag(), conv::BagConvention::kKitti2bagPy); });
  EXPECT_NE(error.find("no world -> base_link"), std::string::npos) << error;
}

geometry_msgs::TwistStamped levelledVelocity(double stamp_s, double forward_mps) {
  geometry_msgs::TwistStamped velocity;
  velocity.header.stamp = ros::Time(stamp_s);
  velocity.header.frame_id = "imu_link";
  velocity.twist.linear.x = forward_mps;
  return velocity;
}

// kitti_bag_adapter's pairing of a levelled velocity with the heading of its own instant,
// whichever of the two messages arrives first.
TEST(LevelledVelocityPairing, AVelocityTakesTheHeadingOfItsOwnStampInEitherOrder) {
  const Eigen::Matrix3d east = rpy(0, 0, 0), north = rpy(0, 0, M_PI / 2);
  conv::LevelledVelocityPairing pairing("map");
  // The IMU first: the velocity leaves at once, with that instant's heading.
  EXPECT_TRUE(pairing.addOrientation(ros::Time(10.0), east).empty());
  auto released = pairing.addVelocity(levelledVelocity(10.0, 5.0));
  ASSERT_EQ(released.size(), 1u);
  EXPECT_NEAR(released[0].twist.linear.x, 5.0, 1e-12);
  EXPECT_EQ(released[0].header.frame_id, "map");
  // The velocity first: it waits for the IMU message of its stamp, not the previous one's.
  EXPECT_TRUE(pairing.addVelocity(levelledVelocity(10.1, 5.0)).empty());
  EXPECT_EQ(pairing.pending(), 1u);
  released = pairing.addOrientation(ros::Time(10.1), north);
  ASSERT_EQ(released.size(), 1u);
  EXPECT_NEAR(released[0].twist.linear.y, 5.0, 1e-12);
  EXPECT_NEAR(released[0].twist.linear.x, 0.0, 1e-12);
  EXPECT_EQ(pairing.pending(), 0u);
  EXPECT_EQ(pairing.dropped(), 0u);
}

TEST(LevelledVelocityPairing, WithoutAnyImuOnlyTheNewestVelocitiesWait) {
  conv::LevelledVelocityPairing pairing("map");
  const std::size_t extra = 7;
  for (std::size_t i = 0; i < conv::LevelledVelocityPairing::kMaxPendingVelocities + extra; ++i) {
    EXPECT_TRUE(pairing.addVelocity(levelledVelocity(1.0 + 0.1 * i, 1.0)).empty());
  }
  EXPECT_EQ(pairing.pending(), conv::LevelledVelocityPairing::kMaxPendingVelocities);
  EXPECT_EQ(pairing.dropped(), extra);
  EXPECT_NEAR(pairing.lastDroppedStamp().toSec(), 1.0 + 0.1 * (extra - 1), 1e-6);
}

TEST(LevelledVelocityPairing, ABagLoopForgetsTheOtherTimeline) {
  conv::LevelledVelocityPairing pairing("map");
  pairing.addOrientation(ros::Time(100.0), rpy(0, 0, 0));
  // A velocity of the old timeline's future waits...
  EXPECT_TRUE(pairing.addVelocity(levelledVelocity(100.5, 1.0)).empty());
  // ... and is forgotten when the IMU jumps back more than kLoopJumpS before it.
  EXPECT_TRUE(pairing.addOrientation(ros::Time(10.0), rpy(0, 0, 0)).empty());
  EXPECT_EQ(pairing.pending(), 0u);
  // The new timeline pairs as before.
  EXPECT_EQ(pairing.addVelocity(levelledVelocity(10.0, 1.0)).size(), 1u);
}

}  // namespace
}  // namespace inekf_semantic_mapping
