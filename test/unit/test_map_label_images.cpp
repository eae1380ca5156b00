// mapLabelImage: the fused map's classes written where the camera sees each lidar point, nothing
// where the map knows no class (free, unknown, classless or unsure voxels).
#include <gtest/gtest.h>

#include <stdexcept>
#include <vector>

#include "camera_test_scene.h"
#include "inekf_semantic_mapping/mapping/map_label_images.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"

namespace inekf_semantic_mapping {
namespace mapping {
namespace {

using test_scene::testCamera;
using test_scene::testLabels;

// A wall 10 m ahead (x in [-2, 2], y in [-1, 1]).
Eigen::Matrix3Xf wall(float z = 10.05f) {
  std::vector<Eigen::Vector3f> points;
  for (float x = -1.95f; x < 2.f; x += 0.1f) {
    for (float y = -0.95f; y < 1.f; y += 0.1f) points.emplace_back(x, y, z);
  }
  Eigen::Matrix3Xf matrix(3, static_cast<Eigen::Index>(points.size()));
  for (std::size_t i = 0; i < points.size(); ++i)
    matrix.col(static_cast<Eigen::Index>(i)) = points[i];
  return matrix;
}

SemanticMappingSession mappedWall() {
  SemanticMappingConfig config;
  config.resolution_m = 0.1;
  SemanticMappingSession session(config);
  const std::vector<std::uint8_t> labels = testLabels();
  const LabelImageView view{labels.data(), 100, 100, 100};
  const CameraModel camera = testCamera();
  for (int i = 0; i < 3; ++i)
    session.insertScan(wall(), Eigen::Isometry3d::Identity(), &view, &camera);
  return session;
}

TEST(MapLabelImageTest, EachSeenPointTakesItsVoxelsClassAtItsPixel) {
  SemanticMappingSession session = mappedWall();
  MapLabelImageStats stats;
  const OwnedLabelImage image = mapLabelImage(session.tree(), wall(), Eigen::Isometry3d::Identity(),
                                              testCamera(), MapLabelImageOptions(), &stats);
  ASSERT_EQ(image.width, 100);
  ASSERT_EQ(image.height, 100);
  ASSERT_EQ(image.pixels.size(), 100u * 100u);
  const std::vector<std::uint8_t> truth = testLabels();
  std::size_t labelled = 0;
  for (std::size_t i = 0; i < image.pixels.size(); ++i) {
    if (image.pixels[i] == 0) continue;
    ++labelled;
    // The class the camera gave that pixel when the map was made (the same projection).
    EXPECT_EQ(image.pixels[i], truth[i]) << "pixel (" << i % 100 << ", " << i / 100 << ")";
  }
  EXPECT_EQ(labelled, stats.labelled);
  EXPECT_EQ(stats.points_in_view, static_cast<std::size_t>(wall().cols()));
  // The wall covers about 20 x 10 pixels (two points per pixel along a row); its rows >= 48
  // carried classes.
  EXPECT_GT(labelled, 120u);
  EXPECT_LT(labelled, 220u);
  std::size_t road = 0, building = 0;
  for (std::uint8_t p : image.pixels) {
    road += p == 7;
    building += p == 11;
  }
  EXPECT_GT(road, 60u);
  EXPECT_GT(building, 60u);
}

TEST(MapLabelImageTest, FreeUnknownAndUnsureVoxelsLabelNothing) {
  SemanticMappingSession session = mappedWall();
  // 5 m ahead: the rays to the wall crossed it (free); 30 m: never seen (unknown).
  for (float z : {5.05f, 30.05f}) {
    const OwnedLabelImage image =
        mapLabelImage(session.tree(), wall(z), Eigen::Isometry3d::Identity(), testCamera(),
                      MapLabelImageOptions());
    for (std::uint8_t p : image.pixels) ASSERT_EQ(p, 0) << "points at z = " << z;
  }
  MapLabelImageOptions unsure;
  unsure.min_class_probability = 1.01;  // no posterior reaches it
  const OwnedLabelImage none =
      mapLabelImage(session.tree(), wall(), Eigen::Isometry3d::Identity(), testCamera(), unsure);
  for (std::uint8_t p : none.pixels) ASSERT_EQ(p, 0);
  unsure.min_class_probability = 0.5;  // three agreeing views: well above
  const OwnedLabelImage sure =
      mapLabelImage(session.tree(), wall(), Eigen::Isometry3d::Identity(), testCamera(), unsure);
  std::size_t labelled = 0;
  for (std::uint8_t p : sure.pixels) labelled += p != 0;
  EXPECT_GT(labelled, 120u);
}

// A voxel that had classes and was then seen through (a car that drove away) labels nothing.
TEST(MapLabelImageTest, AClassedVoxelSeenFreeAgainLabelsNothing) {
  SemanticMappingSession session = mappedWall();
  // A wall twice as far and twice as wide: its rays cross every voxel of the first one.
  Eigen::Matrix3Xf far = 2.0f * wall();
  far.row(2).setConstant(20.05f);
  for (int i = 0; i < 12; ++i) session.insertScan(far, Eigen::Isometry3d::Identity());
  const OwnedLabelImage image = mapLabelImage(session.tree(), wall(), Eigen::Isometry3d::Identity(),
                                              testCamera(), MapLabelImageOptions());
  for (std::uint8_t p : image.pixels) ASSERT_EQ(p, 0);
}

TEST(MapLabelImageTest, TheSensorPoseMovesThePointsIntoTheMap) {
  SemanticMappingSession session = mappedWall();
  // The same wall seen from 4 m closer: points 6.05 m ahead of a sensor at z = 4.
  Eigen::Isometry3d T_map_sensor = Eigen::Isometry3d::Identity();
  T_map_sensor.translation() << 0.0, 0.0, 4.0;
  const OwnedLabelImage image = mapLabelImage(session.tree(), wall(6.05f), T_map_sensor,
                                              testCamera(), MapLabelImageOptions());
  std::size_t labelled = 0;
  for (std::uint8_t p : image.pixels) labelled += p != 0;
  EXPECT_GT(labelled, 120u);
}

// A class whose label id does not fit a byte (SemanticKITTI's moving-truck, 258) labels nothing,
// rather than another class (258 written as 2).
TEST(MapLabelImageTest, LabelIdsAboveAByteLabelNothing) {
  SemanticMappingConfig config;
  config.resolution_m = 0.1;
  SemanticMappingSession session(config);
  const Eigen::Matrix3Xf points = wall();
  const std::vector<std::uint32_t> moving_truck(static_cast<std::size_t>(points.cols()), 258);
  for (int i = 0; i < 3; ++i) {
    session.insertScanWithPointLabels(points, Eigen::Isometry3d::Identity(), moving_truck, 0);
  }
  MapLabelImageStats stats;
  const OwnedLabelImage image = mapLabelImage(session.tree(), points, Eigen::Isometry3d::Identity(),
                                              testCamera(), MapLabelImageOptions(), &stats);
  EXPECT_EQ(stats.points_in_view, static_cast<std::size_t>(points.cols()));
  EXPECT_EQ(stats.labelled, 0u);
  for (std::uint8_t p : image.pixels) ASSERT_EQ(p, 0);
}

TEST(MapLabelImageTest, ABadImageSizeOrNoneLabelIsAClearError) {
  SemanticMappingSession session = mappedWall();
  CameraModel camera = testCamera();
  camera.width = 0;
  EXPECT_THROW(mapLabelImage(session.tree(), wall(), Eigen::Isometry3d::Identity(), camera,
                             MapLabelImageOptions()),
               std::invalid_argument);
  MapLabelImageOptions options;
  options.none_label = 300;
  EXPECT_THROW(
      mapLabelImage(session.tree(), wall(), Eigen::Isometry3d::Identity(), testCamera(), options),
      std::invalid_argument);
}

}  // namespace
}  // namespace mapping
}  // namespace inekf_semantic_mapping
