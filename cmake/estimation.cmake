# Component: estimation — Lie groups, the InEKF / ESKF filters, the streaming Localizer,
# inekf_offline, their tests and benchmark.
ism_add_core_library(${PROJECT_NAME}_lie SOURCES ${ISM_LIE_SOURCES})
ism_add_core_library(${PROJECT_NAME}_estimation
  SOURCES ${ISM_ESTIMATION_SOURCES}
  LINK ${PROJECT_NAME}_lie ${PROJECT_NAME}_common)

ism_add_gtest(test_lie SOURCES test/unit/test_lie.cpp LINK ${PROJECT_NAME}_lie)
ism_add_gtest(test_imu_filters SOURCES test/unit/test_imu_filters.cpp
  LINK ${PROJECT_NAME}_estimation)

# The streaming session both inekf_node and inekf_offline drive (geodetic fixes: needs kitti's
# Mercator).
ism_add_core_library(${PROJECT_NAME}_localization_session
  SOURCES ${ISM_LOCALIZATION_SESSION_SOURCES}
  LINK ${PROJECT_NAME}_estimation ${PROJECT_NAME}_kitti ${PROJECT_NAME}_common)
# Runs the session over KITTI OXTS (inekf_offline, real-drive tests, benchmark).
ism_add_core_library(${PROJECT_NAME}_estimation_oxts
  SOURCES ${ISM_ESTIMATION_OXTS_SOURCES}
  LINK ${PROJECT_NAME}_localization_session)
# Lidar scan registration for the loop closure (PCL GICP): the one library that sees PCL.
ism_add_core_library(${PROJECT_NAME}_registration
  SOURCES ${ISM_REGISTRATION_SOURCES}
  LINK ${PROJECT_NAME}_estimation_oxts ${PROJECT_NAME}_kitti ${PCL_LIBRARIES}
  SYSTEM_INCLUDES ${PCL_INCLUDE_DIRS})
# GCC 12's -Warray-bounds fires inside Eigen's SSE loads inlined from PCL's Umeyama (a known false
# positive on Eigen::Vector3f, reported in xmmintrin.h): kept as a warning, not an error, here only.
target_compile_options(${PROJECT_NAME}_registration PRIVATE -Wno-error=array-bounds)
ism_add_tool(inekf_offline SOURCES src/tools/inekf_offline.cpp
  LINK ${PROJECT_NAME}_estimation_oxts ${PROJECT_NAME}_registration)
# On a synthetic drive (cmake/synthetic.cmake's library: resolved when the build is generated).
ism_add_gtest(test_inekf_offline SOURCES test/cli/test_inekf_offline.cpp
  LINK ${PROJECT_NAME}_synthetic
  TOOL inekf_offline TOOL_MACRO INEKF_OFFLINE_PATH)
ism_add_gtest(test_smoother SOURCES test/unit/test_smoother.cpp
  LINK ${PROJECT_NAME}_estimation)
ism_add_gtest(test_pose_graph SOURCES test/unit/test_pose_graph.cpp
  LINK ${PROJECT_NAME}_estimation)
ism_add_gtest(test_smoothed_posterior_graph SOURCES test/unit/test_smoothed_posterior_graph.cpp
  LINK ${PROJECT_NAME}_estimation_oxts)
# Loop closure end to end on a synthetic drive it generates (lidar, 30 s GPS outage).
ism_add_gtest(test_loop_closure SOURCES test/unit/test_loop_closure.cpp
  LINK ${PROJECT_NAME}_registration ${PROJECT_NAME}_synthetic)
ism_add_gtest(test_loop_closure_data SOURCES test/data/test_loop_closure_data.cpp
  LINK ${PROJECT_NAME}_registration ${PROJECT_NAME}_synthetic)
ism_add_gtest(test_localizer SOURCES test/unit/test_localizer.cpp
  LINK ${PROJECT_NAME}_estimation)
ism_add_gtest(test_standstill_detector SOURCES test/unit/test_standstill_detector.cpp
  LINK ${PROJECT_NAME}_estimation)
ism_add_gtest(test_lazy_start SOURCES test/unit/test_lazy_start.cpp
  LINK ${PROJECT_NAME}_estimation)
ism_add_gtest(test_localization_session SOURCES test/unit/test_localization_session.cpp
  LINK ${PROJECT_NAME}_estimation_oxts)
ism_add_gtest(test_localization_session_data SOURCES test/data/test_localization_session_data.cpp
  LINK ${PROJECT_NAME}_estimation_oxts)
ism_add_gtest(test_inekf_real_drives SOURCES test/accuracy/test_inekf_real_drives.cpp
  LINK ${PROJECT_NAME}_estimation_oxts)

if(benchmark_FOUND)
  ism_add_tool(bench_inekf SOURCES bench/bench_inekf.cpp
    LINK ${PROJECT_NAME}_estimation_oxts benchmark::benchmark)
endif()
