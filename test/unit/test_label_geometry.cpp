// Lidar geometry as a check on camera labels: the ground estimate on synthetic scans (a flat
// road, a car-sized box with no ground visible under its roof, a 10 % grade, an embankment) and
// the labels it rejects or keeps.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "inekf_semantic_mapping/perception/label_geometry.h"

namespace inekf_semantic_mapping {
namespace perception {
namespace {

constexpr float kSensorHeight = 1.73f;  // HDL-64 on the KITTI car
constexpr std::uint32_t kNone = 0xFFFFFFFF;

struct Scene {
  std::vector<Eigen::Vector3f> points;
  std::vector<std::uint32_t> labels;
  void add(float x, float y, float z, std::uint32_t label) {
    points.emplace_back(x, y, z);
    labels.push_back(label);
  }
  Eigen::Matrix3Xf matrix() const {
    Eigen::Matrix3Xf m(3, static_cast<Eigen::Index>(points.size()));
    for (std::size_t i = 0; i < points.size(); ++i) m.col(static_cast<Eigen::Index>(i)) = points[i];
    return m;
  }
};

// Ground of height z(x, y) sampled every 0.25 m over [x0, x1] x [y0, y1], labelled `label`.
template <typename Height>
void addGround(Scene* scene, float x0, float x1, float y0, float y1, Height z,
               std::uint32_t label) {
  for (float x = x0; x <= x1; x += 0.25f)
    for (float y = y0; y <= y1; y += 0.25f) scene->add(x, y, z(x, y), label);
}

// A car-sized box (4 x 2 m, 1.5 m tall) standing on z = ground, its roof and four sides
// sampled every 0.1 m, labelled `label`. Its footprint has no ground points: the lidar cannot see
// under a car.
void addBox(Scene* scene, float cx, float cy, float ground, std::uint32_t label) {
  const float hx = 2.0f, hy = 1.0f, top = ground + 1.5f;
  for (float x = cx - hx; x <= cx + hx; x += 0.1f) {
    for (float y = cy - hy; y <= cy + hy; y += 0.1f) scene->add(x, y, top, label);
    for (float z = ground + 0.3f; z <= top; z += 0.1f) {
      scene->add(x, cy - hy, z, label);
      scene->add(x, cy + hy, z, label);
    }
  }
  for (float y = cy - hy; y <= cy + hy; y += 0.1f) {
    for (float z = ground + 0.3f; z <= top; z += 0.1f) {
      scene->add(cx - hx, y, z, label);
      scene->add(cx + hx, y, z, label);
    }
  }
}

// Removes from `scene` the ground points inside the box footprint (they would be hidden).
void clearFootprint(Scene* scene, float cx, float cy, float ground) {
  Scene kept;
  for (std::size_t i = 0; i < scene->points.size(); ++i) {
    const Eigen::Vector3f& p = scene->points[i];
    const bool under = std::abs(p.x() - cx) < 2.0f && std::abs(p.y() - cy) < 1.0f &&
                       std::abs(p.z() - ground) < 0.01f;
    if (!under) kept.add(p.x(), p.y(), p.z(), scene->labels[i]);
  }
  *scene = kept;
}

Eigen::VectorXf heightsOf(const Scene& scene, const GroundGridOptions& options = {}) {
  const Eigen::Matrix3Xf points = scene.matrix();
  Eigen::VectorXf heights;
  heightAboveGround(points, options, &heights);
  return heights;
}

std::size_t reject(const Scene& scene, std::vector<std::uint32_t>* labels,
                   const LabelGeometryOptions& options = {}) {
  std::size_t rejected = 0;
  rejectGeometricallyInconsistentLabels(heightsOf(scene, options.ground), cityscapesSurfaceKinds(),
                                        options, kNone, labels, &rejected);
  return rejected;
}

// The cone (max_slope 0.5) caps the cells under a car's roof, where the lidar sees no ground.
GroundGridOptions withCone() {
  GroundGridOptions options;
  options.max_slope = 0.5f;
  return options;
}

LabelGeometryOptions checkWithCone() {
  LabelGeometryOptions options;
  options.ground = withCone();
  return options;
}

TEST(LabelGeometryTest, FlatRoadIsAtZeroAndACarRoofWellAboveIt) {
  Scene scene;
  const auto flat = [](float, float) { return -kSensorHeight; };
  addGround(&scene, 3, 30, -10, 10, flat, cityscapes::kRoad);
  clearFootprint(&scene, 12, 2, -kSensorHeight);
  const std::size_t ground_points = scene.points.size();
  addBox(&scene, 12, 2, -kSensorHeight, cityscapes::kCar);
  const Eigen::VectorXf h = heightsOf(scene, withCone());
  // Away from the car the road is at 0. Next to it the blend takes in the car's cells, whose
  // envelope (0.5 m: one cell at the 0.5 slope) is an upper bound of the ground there: the road
  // reads a little low, never high (a flat label is never rejected for it).
  for (std::size_t i = 0; i < ground_points; ++i) {
    const Eigen::Vector3f& p = scene.points[i];
    const bool near_car = std::abs(p.x() - 12) < 3.5f && std::abs(p.y() - 2) < 2.5f;
    if (near_car) {
      ASSERT_GT(h(i), -0.3f) << i;
      ASSERT_LT(h(i), 0.02f) << i;
    } else {
      ASSERT_NEAR(h(i), 0.0f, 0.02f) << i;
    }
  }
  // The roof: no ground under it, yet the neighbours' ground caps its cells (the cell minimum
  // alone would be the roof and give 0).
  for (std::size_t i = ground_points; i < scene.points.size(); ++i) {
    if (std::abs(scene.points[i].z() - (-kSensorHeight + 1.5f)) < 1e-3f) {
      ASSERT_GT(h(i), 0.9f) << "roof point " << i;
    }
  }
}

TEST(LabelGeometryTest, RoadLabelsOnACarAndSignLabelsOnTheRoadAreRejected) {
  Scene scene;
  const auto flat = [](float, float) { return -kSensorHeight; };
  addGround(&scene, 3, 30, -10, 10, flat, cityscapes::kRoad);
  clearFootprint(&scene, 12, 2, -kSensorHeight);
  const std::size_t ground_points = scene.points.size();
  addBox(&scene, 12, 2, -kSensorHeight, cityscapes::kCar);

  // The camera called the whole car road (label bleeding), and a stretch of road a sign.
  std::vector<std::uint32_t> labels = scene.labels;
  std::size_t car_points_high = 0, sign_on_road = 0;
  const Eigen::VectorXf h = heightsOf(scene, withCone());
  for (std::size_t i = ground_points; i < labels.size(); ++i) {
    labels[i] = cityscapes::kRoad;
    car_points_high += h(i) > LabelGeometryOptions().max_flat_height_m;
  }
  for (std::size_t i = 0; i < ground_points; i += 7) {
    labels[i] = cityscapes::kTrafficSign;
    ++sign_on_road;
  }
  const std::size_t rejected = reject(scene, &labels, checkWithCone());
  EXPECT_EQ(rejected, car_points_high + sign_on_road);
  ASSERT_GT(car_points_high, 1000u);
  for (std::size_t i = 0; i < ground_points; ++i) {
    if (i % 7 == 0) {
      EXPECT_EQ(labels[i], kNone) << "sign on the road kept at " << i;
    } else {
      ASSERT_EQ(labels[i], cityscapes::kRoad) << "road on the road rejected at " << i;
    }
  }
  // The car's own label and a sign above the roof are what the geometry allows.
  std::vector<std::uint32_t> right = scene.labels;
  for (std::size_t i = ground_points; i < right.size(); ++i) {
    if (h(i) > 1.0f) right[i] = cityscapes::kTrafficSign;
  }
  EXPECT_EQ(reject(scene, &right, checkWithCone()), 0u);
  // Without the cone (the default) the roof cells keep the roof as their ground: fewer of the
  // car's road labels go, never a label the geometry allows.
  std::vector<std::uint32_t> without_cone = labels;
  for (std::size_t i = ground_points; i < without_cone.size(); ++i)
    without_cone[i] = cityscapes::kRoad;
  const std::size_t rejected_without = reject(scene, &without_cone);
  EXPECT_GT(rejected_without, 100u);
  EXPECT_LT(rejected_without, rejected);
}

TEST(LabelGeometryTest, SpuriousReturnsBelowTheRoadSinkOnlyTheirOwnNeighbourhood) {
  // Real scans hold clusters of reflections metres below the road (SemanticKITTI "outlier").
  Scene scene;
  const auto flat = [](float, float) { return -kSensorHeight; };
  addGround(&scene, 3, 30, -10, 10, flat, cityscapes::kRoad);
  const std::size_t ground_points = scene.points.size();
  for (int k = 0; k < 8; ++k) scene.add(20.2f + 0.05f * k, 0.3f, -11.0f + 0.02f * k, 0);
  scene.add(10.5f, 5.5f, -9.0f, 0);  // a lone one: below min_support, ignored altogether
  const Eigen::VectorXf h = heightsOf(scene);
  for (std::size_t i = 0; i < ground_points; ++i) {
    const Eigen::Vector3f& p = scene.points[i];
    if (std::abs(p.x() - 20.5f) > 1.5f || std::abs(p.y() - 0.5f) > 1.5f) {
      ASSERT_NEAR(h(i), 0.0f, 0.02f) << "x " << p.x() << " y " << p.y();
    }
  }
}

TEST(LabelGeometryTest, ATenPercentGradeKeepsItsRoadLabels) {
  // A hill ahead (10 % up along x) with a 3 % cross fall, in the sensor frame of a car standing
  // on level ground at its foot: the ground rises 3.3 m over the 33 m ahead.
  Scene scene;
  const auto hill = [](float x, float y) {
    return -kSensorHeight + 0.1f * std::max(0.0f, x - 5.0f) + 0.03f * y;
  };
  addGround(&scene, 2, 38, -8, 8, hill, cityscapes::kRoad);
  const Eigen::VectorXf h = heightsOf(scene);
  // Half a cell of grade and cross fall at most: the lowest point of a cell is on its low side.
  for (Eigen::Index i = 0; i < h.size(); ++i) ASSERT_LT(std::abs(h(i)), 0.15f) << i;
  std::vector<std::uint32_t> labels = scene.labels;
  EXPECT_EQ(reject(scene, &labels), 0u);
  // The same hill sloping down (the car at its top) too.
  Scene down;
  const auto valley = [](float x, float y) {
    return -kSensorHeight - 0.1f * std::max(0.0f, x - 5.0f) + 0.03f * y;
  };
  addGround(&down, 2, 38, -8, 8, valley, cityscapes::kRoad);
  labels = down.labels;
  EXPECT_EQ(reject(down, &labels), 0u);
}

TEST(LabelGeometryTest, AnEmbankmentKeepsItsTerrainLabelsButAHedgeOnItLosesThem) {
  // Road to |y| < 4, then grass rising at 20 deg (tan = 0.36) to 3 m above the road.
  Scene scene;
  const auto bank = [](float, float y) {
    const float d = std::max(0.0f, std::abs(y) - 4.0f);
    return -kSensorHeight + std::min(3.0f, 0.364f * d);
  };
  addGround(&scene, 3, 30, -14, 14, bank, cityscapes::kTerrain);
  std::vector<std::uint32_t> labels = scene.labels;
  EXPECT_EQ(reject(scene, &labels), 0u);
  // A 1.2 m hedge on the flat top at y = 13, labelled terrain by the camera: rejected.
  const std::size_t ground_points = scene.points.size();
  for (float x = 3; x <= 30; x += 0.1f)
    for (float z = 0.7f; z <= 1.2f; z += 0.1f)
      scene.add(x, 13.0f, -kSensorHeight + 3.0f + z, cityscapes::kTerrain);
  labels = scene.labels;
  const std::size_t rejected = reject(scene, &labels);
  EXPECT_EQ(rejected, scene.points.size() - ground_points);
  for (std::size_t i = ground_points; i < labels.size(); ++i) ASSERT_EQ(labels[i], kNone);

  // With the Cityscapes relabel table the hedge's terrain becomes vegetation; a road label up
  // there has no such reading and goes.
  labels = scene.labels;
  for (std::size_t i = ground_points; i < labels.size(); i += 2) labels[i] = cityscapes::kRoad;
  std::size_t changed = 0;
  rejectGeometricallyInconsistentLabels(heightsOf(scene), cityscapesSurfaceKinds(),
                                        LabelGeometryOptions(), kNone, &labels, &changed,
                                        &cityscapesHighFlatRelabels());
  EXPECT_EQ(changed, scene.points.size() - ground_points);
  for (std::size_t i = ground_points; i < labels.size(); ++i) {
    ASSERT_EQ(labels[i],
              (i - ground_points) % 2 == 0 ? kNone : std::uint32_t{cityscapes::kVegetation})
        << i;
  }
  for (std::size_t i = 0; i < ground_points; ++i) ASSERT_EQ(labels[i], cityscapes::kTerrain);
}

TEST(LabelGeometryTest, PointsOutOfRangeOrNotFiniteAreLeftAlone) {
  Scene scene;
  const auto flat = [](float, float) { return -kSensorHeight; };
  addGround(&scene, 3, 10, -3, 3, flat, cityscapes::kRoad);
  scene.add(60.0f, 0.0f, 5.0f, cityscapes::kRoad);  // beyond the 40 m grid
  scene.add(std::numeric_limits<float>::quiet_NaN(), 0.0f, 0.0f, cityscapes::kRoad);
  const Eigen::VectorXf h = heightsOf(scene);
  EXPECT_TRUE(std::isnan(h(h.size() - 1)));
  EXPECT_TRUE(std::isnan(h(h.size() - 2)));
  std::vector<std::uint32_t> labels = scene.labels;
  EXPECT_EQ(reject(scene, &labels), 0u);
  EXPECT_EQ(labels, scene.labels);
}

// A point on the lines through a cell's centre weighs nothing on the cells across them: with no
// ground in its own cells it takes the nearest supported cell's ground, not none.
TEST(LabelGeometryTest, APointOnACellCentreTakesTheNearestSupportedGround) {
  Scene scene;
  for (int i = 0; i < 5; ++i) scene.add(1.5f, 0.5f, -kSensorHeight, cityscapes::kRoad);
  scene.add(0.5f, 0.5f, 0.27f, cityscapes::kCar);  // the centre of the empty cell beside them
  const Eigen::VectorXf h = heightsOf(scene);
  ASSERT_FALSE(std::isnan(h(5)));
  EXPECT_NEAR(h(5), 2.0f, 1e-5f);
}

// The cone is the same in all eight directions: a low cell caps each of its neighbours at
// slope * 1 cell straight across and slope * sqrt(2) cells diagonally, whichever side they are on.
TEST(LabelGeometryTest, TheConeCapsEveryNeighbourByItsDistance) {
  const GroundGridOptions options = withCone();  // 1 m cells, slope 0.5
  Scene scene;
  const float cx = 10.5f, cy = 0.5f;  // a cell centre
  for (int i = 0; i < options.min_support; ++i) scene.add(cx, cy, 0.0f, cityscapes::kRoad);
  for (int dy = -1; dy <= 1; ++dy) {
    for (int dx = -1; dx <= 1; ++dx) {
      if (dx == 0 && dy == 0) continue;
      // A wall top 3 m up over each neighbour's centre, its ground unseen.
      for (int i = 0; i < options.min_support; ++i)
        scene.add(cx + dx, cy + dy, 3.0f, cityscapes::kWall);
    }
  }
  const Eigen::VectorXf h = heightsOf(scene, options);
  std::size_t i = static_cast<std::size_t>(options.min_support);
  for (int dy = -1; dy <= 1; ++dy) {
    for (int dx = -1; dx <= 1; ++dx) {
      if (dx == 0 && dy == 0) continue;
      const float distance = std::sqrt(static_cast<float>(dx * dx + dy * dy)) * options.cell_size_m;
      for (int k = 0; k < options.min_support; ++k, ++i) {
        ASSERT_NEAR(h(static_cast<Eigen::Index>(i)), 3.0f - options.max_slope * distance, 1e-4f)
            << "dx " << dx << " dy " << dy;
      }
    }
  }
}

TEST(LabelGeometryTest, ClassesWithoutAKindAreNeverRejected) {
  const SurfaceKindTable& kinds = cityscapesSurfaceKinds();
  for (int id : {cityscapes::kRoad, cityscapes::kSidewalk, cityscapes::kParking,
                 cityscapes::kTerrain, cityscapes::kGround})
    EXPECT_EQ(kinds[id], SurfaceKind::kFlat) << id;
  for (int id : {cityscapes::kTrafficSign, cityscapes::kTrafficLight})
    EXPECT_EQ(kinds[id], SurfaceKind::kRaised) << id;
  for (int id : {cityscapes::kCar, cityscapes::kBuilding, cityscapes::kVegetation,
                 cityscapes::kPole, cityscapes::kPerson})
    EXPECT_EQ(kinds[id], SurfaceKind::kAny) << id;
}

TEST(LabelGeometryTest, BadInputsThrow) {
  Eigen::Matrix3Xf points = Eigen::Matrix3Xf::Zero(3, 4);
  Eigen::VectorXf heights;
  GroundGridOptions bad;
  bad.cell_size_m = 0.0f;
  EXPECT_THROW(heightAboveGround(points, bad, &heights), std::invalid_argument);
  heightAboveGround(points, GroundGridOptions(), &heights);
  std::vector<std::uint32_t> labels(3, cityscapes::kRoad);
  EXPECT_THROW(rejectGeometricallyInconsistentLabels(heights, cityscapesSurfaceKinds(),
                                                     LabelGeometryOptions(), kNone, &labels),
               std::invalid_argument);
}

// A spinning lidar's scan in ring order (KITTI's): rings at elevations -24..-6 deg, each once
// around from behind the sensor (azimuth -pi .. pi in 0.2 deg steps), cast analytically against
// a road at the sensor's height below it with kerbs `kerb_height` high at y = +4 m (left) and
// y = -5 m (right) and sidewalks beyond, an optional box (a parked car) and an optional narrow
// strip `bump_height` high at y = 2.0..2.3 m (a drain's edge, no sidewalk).
struct KerbWorld {
  float kerb_height = 0.12f;
  bool parked_car = false;  // x 6..10, y 2.2..3.8, 1.5 m tall
  float bump_height = 0.0f;
  float groundAt(float y) const {
    if (y >= 4.0f || y <= -5.0f) return -kSensorHeight + kerb_height;
    if (bump_height > 0.0f && y >= 2.0f && y <= 2.3f) return -kSensorHeight + bump_height;
    return -kSensorHeight;
  }
};

// Where the ray (unit direction d) meets the world first, or false beyond 40 m.
bool castRay(const KerbWorld& world, const Eigen::Vector3f& d, Eigen::Vector3f* hit) {
  float best = 40.0f;
  bool found = false;
  // Horizontal surfaces: the road, the raised parts.
  for (float z :
       {-kSensorHeight, -kSensorHeight + world.kerb_height, -kSensorHeight + world.bump_height}) {
    if (d.z() >= 0.0f || z >= 0.0f) continue;
    const float t = z / d.z();
    if (t > 0.0f && t < best && std::abs(world.groundAt(t * d.y()) - z) < 1e-4f) {
      best = t;
      found = true;
    }
  }
  // Vertical faces: the kerbs and the bump's sides, between the two levels they join.
  for (float y : {4.0f, -5.0f, 2.0f, 2.3f}) {
    if (std::abs(d.y()) < 1e-6f) continue;
    const float t = y / d.y();
    const float z = t * d.z();
    const float low = -kSensorHeight;
    const float high = std::max(world.groundAt(y - 1e-3f), world.groundAt(y + 1e-3f));
    if (t > 0.0f && t < best && z >= low && z <= high) {
      best = t;
      found = true;
    }
  }
  if (world.parked_car) {  // slab test against the box
    const Eigen::Vector3f lo(6.0f, 2.2f, -kSensorHeight), hi(10.0f, 3.8f, -kSensorHeight + 1.5f);
    float t_in = 0.0f, t_out = best;
    bool hits = true;
    for (int a = 0; a < 3 && hits; ++a) {
      if (std::abs(d[a]) < 1e-9f) {
        hits = lo[a] <= 0.0f && 0.0f <= hi[a];
        continue;
      }
      float t0 = lo[a] / d[a], t1 = hi[a] / d[a];
      if (t0 > t1) std::swap(t0, t1);
      t_in = std::max(t_in, t0);
      t_out = std::min(t_out, t1);
      hits = t_in <= t_out;
    }
    if (hits && t_in < best) {
      best = t_in;
      found = true;
    }
  }
  if (found) *hit = best * d;
  return found;
}

Eigen::Matrix3Xf ringOrderedScan(const KerbWorld& world) {
  std::vector<Eigen::Vector3f> points;
  constexpr float kDeg = 3.14159265f / 180.0f;
  for (float elevation = -24.0f; elevation <= -6.0f; elevation += 0.4f) {
    for (float azimuth = -179.9f; azimuth < 180.0f; azimuth += 0.2f) {
      const Eigen::Vector3f d(std::cos(elevation * kDeg) * std::cos(azimuth * kDeg),
                              std::cos(elevation * kDeg) * std::sin(azimuth * kDeg),
                              std::sin(elevation * kDeg));
      Eigen::Vector3f hit;
      if (castRay(world, d, &hit)) points.push_back(hit);
    }
  }
  Eigen::Matrix3Xf m(3, static_cast<Eigen::Index>(points.size()));
  for (std::size_t i = 0; i < points.size(); ++i) m.col(static_cast<Eigen::Index>(i)) = points[i];
  return m;
}

struct KerbCounts {
  int road = 0, road_flagged = 0, sidewalk = 0, sidewalk_flagged = 0;
  int raised_flagged = 0;  // points higher than the sidewalk (a car)
};

// Points ahead within 20 m: the road between the kerbs, the sidewalks beyond.
KerbCounts countFlags(const Eigen::Matrix3Xf& scan, const std::vector<std::uint8_t>& beyond) {
  KerbCounts counts;
  for (Eigen::Index i = 0; i < scan.cols(); ++i) {
    const Eigen::Vector3f p = scan.col(i);
    if (p.x() <= 0.0f || p.x() > 20.0f) continue;
    const bool flagged = beyond[static_cast<std::size_t>(i)] != 0;
    const bool on_road = std::abs(p.z() + kSensorHeight) < 1e-3f && p.y() < 4.0f && p.y() > -5.0f;
    const bool on_sidewalk =
        std::abs(p.z() + kSensorHeight - 0.12f) < 1e-3f && (p.y() > 4.0f || p.y() < -5.0f);
    if (on_road) {
      ++counts.road;
      counts.road_flagged += flagged;
    } else if (on_sidewalk) {
      ++counts.sidewalk;
      counts.sidewalk_flagged += flagged;
    } else if (p.z() + kSensorHeight > 0.15f) {
      counts.raised_flagged += flagged;
    }
  }
  return counts;
}

TEST(CurbTest, SidewalksBeyondBothKerbsAreFoundAndNoRoadPoint) {
  const Eigen::Matrix3Xf scan = ringOrderedScan(KerbWorld());
  std::vector<std::uint8_t> beyond;
  EXPECT_GE(markPointsBeyondCurbs(scan, CurbOptions(), &beyond), 30);
  const KerbCounts counts = countFlags(scan, beyond);
  ASSERT_GT(counts.road, 1000);
  ASSERT_GT(counts.sidewalk, 1000);
  EXPECT_EQ(counts.road_flagged, 0);
  EXPECT_GT(counts.sidewalk_flagged, 0.9 * counts.sidewalk);

  // A lidar spinning the other way: each ring's points in reverse, the same kerbs found.
  Eigen::Matrix3Xf reversed(3, scan.cols());
  for (Eigen::Index i = 0; i < scan.cols(); ++i) reversed.col(i) = scan.col(scan.cols() - 1 - i);
  std::vector<std::uint8_t> reversed_beyond;
  markPointsBeyondCurbs(reversed, CurbOptions(), &reversed_beyond);
  EXPECT_EQ(countFlags(reversed, reversed_beyond).road_flagged, 0);
  EXPECT_EQ(countFlags(reversed, reversed_beyond).sidewalk_flagged, counts.sidewalk_flagged);

  // The scan cropped to a camera's view (what the session keeps of a scan whose label image
  // comes late): the same points marked.
  std::vector<Eigen::Index> in_view;
  for (Eigen::Index i = 0; i < scan.cols(); ++i) {
    if (scan(0, i) > 0.0f && std::abs(std::atan2(scan(1, i), scan(0, i))) < 0.7f)
      in_view.push_back(i);
  }
  Eigen::Matrix3Xf cropped(3, static_cast<Eigen::Index>(in_view.size()));
  for (std::size_t i = 0; i < in_view.size(); ++i)
    cropped.col(static_cast<Eigen::Index>(i)) = scan.col(in_view[i]);
  std::vector<std::uint8_t> cropped_beyond;
  EXPECT_GE(markPointsBeyondCurbs(cropped, CurbOptions(), &cropped_beyond), 30);
  std::size_t same = 0, marked = 0;
  for (std::size_t i = 0; i < in_view.size(); ++i) {
    marked += beyond[in_view[i]];
    same += cropped_beyond[i] == beyond[in_view[i]];
  }
  EXPECT_GT(marked, 1000u);
  EXPECT_GE(same, in_view.size() - in_view.size() / 50);  // at most 2 % differ (cut kerbs)

  // A step higher than a kerb (a wall's foot, a loading dock) may mark what lies beyond it, never
  // the road before it.
  KerbWorld high;
  high.kerb_height = 0.45f;
  const Eigen::Matrix3Xf high_scan = ringOrderedScan(high);
  markPointsBeyondCurbs(high_scan, CurbOptions(), &beyond);
  EXPECT_EQ(countFlags(high_scan, beyond).road_flagged, 0);
}

// An organized cloud's no-returns (NaN coordinates, any of the three) among the points: the same
// points are marked as without them (a NaN beside a ring's end hid the end and merged two
// rings; a NaN x or y passed the forward-half filter and upset the ring's medians).
TEST(CurbTest, PointsWithoutFiniteCoordinatesChangeNothing) {
  const Eigen::Matrix3Xf scan = ringOrderedScan(KerbWorld());
  std::vector<std::uint8_t> clean;
  const int rings = markPointsBeyondCurbs(scan, CurbOptions(), &clean);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  // Every 7th point followed by a NaN one (x, y, z or all in turn), and one after each point
  // where the azimuth jumps back (a ring's end).
  std::vector<Eigen::Index> original;
  std::vector<Eigen::Vector3f> columns;
  for (Eigen::Index i = 0; i < scan.cols(); ++i) {
    columns.push_back(scan.col(i));
    original.push_back(i);
    const bool ring_end = i + 1 < scan.cols() && std::atan2(scan(1, i + 1), scan(0, i + 1)) <
                                                     std::atan2(scan(1, i), scan(0, i)) - 0.5f;
    if (i % 7 == 0 || ring_end) {
      Eigen::Vector3f bad = scan.col(i);
      const int which = static_cast<int>(i % 4);
      if (which == 3) {
        bad.setConstant(nan);
      } else {
        bad[which] = nan;
      }
      columns.push_back(bad);
      original.push_back(-1);
    }
  }
  Eigen::Matrix3Xf holey(3, static_cast<Eigen::Index>(columns.size()));
  for (std::size_t i = 0; i < columns.size(); ++i)
    holey.col(static_cast<Eigen::Index>(i)) = columns[i];
  std::vector<std::uint8_t> marked;
  EXPECT_EQ(markPointsBeyondCurbs(holey, CurbOptions(), &marked), rings);
  std::size_t differ = 0;
  for (std::size_t i = 0; i < original.size(); ++i) {
    if (original[i] < 0) {
      EXPECT_EQ(marked[i], 0) << "a NaN point marked";
    } else {
      differ += marked[i] != clean[static_cast<std::size_t>(original[i])];
    }
  }
  EXPECT_EQ(differ, 0u);
}

TEST(CurbTest, AParkedCarStopsItsRingsAndTheKerbLineStillMarksTheSidewalk) {
  KerbWorld world;
  world.parked_car = true;
  const Eigen::Matrix3Xf scan = ringOrderedScan(world);
  std::vector<std::uint8_t> beyond;
  CurbOptions rings_only;
  rings_only.line_min_points = 0;
  markPointsBeyondCurbs(scan, rings_only, &beyond);
  const KerbCounts by_rings = countFlags(scan, beyond);
  markPointsBeyondCurbs(scan, CurbOptions(), &beyond);
  const KerbCounts with_line = countFlags(scan, beyond);
  EXPECT_EQ(by_rings.road_flagged, 0);
  EXPECT_EQ(with_line.road_flagged, 0);
  EXPECT_EQ(with_line.raised_flagged, 0);  // nothing of the car
  // The rings that meet the car before the kerb find none; the line through the others' kerbs
  // marks the sidewalk those rings reach past the car.
  EXPECT_GT(with_line.sidewalk_flagged, by_rings.sidewalk_flagged);
  EXPECT_GT(with_line.sidewalk_flagged, 0.85 * with_line.sidewalk);
}

TEST(CurbTest, ANarrowStripOrAKerbTooLowIsNoKerb) {
  for (const auto& [kerb, bump] : {std::pair<float, float>{0.0f, 0.08f}, {0.03f, 0.0f}}) {
    KerbWorld world;
    world.kerb_height = kerb;
    world.bump_height = bump;
    const Eigen::Matrix3Xf scan = ringOrderedScan(world);
    std::vector<std::uint8_t> beyond;
    markPointsBeyondCurbs(scan, CurbOptions(), &beyond);
    EXPECT_EQ(std::count(beyond.begin(), beyond.end(), 1), 0) << kerb << " " << bump;
  }
}

TEST(CurbTest, AScanNotInRingOrderFlagsNothing) {
  Eigen::Matrix3Xf scan = ringOrderedScan(KerbWorld());
  std::vector<Eigen::Index> order(static_cast<std::size_t>(scan.cols()));
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<Eigen::Index>(i);
  std::shuffle(order.begin(), order.end(), std::mt19937(3));
  Eigen::Matrix3Xf shuffled(3, scan.cols());
  for (std::size_t i = 0; i < order.size(); ++i)
    shuffled.col(static_cast<Eigen::Index>(i)) = scan.col(order[i]);
  std::vector<std::uint8_t> beyond;
  // A shuffled scan jumps back in azimuth everywhere: no ring is a full revolution's run...
  markPointsBeyondCurbs(shuffled, CurbOptions(), &beyond);
  EXPECT_EQ(std::count(beyond.begin(), beyond.end(), 1), 0);
  // ... and a scan of a few points is no scan of rings.
  EXPECT_EQ(markPointsBeyondCurbs(scan.leftCols(500), CurbOptions(), &beyond), 0);
  EXPECT_EQ(beyond.size(), 500u);
}

TEST(CurbTest, OnlyRoadBeyondAKerbBecomesSidewalk) {
  std::vector<std::uint32_t> labels = {cityscapes::kRoad, cityscapes::kRoad, cityscapes::kCar,
                                       cityscapes::kTerrain, kNone};
  const std::vector<std::uint8_t> beyond = {1, 0, 1, 1, 1};
  std::size_t changed = 0;
  relabelBeyondCurbs(beyond, cityscapesBeyondCurbRelabels(), &labels, &changed);
  EXPECT_EQ(changed, 1u);
  EXPECT_EQ(labels, (std::vector<std::uint32_t>{cityscapes::kSidewalk, cityscapes::kRoad,
                                                cityscapes::kCar, cityscapes::kTerrain, kNone}));
  EXPECT_THROW(relabelBeyondCurbs({1}, cityscapesBeyondCurbRelabels(), &labels),
               std::invalid_argument);
}

}  // namespace
}  // namespace perception
}  // namespace inekf_semantic_mapping
