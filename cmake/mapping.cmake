# Component: mapping — SemanticOcTree (octomap), the mapping session, semantic_octomap_node,
# semantic_map_offline; project_cloud (the projection library is perception's).

ism_add_core_library(${PROJECT_NAME}_mapping
  SOURCES ${ISM_MAPPING_SOURCES}
  LINK ${PROJECT_NAME}_kitti ${PROJECT_NAME}_projection ${PROJECT_NAME}_common
       ${OCTOMAP_LIBRARIES} Threads::Threads
  SYSTEM_INCLUDES ${OCTOMAP_INCLUDE_DIRS})

ism_add_gtest(test_semantic_octree
  SOURCES test/unit/test_semantic_octree.cpp
  LINK ${PROJECT_NAME}_mapping)
# The hashed-grid insertion against the octree's (synthetic and real scans).
ism_add_gtest(test_hashed_voxel_grid
  SOURCES test/unit/test_hashed_voxel_grid.cpp
  LINK ${PROJECT_NAME}_mapping)
ism_add_gtest(test_hashed_voxel_grid_data
  SOURCES test/data/test_hashed_voxel_grid_data.cpp
  LINK ${PROJECT_NAME}_mapping ${PROJECT_NAME}_kitti)
ism_add_gtest(test_grid_projection
  SOURCES test/unit/test_grid_projection.cpp
  LINK ${PROJECT_NAME}_mapping)
ism_add_gtest(test_semantic_mapping_session
  SOURCES test/unit/test_semantic_mapping_session.cpp
  LINK ${PROJECT_NAME}_mapping)
ism_add_gtest(test_scan_label_pairing
  SOURCES test/unit/test_scan_label_pairing.cpp
  LINK ${PROJECT_NAME}_mapping)
ism_add_gtest(test_map_label_images
  SOURCES test/unit/test_map_label_images.cpp
  LINK ${PROJECT_NAME}_mapping)

ism_add_tool(project_cloud
  SOURCES src/tools/project_cloud.cpp
  LINK ${PROJECT_NAME}_projection ${PROJECT_NAME}_kitti ${OpenCV_LIBS})
target_include_directories(project_cloud SYSTEM PRIVATE ${OpenCV_INCLUDE_DIRS})
ism_add_tool(semantic_map_offline
  SOURCES src/tools/semantic_map_offline.cpp
  LINK ${PROJECT_NAME}_mapping ${PROJECT_NAME}_perception)

# Unit tests; the CLI tests run the tools (TOOL: built first).
ism_add_gtest(test_projection
  SOURCES test/unit/test_projection.cpp
  LINK ${PROJECT_NAME}_projection ${PROJECT_NAME}_kitti)
ism_add_gtest(test_projection_data
  SOURCES test/data/test_projection_data.cpp
  LINK ${PROJECT_NAME}_projection ${PROJECT_NAME}_kitti)
ism_add_gtest(test_project_cloud
  SOURCES test/cli/test_project_cloud.cpp
  LINK ${PROJECT_NAME}_projection ${PROJECT_NAME}_kitti ${OpenCV_LIBS}
  TOOL project_cloud TOOL_MACRO PROJECT_CLOUD_PATH)
# The lidar-geometry check on camera labels (ground estimate, flat / raised classes).
ism_add_gtest(test_label_geometry
  SOURCES test/unit/test_label_geometry.cpp
  LINK ${PROJECT_NAME}_projection)
ism_add_gtest(test_semantic_octree_offline
  SOURCES test/unit/test_semantic_octree_offline.cpp
  LINK ${PROJECT_NAME}_mapping)
ism_add_gtest(test_semantic_octree_offline_data
  SOURCES test/data/test_semantic_octree_offline_data.cpp
  LINK ${PROJECT_NAME}_mapping)
ism_add_gtest(test_raw_drive_scans SOURCES test/unit/test_raw_drive_scans.cpp
  LINK ${PROJECT_NAME}_mapping)
ism_add_gtest(test_semantic_map_offline
  SOURCES test/cli/test_semantic_map_offline.cpp
  LINK ${PROJECT_NAME}_mapping ${OpenCV_LIBS}
  TOOL semantic_map_offline TOOL_MACRO SEMANTIC_MAP_OFFLINE_PATH)
if(TARGET test_semantic_map_offline)
  target_include_directories(test_semantic_map_offline SYSTEM PRIVATE ${OpenCV_INCLUDE_DIRS})
endif()

if(benchmark_FOUND)
  ism_add_tool(bench_semantic_octree
    SOURCES bench/bench_semantic_octree.cpp
    LINK ${PROJECT_NAME}_mapping benchmark::benchmark)
  target_compile_definitions(bench_semantic_octree PRIVATE
    ISM_SHARED_DIR_DEFAULT="${ISM_SHARED_DIR}")
endif()

# Message <-> session conversions of semantic_octomap_node and its work, shared by the node and
# its nodelet (ROS-facing, not core).
ism_add_ros_library(${PROJECT_NAME}_mapping_ros
  SOURCES ${ISM_MAPPING_ROS_SOURCES}
  LINK ${PROJECT_NAME}_mapping ${PROJECT_NAME}_node_ros yaml-cpp)

ism_add_ros_executable(semantic_octomap_node
  SOURCES src/nodes/semantic_octomap_node.cpp
  LINK ${PROJECT_NAME}_mapping_ros)
ism_add_gtest(test_mapping_diagnostics
  SOURCES test/unit/test_mapping_diagnostics.cpp
  LINK ${PROJECT_NAME}_mapping_ros)
ism_add_gtest(test_label_camera
  SOURCES test/unit/test_label_camera.cpp
  LINK ${PROJECT_NAME}_mapping_ros)
foreach(mapping_ros_test test_mapping_diagnostics test_label_camera)
  if(TARGET ${mapping_ros_test})
    target_include_directories(${mapping_ros_test} PRIVATE ${ISM_ROS_INCLUDE_DIRS})
  endif()
endforeach()

# The segmentation and map nodes as nodelets in one library (nodelet_plugins.xml).
ism_add_ros_library(${PROJECT_NAME}_nodelets
  SOURCES ${ISM_NODELET_SOURCES}
  LINK ${PROJECT_NAME}_segmentation_ros ${PROJECT_NAME}_mapping_ros)
install(FILES nodelet_plugins.xml DESTINATION ${CATKIN_PACKAGE_SHARE_DESTINATION})
if(CATKIN_ENABLE_TESTING)
  add_rostest(test/ros/semantic_octomap_node.test DEPENDENCIES semantic_octomap_node)
  add_rostest(test/ros/semantic_octomap_lidar_only.test DEPENDENCIES semantic_octomap_node)
  add_rostest(test/ros/semantic_octomap_shutdown_save.test DEPENDENCIES semantic_octomap_node)
  add_rostest(test/ros/semantic_octomap_nodelet_shutdown_save.test
              DEPENDENCIES ${PROJECT_NAME}_nodelets)
  add_rostest(test/ros/semantic_octomap_grids.test DEPENDENCIES semantic_octomap_node)
  add_rostest(test/ros/semantic_octomap_clock_stopped.test DEPENDENCIES semantic_octomap_node)
endif()

# Bad values in KITTI, calibration and pose files (regressions of the fault-injection findings).
ism_add_gtest(test_input_validation
  SOURCES test/unit/test_input_validation.cpp
  LINK ${PROJECT_NAME}_mapping ${PROJECT_NAME}_kitti)
ism_add_gtest(test_input_validation_data
  SOURCES test/data/test_input_validation_data.cpp
  LINK ${PROJECT_NAME}_mapping ${PROJECT_NAME}_kitti)
