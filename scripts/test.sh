#!/usr/bin/env bash
# Installs what is missing, builds, runs every gtest and rostest, and judges the results with
# catkin_test_results (`catkin_make run_tests` exits 0 even when tests fail).
# Ends with one line `N passed, N failed, N skipped`; exits non-zero on any failure.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
start=$(date +%s)

"$ISM_ROOT/scripts/install_deps.sh"
if ! ISM_SKIP_DEPS=1 "$ISM_ROOT/scripts/build.sh" all tests; then
  echo "[test] BUILD FAILED"
  echo "0 passed, 1 failed"
  exit 1
fi

cd "$ISM_WS"
rm -rf build/test_results
log=$ISM_WS/run_tests.log
echo "[test] running tests (log: $log)"
# Tests run one after another: rostests start their own masters and share the 2 cores.
set +e
stdbuf -oL -eL catkin_make run_tests -j1 >"$log" 2>&1
set -e
grep -E '^\[ *(RUN|OK|FAILED|SKIPPED|PASSED) *\]|^\[ROSTEST\]|^\[ROSUNIT\]|SKIPPED:|FAILURE|Error' "$log" | tail -n 400 || true

# The core's unit tests again under ASan + UBSan, and every parser's fuzz harness for a bounded
# time (ISM_FUZZ_SECONDS each); both write their results beside the others.
if [[ ${ISM_SKIP_SANITIZERS:-0} != 1 ]]; then
  "$ISM_ROOT/scripts/sanitize.sh" || true
  "$ISM_ROOT/scripts/fuzz.sh" "${ISM_FUZZ_SECONDS:-15}" || true
fi

summary=$(catkin_test_results build/test_results --verbose 2>&1 || true)
echo "$summary" | grep -vE '^$' | tail -n 60
line=$(echo "$summary" | grep -E '^Summary:' | tail -n 1)
total=$(echo "$line" | sed -E 's/.*Summary: ([0-9]+) tests.*/\1/')
errors=$(echo "$line" | sed -E 's/.* ([0-9]+) errors.*/\1/')
failures=$(echo "$line" | sed -E 's/.* ([0-9]+) failures.*/\1/')
skipped=$(echo "$line" | sed -E 's/.* ([0-9]+) skipped.*/\1/')
[[ $total =~ ^[0-9]+$ ]] || { echo "[test] no test results found"; echo "0 passed, 1 failed"; exit 1; }
[[ $skipped =~ ^[0-9]+$ ]] || skipped=0
failed=$((errors + failures))
passed=$((total - failed - skipped))
echo "[test] finished in $(( $(date +%s) - start )) s"
echo "$passed passed, $failed failed, $skipped skipped"
((failed == 0 && total > 0))
