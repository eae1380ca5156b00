# Component: synthetic — KITTI-format drive generator with full ground truth (world, route,
# sensors), the generate_synthetic_drive tool, unit tests and a benchmark.
ism_add_core_library(${PROJECT_NAME}_synthetic
  SOURCES ${ISM_SYNTHETIC_SOURCES}
  LINK ${PROJECT_NAME}_kitti opencv_core opencv_imgcodecs Threads::Threads
  SYSTEM_INCLUDES ${OpenCV_INCLUDE_DIRS})

ism_add_tool(generate_synthetic_drive
  SOURCES src/tools/generate_synthetic_drive.cpp
  LINK ${PROJECT_NAME}_synthetic)

ism_add_gtest(test_synthetic_world SOURCES test/unit/test_synthetic_world.cpp
  LINK ${PROJECT_NAME}_synthetic)
ism_add_gtest(test_synthetic_drive SOURCES test/unit/test_synthetic_drive.cpp
  LINK ${PROJECT_NAME}_synthetic ${PROJECT_NAME}_kitti opencv_imgcodecs)
ism_add_gtest(test_synthetic_drive_data SOURCES test/data/test_synthetic_drive_data.cpp
  LINK ${PROJECT_NAME}_synthetic ${PROJECT_NAME}_kitti)

if(benchmark_FOUND)
  ism_add_tool(bench_synthetic SOURCES bench/bench_synthetic.cpp
    LINK ${PROJECT_NAME}_synthetic benchmark::benchmark)
endif()
