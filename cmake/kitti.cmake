# Component: kitti — KITTI raw I/O core (Eigen only), ROS conversions, kitti_player, kitti2bag.
ism_add_core_library(${PROJECT_NAME}_kitti
  SOURCES
    src/kitti/calibration.cpp
    src/kitti/gps_degradation.cpp
    src/kitti/mercator.cpp
    src/kitti/oxts.cpp
    src/kitti/raw_drive.cpp
    src/kitti/timestamps.cpp
    src/kitti/velodyne.cpp)

ism_add_gtest(test_kitti_io SOURCES test/unit/test_kitti_io.cpp LINK ${PROJECT_NAME}_kitti)
ism_add_gtest(test_kitti_gps_degradation
  SOURCES test/unit/test_kitti_gps_degradation.cpp LINK ${PROJECT_NAME}_kitti)
