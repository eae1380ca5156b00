#!/usr/bin/env bash
# Checks that the tree's C++ files (tracked, under include/ src/ test/ bench/) are as
# clang-format-14 formats them with the repository's .clang-format; lists the files that are not.
# `scripts/check_format.sh --fix` formats them in place. With --junit FILE the result is also
# written as one JUnit case (./scripts/test.sh's full tier, where catkin_test_results reads).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
cd "$ISM_ROOT"
fix=0
junit=""
while (($#)); do
  case $1 in
    --fix) fix=1 ;;
    --junit) junit=$2; shift ;;
    *) echo "usage: $0 [--fix] [--junit FILE]" >&2; exit 2 ;;
  esac
  shift
done
# The JUnit case (with --junit): write_junit SECONDS NAME [FAILURE_MESSAGE].
write_junit() {
  [[ -z $junit ]] || ism_junit_case "$junit" format format "$2" "$1" "${3:-}"
}
# Without clang-format-14 (or git) nothing would be checked: fail instead of passing silently.
for tool in clang-format-14 git; do
  if ! command -v "$tool" >/dev/null; then
    echo "[format] ERROR: $tool not found; scripts/install_deps.sh installs it" >&2
    write_junit 0.000 clang_format_14 "$tool not found (scripts/install_deps.sh installs it)"
    exit 1
  fi
done
mapfile -t files < <(git ls-files -- 'include/*.h' 'include/*.hpp' 'src/*.cpp' 'src/*.h' \
  'test/*.cpp' 'test/*.h' 'bench/*.cpp' 'bench/*.h')
if ((fix)); then
  clang-format-14 -i "${files[@]}"
  echo "[format] formatted ${#files[@]} files"
  exit 0
fi
start_ns=$(date +%s%N)
set +e
output=$(clang-format-14 --dry-run -Werror "${files[@]}" 2>&1)
status=$?
set -e
mapfile -t bad < <(printf '%s\n' "$output" |
  grep -oE '^[^:]+\.(cpp|h|hpp):[0-9]+:[0-9]+: error' | cut -d: -f1 | sort -u)
# clang-format failing for another reason (an unreadable .clang-format) listed no file and passed.
if ((status != 0 && ${#bad[@]} == 0)); then
  echo "[format] ERROR: clang-format-14 failed (exit $status): $(printf '%s\n' "$output" | head -n 3)" >&2
  write_junit 0.000 clang_format_14 "clang-format-14 failed (exit $status)"
  exit 1
fi
elapsed_ms=$((($(date +%s%N) - start_ns) / 1000000))
elapsed=$((elapsed_ms / 1000)).$(printf %03d $((elapsed_ms % 1000)))
if ((${#bad[@]})); then
  echo "[format] ${#bad[@]} of ${#files[@]} files differ from clang-format-14 (scripts/check_format.sh --fix):"
  printf '  %s\n' "${bad[@]}"
else
  echo "[format] ${#files[@]} files as clang-format-14 formats them"
fi
failure=""
((${#bad[@]})) && failure="${#bad[@]} files differ from clang-format-14: ${bad[*]}"
write_junit "$elapsed" "clang_format_14 (${#files[@]} files)" "$failure"
((${#bad[@]} == 0))
