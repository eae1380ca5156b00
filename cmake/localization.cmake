# Component: localization — trajectory evaluation scripts (scripts/evaluate_trajectory.py,
# scripts/compare_filters.py) and inekf_node (ROS face of the estimation library).

if(CATKIN_ENABLE_TESTING)
  # Python unit tests of the evaluation scripts (no ROS graph needed; rostest records them).
  add_rostest(test/ros/evaluate_trajectory.test)
endif()
