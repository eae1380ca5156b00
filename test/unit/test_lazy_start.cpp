// LazyStart: the first fix, the IMU orientation and the GPS velocity in every order inekf_node
// can receive them (separate connections), and what the start is made with.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <optional>

#include "inekf_semantic_mapping/estimation/lazy_start.h"

namespace inekf_semantic_mapping {
namespace estimation {
namespace {

PositionFix fixAt(double stamp_s) {
  PositionFix fix;
  fix.stamp_s = stamp_s;
  fix.position_map = Eigen::Vector3d(1.0, 2.0, 3.0);
  return fix;
}

const Eigen::Matrix3d kHeading =
    Eigen::AngleAxisd(-0.78, Eigen::Vector3d::UnitZ()).toRotationMatrix();

TEST(LazyStart, AFixBeforeItsImuAndVelocityWaitsForBoth) {
  LazyStart gate{LazyStart::Config()};
  gate.offerFix(fixAt(10.0));
  EXPECT_FALSE(gate.poll(10.0, /*velocity_source_exists=*/true));  // nothing else yet
  gate.offerVelocity(10.0, Eigen::Vector3d(6.0, 0.0, 0.0), /*in_body_frame=*/true);
  EXPECT_FALSE(gate.poll(10.0, true));  // the orientation is still on its way
  gate.offerOrientation(kHeading);
  const auto start = gate.poll(10.0, true);
  ASSERT_TRUE(start);
  EXPECT_EQ(start->fix.stamp_s, 10.0);
  ASSERT_TRUE(start->orientation);
  EXPECT_TRUE(start->orientation->isApprox(kHeading));
  ASSERT_TRUE(start->velocity_map);  // the body-frame velocity, rotated into the map
  EXPECT_TRUE(start->velocity_map->isApprox(kHeading * Eigen::Vector3d(6.0, 0.0, 0.0)));
  EXPECT_FALSE(gate.waiting());
  EXPECT_FALSE(gate.poll(10.1, true));  // the fix was used once
}

TEST(LazyStart, WithoutAVelocitySourceTheOrientationIsEnough) {
  LazyStart gate{LazyStart::Config()};
  gate.offerOrientation(kHeading);
  gate.offerFix(fixAt(10.0));
  const auto start = gate.poll(10.0, /*velocity_source_exists=*/false);
  ASSERT_TRUE(start);
  EXPECT_TRUE(start->orientation);
  EXPECT_FALSE(start->velocity_map);
}

TEST(LazyStart, GivesUpWaitingOnceAMessageMaxWaitNewerArrives) {
  LazyStart gate{LazyStart::Config()};
  gate.offerOrientation(kHeading);
  gate.offerFix(fixAt(10.0));
  EXPECT_FALSE(gate.poll(10.1, true));                             // the velocity may still come
  gate.offerVelocity(9.5, Eigen::Vector3d(1.0, 0.0, 0.0), false);  // not this fix's instant
  EXPECT_FALSE(gate.poll(10.2, true));
  const auto start = gate.poll(10.3, true);
  ASSERT_TRUE(start);
  EXPECT_TRUE(start->orientation);
  EXPECT_FALSE(start->velocity_map);  // 0.5 s old: the Localizer's unknown-velocity sigma instead
}

TEST(LazyStart, TheNewestFixReplacesAWaitingOne) {
  LazyStart gate{LazyStart::Config()};
  gate.offerFix(fixAt(10.0));
  gate.offerFix(fixAt(11.0));
  gate.offerOrientation(kHeading);
  gate.offerVelocity(11.0, Eigen::Vector3d(1.0, 2.0, 0.0), /*in_body_frame=*/false);
  const auto start = gate.poll(11.0, true);
  ASSERT_TRUE(start);
  EXPECT_EQ(start->fix.stamp_s, 11.0);
  EXPECT_EQ(*start->velocity_map, Eigen::Vector3d(1.0, 2.0, 0.0));  // already in the map frame
}

TEST(LazyStart, LevelledStartsAtTheFixWithoutReference) {
  LazyStart::Config config;
  config.use_reference = false;
  LazyStart gate(config);
  gate.offerOrientation(kHeading);
  gate.offerVelocity(10.0, Eigen::Vector3d(1.0, 0.0, 0.0), false);
  gate.offerFix(fixAt(10.0));
  const auto start = gate.poll(10.0, true);
  ASSERT_TRUE(start);
  EXPECT_FALSE(start->orientation);  // the Localizer levels from gravity
  // A map-frame GPS velocity needs no orientation: it is the start's (it was dropped).
  ASSERT_TRUE(start->velocity_map);
  EXPECT_EQ(*start->velocity_map, Eigen::Vector3d(1.0, 0.0, 0.0));
  // A body-frame one would need the orientation this start does not use.
  gate.offerVelocity(10.0, Eigen::Vector3d(1.0, 0.0, 0.0), true);
  gate.offerFix(fixAt(10.0));
  const auto body = gate.poll(10.0, true);
  ASSERT_TRUE(body);
  EXPECT_FALSE(body->velocity_map);
}

TEST(LazyStart, ResetForgetsTheFixAndTheReferences) {
  LazyStart gate{LazyStart::Config()};
  gate.offerOrientation(kHeading);
  gate.offerVelocity(10.0, Eigen::Vector3d(1.0, 0.0, 0.0), false);
  gate.offerFix(fixAt(10.0));
  gate.reset();
  EXPECT_FALSE(gate.waiting());
  gate.offerFix(fixAt(10.0));
  EXPECT_FALSE(gate.poll(10.0, true));   // the old orientation and velocity are gone
  EXPECT_FALSE(gate.poll(10.5, false));  // and so is the IMU: its first message may bring one
  gate.noteImu();                        // it came, without an orientation
  const auto start = gate.poll(10.5, false);
  ASSERT_TRUE(start);
  EXPECT_FALSE(start->orientation);
}

// A 10 Hz GPS and an IMU without orientation: each fix replaced the waiting one and restarted
// its 0.2 s wait, so the filter never started. The wait runs from the first fix; the start is
// made at the newest.
TEST(LazyStart, AFastGpsDoesNotRestartTheWaitForAnOrientationThatNeverComes) {
  LazyStart gate{LazyStart::Config()};
  std::optional<LazyStart::Start> start;
  double t = 10.0;
  for (; !start && t < 12.0; t += 0.1) {
    gate.offerFix(fixAt(t));
    for (double imu = t; imu < t + 0.099; imu += 0.01) {
      gate.noteImu();
      start = gate.poll(imu, /*velocity_source_exists=*/false);
      if (start) break;
    }
  }
  ASSERT_TRUE(start);
  EXPECT_FALSE(start->orientation);
  EXPECT_NEAR(start->fix.stamp_s, 10.2, 1e-9);  // the newest fix once 0.2 s had passed
  // The same with a velocity source whose stamps never match a fix.
  LazyStart velocity_gate{LazyStart::Config()};
  velocity_gate.offerOrientation(kHeading);
  std::optional<LazyStart::Start> with_velocity;
  for (double fix = 10.0; !with_velocity && fix < 12.0; fix += 0.1) {
    velocity_gate.offerFix(fixAt(fix));
    velocity_gate.offerVelocity(fix - 5.0, Eigen::Vector3d::UnitX(), false);
    with_velocity = velocity_gate.poll(fix + 0.05, /*velocity_source_exists=*/true);
  }
  ASSERT_TRUE(with_velocity);
  EXPECT_LT(with_velocity->fix.stamp_s, 10.35);
  EXPECT_TRUE(with_velocity->orientation);
}

// A velocity offered before a reset is of the ended time line: not the next start's.
TEST(LazyStart, ResetForgetsTheVelocity) {
  LazyStart gate{LazyStart::Config()};
  gate.offerVelocity(10.0, Eigen::Vector3d(1.0, 0.0, 0.0), /*in_body_frame=*/false);
  gate.reset();
  gate.offerOrientation(kHeading);
  gate.offerFix(fixAt(10.0));
  EXPECT_FALSE(gate.poll(10.0, /*velocity_source_exists=*/true));  // this fix's is still to come
  const auto start = gate.poll(10.5, true);
  ASSERT_TRUE(start);
  EXPECT_FALSE(start->velocity_map);
}

}  // namespace
}  // namespace estimation
}  // namespace inekf_semantic_mapping
