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

# judge RESULTS_DIR: the closing line from catkin_test_results; non-zero on any failure.
judge() {
  local summary line total errors failures skipped failed passed
  summary=$(catkin_test_results "$1" --verbose 2>&1 || true)
  echo "$summary" | grep -vE '^$' | tail -n 60
  line=$(echo "$summary" | grep -E '^Summary:' | tail -n 1)
  total=$(echo "$line" | sed -E 's/.*Summary: ([0-9]+) tests.*/\1/')
  errors=$(echo "$line" | sed -E 's/.* ([0-9]+) errors.*/\1/')
  failures=$(echo "$line" | sed -E 's/.* ([0-9]+) failures.*/\1/')
  skipped=$(echo "$line" | sed -E 's/.* ([0-9]+) skipped.*/\1/')
  [[ $total =~ ^[0-9]+$ ]] || { echo "[test] no test results found"; echo "0 passed, 1 failed"; return 1; }
  [[ $skipped =~ ^[0-9]+$ ]] || skipped=0
  failed=$((errors + failures))
  passed=$((total - failed - skipped))
  echo "[test] $tier tier finished in $(( $(date +%s) - start )) s"
  echo "$passed passed, $failed failed, $skipped skipped"
  ((failed == 0 && total > 0))
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
      [[ -s $results/gtest-$name.xml ]] ||
        ism_junit_failure "$results/gtest-$name.xml" "$name" "$name" "exit $rc, no results"
    fi
  done <"$list"
  judge "$results"
  exit
fi

phase install_deps "$ISM_ROOT/scripts/install_deps.sh"
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
phase run_tests run_tests || true
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
