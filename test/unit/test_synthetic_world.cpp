// SyntheticWorld (ray casting, labelAt, world.txt), SyntheticRoute (IMU kinematics) and the
// lidar model, without writing a drive.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <tuple>

#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "inekf_semantic_mapping/synthetic/label_iou.h"
#include "inekf_semantic_mapping/synthetic/route.h"
#include "inekf_semantic_mapping/synthetic/sensors.h"
#include "inekf_semantic_mapping/synthetic/world.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace synthetic {
namespace {
namespace cs = cityscapes;

const SyntheticWorld& town() {
  static const SyntheticWorld world = SyntheticWorld::generateTown(7);
  return world;
}

Eigen::Matrix3d expSO3(const Eigen::Vector3d& w) {
  const double angle = w.norm();
  if (angle < 1e-12) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(angle, w / angle).toRotationMatrix();
}

TEST(SyntheticWorld, DownwardRayHitsTheHeightfieldAtItsHeight) {
  const SyntheticWorld& world = town();
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> coord(-100, 100);
  for (int i = 0; i < 200; ++i) {
    const double x = coord(rng), y = coord(rng);
    RayHit hit;
    const Eigen::Vector3d origin(x, y, 60.0);
    ASSERT_TRUE(world.raycast(origin, -Eigen::Vector3d::UnitZ(), 200.0, &hit));
    if (hit.primitive_index >= 0) {  // roof, crown, car: must be above the ground
      EXPECT_GT(hit.point.z(), world.ground().height(x, y));
      continue;
    }
    EXPECT_NEAR(hit.point.z(), world.ground().height(x, y), 1e-5);
    EXPECT_EQ(hit.label_id, world.streets().groundLabel(x, y));
    EXPECT_GT(hit.normal.z(), 0.95);
  }
}

TEST(SyntheticWorld, GrazingRaysNeverPassUnderTheGround) {
  // Shallow rays over the hills: the first crossing must be found, not a later one.
  const SyntheticWorld& world = town();
  SyntheticWorld bare;
  bare.setGround(world.ground());
  bare.setStreets(world.streets());
  bare.buildIndex();
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> angle(0, 2 * M_PI), pitch(-0.08, -0.005);
  for (int i = 0; i < 500; ++i) {
    const Eigen::Vector3d origin(0, 0, world.ground().height(0, 0) + 0.5);
    const double a = angle(rng), p = pitch(rng);
    const Eigen::Vector3d d(std::cos(p) * std::cos(a), std::cos(p) * std::sin(a), std::sin(p));
    RayHit hit;
    if (!bare.raycast(origin, d, 300, &hit)) continue;
    // March densely up to the hit: the ray must stay above the ground.
    for (double t = 0.05; t < hit.distance - 1e-3; t += 0.05) {
      const Eigen::Vector3d q = origin + t * d;
      ASSERT_GT(q.z(), world.ground().height(q.x(), q.y()) - 1e-6) << "ray " << i << " t " << t;
    }
  }
}

TEST(SyntheticWorld, BoxCylinderEllipsoidDistancesAndNormals) {
  SyntheticWorld world;
  GroundSurface flat;
  flat.offset = -10;
  world.setGround(flat);
  Primitive box;
  box.type = PrimitiveType::kBox;
  box.label_id = cs::kBuilding;
  box.center = {10, 0, 0};
  box.half_size = {1, 2, 3};
  box.yaw = M_PI / 2;  // its local x now points along map y: the face at x = 10 - 2
  world.addPrimitive(box);
  Primitive pole;
  pole.type = PrimitiveType::kCylinder;
  pole.label_id = cs::kPole;
  pole.center = {0, 10, 0};
  pole.half_size = {0.5, 0.5, 5};
  world.addPrimitive(pole);
  Primitive crown;
  crown.type = PrimitiveType::kEllipsoid;
  crown.label_id = cs::kVegetation;
  crown.center = {-10, 0, 0};
  crown.half_size = {2, 1, 1};
  world.addPrimitive(crown);
  world.buildIndex(1.5);

  RayHit hit;
  ASSERT_TRUE(world.raycast(Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitX(), 100, &hit));
  EXPECT_NEAR(hit.distance, 8.0, 1e-9);
  EXPECT_EQ(hit.label_id, cs::kBuilding);
  EXPECT_NEAR(hit.normal.x(), -1.0, 1e-9);
  ASSERT_TRUE(world.raycast(Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitY(), 100, &hit));
  EXPECT_NEAR(hit.distance, 9.5, 1e-9);
  EXPECT_EQ(hit.label_id, cs::kPole);
  ASSERT_TRUE(world.raycast(Eigen::Vector3d::Zero(), -Eigen::Vector3d::UnitX(), 100, &hit));
  EXPECT_NEAR(hit.distance, 8.0, 1e-9);
  EXPECT_EQ(hit.label_id, cs::kVegetation);
  // Downwards: the flat ground at z = -10.
  ASSERT_TRUE(world.raycast(Eigen::Vector3d::Zero(), -Eigen::Vector3d::UnitZ(), 100, &hit));
  EXPECT_NEAR(hit.distance, 10.0, 1e-5);
  EXPECT_EQ(hit.primitive_index, -1);
  // Out of range: nothing.
  EXPECT_FALSE(world.raycast(Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitX(), 7.9, &hit));

  EXPECT_EQ(world.labelAt({8.0, 0.5, 1.0}, 0.05), cs::kBuilding);
  EXPECT_EQ(world.labelAt({0.5, 10.0, 0.0}, 0.05), cs::kPole);
  EXPECT_EQ(world.labelAt({-8.0, 0.0, 0.0}, 0.05), cs::kVegetation);
  EXPECT_EQ(world.labelAt({0.0, 0.0, -9.98}, 0.05), cs::kTerrain);  // no streets: terrain
  EXPECT_EQ(world.labelAt({0.0, 0.0, 0.0}, 0.5), cs::kUnlabeled);   // in the air
  EXPECT_EQ(world.labelAt({7.8, 0.5, 1.0}, 0.1), cs::kUnlabeled);   // 0.2 m off the wall
}

TEST(SyntheticWorld, TownHasEveryClassAndStreetLayout) {
  const SyntheticWorld& world = town();
  std::set<int> labels;
  for (const Primitive& p : world.primitives()) labels.insert(p.label_id);
  for (int expected :
       {cs::kBuilding, cs::kVegetation, cs::kPole, cs::kCar, cs::kFence, cs::kTrafficSign}) {
    EXPECT_TRUE(labels.count(expected)) << cs::labelName(expected);
  }
  EXPECT_GT(world.primitives().size(), 300u);
  // The route's start (the map origin) is on the road, in the right-hand lane, at IMU height.
  EXPECT_EQ(world.streets().groundLabel(0, 0), cs::kRoad);
  EXPECT_NEAR(world.ground().height(0, 0), -RouteLayout().imu_height_m, 1e-12);
}

TEST(SyntheticWorld, SaveLoadRoundTripGivesIdenticalRaycasts) {
  const SyntheticWorld& world = town();
  const std::string dir = test::makeTempDir("synthetic_world");
  world.save(dir + "/world.txt");
  const SyntheticWorld loaded = SyntheticWorld::load(dir + "/world.txt");
  ASSERT_EQ(loaded.primitives().size(), world.primitives().size());
  EXPECT_EQ(loaded.seed(), world.seed());
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> coord(-60, 60), unit(-1, 1);
  for (int i = 0; i < 300; ++i) {
    const Eigen::Vector3d origin(coord(rng), coord(rng), 1.8);
    const Eigen::Vector3d d = Eigen::Vector3d(unit(rng), unit(rng), 0.3 * unit(rng)).normalized();
    RayHit a, b;
    const bool hit_a = world.raycast(origin, d, 150, &a);
    ASSERT_EQ(hit_a, loaded.raycast(origin, d, 150, &b));
    if (!hit_a) continue;
    EXPECT_EQ(a.label_id, b.label_id);
    EXPECT_NEAR(a.distance, b.distance, 1e-9);
  }
  std::filesystem::remove_all(dir);
}

TEST(SyntheticWorld, LoadNamesTheBadLine) {
  const std::string dir = test::makeTempDir("synthetic_world_bad");
  {
    std::ofstream out(dir + "/world.txt");
    out << "# comment\nground 0 1 0.1 0 1 0.1 0\nbox 11 0 0 0 1 1 oops 0 0.5 0.5 0.5\n";
  }
  try {
    SyntheticWorld::load(dir + "/world.txt");
    FAIL() << "expected an exception";
  } catch (const std::runtime_error& error) {
    EXPECT_NE(std::string(error.what()).find("world.txt:3"), std::string::npos) << error.what();
    EXPECT_NE(std::string(error.what()).find("half_z"), std::string::npos) << error.what();
  }
  // Found by fault injection: a coordinate of 1e12 overflowed the spatial index's cell count
  // and asked for 4.47 GB.
  {
    std::ofstream out(dir + "/world.txt");
    out << "ground 0 1 0.1 0 1 0.1 0\nbox 11 1e12 0 0 1 1 1 0 0.5 0.5 0.5\n";
  }
  try {
    SyntheticWorld::load(dir + "/world.txt");
    FAIL() << "expected an exception";
  } catch (const std::runtime_error& error) {
    EXPECT_NE(std::string(error.what()).find("world.txt:2"), std::string::npos) << error.what();
    EXPECT_NE(std::string(error.what()).find("out of range"), std::string::npos) << error.what();
  }
  // The largest allowed town still gets a bounded index (and answers rays).
  {
    std::ofstream out(dir + "/world.txt");
    out << "ground 0 1 0.1 0 1 0.1 0\nbox 11 -99000 -99000 0 1 1 1 0 0.5 0.5 0.5\n"
           "box 11 99000 99000 0 1 1 1 0 0.5 0.5 0.5\n";
  }
  const SyntheticWorld huge = SyntheticWorld::load(dir + "/world.txt");
  RayHit hit;
  ASSERT_TRUE(
      huge.raycast(Eigen::Vector3d(99000, 99000, 5), Eigen::Vector3d(0, 0, -1), 10.0, &hit));
  EXPECT_EQ(hit.label_id, 11);
  std::filesystem::remove_all(dir);
}

TEST(SyntheticLidar, EveryPointLiesOnASurfaceOfItsLabel) {
  const SyntheticWorld& world = town();
  const SyntheticRoute route = SyntheticRoute::forWorld(world);
  const VehicleState state = route.poseAt(6.0);
  Eigen::Isometry3d T_map_velo = Eigen::Isometry3d::Identity();
  T_map_velo.linear() = state.rotation;
  T_map_velo.translation() = state.position + state.rotation * Eigen::Vector3d(0.81, -0.32, 0.8);
  LidarModel model;
  model.azimuth_step_deg = 0.5;
  const LidarScan scan = simulateLidarScan(world, T_map_velo, model, 1);
  ASSERT_GT(scan.size(), 20000u);
  std::size_t agree = 0;
  std::map<int, int> per_class;
  for (std::size_t i = 0; i < scan.size(); ++i) {
    const Eigen::Vector3d p(scan.xyzi[4 * i], scan.xyzi[4 * i + 1], scan.xyzi[4 * i + 2]);
    const int label = scan.labels[i] & 0xFFFF;
    ++per_class[label];
    // 2 cm range noise, float storage: 10 cm tolerance.
    if (world.labelAt(T_map_velo * p, 0.1) == label) ++agree;
    EXPECT_LE(p.norm(), model.max_range_m + 0.2);
  }
  EXPECT_GT(static_cast<double>(agree) / scan.size(), 0.99);
  EXPECT_GT(per_class[cs::kRoad], 1000);
  EXPECT_GT(per_class[cs::kBuilding], 1000);
}

TEST(LabelIouCounter, CountsPerClassIouOverTheClassesInTheTruth) {
  LabelIouCounter counter;
  EXPECT_EQ(counter.meanIou(), 0.0);
  // road (7): 3 right, 1 called car; car (26): 1 right; building (11) only predicted, never true.
  for (int i = 0; i < 3; ++i) counter.add(7, 7);
  counter.add(7, 26);
  counter.add(26, 26);
  counter.add(26, 11);
  const std::vector<ClassIou> classes = counter.classes();
  ASSERT_EQ(classes.size(), 2u);  // building is not in the truth
  EXPECT_EQ(classes[0].label_id, 7);
  EXPECT_DOUBLE_EQ(classes[0].iou(), 3.0 / 4.0);  // tp 3, fn 1, fp 0
  EXPECT_EQ(classes[1].label_id, 26);
  EXPECT_DOUBLE_EQ(classes[1].iou(), 1.0 / 3.0);  // tp 1, fn 1, fp 1
  EXPECT_DOUBLE_EQ(counter.meanIou(), (3.0 / 4.0 + 1.0 / 3.0) / 2.0);
  EXPECT_EQ(counter.pairs(), 6u);
  EXPECT_EQ(counter.correct(), 4u);
}

TEST(SyntheticRoute, StartsAtTheOriginAtRestAndLoopsBack) {
  const SyntheticRoute route = SyntheticRoute::forWorld(town());
  const VehicleState start = route.stateAt(0.0);
  EXPECT_LT(start.position.norm(), 1e-12);
  EXPECT_LT(start.velocity.norm(), 1e-12);
  EXPECT_NEAR(start.specificForceBody().norm(), kGravity, 1e-9);
  // The route is closed: at one loop length of distance, back at the start heading east.
  double lo = 0, hi = 200;
  for (int i = 0; i < 100; ++i) {
    const double mid = 0.5 * (lo + hi);
    (route.distanceAt(mid) < route.loopLength() ? lo : hi) = mid;
  }
  const VehicleState back = route.poseAt(hi);
  EXPECT_LT(back.position.norm(), 1e-6);
  EXPECT_NEAR(std::cos(back.yaw), 1.0, 1e-9);
  EXPECT_GT(route.loopLength(), 100.0);
}

TEST(SyntheticRoute, DerivativesAreConsistentWithThePositions) {
  const SyntheticRoute route = SyntheticRoute::forWorld(town());
  constexpr double h = 1e-4;
  for (double t : {2.0, 5.3, 9.0, 11.1, 15.7, 21.0, 24.4, 27.9}) {
    const VehicleState s = route.stateAt(t);
    const Eigen::Vector3d v_numeric =
        (route.poseAt(t + h).position - route.poseAt(t - h).position) / (2 * h);
    const Eigen::Vector3d a_numeric =
        (route.poseAt(t + h).velocity - route.poseAt(t - h).velocity) / (2 * h);
    EXPECT_LT((s.velocity - v_numeric).norm(), 1e-6) << "t " << t;
    EXPECT_LT((s.acceleration - a_numeric).norm(), 1e-5) << "t " << t;
    // The body z axis is the ground normal.
    const Eigen::Vector2d g = town().ground().gradient(s.position.x(), s.position.y());
    const Eigen::Vector3d normal = Eigen::Vector3d(-g.x(), -g.y(), 1).normalized();
    EXPECT_LT((s.rotation.col(2) - normal).norm(), 1e-9) << "t " << t;
  }
}

TEST(SyntheticRoute, IntegratingThePerfectImuReproducesTheTrajectory) {
  // Strapdown integration of specific force and body rate at 100 Hz over 8 s (a turn, a stop,
  // hills): what a filter would do with a perfect IMU.
  const SyntheticRoute route = SyntheticRoute::forWorld(town());
  const double dt = 0.01, t0 = 8.0;
  VehicleState truth = route.stateAt(t0);
  Eigen::Matrix3d R = truth.rotation;
  Eigen::Vector3d v = truth.velocity, p = truth.position;
  const Eigen::Vector3d gravity(0, 0, -kGravity);
  for (int k = 0; k < 800; ++k) {
    const VehicleState a = route.stateAt(t0 + k * dt);
    const VehicleState b = route.stateAt(t0 + (k + 1) * dt);
    const Eigen::Matrix3d R_next =
        R * expSO3(0.5 * (a.angular_velocity_body + b.angular_velocity_body) * dt);
    const Eigen::Vector3d acc_a = R * a.specificForceBody() + gravity;
    const Eigen::Vector3d acc_b = R_next * b.specificForceBody() + gravity;
    p += v * dt + (acc_a / 3 + acc_b / 6) * dt * dt;
    v += 0.5 * (acc_a + acc_b) * dt;
    R = R_next;
  }
  truth = route.stateAt(t0 + 8.0);
  std::printf("[ figure ] perfect IMU integrated over 8 s: position error %.2e m\n",
              (p - truth.position).norm());
  EXPECT_LT((p - truth.position).norm(), 0.03);
  EXPECT_LT((v - truth.velocity).norm(), 0.01);
  const Eigen::AngleAxisd rotation_error(R.transpose() * truth.rotation);
  EXPECT_LT(std::abs(rotation_error.angle()), 1e-4);
  // And the route really moved: turned and drove (otherwise the test proves nothing).
  EXPECT_GT((truth.position - route.stateAt(t0).position).norm(), 20.0);
}

}  // namespace
}  // namespace synthetic
}  // namespace inekf_semantic_mapping
