# Component: perception — Segmenter (OpenCV dnn) and model cards; segmentation_node,
# segment_image. projection.* in the same folder is built by the mapping fragment.
ism_add_core_library(${PROJECT_NAME}_perception
  SOURCES src/perception/model_card.cpp src/perception/segmenter.cpp
  LINK ${OpenCV_LIBS} yaml-cpp
  SYSTEM_INCLUDES ${OpenCV_INCLUDE_DIRS})

ism_add_gtest(test_segmenter
  SOURCES test/unit/test_segmenter.cpp
  LINK ${PROJECT_NAME}_perception)
