# Component: system — end-to-end and robustness rostests (launch/, rviz/, scripts/demo.sh and
# bench/realtime_pipeline.sh need no build step).
#
# A rostest is registered only when the executables it drives are targets of this build, so the
# fragment configures (and the suite stays green) while components are still landing; a missing
# one is reported at configure time.

# ism_add_system_rostest(FILE NEEDS target... [NEEDS_FILES repo-relative-path...])
function(ism_add_system_rostest file)
  cmake_parse_arguments(ARG "" "" "NEEDS;NEEDS_FILES" ${ARGN})
  set(missing "")
  foreach(target ${ARG_NEEDS})
    if(NOT TARGET ${target})
      list(APPEND missing ${target})
    endif()
  endforeach()
  foreach(needed_file ${ARG_NEEDS_FILES})
    if(NOT EXISTS ${PROJECT_SOURCE_DIR}/${needed_file})
      list(APPEND missing ${needed_file})
    endif()
  endforeach()
  if(missing)
    message(STATUS "system: ${file} not registered, missing: ${missing}")
    return()
  endif()
  add_rostest(${file} DEPENDENCIES ${ARG_NEEDS})
endfunction()

if(CATKIN_ENABLE_TESTING)
  set(ISM_PIPELINE_TARGETS
    generate_synthetic_drive kitti2bag inekf_node segmentation_node semantic_octomap_node)
  # The pipeline runs the default segmentation model (models/unet_synthetic.onnx).
  set(ISM_PIPELINE_FILES models/unet_synthetic.onnx)
  ism_add_system_rostest(test/ros/e2e_synthetic.test
    NEEDS ${ISM_PIPELINE_TARGETS} NEEDS_FILES ${ISM_PIPELINE_FILES})
  ism_add_system_rostest(test/ros/e2e_real_oxts.test NEEDS kitti2bag inekf_node)
  # Real lidar + camera through the whole pipeline with the ENet from ../shared (skips without).
  ism_add_system_rostest(test/ros/e2e_real_drive.test
    NEEDS kitti2bag inekf_node segmentation_node semantic_octomap_node)
  # Bags in the Python kitti2bag's conventions (test/ros/kitti2bag_py_fixture.py writes them)
  # through kitti_bag.launch, against this package's own bag of the same drive.
  set(ISM_KITTI_BAG_TARGETS
    generate_synthetic_drive kitti2bag kitti_bag_adapter inekf_node semantic_octomap_node)
  ism_add_system_rostest(test/ros/e2e_kitti2bag_py_synthetic.test NEEDS ${ISM_KITTI_BAG_TARGETS})
  ism_add_system_rostest(test/ros/e2e_kitti2bag_py_real.test NEEDS ${ISM_KITTI_BAG_TARGETS})
  # The adapter alone: a velocity before its instant's IMU message (either order of arrival).
  ism_add_system_rostest(test/ros/kitti_bag_adapter.test NEEDS kitti_bag_adapter)
  ism_add_system_rostest(test/ros/robustness_gps_outage.test
    NEEDS generate_synthetic_drive kitti2bag inekf_node)
  ism_add_system_rostest(test/ros/robustness_bag_loop.test
    NEEDS ${ISM_PIPELINE_TARGETS} NEEDS_FILES ${ISM_PIPELINE_FILES})
  ism_add_system_rostest(test/ros/robustness_node_restart.test
    NEEDS ${ISM_PIPELINE_TARGETS} NEEDS_FILES ${ISM_PIPELINE_FILES})
  # Segmentation on a second host: two network namespaces (scripts/two_host_demo.sh; skips
  # loudly without root / ip netns).
  ism_add_system_rostest(test/ros/two_host.test
    NEEDS ${ISM_PIPELINE_TARGETS} NEEDS_FILES ${ISM_PIPELINE_FILES} scripts/two_host_demo.sh)
endif()

# Header-only helpers the tools share (include/inekf_semantic_mapping/common/).
ism_add_gtest(test_atomic_file SOURCES test/unit/test_atomic_file.cpp)
ism_add_gtest(test_cli_args SOURCES test/unit/test_cli_args.cpp)
foreach(common_test test_atomic_file test_cli_args)
  if(TARGET ${common_test})
    target_include_directories(${common_test} PRIVATE ${ISM_CORE_INCLUDE_DIRS})
  endif()
endforeach()
