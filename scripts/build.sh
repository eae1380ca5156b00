#!/usr/bin/env bash
# Builds the package (Release) in the catkin workspace .ws/ (override with ISM_WS=DIR);
# .ws/src/inekf_semantic_mapping is this repository: a folder of symlinks to its top-level
# entries. Extra arguments go to catkin_make, e.g. `scripts/build.sh tests` or
# `scripts/build.sh inekf_offline`.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"

[[ ${ISM_SKIP_DEPS:-0} == 1 ]] || "$ISM_ROOT/scripts/install_deps.sh"

# Not one symlink to the repository: the workspace lives inside it, so that link would lead back
# to its own ancestor, and rosrun (`find -L` over the package) would print "File system loop
# detected" before every tool. Each top-level entry is linked instead, except the workspaces
# themselves, .git and output/ (nothing a package path needs, and big).
package_dir=$ISM_WS/src/inekf_semantic_mapping
mkdir -p "$ISM_WS/src"
[[ -L $package_dir ]] && rm "$package_dir"  # the earlier layout
mkdir -p "$package_dir"
shopt -s dotglob nullglob
for entry in "$ISM_ROOT"/*; do
  name=${entry##*/}
  [[ $name == .ws* || $name == .git || $name == output ]] && continue
  [[ $(realpath "$entry") == "$(realpath "$ISM_WS")" ]] && continue
  ln -sfn "$entry" "$package_dir/$name"
done
for link in "$package_dir"/*; do  # entries since removed from the repository
  [[ -L $link && ! -e $link ]] && rm "$link"
done
shopt -u dotglob nullglob
# On a clean first build, catkin only puts devel/lib/python3/dist-packages on the Python path
# if it exists at configure time: without it rostests cannot import the generated messages.
mkdir -p "$ISM_WS/devel/lib/python3/dist-packages"

cd "$ISM_WS"
echo "[build] workspace $ISM_WS, $ISM_JOBS jobs"
catkin_make -DCMAKE_BUILD_TYPE=Release -DPYTHON_EXECUTABLE=/usr/bin/python3 \
  -DCATKIN_ENABLE_TESTING=ON -j"$ISM_JOBS" "$@"
echo "[build] executables in $ISM_BIN"
