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
