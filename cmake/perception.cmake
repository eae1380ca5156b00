# Component: perception — lidar-to-camera projection and the lidar geometry check on camera labels
# (Eigen only), Segmenter (OpenCV dnn) and model cards; segmentation_node, segment_image.
ism_add_core_library(${PROJECT_NAME}_projection
  SOURCES ${ISM_PROJECTION_SOURCES})

ism_add_core_library(${PROJECT_NAME}_perception
  SOURCES ${ISM_PERCEPTION_SOURCES}
  LINK ${PROJECT_NAME}_common ${OpenCV_LIBS} yaml-cpp
  SYSTEM_INCLUDES ${OpenCV_INCLUDE_DIRS})

ism_add_gtest(test_segmenter
  SOURCES test/unit/test_segmenter.cpp
  LINK ${PROJECT_NAME}_perception)
ism_add_gtest(test_dnn_bilinear_resize
  SOURCES test/unit/test_dnn_bilinear_resize.cpp
  LINK ${PROJECT_NAME}_perception)
ism_add_gtest(test_segmenter_data
  SOURCES test/data/test_segmenter_data.cpp
  LINK ${PROJECT_NAME}_perception)

# The default U-Net's mIoU target on held-out synthetic drives it renders itself.
ism_add_gtest(test_unet_synthetic_accuracy
  SOURCES test/accuracy/test_unet_synthetic_accuracy.cpp
  LINK ${PROJECT_NAME}_perception ${PROJECT_NAME}_synthetic)

ism_add_tool(segment_image
  SOURCES src/tools/segment_image.cpp
  LINK ${PROJECT_NAME}_perception)
ism_add_gtest(test_segment_image
  SOURCES test/cli/test_segment_image.cpp
  LINK ${PROJECT_NAME}_perception
  TOOL segment_image TOOL_MACRO SEGMENT_IMAGE_PATH)

ism_add_gtest(test_segmenter_frame_buffer
  SOURCES test/unit/test_segmenter_frame_buffer.cpp
  LINK ${PROJECT_NAME}_perception)

# segmentation_node's work (ROS-facing), shared by the node and its nodelet.
ism_add_ros_library(${PROJECT_NAME}_segmentation_ros
  SOURCES ${ISM_SEGMENTATION_ROS_SOURCES}
  LINK ${PROJECT_NAME}_perception ${PROJECT_NAME}_node_ros)
ism_add_ros_executable(segmentation_node
  SOURCES src/nodes/segmentation_node.cpp
  LINK ${PROJECT_NAME}_segmentation_ros)

if(benchmark_FOUND)
  ism_add_tool(bench_segmentation
    SOURCES bench/bench_segmentation.cpp
    LINK ${PROJECT_NAME}_perception benchmark::benchmark)
  target_compile_definitions(bench_segmentation PRIVATE
    ISM_SHARED_DIR_DEFAULT="${ISM_SHARED_DIR}" ISM_REPO_ROOT="${ISM_REPO_ROOT}")
endif()

if(CATKIN_ENABLE_TESTING)
  add_rostest(test/ros/segmentation_node.test)
  # The camera adaptation (training/, scripts/adapt_segmentation.sh) on a tiny budget: its ONNX
  # export through segment_image against PyTorch.
  add_rostest(test/ros/adapt_segmentation.test DEPENDENCIES segment_image)
endif()
