#!/usr/bin/env bash
# Installs the Debian 12 packages this package needs (ROS 1 from Debian's own archive).
# Idempotent: runs `apt-get update` and `apt-get install` only when something is missing.
# Usage: scripts/install_deps.sh   (the training's packages are in the list: its test runs in CI)
set -euo pipefail
export PATH=/usr/bin:/bin:/usr/sbin:/sbin:$PATH

PACKAGES=(
  # build + ROS core
  build-essential cmake catkin catkin-lint libroscpp-dev python3-rospy rosout rosbash
  python3-rosmaster python3-roslaunch python3-rostest librostest-dev python3-rostopic
  python3-rosservice python3-rosnode python3-rosparam python3-rosmsg python3-rosgraph
  ros-message-generation ros-message-runtime
  # messages (C++ headers, .msg definitions, Python bindings)
  libstd-msgs-dev ros-std-msgs python3-std-msgs
  libgeometry-msgs-dev ros-geometry-msgs python3-geometry-msgs
  libsensor-msgs-dev ros-sensor-msgs python3-sensor-msgs
  libnav-msgs-dev ros-nav-msgs python3-nav-msgs
  libvisualization-msgs-dev ros-visualization-msgs python3-visualization-msgs
  libstd-srvs-dev ros-std-srvs python3-std-srvs
  libros-rosgraph-msgs-dev ros-rosgraph-msgs python3-rosgraph-msgs
  libdiagnostic-msgs-dev ros-diagnostic-msgs python3-diagnostic-msgs
  # /diagnostics of every node (diagnostic_updater)
  libdiagnostic-updater-dev
  # the segmentation and map nodes as nodelets, and the nodelet manager
  libnodeletlib-dev libnodelet-dev libnodeletlib-tools pluginlib-dev
  # tf, bags, sync, images, clouds
  libtf2-ros-dev python3-tf2-ros tf2-tools libtf2-eigen-dev libtf2-geometry-msgs-dev
  librosbag-dev python3-rosbag libmessage-filters-dev
  libcv-bridge-dev python3-cv-bridge libimage-transport-dev
  libpcl-ros-dev libpcl-conversions-dev
  # core libraries
  libeigen3-dev libopencv-dev liboctomap-dev octomap-tools octovis libyaml-cpp-dev
  libpcl-dev  # registration for the loop closure (PCL GICP)
  # tests, benchmarks, scripts, headless rviz
  libgtest-dev libbenchmark-dev python3-numpy python3-matplotlib python3-yaml
  rviz xvfb imagemagick
  # network namespaces of scripts/two_host_demo.sh (segmentation on a second host)
  iproute2
  # fuzz harnesses (libFuzzer with clang) run by scripts/fuzz.sh
  clang-14 libfuzzer-14-dev
  # scripts/check_format.sh (clang-format-14 over the files git tracks)
  clang-format-14 git
  # the camera adaptation (training/) and its test: PyTorch, ONNX (the export's input size and
  # checks), OpenCV's Python binding
  python3-torch python3-onnx python3-opencv
)

missing=()
for pkg in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
if ((${#missing[@]} == 0)); then
  echo "[install_deps] all ${#PACKAGES[@]} packages present"
  exit 0
fi
echo "[install_deps] installing ${#missing[@]} missing packages: ${missing[*]}"
SUDO=""
[[ $(id -u) -ne 0 ]] && SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
echo "[install_deps] done"
