// Offline mapping on real drive 0013 of ../shared: the road ahead lies below the IMU at its
// mounting height.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "inekf_semantic_mapping/kitti/mercator.h"
#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/kitti/poses.h"
#include "inekf_semantic_mapping/mapping/map_io.h"
#include "inekf_semantic_mapping/mapping/offline_mapping.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace mapping {
namespace {

// The raw-drive path on the real drive in ../shared: the scans go in at T_map_imu * inv(T_velo_imu)
// (the IMU sits about 0.93 m above the road, the lidar 0.8 m above the IMU), so the road ahead of
// the car lies about 0.93 m below the OXTS position.
TEST(OfflineRawDriveTest, RoadAheadLiesBelowTheImuAtItsMountingHeight) {
  ISM_REQUIRE_SHARED("data/kitti_raw/2011_09_26/2011_09_26_drive_0013_sync/velodyne_points");
  SemanticMappingConfig config;
  config.insert_points_outside_image = true;
  SemanticMappingSession session(config);
  OfflineRawDrive drive;
  drive.drive_dir = test::sharedPath("data/kitti_raw/2011_09_26/2011_09_26_drive_0013_sync");
  drive.max_scans = 3;
  mapRawDrive(drive, &session, nullptr, nullptr);
  EXPECT_EQ(session.statistics().scans_inserted, 3u);
  // The first OXTS pose is the map origin with the devkit's roll/pitch/yaw.
  const Eigen::Isometry3d T_map_imu = [] {
    const auto oxts = kitti::readOxtsFolder(
        test::sharedPath("data/kitti_raw/2011_09_26/2011_09_26_drive_0013_sync/oxts"));
    return kitti::MercatorProjection::atFirstFix(oxts.front().record)
        .poseInMap(oxts.front().record);
  }();
  int road_columns = 0;
  for (double ahead = 5.0; ahead <= 9.0; ahead += 1.0) {
    const Eigen::Vector3d column = T_map_imu * Eigen::Vector3d(ahead, 0.0, 0.0);
    double highest = -1e9;
    for (double dz = -2.5; dz <= 0.5; dz += 0.1) {
      const SemanticOcTreeNode* node =
          session.tree().search(column.x(), column.y(), column.z() + dz);
      if (node && session.tree().isNodeOccupied(node)) highest = dz;
    }
    if (highest > -1.3 && highest < -0.55) ++road_columns;
  }
  EXPECT_GE(road_columns, 4) << "the road ahead is not 0.6..1.3 m below the IMU";
}

}  // namespace
}  // namespace mapping
}  // namespace inekf_semantic_mapping
