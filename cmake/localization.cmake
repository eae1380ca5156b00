# Component: localization — trajectory evaluation scripts (scripts/evaluate_trajectory.py,
# scripts/compare_filters.py) and inekf_node (ROS face of the estimation library's Localizer).

# Message <-> session conversions of inekf_node (ROS-facing, not core): one library for the node
# and its test; with the bag conventions kitti_bag_adapter turns into the nodes' one.
ism_add_ros_library(${PROJECT_NAME}_localization_ros
  SOURCES ${ISM_LOCALIZATION_ROS_SOURCES}
  LINK ${PROJECT_NAME}_localization_session ${PROJECT_NAME}_node_ros)

ism_add_ros_executable(inekf_node
  SOURCES src/nodes/inekf_node.cpp src/ros/inekf_node_core.cpp
  LINK ${PROJECT_NAME}_localization_ros roslib)
ism_add_gtest(test_localization_conversions
  SOURCES test/unit/test_localization_conversions.cpp
  LINK ${PROJECT_NAME}_localization_ros)
if(TARGET test_localization_conversions)
  target_include_directories(test_localization_conversions PRIVATE ${ISM_ROS_INCLUDE_DIRS})
endif()
# kitti_bag.launch's adapter: plays bags of this package's kitti2bag or of the Python kitti2bag
# (tomas789/kitti2bag) into the nodes in one convention.
ism_add_ros_executable(kitti_bag_adapter
  SOURCES src/nodes/kitti_bag_adapter.cpp
  LINK ${PROJECT_NAME}_localization_ros)
ism_add_gtest(test_kitti_bag_conventions
  SOURCES test/unit/test_kitti_bag_conventions.cpp
  LINK ${PROJECT_NAME}_localization_ros ${PROJECT_NAME}_kitti)
ism_add_gtest(test_kitti_bag_conventions_data
  SOURCES test/data/test_kitti_bag_conventions_data.cpp
  LINK ${PROJECT_NAME}_localization_ros ${PROJECT_NAME}_kitti)
foreach(conventions_test test_kitti_bag_conventions test_kitti_bag_conventions_data)
  if(TARGET ${conventions_test})
    target_include_directories(${conventions_test} PRIVATE ${ISM_ROS_INCLUDE_DIRS})
  endif()
endforeach()
if(CATKIN_ENABLE_TESTING)
  # A real OXTS drive from ../shared played into inekf_node (skips without ../shared).
  add_rostest(test/ros/inekf_node.test
    DEPENDENCIES inekf_node ${PROJECT_NAME}_generate_messages_py)
  add_rostest(test/ros/inekf_node_robustness.test
    DEPENDENCIES inekf_node ${PROJECT_NAME}_generate_messages_py)
  # Another robot's mounting from tf: the IMU turned 90 deg, the GPS antenna on a lever arm.
  add_rostest(test/ros/inekf_node_mounting.test
    DEPENDENCIES inekf_node ${PROJECT_NAME}_generate_messages_py)
  # An IMU without orientation: the odometry from the start, tf once the heading is known.
  add_rostest(test/ros/inekf_node_heading_unknown.test
    DEPENDENCIES inekf_node ${PROJECT_NAME}_generate_messages_py)
  # /diagnostics without fixes: WARN, then ERROR (seconds).
  add_rostest(test/ros/inekf_node_diagnostics.test DEPENDENCIES inekf_node)
  add_rostest(test/ros/inekf_node_kitti_player.test ARGS shared_dir:=${ISM_SHARED_DIR}
    DEPENDENCIES inekf_node kitti_player ${PROJECT_NAME}_generate_messages_py)
endif()

if(CATKIN_ENABLE_TESTING)
  # Python unit tests of the evaluation scripts (no ROS graph needed; rostest records them).
  add_rostest(test/ros/evaluate_trajectory.test)
endif()
