#!/usr/bin/env bash
# The whole system on one drive, headless, in a few minutes:
#   scripts/demo.sh                   # synthetic 30 s drive (fixed seed), generated here
#   scripts/demo.sh KITTI_DRIVE_DIR   # a KITTI raw <date>_drive_<nnnn>_sync folder
# Installs what is missing and builds (scripts/build.sh), converts the drive into a bag with
# kitti2bag (GPS degraded as in the issue 3 protocol: 1.5 m / 3 m noise, 1 Hz), runs
# launch/kitti_bag.launch with rviz on a virtual display (Xvfb + Mesa), saves the map with
# ~save_map, and writes output/demo/: trajectory.png, metrics.json, semantic_map.ot,
# semantic_map.ply, rviz.png (+ logs).
# Environment: ISM_DEMO_DURATION (synthetic drive seconds, 30), ISM_DEMO_SEED (42),
# ISM_DEMO_GENERATOR_ARGS (default: a 32-beam lidar and 621x188 images, so that generation and
# segmentation fit a few minutes on 2 cores; "" for the full HDL-64 / 1242x375 rig),
# ISM_DEMO_MODEL (segmentation model, default models/unet_synthetic.onnx), ISM_DEMO_RATE
# (playback rate, 1.0), ISM_DEMO_SKIP_BUILD=1, ISM_DEMO_PORT (ROS master port).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
start=$(date +%s)
drive=${1:-}
duration=${ISM_DEMO_DURATION:-30}
seed=${ISM_DEMO_SEED:-42}
rate=${ISM_DEMO_RATE:-1.0}
generator_args=${ISM_DEMO_GENERATOR_ARGS---lidar-beams 32 --azimuth-step-deg 0.4 --image-size 621x188}
model=${ISM_DEMO_MODEL:-$ISM_ROOT/models/unet_synthetic.onnx}
out=$ISM_ROOT/output/demo
log() { echo "[demo $(($(date +%s) - start))s] $*"; }

mkdir -p "$ISM_ROOT/output"
if [[ ${ISM_DEMO_SKIP_BUILD:-0} != 1 ]]; then
  log "installing dependencies and building (scripts/build.sh)"
  "$ISM_ROOT/scripts/build.sh" all >"$ISM_ROOT/output/demo_build.log" 2>&1 || {
    tail -n 40 "$ISM_ROOT/output/demo_build.log"; echo "[demo] BUILD FAILED"; exit 1; }
fi
ism_source_workspace
# rviz finds its plugins' media through rospack: Debian's ROS packages live in /usr/share.
[[ :${ROS_PACKAGE_PATH:-}: == *:/usr/share:* ]] || export ROS_PACKAGE_PATH=${ROS_PACKAGE_PATH:+$ROS_PACKAGE_PATH:}/usr/share
for exe in kitti2bag inekf_node segmentation_node semantic_octomap_node; do
  [[ -x $ISM_BIN/$exe ]] || { echo "[demo] $ISM_BIN/$exe missing: build failed?"; exit 1; }
done
[[ -f $model ]] || { echo "[demo] segmentation model $model missing (set ISM_DEMO_MODEL)"; exit 1; }

rm -rf "$out"
mkdir -p "$out"
ground_truth=""
if [[ -z $drive ]]; then
  log "generating a ${duration} s synthetic drive (seed $seed)"
  t0=$(date +%s)
  # shellcheck disable=SC2086  # generator_args is a list of flags
  "$ISM_BIN/generate_synthetic_drive" --output "$out/synthetic" --seed "$seed" --duration "$duration" \
    $generator_args >"$out/generate.log" 2>&1 || { tail -n 20 "$out/generate.log"; exit 1; }
  generate_s=$(($(date +%s) - t0))
  drive=$(ls -d "$out"/synthetic/*/*_drive_*_sync | head -n 1)
  for candidate in "$drive/ground_truth" "$(dirname "$drive")/ground_truth" "$out/synthetic/ground_truth"; do
    [[ -d $candidate ]] && ground_truth=$candidate && break
  done
else
  drive=$(cd "$drive" && pwd)
  generate_s=0
fi

# The map frame is the devkit Mercator frame at the drive's first fix (as the ground truth's):
# inekf_node gets that origin instead of its first noisy fix, so the two trajectories compare.
read -r origin_lat origin_lon origin_alt _ <"$(ls "$drive"/oxts/data/*.txt | head -n 1)"

log "converting $drive into a bag (kitti2bag, GPS: 1.5 m / 3 m noise, every 10th fix)"
t0=$(date +%s)
"$ISM_BIN/kitti2bag" --drive "$drive" --calib-dir "$(dirname "$drive")" --output "$out/drive.bag" \
  --gps-sigma-h 1.5 --gps-sigma-v 3 --gps-every 10 --seed 1 >"$out/kitti2bag.log" 2>&1 ||
  { tail -n 20 "$out/kitti2bag.log"; exit 1; }
convert_s=$(($(date +%s) - t0))
read -r bag_duration bag_end < <(/usr/bin/python3 -c "import rosbag,sys; b=rosbag.Bag(sys.argv[1]); print(int(b.get_end_time()-b.get_start_time()+1), '%.6f' % b.get_end_time())" "$out/drive.bag")

# True while rosbag_play is registered; a failed listing (busy master) counts as still running.
bag_running() {
  local nodes
  nodes=$(rosnode list 2>/dev/null) || return 0
  [[ $nodes == */rosout* ]] || return 0
  grep -q /rosbag_play <<<"$nodes"
}

# A private ROS master and X display, so the demo never disturbs another running system.
port=${ISM_DEMO_PORT:-$((11400 + RANDOM % 500))}
export ROS_MASTER_URI=http://localhost:$port ROS_HOSTNAME=localhost
display=:$((90 + RANDOM % 100))
pids=()
cleanup() {
  for ((i = ${#pids[@]} - 1; i >= 0; i--)); do kill -INT "${pids[i]}" 2>/dev/null || true; done
  sleep 2
  for pid in "${pids[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
}
trap cleanup EXIT

Xvfb "$display" -screen 0 1400x900x24 -nolisten tcp >"$out/xvfb.log" 2>&1 &
pids+=($!)
export DISPLAY=$display LIBGL_ALWAYS_SOFTWARE=1

log "running kitti_bag.launch (bag ${bag_duration} s at rate $rate, master port $port)"
roslaunch -p "$port" inekf_semantic_mapping kitti_bag.launch bag:="$out/drive.bag" rate:="$rate" model:="$model" \
  rviz:=false play_delay:=5 origin_lat:="$origin_lat" origin_lon:="$origin_lon" origin_alt:="$origin_alt" gps_sigma_h:=1.5 gps_sigma_v:=3 gps_every:=10 >"$out/launch.log" 2>&1 &
pids+=($!)
until rosnode list 2>/dev/null | grep -q /semantic_octomap_node; do sleep 0.5; done
"$ISM_ROOT/scripts/pipeline_monitor.py" _output_dir:="$out" >"$out/monitor.log" 2>&1 &
monitor_pid=$!
pids+=($monitor_pid)
until rosnode list 2>/dev/null | grep -q /rosbag_play; do sleep 0.5; done
play_start=$(date +%s)
sleep 2
for node in /inekf_node /segmentation_node /semantic_octomap_node; do
  for ((try = 0; try < 30; try++)); do
    rosnode list 2>/dev/null | grep -qx "$node" && break
    sleep 1
  done
  ((try < 30)) ||
    { echo "[demo] $node is not running; its error from $out/launch.log:"; grep -E "FATAL|ERROR|died" "$out/launch.log" | head -n 5; exit 1; }
done
# rviz joins for the last part of the drive only: software GL on 2 cores would otherwise take
# CPU from the pipeline for the whole run (the path, map and markers are complete at the end).
rviz_started=0
while bag_running; do
  elapsed=$(($(date +%s) - play_start))
  remaining=$(/usr/bin/python3 -c "print(int(($bag_duration + 5) / $rate - $elapsed))")
  if ((rviz_started == 0 && remaining <= 15)); then
    rosrun rviz rviz -d "$ISM_ROOT/rviz/kitti.rviz" >"$out/rviz.log" 2>&1 &
    pids+=($!)
    rviz_started=1
  fi
  sleep 1
done
play_wall_s=$(($(date +%s) - play_start))
log "bag finished after ${play_wall_s} s; saving the map"
# Time goes on after the bag (see scripts/clock_after_bag.py: a tf wait under a stopped sim clock
# would block the map node's service).
"$ISM_ROOT/scripts/clock_after_bag.py" _start:="$bag_end" >"$out/clock.log" 2>&1 &
pids+=($!)
sleep 3
((rviz_started)) || { rosrun rviz rviz -d "$ISM_ROOT/rviz/kitti.rviz" >"$out/rviz.log" 2>&1 & pids+=($!); sleep 15; }
for format in ot ply; do
  timeout 120 rosservice call /semantic_octomap_node/save_map "{path: '$out/semantic_map.$format', format: $format}" |
    tee -a "$out/save_map.log" || log "save_map ($format) failed or timed out"
done
sleep 2
import -display "$display" -window root "$out/rviz.png" || log "screenshot failed"
kill -INT "$monitor_pid"
wait "$monitor_pid" || true
cleanup
trap - EXIT

log "computing metrics"
metrics_args=(--monitor-dir "$out" --bag "$out/drive.bag" --map-ply "$out/semantic_map.ply"
  --output "$out/metrics.json" --plot "$out/trajectory.png"
  --extra "timing_s={\"generate\": $generate_s, \"kitti2bag\": $convert_s, \"playback_wall\": $play_wall_s, \"bag_duration\": $bag_duration}")
[[ -n $ground_truth ]] && metrics_args+=(--ground-truth "$ground_truth")
if [[ -x $ISM_ROOT/scripts/evaluate_trajectory.py ]]; then
  metrics_args+=(--evaluate-trajectory "$ISM_ROOT/scripts/evaluate_trajectory.py")
fi
/usr/bin/python3 "$ISM_ROOT/scripts/compute_demo_metrics.py" "${metrics_args[@]}"

log "done in $(($(date +%s) - start)) s. Outputs in $out:"
for f in trajectory.png metrics.json semantic_map.ot semantic_map.ply rviz.png; do
  if [[ -s $out/$f ]]; then printf '  %-18s %s\n' "$f" "$(du -h "$out/$f" | cut -f1)"; else printf '  %-18s MISSING\n' "$f"; fi
done
echo "  logs: $out/*.log"
