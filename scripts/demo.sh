#!/usr/bin/env bash
# The whole system on one drive, headless, in a few minutes:
#   scripts/demo.sh                                   # synthetic 30 s drive (fixed seed), generated here
#   scripts/demo.sh KITTI_DRIVE_DIR --model MODEL     # a KITTI raw <date>_drive_<nnnn>_sync folder
#   ... [--output DIR]                                # where the results go (output/demo)
# MODEL is the segmentation network for the drive's camera images (ONNX, Torch7 .net, ...): for a
# real drive the network adapted to the KITTI camera (output/models/kitti/kitti_adapted.onnx from
# scripts/adapt_segmentation.sh), the Cityscapes ENet (.../enet-cityscapes/enet-model.net), or
# `none` for a lidar-only map. A real drive without --model is an error: the default U-Net (models/unet_synthetic.onnx)
# was trained on the project's synthetic world only and labels real images wrongly, and a demo
# that quietly maps with it would look like a broken pipeline.
# Installs what is missing and builds (scripts/build.sh), converts the drive into a bag with
# kitti2bag (GPS degraded as in the evaluation protocol: 1.5 m / 3 m noise, 1 Hz), runs
# launch/kitti_bag.launch with rviz on a virtual display (Xvfb + Mesa), saves the map with
# ~save_map, and writes output/demo/ (or --output DIR, emptied first: a folder of its own, or one
# an earlier demo wrote): trajectory.png, metrics.json, semantic_map.ot,
# semantic_map.ply, rviz.png (+ logs), and prints a summary (trajectory error against the OXTS
# truth, scans in the map, label images per second, scan-to-map latency).
# Environment: ISM_DEMO_MODEL (same as --model; the synthetic drive's default is
# models/unet_synthetic.onnx), ISM_DEMO_DURATION (synthetic drive seconds, 30), ISM_DEMO_SEED (42),
# ISM_DEMO_GENERATOR_ARGS (default: a 32-beam lidar and 621x188 images, so that generation and
# segmentation fit a few minutes on 2 cores; "" for the full HDL-64 / 1242x375 rig),
# ISM_DEMO_RATE (playback rate, 1.0), ISM_DEMO_SKIP_BUILD=1, ISM_DEMO_PORT (ROS master port).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
start=$(date +%s)
# The header comment: line 2 up to the first line that is not a comment.
usage() { sed -n '2,/^[^#]/{/^#/p}' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; }
drive=""
model=${ISM_DEMO_MODEL:-}
out=$ISM_ROOT/output/demo
while (($#)); do
  case $1 in
    --model) [[ $# -ge 2 ]] || { echo "[demo] --model needs a value (a model file or none)" >&2; exit 2; }
             model=$2; shift 2 ;;
    --model=*) model=${1#--model=}; shift ;;
    --output) [[ $# -ge 2 ]] || { echo "[demo] --output needs a folder" >&2; exit 2; }
              out=$2; shift 2 ;;
    --output=*) out=${1#--output=}; shift ;;
    -h | --help) usage; exit 0 ;;
    -*) echo "[demo] unknown option $1" >&2; usage >&2; exit 2 ;;
    *) [[ -z $drive ]] || { echo "[demo] one drive only (got $drive and $1)" >&2; exit 2; }
       drive=$1; shift ;;
  esac
done
synthetic_model=$ISM_ROOT/models/unet_synthetic.onnx
if [[ -z $drive ]]; then
  model=${model:-$synthetic_model}
elif [[ -z $model ]]; then
  cat >&2 <<EOM
[demo] ERROR: $drive is a real drive and no segmentation model was given.
[demo] The default U-Net (models/unet_synthetic.onnx) knows only the synthetic world; on real
[demo] images its labels are wrong. Pass the network adapted to the KITTI camera (made by
[demo] scripts/adapt_segmentation.sh from the Cityscapes weights and KITTI labels you have), e.g.
[demo]   scripts/demo.sh $drive --model output/models/kitti/kitti_adapted.onnx
[demo] or the Cityscapes ENet (the e-lab ENet, Torch7 enet-model.net, CC BY-NC 4.0: not part
[demo] of this repository), e.g.
[demo]   scripts/demo.sh $drive --model /path/to/shared/models/enet-cityscapes/enet-model.net
[demo] or map without labels (occupancy only):
[demo]   scripts/demo.sh $drive --model none
EOM
  exit 2
elif [[ $model != none && -f $model && $(realpath "$model") == $(realpath "$synthetic_model") ]]; then
  echo "[demo] WARNING: the synthetic-world U-Net on a real drive: expect wrong labels" >&2
fi
if [[ $model == none ]]; then
  echo "[demo] --model none: no segmentation, the map holds occupancy only (unlabeled voxels)" >&2
else
  [[ -f $model ]] || { echo "[demo] segmentation model $model not found (--model FILE, or --model none)" >&2; exit 2; }
  model=$(realpath "$model")
fi
[[ -z $drive || -d $drive/oxts ]] || { echo "[demo] $drive is not a KITTI raw drive folder (no oxts/)" >&2; exit 2; }
duration=${ISM_DEMO_DURATION:-30}
seed=${ISM_DEMO_SEED:-42}
rate=${ISM_DEMO_RATE:-1.0}
generator_args=${ISM_DEMO_GENERATOR_ARGS---lidar-beams 32 --azimuth-step-deg 0.4 --image-size 621x188}
# The folder is emptied below: only the default one, an empty or new one, or one a demo wrote
# (its marker file) -- never a folder of the user's with other things in it.
out=$(realpath -m "$out")
marker=.ism_demo_output
if [[ $out != $(realpath -m "$ISM_ROOT/output/demo") && -d $out && -n $(ls -A "$out") &&
      ! -f $out/$marker ]]; then
  echo "[demo] --output $out holds files a demo did not write: give a new or empty folder" >&2
  exit 2
fi
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

rm -rf "$out"
mkdir -p "$out"
touch "$out/$marker"
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
# The calibration is in the date folder: beside the drive as given, or beside the folder a link to
# the drive points to.
calib_dir=$(dirname "$drive")
[[ -f $calib_dir/calib_cam_to_cam.txt ]] || calib_dir=$(dirname "$(cd "$drive" && pwd -P)")

# The map frame is the devkit Mercator frame at the drive's first fix (as the ground truth's):
# inekf_node gets that origin instead of its first noisy fix, so the two trajectories compare.
read -r origin_lat origin_lon origin_alt _ <"$(ls "$drive"/oxts/data/*.txt | head -n 1)"

log "converting $drive into a bag (kitti2bag, GPS: 1.5 m / 3 m noise, every 10th fix)"
t0=$(date +%s)
"$ISM_BIN/kitti2bag" --drive "$drive" --calib-dir "$calib_dir" --output "$out/drive.bag" \
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
xvfb_pid="" launch_pid="" monitor_pid="" rviz_pid="" clock_pid=""
# Stops one child and reaps it: SIGNAL, up to SECONDS to exit, then SIGKILL.
stop_child() {
  local pid=$1 signal=$2 seconds=$3 i
  [[ -n $pid ]] || return 0
  kill "-$signal" "$pid" 2>/dev/null || return 0
  for ((i = 0; i < seconds * 10; i++)); do
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.1
  done
  kill -0 "$pid" 2>/dev/null && kill -KILL "$pid" 2>/dev/null
  wait "$pid" 2>/dev/null || true
}
# Users of the X display first, the display last: rviz whose X server goes away first dies with
# "Aborted" (Qt's fatal X I/O error) instead of shutting down.
cleanup() {
  stop_child "$rviz_pid" INT 10
  stop_child "$monitor_pid" INT 10
  stop_child "$clock_pid" INT 5
  stop_child "$launch_pid" INT 30
  stop_child "$xvfb_pid" TERM 5
  xvfb_pid="" launch_pid="" monitor_pid="" rviz_pid="" clock_pid=""
}
trap cleanup EXIT

Xvfb "$display" -screen 0 1400x900x24 -nolisten tcp >"$out/xvfb.log" 2>&1 &
xvfb_pid=$!
export DISPLAY=$display LIBGL_ALWAYS_SOFTWARE=1

log "running kitti_bag.launch (bag ${bag_duration} s at rate $rate, master port $port, model $model)"
roslaunch -p "$port" inekf_semantic_mapping kitti_bag.launch bag:="$out/drive.bag" rate:="$rate" model:="$model" \
  rviz:=false play_delay:=5 origin_lat:="$origin_lat" origin_lon:="$origin_lon" origin_alt:="$origin_alt" gps_sigma_h:=1.5 gps_sigma_v:=3 gps_every:=10 >"$out/launch.log" 2>&1 &
launch_pid=$!
# Waits up to 120 s for NODE to register; stops the demo (the EXIT trap cleans up) when roslaunch
# dies or the time runs out.
wait_for_node() {
  local node=$1 i
  for ((i = 0; i < 240; i++)); do
    rosnode list 2>/dev/null | grep -q "$node" && return 0
    if ! kill -0 "$launch_pid" 2>/dev/null; then
      echo "[demo] roslaunch exited before $node started; the end of $out/launch.log:" >&2
      tail -n 30 "$out/launch.log" >&2
      exit 1
    fi
    sleep 0.5
  done
  echo "[demo] $node did not start within 120 s; the end of $out/launch.log:" >&2
  tail -n 30 "$out/launch.log" >&2
  exit 1
}
wait_for_node /semantic_octomap_node
"$ISM_ROOT/scripts/pipeline_monitor.py" _output_dir:="$out" >"$out/monitor.log" 2>&1 &
monitor_pid=$!
wait_for_node /rosbag_play
play_start=$(date +%s)
sleep 2
nodes=(/inekf_node /semantic_octomap_node)
[[ $model == none ]] || nodes+=(/segmentation_node)
for node in "${nodes[@]}"; do
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
    rviz_pid=$!
    rviz_started=1
  fi
  sleep 1
done
play_wall_s=$(($(date +%s) - play_start))
log "bag finished after ${play_wall_s} s; saving the map"
# Time goes on after the bag (see scripts/clock_after_bag.py: a tf wait under a stopped sim clock
# would block the map node's service).
"$ISM_ROOT/scripts/clock_after_bag.py" _start:="$bag_end" >"$out/clock.log" 2>&1 &
clock_pid=$!
sleep 3
if ((rviz_started == 0)); then
  rosrun rviz rviz -d "$ISM_ROOT/rviz/kitti.rviz" >"$out/rviz.log" 2>&1 &
  rviz_pid=$!
  sleep 15
fi
for format in ot ply; do
  timeout 120 rosservice call /semantic_octomap_node/save_map "{path: '$out/semantic_map.$format', format: $format}" |
    tee -a "$out/save_map.log" || log "save_map ($format) failed or timed out"
done
sleep 2
import -display "$display" -window root "$out/rviz.png" || log "screenshot failed"
cleanup
trap - EXIT

log "computing metrics"
metrics_args=(--monitor-dir "$out" --bag "$out/drive.bag" --map-ply "$out/semantic_map.ply" --map-ot "$out/semantic_map.ot"
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
