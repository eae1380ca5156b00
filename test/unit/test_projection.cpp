// Lidar-to-camera projection: image bounds, non-finite input, occlusion. On the real KITTI
// calibration: test/data/test_projection_data.cpp; project_cloud: test/cli/.
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

TEST(Projection, ImageBoundsAndNonFiniteInput) {
  Eigen::Matrix<double, 3, 4> P = Eigen::Matrix<double, 3, 4>::Zero();
  P.leftCols<3>() << 100, 0, 50, 0, 100, 25, 0, 0, 1;  // 100x50 image, camera = lidar frame
  const PointProjector projector(P, Eigen::Matrix3d::Identity(), Eigen::Isometry3d::Identity(), 100,
                                 50);
  // Pixel centres at integers: pixel k covers [k - 0.5, k + 0.5), so the image spans
  // [-0.5, 99.5) x [-0.5, 49.5). (0 <= u < 100 turned points away from pixel 0's left half and
  // clamped points beyond the last pixel onto it.)
  Eigen::Matrix3Xf points(3, 9);
  points.col(0) << 0.f, 0.f, 2.f;            // principal point
  points.col(1) << -0.5f, -0.25f, 1.f;       // (0, 0): the centre of the first pixel
  points.col(2) << 0.5f, 0.f, 1.f;           // u = 100: outside
  points.col(3) << 0.f, 0.f, 0.05f;          // closer than the minimum depth
  points.col(4) << std::nanf(""), 0.f, 1.f;  // NaN never valid
  points.col(5) << 0.49f, 0.24f, 1.f;        // u = 99, v = 49: last pixel
  points.col(6) << -0.503f, -0.253f, 1.f;    // (-0.3, -0.3): inside pixel (0, 0)
  points.col(7) << 0.497f, 0.f, 1.f;         // u = 99.7: beyond the last pixel
  points.col(8) << 0.f, 0.247f, 1.f;         // v = 49.7: below the last row
  ProjectedPoints projected;
  projector.project(points, &projected);
  EXPECT_NEAR(projected.u[0], 50.f, 1e-4);
  EXPECT_NEAR(projected.v[0], 25.f, 1e-4);
  const std::vector<std::uint8_t> expected_valid = {1, 1, 0, 0, 0, 1, 1, 0, 0};
  EXPECT_EQ(projected.valid, expected_valid);
  EXPECT_EQ(projected.validCount(), 4u);
  // The same rule by itself (evaluate_map's camera view uses it).
  EXPECT_TRUE(pixelInImage(-0.5f, -0.5f, 100, 50));
  EXPECT_TRUE(pixelInImage(99.49f, 49.49f, 100, 50));
  EXPECT_FALSE(pixelInImage(99.5f, 0.f, 100, 50));
  EXPECT_FALSE(pixelInImage(0.f, 49.5f, 100, 50));
  EXPECT_FALSE(pixelInImage(-0.51f, 0.f, 100, 50));
  EXPECT_FALSE(pixelInImage(0.f, std::nanf(""), 100, 50));
  // The label looked up is the pixel the point falls in.
  std::vector<std::uint8_t> image(100 * 50, 0);
  image[0] = 7;
  image[49 * 100 + 99] = 9;
  std::vector<std::uint32_t> labels;
  labelPointsFromImage(projected, image.data(), 100, 50, 100, 255, &labels);
  EXPECT_EQ(labels[1], 7u);
  EXPECT_EQ(labels[5], 9u);
  EXPECT_EQ(labels[6], 7u);
  EXPECT_EQ(labels[7], 255u);

  // Columns of an interleaved x y z intensity buffer project without a copy.
  std::vector<float> xyzi = {0.f, 0.f, 2.f, 0.7f, 0.5f, 0.f, 1.f, 0.1f};
  Eigen::Map<const Eigen::Matrix<float, 4, Eigen::Dynamic>> buffer(xyzi.data(), 4, 2);
  projector.project(buffer.topRows<3>(), &projected);
  EXPECT_EQ(projected.valid, (std::vector<std::uint8_t>{1, 0}));
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

// Points -> label image, the inverse of labelPointsFromImage: the nearest point that carries a
// label wins its pixel, points to skip and invalid ones write nothing, and reading the image
// back at the points gives each winner its own label.
TEST(RasterizePointLabels, NearestLabelledPointWinsAndReadsBack) {
  ProjectedPoints projected;
  projected.u = Eigen::VectorXf(5);
  projected.v = Eigen::VectorXf(5);
  projected.depth = Eigen::VectorXf(5);
  projected.u << 2.4f, 2.6f, 2.2f, 0.f, 4.49f;
  projected.v << 1.f, 1.f, 1.f, 0.f, 2.51f;
  projected.depth << 5.f, 4.f, 3.f, 1.f, 2.f;
  projected.valid = {1, 1, 1, 0, 1};
  // Points 0 and 2 land on pixel (2, 1), point 1 on (3, 1); point 2 is nearer than 0 but skipped.
  const std::vector<std::uint32_t> labels = {7, 8, 99, 9, 300};
  std::vector<std::uint32_t> image;
  EXPECT_EQ(rasterizePointLabels(projected, labels, 5, 3, 99, 0, &image), 3u);
  ASSERT_EQ(image.size(), 15u);
  EXPECT_EQ(image[1 * 5 + 2], 7u);
  EXPECT_EQ(image[1 * 5 + 3], 8u);
  EXPECT_EQ(image[2 * 5 + 4], 300u);  // (4.49, 2.51): rounded, clamped to the last column
  EXPECT_EQ(image[0], 0u);            // point 3 is not valid

  // The nearer of two labelled points wins whatever their order.
  std::vector<std::uint32_t> both = labels;
  both[2] = 11;
  rasterizePointLabels(projected, both, 5, 3, 99, 0, &image);
  EXPECT_EQ(image[1 * 5 + 2], 11u);

  std::vector<std::uint8_t> bytes(image.begin(), image.end());
  std::vector<std::uint32_t> back;
  labelPointsFromImage(projected, bytes.data(), 5, 3, 5, 255, &back);
  EXPECT_EQ(back[2], 11u);
  EXPECT_EQ(back[1], 8u);

  EXPECT_THROW(rasterizePointLabels(projected, {1, 2}, 5, 3, 99, 0, &image), std::invalid_argument);
  EXPECT_THROW(rasterizePointLabels(projected, labels, 0, 3, 99, 0, &image), std::invalid_argument);
}

// The count is of pixels labelled: a nearer point overwriting a pixel adds none.
TEST(RasterizePointLabels, ANearerPointOverwritingAPixelCountsItOnce) {
  ProjectedPoints projected;
  projected.u = Eigen::VectorXf::Constant(3, 1.f);
  projected.v = Eigen::VectorXf::Constant(3, 1.f);
  projected.depth = Eigen::VectorXf(3);
  projected.depth << 5.f, 4.f, 3.f;  // each nearer than the one before
  projected.valid = {1, 1, 1};
  std::vector<std::uint32_t> image;
  EXPECT_EQ(rasterizePointLabels(projected, {7, 8, 11}, 3, 3, 99, 0, &image), 1u);
  EXPECT_EQ(image[1 * 3 + 1], 11u);
}

TEST(RejectOccludedPoints, OcclusionWindowReachesRadiusCellsToBothSides) {
  const OcclusionOptions options;
  for (int side : {-1, 1}) {
    ProjectedPoints p;
    p.u.resize(2);
    p.v.resize(2);
    p.depth.resize(2);
    p.valid = {1, 1};
    p.u << 200.f, 200.f + side * options.window_radius_x * options.cell_width_px;
    p.v << 100.f, 100.f;
    p.depth << 5.f, 20.f;
    std::vector<std::uint32_t> labels{7, 7};
    rejectOccludedPoints(p, 1220, 370, options, 0, &labels);
    EXPECT_EQ(labels[0], 7u) << side;
    EXPECT_EQ(labels[1], 0u) << side;
  }
}

// A point is hidden only beyond local minimum * (1 + relative_margin) + absolute_margin_m: near
// the camera the absolute margin dominates (2 m: 2.5 m), far away the relative one (40 m: 44.3 m).
TEST(RejectOccludedPoints, APointWithinTheMarginsBehindTheNearestIsKept) {
  const OcclusionOptions options;  // 10 % and 0.3 m
  for (float nearest : {2.f, 40.f}) {
    const float limit = nearest * (1.f + options.relative_margin) + options.absolute_margin_m;
    ProjectedPoints p;
    p.u = Eigen::VectorXf::Constant(3, 200.f);
    p.v = Eigen::VectorXf::Constant(3, 100.f);
    p.depth.resize(3);
    p.depth << nearest, limit - 0.05f, limit + 0.05f;
    p.valid = {1, 1, 1};
    std::vector<std::uint32_t> labels{7, 7, 7};
    std::size_t rejected = 0;
    rejectOccludedPoints(p, 1220, 370, options, 0, &labels, &rejected);
    EXPECT_EQ(labels, (std::vector<std::uint32_t>{7, 7, 0})) << "nearest " << nearest;
    EXPECT_EQ(rejected, 1u) << "nearest " << nearest;
  }
}
}  // namespace
}  // namespace perception
}  // namespace inekf_semantic_mapping
