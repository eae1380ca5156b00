# Component: kitti — KITTI raw I/O core (Eigen only), ROS conversions, kitti_player, kitti2bag.
ism_add_core_library(${PROJECT_NAME}_kitti
  SOURCES ${ISM_KITTI_SOURCES})

ism_add_gtest(test_kitti_io SOURCES test/unit/test_kitti_io.cpp LINK ${PROJECT_NAME}_kitti)
ism_add_gtest(test_kitti_io_data SOURCES test/data/test_kitti_io_data.cpp LINK ${PROJECT_NAME}_kitti)
ism_add_gtest(test_kitti_gps_degradation
  SOURCES test/unit/test_kitti_gps_degradation.cpp LINK ${PROJECT_NAME}_kitti)

# KITTI -> ROS message conversions shared by kitti_player and kitti2bag (ROS-facing, not core).
ism_add_ros_library(${PROJECT_NAME}_kitti_ros
  SOURCES ${ISM_KITTI_ROS_SOURCES}
  LINK ${PROJECT_NAME}_kitti ${PROJECT_NAME}_node_ros opencv_core opencv_imgcodecs
  SYSTEM_INCLUDES ${OpenCV_INCLUDE_DIRS})

ism_add_ros_executable(kitti_player SOURCES src/nodes/kitti_player.cpp
  LINK ${PROJECT_NAME}_kitti_ros)

if(CATKIN_ENABLE_TESTING)
  add_rostest(test/ros/kitti_player.test ARGS shared_dir:=${ISM_SHARED_DIR}
    DEPENDENCIES kitti_player)
endif()

ism_add_ros_executable(kitti2bag SOURCES src/tools/kitti2bag.cpp LINK ${PROJECT_NAME}_kitti_ros)

# The conversions, and kitti2bag end to end on a synthetic drive the test writes (no ../shared
# needed).
ism_add_gtest(test_kitti_conversions SOURCES test/unit/test_kitti_conversions.cpp
  LINK ${PROJECT_NAME}_kitti_ros)
ism_add_gtest(test_kitti2bag SOURCES test/cli/test_kitti2bag.cpp
  LINK ${PROJECT_NAME}_kitti_ros TOOL kitti2bag TOOL_MACRO KITTI2BAG_PATH)
foreach(conversion_test test_kitti_conversions test_kitti2bag)
  if(TARGET ${conversion_test})
    target_include_directories(${conversion_test} PRIVATE ${ISM_ROS_INCLUDE_DIRS})
    target_include_directories(${conversion_test} SYSTEM PRIVATE ${OpenCV_INCLUDE_DIRS})
    target_link_libraries(${conversion_test} opencv_imgcodecs)
  endif()
endforeach()

if(benchmark_FOUND)
  ism_add_tool(bench_kitti SOURCES bench/bench_kitti.cpp
    LINK ${PROJECT_NAME}_kitti_ros benchmark::benchmark)
  target_include_directories(bench_kitti PRIVATE ${ISM_ROS_INCLUDE_DIRS})
  target_compile_definitions(bench_kitti PRIVATE ISM_SHARED_DIR_DEFAULT="${ISM_SHARED_DIR}")
endif()
