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
# Writes a JUnit file with one case, where catkin_test_results counts it:
# ism_junit_case FILE SUITE CLASS CASE SECONDS [FAILURE_MESSAGE] (no message: the case passed).
ism_junit_case() {
  local failure="" failures=0 suite classname name message
  # Escaped: a file that does not parse was left out of the counts without a word.
  suite=$(ism_xml_escape "$2")
  classname=$(ism_xml_escape "$3")
  name=$(ism_xml_escape "$4")
  if [[ -n ${6:-} ]]; then
    message=$(ism_xml_escape "$6")
    failure="<failure message=\"$message\"/>"
    failures=1
  fi
  mkdir -p "$(dirname "$1")"
  cat >"$1" <<XML
<?xml version="1.0" encoding="UTF-8"?>
<testsuite name="$suite" tests="1" failures="$failures" errors="0" time="$5">
  <testcase classname="$classname" name="$name" time="$5">$failure</testcase>
</testsuite>
XML
}
ism_xml_escape() {
  # sed, not ${//}: bash 5.2 puts the match where a replacement says '&'.
  printf '%s' "$1" | sed -e 's/&/\&amp;/g' -e 's/</\&lt;/g' -e 's/>/\&gt;/g' -e 's/"/\&quot;/g'
}
# ism_junit_failure FILE SUITE CASE MESSAGE: one failed case (for a step that fails before it
# can report itself).
ism_junit_failure() { ism_junit_case "$1" "$2" "$2" "$3" 0 "$4"; }
