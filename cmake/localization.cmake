# Component: localization — trajectory evaluation scripts (scripts/evaluate_trajectory.py,
# scripts/compare_filters.py) and inekf_node (ROS face of the estimation library's Localizer).

# inekf_node needs the estimation and KITTI libraries: added once both components define them.
if(TARGET ${PROJECT_NAME}_estimation AND TARGET ${PROJECT_NAME}_kitti)
  ism_add_ros_executable(inekf_node
    SOURCES src/nodes/inekf_node.cpp src/ros/localization_conversions.cpp
    LINK ${PROJECT_NAME}_localization_session roslib)
  # The node's message conversions (ROS headers: not a core library, so the ROS include path is
  # added here).
  ism_add_gtest(test_localization_conversions
    SOURCES test/unit/test_localization_conversions.cpp src/ros/localization_conversions.cpp
    LINK ${PROJECT_NAME}_localization_session ${catkin_LIBRARIES})
  if(TARGET test_localization_conversions)
    target_include_directories(test_localization_conversions PRIVATE ${ISM_ROS_INCLUDE_DIRS})
    add_dependencies(test_localization_conversions ${PROJECT_NAME}_generate_messages_cpp)
  endif()
  if(CATKIN_ENABLE_TESTING)
    # A real OXTS drive from ../shared played into inekf_node (skips without ../shared).
    add_rostest(test/ros/inekf_node.test
      DEPENDENCIES inekf_node ${PROJECT_NAME}_generate_messages_py)
    add_rostest(test/ros/inekf_node_robustness.test
      DEPENDENCIES inekf_node ${PROJECT_NAME}_generate_messages_py)
    if(TARGET kitti_player)
      add_rostest(test/ros/inekf_node_kitti_player.test ARGS shared_dir:=${ISM_SHARED_DIR}
        DEPENDENCIES inekf_node kitti_player ${PROJECT_NAME}_generate_messages_py)
    endif()
  endif()
else()
  message(STATUS "localization: inekf_node not added (needs ${PROJECT_NAME}_estimation and ${PROJECT_NAME}_kitti)")
endif()

if(CATKIN_ENABLE_TESTING)
  # Python unit tests of the evaluation scripts (no ROS graph needed; rostest records them).
  add_rostest(test/ros/evaluate_trajectory.test)
endif()
