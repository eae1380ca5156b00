#!/usr/bin/env bash
# Builds the unit tests of the ROS-free core with AddressSanitizer + UndefinedBehaviorSanitizer
# (clang-14, test/fuzz/CMakeLists.txt: the build the fuzz harnesses share, in
# $ISM_WS/sanitizers) and runs them; any sanitizer report fails the test it occurs in. Results go
# where catkin_test_results reads (prefixed "asan-"), so ./scripts/test.sh counts them. The list
# of tests is SANITIZED_TESTS in test/fuzz/CMakeLists.txt; the data-heavy accuracy tests (real
# drives, networks) run only in the normal build.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
build=$ISM_WS/sanitizers
results=$ISM_WS/build/test_results/inekf_semantic_mapping
log=$ISM_WS/asan_build.log
mkdir -p "$build" "$results"

echo "[sanitize] building the core's unit tests with ASan + UBSan (clang-14) in $build"
if ! { CC=clang-14 CXX=clang++-14 cmake -S "$ISM_ROOT/test/fuzz" -B "$build" \
         -DCMAKE_BUILD_TYPE=Debug &&
       cmake --build "$build" --target sanitized_tests -j"$ISM_JOBS"; } >"$log" 2>&1; then
  tail -n 40 "$log"
  echo "[sanitize] BUILD FAILED"
  ism_junit_failure "$results/asan-build.xml" asan_build build "see $log"
  exit 1
fi

# From the repository root, as catkin runs the gtests (relative paths such as config/ resolve).
cd "$ISM_ROOT"
failed=0
count=0
while read -r binary; do
  test=${binary##*/}
  count=$((count + 1))
  set +e
  ASAN_OPTIONS=detect_leaks=1:abort_on_error=0 UBSAN_OPTIONS=print_stacktrace=1 \
    "$binary" --gtest_output="xml:$results/asan-$test.xml" >"$ISM_WS/asan-$test.log" 2>&1
  rc=$?
  set -e
  if ((rc != 0)); then
    failed=$((failed + 1))
    echo "[sanitize] $test: FAILED (exit $rc), log $ISM_WS/asan-$test.log"
    grep -E 'ERROR: |runtime error|SUMMARY|FAILED' "$ISM_WS/asan-$test.log" | head -n 8 || true
    # A case of its own whatever the XML says: an abort leaves none, and LeakSanitizer reports
    # at exit, after gtest wrote a passing one.
    ism_junit_failure "$results/asan-exit-$test.xml" "asan_$test" "$test" \
      "exit $rc under ASan/UBSan (a sanitizer report or a failed case: see asan-$test.log)"
  else
    echo "[sanitize] $test: passed, no sanitizer report"
  fi
done <"$build/sanitized_tests.txt"
echo "[sanitize] $count tests, $failed failed"
((failed == 0))
