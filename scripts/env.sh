# Sourced by the other scripts: a clean environment for Debian's ROS 1.
# A pyenv python3 earlier on PATH breaks catkin and rospy, so /usr/bin goes first.
export PATH=/usr/bin:/bin:/usr/sbin:/sbin:${PATH}
unset PYTHONHOME PYENV_VERSION
ISM_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
ISM_WS=${ISM_WS:-$ISM_ROOT/.ws}
ISM_JOBS=${ISM_JOBS:-$(nproc)}
ISM_BIN=$ISM_WS/devel/lib/inekf_semantic_mapping
export ISM_ROOT ISM_WS ISM_JOBS ISM_BIN
# Source the workspace (if built) without tripping `set -u` in catkin's setup files.
ism_source_workspace() {
  if [[ -f $ISM_WS/devel/setup.bash ]]; then
    set +u
    # shellcheck disable=SC1091
    source "$ISM_WS/devel/setup.bash"
    set -u
  fi
}
# Writes a JUnit file with one failed case, where catkin_test_results counts it:
# ism_junit_failure FILE SUITE CASE MESSAGE (for a step that fails before it can report itself).
ism_junit_failure() {
  cat >"$1" <<XML
<?xml version="1.0" encoding="UTF-8"?>
<testsuite name="$2" tests="1" failures="1" errors="0">
  <testcase classname="$2" name="$3"><failure message="$4"/></testcase>
</testsuite>
XML
}
