#!/usr/bin/env bash
# Segmentation on a second host, tried on one machine: two network namespaces joined by a veth
# pair stand for the robot and a GPU host.
#   ism_robot  10.77.0.1/24: roscore, inekf_node, semantic_octomap_node
#              (launch/include/pipeline.launch run_segmentation:=false), rosbag play
#   ism_gpu    10.77.0.2/24: segmentation_node alone (ROS_MASTER_URI=http://10.77.0.1:11311)
# Every ROS connection between the two (images out, label images back, the master's XML-RPC)
# crosses the veth, whose byte counters give the bandwidth.
#   scripts/two_host_demo.sh                                  # synthetic 10 s drive, U-Net
#   scripts/two_host_demo.sh KITTI_DRIVE_DIR --model MODEL    # a real drive (ENet .net for KITTI)
#   scripts/two_host_demo.sh --bag BAG --model MODEL          # an existing kitti2bag bag
# Options: --duration S (synthetic drive seconds, 10), --rate R (playback rate, 1.0),
#   --link RATE (shape both veth ends with tc tbf, e.g. 100mbit: a slower network),
#   --out DIR (output/two_host), --check (exit 1 unless label images crossed and the map got
#   labelled scans). Needs root and `ip netns`; exits 77 (skip) when namespaces cannot be made.
# Prints and writes DIR/summary.json: label images published (gpu side) and received by the map
# node (robot side, /semantic_map/info), scans in the map, bytes/s over the veth each way, and the
# raw vs PNG/JPEG sizes of the images and label images (what a compressed transport would save).
# Environment: ISM_TWO_HOST_GENERATOR_ARGS (default: 32 beams, 621x188 images as scripts/demo.sh;
# "" for the full HDL-64 / 1242x375 rig), ISM_TWO_HOST_SEED (42), ISM_TWO_HOST_ID (suffix of the
# namespace and interface names, default the shell's pid: parallel runs do not collide).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
start=$(date +%s)
usage() { sed -n '2,24p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; }
log() { echo "[two_host $(($(date +%s) - start))s] $*"; }
die() { echo "[two_host] ERROR: $*" >&2; exit 1; }
skip() { echo "[two_host] SKIPPED: $*" >&2; exit 77; }

drive="" bag="" model="" duration=10 rate=1.0 link="" out=$ISM_ROOT/output/two_host check=0
while (($#)); do
  case $1 in
    --model | --bag | --duration | --rate | --link | --out)
      [[ $# -ge 2 ]] || { echo "[two_host] $1 needs a value" >&2; exit 2; }
      case $1 in
        --model) model=$2 ;; --bag) bag=$2 ;; --duration) duration=$2 ;;
        --rate) rate=$2 ;; --link) link=$2 ;; --out) out=$2 ;;
      esac
      shift 2 ;;
    --check) check=1; shift ;;
    -h | --help) usage; exit 0 ;;
    -*) echo "[two_host] unknown option $1" >&2; usage >&2; exit 2 ;;
    *) [[ -z $drive ]] || { echo "[two_host] one drive only" >&2; exit 2; }
       drive=$1; shift ;;
  esac
done
synthetic_model=$ISM_ROOT/models/unet_synthetic.onnx
if [[ -z $drive && -z $bag ]]; then
  model=${model:-$synthetic_model}
elif [[ -z $model ]]; then
  echo "[two_host] a real drive or a bag needs --model (the Cityscapes ENet enet-model.net for KITTI images)" >&2
  exit 2
fi
[[ -f $model ]] || { echo "[two_host] model $model not found" >&2; exit 2; }
model=$(realpath "$model")
[[ -z $bag || -f $bag ]] || { echo "[two_host] bag $bag not found" >&2; exit 2; }
[[ -z $drive || -d $drive/oxts ]] || { echo "[two_host] $drive is not a KITTI raw drive folder" >&2; exit 2; }

# Namespaces need root (CAP_SYS_ADMIN + CAP_NET_ADMIN) and iproute2's netns support.
((EUID == 0)) || skip "needs root (ip netns add); run as root, e.g. sudo $0"
command -v ip >/dev/null || skip "no ip command (iproute2)"
ip netns list >/dev/null 2>&1 || skip "ip netns is not available here"

ism_source_workspace
for exe in inekf_node segmentation_node semantic_octomap_node kitti2bag generate_synthetic_drive; do
  [[ -x $ISM_BIN/$exe ]] || die "$ISM_BIN/$exe missing: build first (scripts/build.sh all)"
done
probe=$ISM_ROOT/scripts/two_host_probe.py
mkdir -p "$out"
out=$(realpath "$out")
# Only what this script writes (an --out folder may hold other files).
rm -f "$out"/{summary,labels_published,map_info,image_encodings}.json "$out"/veth_bytes.txt \
  "$out"/{generate,kitti2bag,netns,roscore,segmentation_node,probe_gpu,launch,play,clock,probe_info,probe_encodings}.log

# --- data: a bag (kitti2bag) from a synthetic or real drive, unless one was given ---
origin_args=()
if [[ -z $bag ]]; then
  if [[ -z $drive ]]; then
    log "generating a ${duration} s synthetic drive"
    rm -rf "$out/synthetic"
    # shellcheck disable=SC2086  # a list of flags
    "$ISM_BIN/generate_synthetic_drive" --output "$out/synthetic" --seed "${ISM_TWO_HOST_SEED:-42}" \
      --duration "$duration" ${ISM_TWO_HOST_GENERATOR_ARGS---lidar-beams 32 --azimuth-step-deg 0.4 --image-size 621x188} \
      >"$out/generate.log" 2>&1 || { tail -n 20 "$out/generate.log"; die "generate_synthetic_drive failed"; }
    drive=$(ls -d "$out"/synthetic/*/*_drive_*_sync | head -n 1)
  fi
  drive=$(realpath "$drive")
  read -r lat lon alt _ <"$(ls "$drive"/oxts/data/*.txt | head -n 1)"
  origin_args=(origin_lat:="$lat" origin_lon:="$lon" origin_alt:="$alt")
  log "converting $drive into a bag (kitti2bag)"
  bag=$out/drive.bag
  "$ISM_BIN/kitti2bag" --drive "$drive" --calib-dir "$(dirname "$drive")" --output "$bag" \
    --gps-sigma-h 1.5 --gps-sigma-v 3 --gps-every 10 --seed 1 >"$out/kitti2bag.log" 2>&1 ||
    { tail -n 20 "$out/kitti2bag.log"; die "kitti2bag failed"; }
fi
bag=$(realpath "$bag")
image_topic=/kitti/camera_color_left/image_raw

# --- the two "hosts" ---
id=${ISM_TWO_HOST_ID:-$$}
ns_robot=ism_robot_$id ns_gpu=ism_gpu_$id
veth_robot=ismr${id:0:10} veth_gpu=ismg${id:0:10}  # interface names: 15 characters at most
robot_ip=10.77.0.1 gpu_ip=10.77.0.2 port=11311
master=http://$robot_ip:$port
pids=()
netns_made=()
# Runs a command as the robot / the GPU host: its namespace, its ROS_IP, the robot's master.
# --default-signal: a script's background job starts with SIGINT ignored, and rospy/roslaunch then
# never shut down on SIGINT (killed instead, losing their output); this gives it back.
# Background jobs use the arrays directly ("${as_robot[@]}" cmd &): $! is then the command itself
# (ip and env exec it), not a subshell, so that stop_pid signals the node.
as_robot=(ip netns exec "$ns_robot" env --default-signal=INT -u ROS_HOSTNAME ROS_MASTER_URI="$master" ROS_IP="$robot_ip")
as_gpu=(ip netns exec "$ns_gpu" env --default-signal=INT -u ROS_HOSTNAME ROS_MASTER_URI="$master" ROS_IP="$gpu_ip")
on_robot() { "${as_robot[@]}" "$@"; }
on_gpu() { "${as_gpu[@]}" "$@"; }
stop_pid() {  # PID SIGNAL SECONDS: signal, wait, then SIGKILL
  local pid=$1 i
  kill "-$2" "$pid" 2>/dev/null || return 0
  for ((i = 0; i < $3 * 10; i++)); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
  kill -KILL "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
}
cleanup() {
  local i ns pid
  [[ -z $sampler_pid ]] || stop_pid "$sampler_pid" TERM 5
  sampler_pid=""
  for ((i = ${#pids[@]} - 1; i >= 0; i--)); do stop_pid "${pids[i]}" INT 15; done
  pids=()
  for ns in "${netns_made[@]}"; do
    # Anything still running in our namespaces was started by this script (children of roslaunch).
    for pid in $(ip netns pids "$ns" 2>/dev/null); do kill -KILL "$pid" 2>/dev/null || true; done
    ip netns del "$ns" 2>/dev/null || true  # also removes the veth end inside it
  done
  netns_made=()
  ip link del "$veth_robot" 2>/dev/null || true
}
trap cleanup EXIT
trap 'exit 130' INT TERM
sampler_pid=""

for ns in "$ns_robot" "$ns_gpu"; do
  ip netns add "$ns" 2>"$out/netns.log" || skip "ip netns add $ns failed ($(cat "$out/netns.log")): no CAP_SYS_ADMIN in this container?"
  netns_made+=("$ns")
  # exec needs to mount /sys for the namespace (CAP_SYS_ADMIN): a container may allow add, not exec.
  ip netns exec "$ns" true 2>"$out/netns.log" || skip "ip netns exec $ns failed ($(cat "$out/netns.log"))"
  ip -n "$ns" link set lo up
done
ip link add "$veth_robot" type veth peer name "$veth_gpu" || skip "cannot create a veth pair"
ip link set "$veth_robot" netns "$ns_robot"
ip link set "$veth_gpu" netns "$ns_gpu"
ip -n "$ns_robot" addr add "$robot_ip/24" dev "$veth_robot"
ip -n "$ns_gpu" addr add "$gpu_ip/24" dev "$veth_gpu"
ip -n "$ns_robot" link set "$veth_robot" up
ip -n "$ns_gpu" link set "$veth_gpu" up
if [[ -n $link ]]; then
  ip netns exec "$ns_robot" tc qdisc add dev "$veth_robot" root tbf rate "$link" burst 256kb latency 100ms
  ip netns exec "$ns_gpu" tc qdisc add dev "$veth_gpu" root tbf rate "$link" burst 256kb latency 100ms
fi
log "namespaces $ns_robot ($robot_ip, $veth_robot) and $ns_gpu ($gpu_ip, $veth_gpu) joined${link:+, link shaped to $link}"

# --- robot: the master ---
"${as_robot[@]}" roscore -p "$port" >"$out/roscore.log" 2>&1 &
pids+=($!)
for ((try = 0; try < 60; try++)); do
  on_robot rosparam set /use_sim_time true >/dev/null 2>&1 && break
  sleep 0.5
done
((try < 60)) || { tail -n 20 "$out/roscore.log"; die "roscore did not start in $ns_robot"; }
# The GPU host reaches the master over the veth (no ping in a minimal container: the master is the probe).
for ((try = 0; try < 20; try++)); do
  on_gpu rosparam get /use_sim_time >/dev/null 2>&1 && break
  sleep 0.5
done
((try < 20)) || die "$ns_gpu cannot reach the master $master over the veth"

# --- GPU host: segmentation_node alone, and a counter of what it publishes (local, no veth) ---
on_gpu rosparam load "$ISM_ROOT/config/segmentation.yaml" /segmentation_node
"${as_gpu[@]}" "$ISM_BIN/segmentation_node" __name:=segmentation_node _model:="$model" _image_topic:="$image_topic" \
  >"$out/segmentation_node.log" 2>&1 &
pids+=($!)
"${as_gpu[@]}" /usr/bin/python3 "$probe" count /segmentation/labels "$out/labels_published.json" --png \
  >"$out/probe_gpu.log" 2>&1 &
gpu_probe_pid=$!
pids+=("$gpu_probe_pid")
# segmentation_node subscribed (it loads the model first) before the bag starts. One master
# query per poll: `rostopic info | grep -q` under pipefail can fail on a match (SIGPIPE), and
# once kept a CI run waiting until its time ran out with every node subscribed.
on_robot /usr/bin/python3 "$probe" subscribed 60 "$image_topic=/segmentation_node" ||
  { tail -n 20 "$out/segmentation_node.log"; die "segmentation_node did not subscribe"; }
log "segmentation_node runs in $ns_gpu and subscribes to $image_topic across the veth"

# --- veth byte counters once a second (robot side: tx = towards the GPU host) ---
stats=/sys/class/net/$veth_robot/statistics
ip netns exec "$ns_robot" bash -c "while :; do echo \$(date +%s.%N) \$(cat $stats/tx_bytes) \$(cat $stats/rx_bytes); sleep 1; done" \
  >"$out/veth_bytes.txt" 2>/dev/null &
sampler_pid=$!

# --- robot: the pipeline without segmentation (the nodes of kitti_bag.launch), then the bag ---
# The bag starts once the nodes have subscribed (the e2e tests' pattern): a fixed play delay
# loses the first scans and labels of a node that starts late on a loaded machine.
pipeline=$(on_robot rospack find inekf_semantic_mapping)/launch/include/pipeline.launch
log "starting inekf_node and semantic_octomap_node in $ns_robot (pipeline.launch run_segmentation:=false)"
"${as_robot[@]}" roslaunch -p "$port" "$pipeline" model:="$model" run_segmentation:=false rviz:=false \
  "${origin_args[@]}" >"$out/launch.log" 2>&1 &
launch_pid=$!
pids+=("$launch_pid")
on_robot /usr/bin/python3 "$probe" subscribed 120 /kitti/oxts/imu=/inekf_node \
  /kitti/velo/pointcloud=/semantic_octomap_node /segmentation/labels=/semantic_octomap_node ||
  { tail -n 30 "$out/launch.log"; die "the robot's nodes did not subscribe within 120 s"; }
log "playing $(basename "$bag") at rate $rate in $ns_robot"
play_start=$(date +%s.%N)
"${as_robot[@]}" rosbag play --clock --quiet --rate="$rate" "$bag" >"$out/play.log" 2>&1 &
play_pid=$!
pids+=("$play_pid")
wait "$play_pid" || die "rosbag play failed ($(tail -n 3 "$out/play.log"))"
play_end=$(date +%s.%N)
log "bag finished; letting the last labels arrive"
read -r bag_end < <(/usr/bin/python3 -c "import rosbag,sys; print('%.6f' % rosbag.Bag(sys.argv[1]).get_end_time())" "$bag")
# Time goes on after the bag (the map node's timers run on ROS time: its last info needs it).
"${as_robot[@]}" /usr/bin/python3 "$ISM_ROOT/scripts/clock_after_bag.py" _start:="$bag_end" >"$out/clock.log" 2>&1 &
pids+=($!)
sleep 4
# A node that died (its error is in launch.log) would otherwise show as a missing /semantic_map/info.
if grep -q "process has died" "$out/launch.log"; then
  grep -E "FATAL|ERROR|process has died" "$out/launch.log" | head -n 5 >&2
  die "a node of the robot side died (see $out/launch.log)"
fi
stop_pid "$gpu_probe_pid" INT 10
log "reading /semantic_map/info and the image sizes"
on_robot /usr/bin/python3 "$probe" info "$out/map_info.json" 30 >"$out/probe_info.log" 2>&1 ||
  { cat "$out/probe_info.log"; die "no /semantic_map/info"; }
/usr/bin/python3 "$probe" encodings "$bag" "$image_topic" "$out/image_encodings.json" 20 >"$out/probe_encodings.log" 2>&1 ||
  { cat "$out/probe_encodings.log"; die "image encodings failed"; }
log "stopping the nodes and removing the namespaces"
cleanup
trap - EXIT INT TERM

# --- summary ---
/usr/bin/python3 - "$out" "$play_start" "$play_end" "$rate" "$check" "${link:-none}" <<'PY'
import json, os, sys
out, play_start, play_end, rate, check, link = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]), sys.argv[5] == "1", sys.argv[6]
load = lambda name: json.load(open(os.path.join(out, name)))
labels, info, images = load("labels_published.json"), load("map_info.json"), load("image_encodings.json")
samples = [tuple(map(float, line.split())) for line in open(os.path.join(out, "veth_bytes.txt")) if len(line.split()) == 3]
play = [s for s in samples if play_start <= s[0] <= play_end + 2]
def rate_between(a, b, i):
    return (b[i] - a[i]) / (b[0] - a[0]) if b[0] > a[0] else 0.0
tx = rate_between(play[0], play[-1], 1) if len(play) > 1 else 0.0
rx = rate_between(play[0], play[-1], 2) if len(play) > 1 else 0.0
peak_tx = max((rate_between(a, b, 1) for a, b in zip(samples, samples[1:])), default=0.0)
play_s = play_end - play_start
mb = lambda x: x / 1e6
image_raw = images["raw_bytes"] / max(images["messages"], 1)
jpeg = images["sampled_jpeg80_bytes"] / max(images["sampled"], 1)
png_img = images["sampled_png3_bytes"] / max(images["sampled"], 1)
label_raw = labels["bytes"] / max(labels["messages"], 1)
label_png = labels["png_bytes"] / max(labels["png_messages"], 1)
image_hz = images["messages"] / play_s * 1.0
label_hz = labels["messages"] / play_s
summary = {
    "play_wall_s": round(play_s, 1), "rate": rate, "link": link,
    "label_images_published_gpu": labels["messages"],
    "label_images_received_map": info["label_images_received"],
    "label_images_used_map": info["label_images_used"],
    "scans_received": info["scans_received"], "scans_inserted": info["scans_inserted"],
    "scans_with_labels": info["scans_with_labels"], "occupied_voxels": info["occupied_voxels"],
    "labelled_voxels": sum(v for n, v in zip(info["class_names"], info["class_voxels"]) if n != "unlabeled"),
    "veth_robot_to_gpu_MBps": round(mb(tx), 2), "veth_gpu_to_robot_MBps": round(mb(rx), 3),
    "veth_robot_to_gpu_peak_MBps": round(mb(peak_tx), 2),
    "image": {"size": "%dx%d %s" % (images.get("width", 0), images.get("height", 0), images.get("encoding", "")),
              "frames": images["messages"], "raw_bytes": round(image_raw), "jpeg80_bytes": round(jpeg),
              "png3_bytes": round(png_img), "raw_MBps_at_10Hz": round(mb(image_raw) * 10, 2),
              "jpeg80_MBps_at_10Hz": round(mb(jpeg) * 10, 3)},
    "label": {"size": "%dx%d %s" % (labels.get("width", 0), labels.get("height", 0), labels.get("encoding", "")),
              "raw_bytes": round(label_raw), "png3_bytes": round(label_png),
              "published_hz": round(label_hz, 2), "raw_MBps": round(mb(label_raw) * label_hz, 3),
              "png3_MBps": round(mb(label_png) * label_hz, 4)},
}
json.dump(summary, open(os.path.join(out, "summary.json"), "w"), indent=1)
s, i, l = summary, summary["image"], summary["label"]
print("two hosts (netns + veth), bag played in %.1f s at rate %g, link %s" % (play_s, rate, link))
print("  label images: %d published by segmentation_node (gpu, %.2f Hz), %d received by the map node (robot), %d used"
      % (s["label_images_published_gpu"], l["published_hz"], s["label_images_received_map"], s["label_images_used_map"]))
print("  map: %d scans received, %d inserted, %d with labels; %d occupied voxels, %d of them labelled"
      % (s["scans_received"], s["scans_inserted"], s["scans_with_labels"], s["occupied_voxels"], s["labelled_voxels"]))
print("  veth robot->gpu (images) %.2f MB/s mean over the playback, %.2f MB/s peak 1 s; gpu->robot (labels) %.3f MB/s"
      % (s["veth_robot_to_gpu_MBps"], s["veth_robot_to_gpu_peak_MBps"], s["veth_gpu_to_robot_MBps"]))
print("  image %s: raw %d B, JPEG q80 %d B (%.0fx smaller), PNG %d B; at 10 Hz raw %.2f MB/s (%.0f Mbit/s), JPEG %.3f MB/s"
      % (i["size"], i["raw_bytes"], i["jpeg80_bytes"], i["raw_bytes"] / max(i["jpeg80_bytes"], 1), i["png3_bytes"],
         i["raw_MBps_at_10Hz"], 8 * i["raw_MBps_at_10Hz"], i["jpeg80_MBps_at_10Hz"]))
print("  label %s: raw %d B, PNG %d B (%.0fx smaller); at %.2f Hz raw %.3f MB/s, PNG %.4f MB/s"
      % (l["size"], l["raw_bytes"], l["png3_bytes"], l["raw_bytes"] / max(l["png3_bytes"], 1), l["published_hz"],
         l["raw_MBps"], l["png3_MBps"]))
print("  outputs: %s/summary.json (+ logs)" % out)
if check:
    problems = []
    if s["label_images_published_gpu"] == 0: problems.append("segmentation_node published no label image")
    if s["label_images_received_map"] == 0: problems.append("no label image reached the map node")
    if s["scans_inserted"] == 0: problems.append("no scan in the map")
    if s["scans_with_labels"] == 0: problems.append("no scan got class evidence")
    if s["labelled_voxels"] == 0: problems.append("no labelled voxel")
    if problems:
        print("CHECK FAILED: " + "; ".join(problems))
        sys.exit(1)
    print("CHECK PASSED: labels crossed the veth and the map filled")
PY
log "done in $(($(date +%s) - start)) s"
