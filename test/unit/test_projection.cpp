// Lidar-to-camera projection: hand-computed pixels from the real KITTI object calibration,
// points behind the camera, image bounds, labels from a label image, and alignment of the real
// scan with a 3D box label (its points must land in the box's 2D bounding box).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <sstream>

#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"
#include "inekf_semantic_mapping/perception/projection.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace perception {
namespace {

// Object frame 000000 calibration, copied from ../shared/.../calib/000000.txt.
constexpr double kP2[12] = {7.070493e+02,
                            0,
                            6.040814e+02,
                            4.575831e+01,
                            0,
                            7.070493e+02,
                            1.805066e+02,
                            -3.454157e-01,
                            0,
                            0,
                            1,
                            4.981016e-03};
constexpr double kR0[9] = {9.999128e-01,  1.009263e-02, -8.511932e-03, -1.012729e-02, 9.999406e-01,
                           -4.037671e-03, 8.470675e-03, 4.123522e-03,  9.999556e-01};
constexpr double kTr[12] = {6.927964e-03,  -9.999722e-01, -2.757829e-03, -2.457729e-02,
                            -1.162982e-03, 2.749836e-03,  -9.999955e-01, -6.127237e-02,
                            9.999753e-01,  6.931141e-03,  -1.143899e-03, -3.321029e-01};

// Plain arithmetic, written out independently of PointProjector: P2 * [R0 * (Tr * x); 1].
void projectByHand(const double x[3], double* u, double* v, double* w) {
  double cam[3], rect[4], pixel[3];
  for (int r = 0; r < 3; ++r) {
    cam[r] = kTr[4 * r + 0] * x[0] + kTr[4 * r + 1] * x[1] + kTr[4 * r + 2] * x[2] + kTr[4 * r + 3];
  }
  for (int r = 0; r < 3; ++r) {
    rect[r] = kR0[3 * r + 0] * cam[0] + kR0[3 * r + 1] * cam[1] + kR0[3 * r + 2] * cam[2];
  }
  rect[3] = 1.0;
  for (int r = 0; r < 3; ++r) {
    pixel[r] = 0;
    for (int c = 0; c < 4; ++c) pixel[r] += kP2[4 * r + c] * rect[c];
  }
  *w = pixel[2];
  *u = pixel[0] / pixel[2];
  *v = pixel[1] / pixel[2];
}

PointProjector objectProjector(int width, int height) {
  const std::string calib_path = test::sharedPath("data/kitti_object/training/calib/000000.txt");
  const kitti::CameraProjection camera =
      kitti::readObjectCalibration(calib_path).projection(2, width, height);
  return PointProjector(camera.P_rect, camera.R_rect, camera.T_cam0_velo, width, height);
}

TEST(Projection, HandPickedPointsOnTheRealCalibration) {
  ISM_REQUIRE_SHARED("data/kitti_object/training/calib/000000.txt");
  const PointProjector projector = objectProjector(1224, 370);
  Eigen::Matrix3Xf points(3, 5);
  points.col(0) << 10.f, 0.f, 0.f;       // straight ahead
  points.col(1) << 8.41f, -1.9f, -0.8f;  // near the pedestrian of frame 000000
  points.col(2) << 25.f, 6.f, 1.5f;      // left, up
  points.col(3) << -10.f, 0.f, 0.f;      // behind the car
  points.col(4) << 5.f, -30.f, 0.f;      // far right: in front but outside the image
  ProjectedPoints projected;
  projector.project(points, &projected);
  ASSERT_EQ(projected.size(), 5u);
  for (int i = 0; i < 3; ++i) {
    const double x[3] = {points(0, i), points(1, i), points(2, i)};
    double u, v, w;
    projectByHand(x, &u, &v, &w);
    EXPECT_NEAR(projected.u[i], u, 0.05) << "point " << i;
    EXPECT_NEAR(projected.v[i], v, 0.05) << "point " << i;
    EXPECT_NEAR(projected.depth[i], w, 1e-3) << "point " << i;
    EXPECT_TRUE(projected.valid[i]) << "point " << i << " u=" << u << " v=" << v;
  }
  // Straight ahead lands near the principal point (the camera sits ~0.3 m behind the lidar).
  EXPECT_NEAR(projected.u[0], 604.08 + 707.05 * 0.06 / 10.3, 3.0);
  EXPECT_FALSE(projected.valid[3]);
  EXPECT_LT(projected.depth[3], 0.f);
  EXPECT_FALSE(projected.valid[4]);
  EXPECT_GT(projected.depth[4], 0.f);

  // Labels from an image: valid points read their pixel, the others get "unknown".
  std::vector<std::uint8_t> image(1224 * 370);
  for (int row = 0; row < 370; ++row) {
    for (int col = 0; col < 1224; ++col)
      image[row * 1224 + col] = static_cast<std::uint8_t>(col % 200);
  }
  std::vector<std::uint32_t> labels;
  labelPointsFromImage(projected, image.data(), 1224, 370, 1224, 999, &labels);
  ASSERT_EQ(labels.size(), 5u);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(labels[i], static_cast<std::uint32_t>(std::lround(projected.u[i])) % 200);
  }
  EXPECT_EQ(labels[3], 999u);
  EXPECT_EQ(labels[4], 999u);
}

TEST(Projection, ImageBoundsAndNonFiniteInput) {
  Eigen::Matrix<double, 3, 4> P = Eigen::Matrix<double, 3, 4>::Zero();
  P.leftCols<3>() << 100, 0, 50, 0, 100, 25, 0, 0, 1;  // 100x50 image, camera = lidar frame
  const PointProjector projector(P, Eigen::Matrix3d::Identity(), Eigen::Isometry3d::Identity(), 100,
                                 50);
  Eigen::Matrix3Xf points(3, 6);
  points.col(0) << 0.f, 0.f, 2.f;            // principal point
  points.col(1) << -0.5f, -0.25f, 1.f;       // exactly the top-left corner (0, 0)
  points.col(2) << 0.5f, 0.f, 1.f;           // u = 100: just outside
  points.col(3) << 0.f, 0.f, 0.05f;          // closer than the minimum depth
  points.col(4) << std::nanf(""), 0.f, 1.f;  // NaN never valid
  points.col(5) << 0.49f, 0.24f, 1.f;        // u = 99, v = 49: last pixel
  ProjectedPoints projected;
  projector.project(points, &projected);
  EXPECT_NEAR(projected.u[0], 50.f, 1e-4);
  EXPECT_NEAR(projected.v[0], 25.f, 1e-4);
  const std::vector<std::uint8_t> expected_valid = {1, 1, 0, 0, 0, 1};
  EXPECT_EQ(projected.valid, expected_valid);
  EXPECT_EQ(projected.validCount(), 3u);

  // Columns of an interleaved x y z intensity buffer project without a copy.
  std::vector<float> xyzi = {0.f, 0.f, 2.f, 0.7f, 0.5f, 0.f, 1.f, 0.1f};
  Eigen::Map<const Eigen::Matrix<float, 4, Eigen::Dynamic>> buffer(xyzi.data(), 4, 2);
  projector.project(buffer.topRows<3>(), &projected);
  EXPECT_EQ(projected.valid, (std::vector<std::uint8_t>{1, 0}));
}

// The 3D pedestrian box of object frame 000000 (label_2) must contain lidar points whose
// projections fall inside the box's 2D bounding box: the whole chain lines up with the image.
TEST(Projection, RealScanLinesUpWithTheLabeledPedestrian) {
  ISM_REQUIRE_SHARED("data/kitti_object/training/velodyne/000000.bin");
  ISM_REQUIRE_SHARED("data/kitti_object/training/label_2/000000.txt");
  const std::string base = test::sharedPath("data/kitti_object/training/");
  const kitti::VelodyneScan scan = kitti::readVelodyneBin(base + "velodyne/000000.bin");
  const kitti::ObjectCalibration calib = kitti::readObjectCalibration(base + "calib/000000.txt");
  const kitti::CameraProjection camera = calib.projection(2, 1224, 370);
  const PointProjector projector(camera.P_rect, camera.R_rect, camera.T_cam0_velo, 1224, 370);

  std::ifstream label_file(base + "label_2/000000.txt");
  std::string type;
  double truncated, occluded, alpha, x1, y1, x2, y2, h, w, l, x, y, z, ry;
  label_file >> type >> truncated >> occluded >> alpha >> x1 >> y1 >> x2 >> y2 >> h >> w >> l >>
      x >> y >> z >> ry;
  ASSERT_EQ(type, "Pedestrian");

  Eigen::Map<const Eigen::Matrix<float, 4, Eigen::Dynamic>> buffer(
      scan.xyzi.data(), 4, static_cast<Eigen::Index>(scan.size()));
  ProjectedPoints projected;
  projector.project(buffer.topRows<3>(), &projected);
  EXPECT_GT(projected.validCount(), scan.size() / 20);
  EXPECT_LT(projected.validCount(), scan.size() / 2);  // the camera sees the front only

  int in_box = 0, in_bbox = 0;
  for (std::size_t i = 0; i < scan.size(); ++i) {
    const Eigen::Vector3d p(scan.point(i)[0], scan.point(i)[1], scan.point(i)[2]);
    const Eigen::Vector3d rect = camera.R_rect * (camera.T_cam0_velo * p);
    // Box frame: origin at the bottom center, rotated by ry about the camera y axis. Shrunk by
    // 10 % so that ground points under the feet do not count.
    const Eigen::Vector3d d = rect - Eigen::Vector3d(x, y, z);
    const double along = std::cos(ry) * d.x() - std::sin(ry) * d.z();
    const double across = std::sin(ry) * d.x() + std::cos(ry) * d.z();
    if (std::abs(along) > 0.45 * l || std::abs(across) > 0.45 * w || d.y() > -0.1 * h ||
        d.y() < -0.9 * h) {
      continue;
    }
    ++in_box;
    ASSERT_TRUE(projected.valid[i]);
    if (projected.u[i] >= x1 - 3 && projected.u[i] <= x2 + 3 && projected.v[i] >= y1 - 3 &&
        projected.v[i] <= y2 + 3) {
      ++in_bbox;
    }
  }
  std::cout << in_box << " lidar points in the pedestrian box, " << in_bbox
            << " of them project into its 2D box\n";
  EXPECT_GE(in_box, 20);
  EXPECT_EQ(in_bbox, in_box);
}

// project_cloud's CSV contract on the real frame: header, one row per point inside the image with
// depth > 0, index = row in the .bin, values equal to the library's projection.
TEST(Projection, ProjectCloudToolWritesTheCsvContract) {
  ISM_REQUIRE_SHARED("data/kitti_object/training/velodyne/000000.bin");
  const std::string base = test::sharedPath("data/kitti_object/training/");
  const std::string dir = test::makeTempDir("project_cloud");
  const std::string command =
      std::string(PROJECT_CLOUD_PATH) + " --calib " + base + "calib/000000.txt --velodyne " + base +
      "velodyne/000000.bin --image " + base + "image_2/000000.png --output " + dir +
      "/points.csv --overlay " + dir + "/overlay.png 2>/dev/null";
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
  EXPECT_TRUE(std::filesystem::exists(dir + "/overlay.png"));

  const kitti::VelodyneScan scan = kitti::readVelodyneBin(base + "velodyne/000000.bin");
  const PointProjector projector = objectProjector(1224, 370);  // the PNG's size
  Eigen::Map<const Eigen::Matrix<float, 4, Eigen::Dynamic>> buffer(
      scan.xyzi.data(), 4, static_cast<Eigen::Index>(scan.size()));
  ProjectedPoints projected;
  projector.project(buffer.topRows<3>(), &projected);

  std::ifstream csv(dir + "/points.csv");
  std::string line;
  std::getline(csv, line);
  EXPECT_EQ(line, "index,u,v,depth");
  std::size_t rows = 0;
  while (std::getline(csv, line)) {
    std::istringstream fields(line);
    std::size_t index;
    char comma;
    double u, v, depth;
    ASSERT_TRUE(fields >> index >> comma >> u >> comma >> v >> comma >> depth) << line;
    ASSERT_LT(index, scan.size());
    ASSERT_TRUE(projected.valid[index]) << line;
    EXPECT_NEAR(u, projected.u[index], 2e-3);
    EXPECT_NEAR(v, projected.v[index], 2e-3);
    EXPECT_GT(depth, 0.0);
    EXPECT_TRUE(u >= 0 && u < 1224 && v >= 0 && v < 370) << line;
    ++rows;
  }
  EXPECT_EQ(rows, projected.validCount());
  std::filesystem::remove_all(dir);
}

// A pinhole camera at the origin of the point frame (x right, y down, z forward), 1220 x 370
// pixels with a KITTI-like focal length: points are given in camera coordinates.
PointProjector pinholeProjector() {
  Eigen::Matrix<double, 3, 4> P;
  P << 700, 0, 610, 0, 0, 700, 185, 0, 0, 0, 1, 0;
  return PointProjector(P, Eigen::Matrix3d::Identity(), Eigen::Isometry3d::Identity(), 1220, 370);
}

// Where a ray from `origin` along `direction` first hits the scene: the road plane 1.65 m below
// the camera, a near wall 2 m wide at z = 8 m and a far wall 20 m wide at z = 20 m (both from
// the road up to 1 m / 5 m above the camera). false when the ray hits nothing.
struct Scene {
  static bool inNearWall(const Eigen::Vector3d& p) {
    return std::abs(p.x()) <= 1.0 && p.y() >= -1.0 && p.y() <= 1.65;
  }
  static bool inFarWall(const Eigen::Vector3d& p) {
    return std::abs(p.x()) <= 10.0 && p.y() >= -5.0 && p.y() <= 1.65;
  }
  static bool hit(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                  Eigen::Vector3d* point, int* surface) {
    double best = std::numeric_limits<double>::infinity();
    const auto consider = [&](double t, int id, bool (*inside)(const Eigen::Vector3d&)) {
      if (!(t > 1e-6) || t >= best) return;
      const Eigen::Vector3d p = origin + t * direction;
      if (inside && !inside(p)) return;
      best = t;
      *point = p;
      *surface = id;
    };
    if (direction.y() > 1e-9) consider((1.65 - origin.y()) / direction.y(), 0, nullptr);
    if (direction.z() > 1e-9) {
      consider((8.0 - origin.z()) / direction.z(), 1, &inNearWall);
      consider((20.0 - origin.z()) / direction.z(), 2, &inFarWall);
    }
    return std::isfinite(best);
  }
  // The camera (at the origin) sees p when nothing lies between them.
  static bool visibleFromCamera(const Eigen::Vector3d& p) {
    Eigen::Vector3d first;
    int surface = -1;
    if (!hit(Eigen::Vector3d::Zero(), p.normalized(), &first, &surface)) return false;
    return (first - p).norm() < 1e-3;
  }
};

// A 64-beam lidar at `lidar_origin` (camera coordinates) scanning the scene.
Eigen::Matrix3Xf scanScene(const Eigen::Vector3d& lidar_origin) {
  std::vector<Eigen::Vector3f> points;
  const double kDeg = M_PI / 180.0;
  for (int beam = 0; beam < 64; ++beam) {
    const double elevation = (2.0 - beam * 26.8 / 63.0) * kDeg;
    for (double azimuth = -40.0; azimuth <= 40.0; azimuth += 0.1) {
      const Eigen::Vector3d direction(std::cos(elevation) * std::sin(azimuth * kDeg),
                                      -std::sin(elevation),
                                      std::cos(elevation) * std::cos(azimuth * kDeg));
      Eigen::Vector3d p;
      int surface = -1;
      if (Scene::hit(lidar_origin, direction, &p, &surface)) points.push_back(p.cast<float>());
    }
  }
  Eigen::Matrix3Xf matrix(3, points.size());
  for (std::size_t i = 0; i < points.size(); ++i) matrix.col(i) = points[i];
  return matrix;
}

TEST(Occlusion, PointsBehindANearWallAreRejectedVisibleOnesKept) {
  // The lidar far to the right of the camera (a large parallax, so many of its points are
  // hidden from the camera), and a little above and behind it as on KITTI's car.
  const Eigen::Matrix3Xf points = scanScene(Eigen::Vector3d(1.5, -0.08, -0.27));
  const PointProjector projector = pinholeProjector();
  ProjectedPoints projected;
  projector.project(points, &projected);
  std::vector<std::uint32_t> labels;
  std::vector<std::uint8_t> image(1220 * 370, 7);
  labelPointsFromImage(projected, image.data(), 1220, 370, 1220, 0, &labels);

  std::size_t rejected = 0;
  rejectOccludedPoints(projected, 1220, 370, OcclusionOptions{}, 0, &labels, &rejected);
  std::size_t hidden = 0, hidden_rejected = 0, visible = 0, visible_rejected = 0;
  std::size_t road = 0, road_rejected = 0;
  for (std::size_t i = 0; i < projected.size(); ++i) {
    if (!projected.valid[i]) continue;
    const Eigen::Vector3d p = points.col(i).cast<double>();
    const bool is_rejected = labels[i] == 0;
    if (!Scene::visibleFromCamera(p)) {
      ++hidden;
      hidden_rejected += is_rejected;
    } else {
      ++visible;
      visible_rejected += is_rejected;
      if (std::abs(p.y() - 1.65) < 1e-6) {
        ++road;
        road_rejected += is_rejected;
      }
    }
  }
  std::cout << "hidden " << hidden << " (rejected " << hidden_rejected << "), visible " << visible
            << " (rejected " << visible_rejected << "), road " << road << " (rejected "
            << road_rejected << ")\n";
  ASSERT_GT(hidden, 500u);
  ASSERT_GT(road, 5000u);
  EXPECT_EQ(rejected, hidden_rejected + visible_rejected);
  EXPECT_GE(static_cast<double>(hidden_rejected) / hidden, 0.9);
  EXPECT_LE(static_cast<double>(visible_rejected) / visible, 0.02);
  // Road is lost only beside the near wall (the window's reach past the wall's edge).
  EXPECT_LE(static_cast<double>(road_rejected) / road, 0.02);
}

TEST(Occlusion, SlantedRoadAloneLosesNoPoints) {
  // Only the road: a lidar at the camera (no parallax) sees nothing the camera does not.
  std::vector<Eigen::Vector3f> road;
  for (double z = 4.0; z < 80.0; z *= 1.01)
    for (double x = -15.0; x <= 15.0; x += 0.05) road.emplace_back(x, 1.65f, z);
  Eigen::Matrix3Xf points(3, road.size());
  for (std::size_t i = 0; i < road.size(); ++i) points.col(i) = road[i];
  ProjectedPoints projected;
  pinholeProjector().project(points, &projected);
  std::vector<std::uint32_t> labels(projected.size(), 7);
  std::size_t rejected = 0;
  rejectOccludedPoints(projected, 1220, 370, OcclusionOptions{}, 0, &labels, &rejected);
  EXPECT_GT(projected.validCount(), 10000u);
  EXPECT_EQ(rejected, 0u);
}

TEST(Occlusion, RejectsMismatchedSizesAndBadOptions) {
  ProjectedPoints projected;
  Eigen::Matrix3Xf points(3, 2);
  points << 0, 1, 0, 0, 10, 10;
  pinholeProjector().project(points, &projected);
  std::vector<std::uint32_t> labels(1, 7);
  EXPECT_THROW(rejectOccludedPoints(projected, 1220, 370, OcclusionOptions{}, 0, &labels),
               std::invalid_argument);
  labels.assign(2, 7);
  OcclusionOptions bad;
  bad.cell_width_px = 0;
  EXPECT_THROW(rejectOccludedPoints(projected, 1220, 370, bad, 0, &labels), std::invalid_argument);
  // Two points at the same depth: nothing hidden.
  std::size_t rejected = 5;
  rejectOccludedPoints(projected, 1220, 370, OcclusionOptions{}, 0, &labels, &rejected);
  EXPECT_EQ(rejected, 0u);
  EXPECT_EQ(labels, (std::vector<std::uint32_t>{7, 7}));
}

}  // namespace
}  // namespace perception
}  // namespace inekf_semantic_mapping
