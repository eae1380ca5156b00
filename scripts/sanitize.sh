#!/usr/bin/env bash
# Builds the unit tests of the ROS-free core with AddressSanitizer + UndefinedBehaviorSanitizer in
# their own workspace ($ISM_WS/asan) and runs them; any sanitizer report fails the test it occurs
# in. Results go where catkin_test_results reads (prefixed "asan-"), so ./scripts/test.sh counts
# them. The data-heavy accuracy tests (real drives, networks) run only in the normal build.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
TESTS=(test_lie test_imu_filters test_localizer test_lazy_start test_kitti_io test_kitti_io_data
       test_kitti_gps_degradation test_input_validation test_input_validation_data test_cli_args
       test_atomic_file test_projection test_projection_data test_label_geometry test_semantic_octree test_semantic_mapping_session
       test_pose_graph)
flags="-fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer -g"
asan_ws=$ISM_WS/asan
results=$ISM_WS/build/test_results/inekf_semantic_mapping
mkdir -p "$results"

echo "[sanitize] building ${#TESTS[@]} unit tests with ASan + UBSan in $asan_ws"
if ! ISM_SKIP_DEPS=1 ISM_WS="$asan_ws" "$ISM_ROOT/scripts/build.sh" \
    -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS="$flags" \
    -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" \
    -DCMAKE_SHARED_LINKER_FLAGS="-fsanitize=address,undefined" "${TESTS[@]}" \
    >"$ISM_WS/asan_build.log" 2>&1; then
  tail -n 40 "$ISM_WS/asan_build.log"
  echo "[sanitize] BUILD FAILED"
  ism_junit_failure "$results/asan-build.xml" asan_build build "see $ISM_WS/asan_build.log"
  exit 1
fi

failed=0
for test in "${TESTS[@]}"; do
  set +e
  ASAN_OPTIONS=detect_leaks=1:abort_on_error=0 UBSAN_OPTIONS=print_stacktrace=1 \
    "$asan_ws/devel/lib/inekf_semantic_mapping/$test" \
    --gtest_output="xml:$results/asan-$test.xml" >"$ISM_WS/asan-$test.log" 2>&1
  rc=$?
  set -e
  if ((rc != 0)); then
    failed=$((failed + 1))
    echo "[sanitize] $test: FAILED (exit $rc), log $ISM_WS/asan-$test.log"
    grep -E 'ERROR: |runtime error|SUMMARY|FAILED' "$ISM_WS/asan-$test.log" | head -n 8 || true
    # A sanitizer abort leaves no XML: record the failure so the suite counts it.
    [[ -s $results/asan-$test.xml ]] ||
      ism_junit_failure "$results/asan-$test.xml" "asan_$test" "$test" "exit $rc under ASan/UBSan"
  else
    echo "[sanitize] $test: passed, no sanitizer report"
  fi
done
((failed == 0))
