# Component: mapping — lidar-to-camera projection (Eigen only), SemanticOcTree (octomap),
# semantic_octomap_node, project_cloud, semantic_map_offline.
ism_add_core_library(${PROJECT_NAME}_projection
  SOURCES src/perception/projection.cpp)

ism_add_core_library(${PROJECT_NAME}_mapping
  SOURCES
    src/mapping/semantic_classes.cpp
    src/mapping/semantic_octree.cpp
    src/mapping/map_io.cpp
  LINK ${OCTOMAP_LIBRARIES}
  SYSTEM_INCLUDES ${OCTOMAP_INCLUDE_DIRS})

ism_add_gtest(test_projection
  SOURCES test/unit/test_projection.cpp
  LINK ${PROJECT_NAME}_projection ${PROJECT_NAME}_kitti)
ism_add_gtest(test_semantic_octree
  SOURCES test/unit/test_semantic_octree.cpp
  LINK ${PROJECT_NAME}_mapping)
