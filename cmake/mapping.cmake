# Component: mapping — lidar-to-camera projection (Eigen only), SemanticOcTree (octomap),
# semantic_octomap_node, project_cloud, semantic_map_offline.
ism_add_core_library(${PROJECT_NAME}_projection
  SOURCES src/perception/projection.cpp src/perception/label_geometry.cpp)

ism_add_core_library(${PROJECT_NAME}_mapping
  SOURCES
    src/mapping/semantic_classes.cpp
    src/mapping/semantic_octree.cpp
    src/mapping/map_io.cpp
    src/mapping/offline_mapping.cpp
    src/mapping/semantic_mapping_session.cpp
  LINK ${PROJECT_NAME}_kitti ${PROJECT_NAME}_projection ${PROJECT_NAME}_common
       ${OCTOMAP_LIBRARIES} Threads::Threads
  SYSTEM_INCLUDES ${OCTOMAP_INCLUDE_DIRS})

ism_add_gtest(test_semantic_octree
  SOURCES test/unit/test_semantic_octree.cpp
  LINK ${PROJECT_NAME}_mapping)
ism_add_gtest(test_semantic_mapping_session
  SOURCES test/unit/test_semantic_mapping_session.cpp
  LINK ${PROJECT_NAME}_mapping)

ism_add_tool(project_cloud
  SOURCES src/tools/project_cloud.cpp
  LINK ${PROJECT_NAME}_projection ${PROJECT_NAME}_kitti ${OpenCV_LIBS})
target_include_directories(project_cloud SYSTEM PRIVATE ${OpenCV_INCLUDE_DIRS})
ism_add_tool(semantic_map_offline
  SOURCES src/tools/semantic_map_offline.cpp
  LINK ${PROJECT_NAME}_mapping ${PROJECT_NAME}_perception)

# Unit tests (the CLI tests run the tools, so they depend on them).
ism_add_gtest(test_projection
  SOURCES test/unit/test_projection.cpp
  LINK ${PROJECT_NAME}_projection ${PROJECT_NAME}_kitti)
if(TARGET test_projection)
  target_compile_definitions(test_projection PRIVATE
    PROJECT_CLOUD_PATH="$<TARGET_FILE:project_cloud>")
  add_dependencies(test_projection project_cloud)
endif()
# The lidar-geometry check on camera labels (ground estimate, flat / raised classes).
ism_add_gtest(test_label_geometry
  SOURCES test/unit/test_label_geometry.cpp
  LINK ${PROJECT_NAME}_projection)
ism_add_gtest(test_semantic_octree_offline
  SOURCES test/unit/test_semantic_octree_offline.cpp
  LINK ${PROJECT_NAME}_mapping)
if(TARGET test_semantic_octree_offline)
  target_compile_definitions(test_semantic_octree_offline PRIVATE
    SEMANTIC_MAP_OFFLINE_PATH="$<TARGET_FILE:semantic_map_offline>")
  add_dependencies(test_semantic_octree_offline semantic_map_offline)
endif()

if(benchmark_FOUND)
  ism_add_tool(bench_semantic_octree
    SOURCES bench/bench_semantic_octree.cpp
    LINK ${PROJECT_NAME}_mapping benchmark::benchmark)
  target_compile_definitions(bench_semantic_octree PRIVATE
    ISM_SHARED_DIR_DEFAULT="${ISM_SHARED_DIR}")
endif()

# Message <-> session conversions of semantic_octomap_node (ROS-facing, not core).
add_library(${PROJECT_NAME}_mapping_ros src/ros/mapping_conversions.cpp)
target_include_directories(${PROJECT_NAME}_mapping_ros PRIVATE ${ISM_ROS_INCLUDE_DIRS})
target_link_libraries(${PROJECT_NAME}_mapping_ros PUBLIC
  ${PROJECT_NAME}_mapping ${catkin_LIBRARIES} yaml-cpp)
add_dependencies(${PROJECT_NAME}_mapping_ros
  ${PROJECT_NAME}_generate_messages_cpp ${catkin_EXPORTED_TARGETS})
install(TARGETS ${PROJECT_NAME}_mapping_ros
  ARCHIVE DESTINATION ${CATKIN_PACKAGE_LIB_DESTINATION}
  LIBRARY DESTINATION ${CATKIN_PACKAGE_LIB_DESTINATION})

ism_add_ros_executable(semantic_octomap_node
  SOURCES src/nodes/semantic_octomap_node.cpp
  LINK ${PROJECT_NAME}_mapping_ros)
if(CATKIN_ENABLE_TESTING)
  add_rostest(test/ros/semantic_octomap_node.test DEPENDENCIES semantic_octomap_node)
  add_rostest(test/ros/semantic_octomap_lidar_only.test DEPENDENCIES semantic_octomap_node)
endif()

# Bad values in KITTI, calibration and pose files (regressions of the fault-injection findings).
ism_add_gtest(test_input_validation
  SOURCES test/unit/test_input_validation.cpp
  LINK ${PROJECT_NAME}_mapping ${PROJECT_NAME}_kitti)
