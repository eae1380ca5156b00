# Component: system — end-to-end and robustness rostests (launch/, rviz/, scripts/demo.sh and
# bench/realtime_pipeline.sh need no build step). Each test depends on the executables it drives,
# so `catkin_make run_tests` builds them first.

if(CATKIN_ENABLE_TESTING)
  set(ISM_PIPELINE_TARGETS
    generate_synthetic_drive kitti2bag inekf_node segmentation_node semantic_octomap_node)
  # The pipeline runs the default segmentation model (models/unet_synthetic.onnx).
  # The map is scored with evaluate_map (the package's one map metric).
  add_rostest(test/ros/e2e_synthetic.test
    DEPENDENCIES ${ISM_PIPELINE_TARGETS} evaluate_map)
  # The same with the segmentation and map nodelets in one manager (pipeline.launch nodelets:=true).
  add_rostest(test/ros/e2e_synthetic.test ARGS nodelets:=true
    DEPENDENCIES ${ISM_PIPELINE_TARGETS} ${PROJECT_NAME}_nodelets evaluate_map)
  add_rostest(test/ros/e2e_real_oxts.test DEPENDENCIES kitti2bag inekf_node)
  # The closing line of scripts/test.sh: scripts/count_test_results.py on written result files.
  add_rostest(test/ros/count_test_results.test)
  # launch/robot.launch on a simulated robot that is not KITTI's (mounting and lever arm from tf,
  # an IMU without orientation, an Ouster-like cloud): needs no data.
  add_rostest(test/ros/own_robot.test
    DEPENDENCIES inekf_node semantic_octomap_node ${PROJECT_NAME}_generate_messages_py)
  # inekf_node with wheel odometry in a frame turned from base_link, through a GPS outage.
  add_rostest(test/ros/wheel_odometry.test DEPENDENCIES inekf_node)
  # Two pipelines in two namespaces on one master, each on its own bag (occupancy only).
  add_rostest(test/ros/two_pipelines.test DEPENDENCIES ${ISM_PIPELINE_TARGETS})
  # Real lidar + camera through the whole pipeline with the ENet from ../shared (skips without).
  add_rostest(test/ros/e2e_real_drive.test
    DEPENDENCIES kitti2bag inekf_node segmentation_node semantic_octomap_node)
  # Bags in the Python kitti2bag's conventions (test/ros/kitti2bag_py_fixture.py writes them)
  # through kitti_bag.launch, against this package's own bag of the same drive.
  set(ISM_KITTI_BAG_TARGETS
    generate_synthetic_drive kitti2bag kitti_bag_adapter inekf_node semantic_octomap_node)
  add_rostest(test/ros/e2e_kitti2bag_py_synthetic.test DEPENDENCIES ${ISM_KITTI_BAG_TARGETS})
  add_rostest(test/ros/e2e_kitti2bag_py_real.test DEPENDENCIES ${ISM_KITTI_BAG_TARGETS})
  # The adapter alone: a velocity before its instant's IMU message (either order of arrival).
  add_rostest(test/ros/kitti_bag_adapter.test DEPENDENCIES kitti_bag_adapter)
  add_rostest(test/ros/robustness_gps_outage.test
    DEPENDENCIES generate_synthetic_drive kitti2bag inekf_node)
  add_rostest(test/ros/robustness_bag_loop.test
    DEPENDENCIES ${ISM_PIPELINE_TARGETS})
  add_rostest(test/ros/robustness_node_restart.test
    DEPENDENCIES ${ISM_PIPELINE_TARGETS})
  add_rostest(test/ros/robustness_nodelet_restart.test
    DEPENDENCIES ${ISM_PIPELINE_TARGETS})
  # Segmentation on a second host: two network namespaces (scripts/two_host_demo.sh; skips
  # loudly without root / ip netns).
  add_rostest(test/ros/two_host.test
    DEPENDENCIES ${ISM_PIPELINE_TARGETS})
endif()

# Header-only helpers the tools share (include/inekf_semantic_mapping/common/).
ism_add_gtest(test_atomic_file SOURCES test/unit/test_atomic_file.cpp)
ism_add_gtest(test_cli_args SOURCES test/unit/test_cli_args.cpp)
ism_add_gtest(test_progress_log SOURCES test/unit/test_progress_log.cpp)
foreach(common_test test_atomic_file test_cli_args test_progress_log)
  if(TARGET ${common_test})
    target_include_directories(${common_test} PRIVATE ${ISM_CORE_INCLUDE_DIRS})
  endif()
endforeach()

# Every flag each command-line tool's usage names is accepted by its parser.
set(ISM_CLI_TOOLS evaluate_map evaluate_semantics generate_synthetic_drive inekf_offline kitti2bag
  make_camera_labels project_cloud segment_image semantic_map_offline)
ism_add_gtest(test_tool_usage SOURCES test/cli/test_tool_usage.cpp)
if(TARGET test_tool_usage)
  set(ism_tool_paths "")
  foreach(tool ${ISM_CLI_TOOLS})
    string(APPEND ism_tool_paths "$<TARGET_FILE:${tool}>\n")
    add_dependencies(test_tool_usage ${tool})
  endforeach()
  file(GENERATE OUTPUT ${CMAKE_BINARY_DIR}/${PROJECT_NAME}_cli_tools.txt
    CONTENT "${ism_tool_paths}")
  target_compile_definitions(test_tool_usage PRIVATE
    ISM_TOOL_PATHS_FILE="${CMAKE_BINARY_DIR}/${PROJECT_NAME}_cli_tools.txt")
endif()
