# Component: common — helpers every component shares (the strict YAML config reader; the
# header-only atomic file writes, command-line parsing, number text, timing and progress lines
# live beside it).
ism_add_core_library(${PROJECT_NAME}_common
  SOURCES ${ISM_COMMON_SOURCES}
  LINK yaml-cpp)

# Every node's private parameters through the strict reader (ros/node_parameters.h).
ism_add_ros_library(${PROJECT_NAME}_node_ros
  SOURCES src/ros/node_parameters.cpp src/ros/diagnostics.cpp
  LINK ${PROJECT_NAME}_common yaml-cpp)
ism_add_gtest(test_yaml_reader SOURCES test/unit/test_yaml_reader.cpp LINK ${PROJECT_NAME}_common)
ism_add_gtest(test_decimal_text SOURCES test/unit/test_decimal_text.cpp LINK ${PROJECT_NAME}_common)
