#!/usr/bin/env bash
# Runs the test suite and judges the results with catkin_test_results (`catkin_make run_tests`
# exits 0 even when tests fail). Ends with one line `N passed, N failed, N skipped`; exits
# non-zero on any failure.
#   ./scripts/test.sh          the full tier (CI): installs what is missing, builds, runs every
#                              gtest and rostest, the sanitizer and fuzz runs, the format check
#   ./scripts/test.sh --fast   the data-free unit tests of test/unit only: no install, an
#                              incremental build of those tests, ../shared hidden from them
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
start=$(date +%s)
tier=full
[[ ${1:-} == --fast ]] && tier=fast

# judge RESULTS_DIR: catkin_test_results' listing of what failed, then the closing line from
# count_test_results.py, which counts each test case once (catkin_test_results' own totals count
# a gtest case twice and a Python test's skip as a pass); non-zero on any failure.
judge() {
  local counts passed failed skipped
  catkin_test_results "$1" --verbose 2>&1 | grep -vE '^$|^Summary:' | tail -n 60 || true
  counts=$(/usr/bin/python3 "$ISM_ROOT/scripts/count_test_results.py" "$1" --list-failed) || counts=""
  read -r passed failed skipped <<<"$counts" || true
  if ! [[ ${passed:-} =~ ^[0-9]+$ && ${failed:-} =~ ^[0-9]+$ && ${skipped:-} =~ ^[0-9]+$ ]] ||
    ((passed + failed + skipped == 0)); then
    echo "[test] no test results found"
    echo "0 passed, 1 failed"
    return 1
  fi
  echo "[test] $tier tier finished in $(( $(date +%s) - start )) s"
  echo "$passed passed, $failed failed, $skipped skipped"
  ((failed == 0 && passed > 0))
}

# phase NAME COMMAND...: runs one phase and prints its wall time (the phase table of
# docs/results.md §9 comes from these lines).
phase() {
  local name=$1 t0 rc
  shift
  t0=$(date +%s)
  set +e
  "$@"
  rc=$?
  set -e
  echo "[test] phase $name: $(( $(date +%s) - t0 )) s (exit $rc)"
  return $rc
}

if [[ $tier == fast ]]; then
  results=$ISM_WS/build/test_results_fast
  if ! ISM_SKIP_DEPS=1 "$ISM_ROOT/scripts/build.sh" inekf_semantic_mapping_unit_tests; then
    echo "[test] BUILD FAILED"
    echo "0 passed, 1 failed"
    exit 1
  fi
  rm -rf "$results"
  mkdir -p "$results"
  list=$ISM_WS/build/inekf_semantic_mapping_unit_tests.txt
  echo "[test] running the $(wc -l <"$list") unit tests of test/unit (logs: $results)"
  # No ../shared: a unit test that reached for it would show up as skipped.
  while read -r binary; do
    name=${binary##*/}
    set +e
    ISM_SHARED_DIR=/nonexistent/shared "$binary" --gtest_output="xml:$results/gtest-$name.xml" \
      >"$results/$name.log" 2>&1
    rc=$?
    set -e
    if ((rc != 0)); then
      echo "[test] $name: FAILED (exit $rc)"
      grep -E '^\[  FAILED  \]|Failure' "$results/$name.log" | head -n 10 || true
      # Its own case, whether or not the binary wrote results: a crash after a clean XML (at
      # exit) would be counted as passed.
      ism_junit_failure "$results/exit-$name.xml" "$name" "$name" "exit $rc"
    fi
  done <"$list"
  judge "$results"
  exit
fi

if ! phase install_deps "$ISM_ROOT/scripts/install_deps.sh"; then
  echo "[test] INSTALLING THE DEPENDENCIES FAILED"
  echo "0 passed, 1 failed"
  exit 1
fi
if ! ISM_SKIP_DEPS=1 phase build "$ISM_ROOT/scripts/build.sh" all tests; then
  echo "[test] BUILD FAILED"
  echo "0 passed, 1 failed"
  exit 1
fi

cd "$ISM_WS"
rm -rf build/test_results
log=$ISM_WS/run_tests.log
echo "[test] running tests (log: $log)"
# Tests run one after another: rostests start their own masters and share the 2 cores.
run_tests() { stdbuf -oL -eL catkin_make run_tests -j1 >"$log" 2>&1; }
# catkin's run_tests exits 0 on failing tests: a non-zero status is make's own (a test target
# that did not build or run), after which the later tests never ran. Counted as a failure.
if ! phase run_tests run_tests; then
  echo "[test] catkin_make run_tests stopped with an error (see $log)"
  ism_junit_failure "$ISM_WS/build/test_results/inekf_semantic_mapping/run_tests-status.xml" \
    run_tests catkin_make_run_tests "catkin_make run_tests exited non-zero: see run_tests.log"
fi
grep -E '^\[ *(RUN|OK|FAILED|SKIPPED|PASSED) *\]|^\[ROSTEST\]|^\[ROSUNIT\]|SKIPPED:|FAILURE|Error' "$log" | tail -n 400 || true

# The core's unit tests again under ASan + UBSan, and every parser's fuzz harness for a bounded
# time (ISM_FUZZ_SECONDS each); both write their results beside the others.
if [[ ${ISM_SKIP_SANITIZERS:-0} != 1 ]]; then
  phase sanitize "$ISM_ROOT/scripts/sanitize.sh" || true
  phase fuzz "$ISM_ROOT/scripts/fuzz.sh" "${ISM_FUZZ_SECONDS:-15}" || true
fi

# The C++ files as clang-format-14 formats them: one case beside the others.
phase format "$ISM_ROOT/scripts/check_format.sh" \
  --junit "$ISM_WS/build/test_results/inekf_semantic_mapping/format-clang_format.xml" || true

judge build/test_results
