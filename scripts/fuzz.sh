#!/usr/bin/env bash
# Builds the libFuzzer harnesses of test/fuzz (clang-14, ASan + UBSan, in the build
# scripts/sanitize.sh shares) and runs each for a bounded time from its checked-in seed corpus.
# Each harness is one test case: its JUnit result goes where catkin_test_results reads (so
# ./scripts/test.sh counts it), and a crash input is kept in $ISM_WS/fuzz/findings/. Usage: scripts/fuzz.sh [SECONDS_PER_HARNESS (default 20)]
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
seconds=${1:-${ISM_FUZZ_SECONDS:-20}}
# The build scripts/sanitize.sh shares (the core is compiled once for both).
build=$ISM_WS/sanitizers
results=$ISM_WS/build/test_results/inekf_semantic_mapping
findings=$ISM_WS/fuzz/findings
mkdir -p "$build" "$results" "$findings"

echo "[fuzz] building the harnesses (clang-14, ASan + UBSan) in $build"
build_failed() {
  tail -n 60 "$1"
  ism_junit_failure "$results/fuzz-build.xml" fuzz_build build "see $1"
  exit 1
}
CC=clang-14 CXX=clang++-14 cmake -S "$ISM_ROOT/test/fuzz" -B "$build" -DCMAKE_BUILD_TYPE=Debug \
  >"$build/configure.log" 2>&1 || build_failed "$build/configure.log"
cmake --build "$build" --target fuzz_harnesses -j"$ISM_JOBS" >"$build/build.log" 2>&1 ||
  build_failed "$build/build.log"

failed=0
for harness in oxts calibration velodyne poses semantic_ot configs command_line; do
  corpus=$ISM_WS/fuzz/corpus/$harness
  rm -rf "$corpus"
  mkdir -p "$corpus"
  cp "$ISM_ROOT/test/fuzz/corpus/$harness/"* "$corpus/"
  log=$ISM_WS/fuzz/$harness.log
  start_ns=$(date +%s%N)
  set +e
  # -rss_limit_mb: a file that makes a reader allocate gigabytes is a finding too.
  ASAN_OPTIONS=detect_leaks=0 UBSAN_OPTIONS=print_stacktrace=1 \
    "$build/fuzz_$harness" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 \
    -artifact_prefix="$findings/$harness-" -print_final_stats=1 "$corpus" >"$log" 2>&1
  rc=$?
  set -e
  elapsed_ms=$((($(date +%s%N) - start_ns) / 1000000))
  elapsed=$((elapsed_ms / 1000)).$(printf %03d $((elapsed_ms % 1000)))
  runs=$(grep -aoE 'stat::number_of_executed_units: *[0-9]+' "$log" | grep -oE '[0-9]+$' || echo 0)
  if ((rc == 0)); then
    echo "[fuzz] $harness: $runs inputs in ${seconds} s, no finding"
    failure=""
  else
    failed=$((failed + 1))
    echo "[fuzz] $harness: FINDING (exit $rc), log $log; inputs in $findings"
    grep -aE 'ERROR|runtime error|SUMMARY' "$log" | head -n 5 || true
    failure="libFuzzer exit $rc: see $log"
  fi
  ism_junit_case "$results/fuzz-$harness.xml" "fuzz_$harness" fuzz "$harness ($runs inputs)" \
    "$elapsed" "$failure"
done
((failed == 0))
