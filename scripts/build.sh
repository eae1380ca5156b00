#!/usr/bin/env bash
# Builds the package (Release) in the catkin workspace .ws/ (override with ISM_WS=DIR);
# .ws/src/inekf_semantic_mapping is a symlink to this repository. Extra arguments go to
# catkin_make, e.g. `scripts/build.sh tests` or `scripts/build.sh inekf_offline`.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"

[[ ${ISM_SKIP_DEPS:-0} == 1 ]] || "$ISM_ROOT/scripts/install_deps.sh"

mkdir -p "$ISM_WS/src"
ln -sfn "$ISM_ROOT" "$ISM_WS/src/inekf_semantic_mapping"
# On a clean first build, catkin only puts devel/lib/python3/dist-packages on the Python path
# if it exists at configure time: without it rostests cannot import the generated messages.
mkdir -p "$ISM_WS/devel/lib/python3/dist-packages"

cd "$ISM_WS"
echo "[build] workspace $ISM_WS, $ISM_JOBS jobs"
catkin_make -DCMAKE_BUILD_TYPE=Release -DPYTHON_EXECUTABLE=/usr/bin/python3 \
  -DCATKIN_ENABLE_TESTING=ON -j"$ISM_JOBS" "$@"
echo "[build] executables in $ISM_BIN"
