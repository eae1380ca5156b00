// Lidar-to-camera projection on the real KITTI object calibration and scan of ../shared:
// hand-computed pixels, the scan lining up with the labelled pedestrian.
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

}  // namespace
}  // namespace perception
}  // namespace inekf_semantic_mapping
