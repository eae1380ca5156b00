#!/usr/bin/env bash
# Real-time benchmark of the whole pipeline at rate 1.0 (see bench/realtime_pipeline.py):
#   bench/realtime_pipeline.sh [BAG]                  # ISM_BENCH_MODEL=/abs/model (see below)
#   ISM_BENCH_LAUNCH_ARGS="nodelets:=true" bench/realtime_pipeline.sh   # extra kitti_bag.launch args
# Without BAG, a 30 s synthetic drive (seed 42) is generated and converted with kitti2bag into
# output/bench/. ISM_BENCH_MODEL is the segmentation model; it defaults to the synthetic-world
# U-Net (models/unet_synthetic.onnx), which suits synthetic bags only: give the ENet for a real
# one. Needs a built workspace (ISM_WS, default .ws). Prints markdown tables
# (output/bench/realtime.md, or ISM_BENCH_OUTPUT/realtime.md).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/../scripts/env.sh"
ism_source_workspace
out=$ISM_ROOT/output/bench
mkdir -p "$out"
bag=${1:-}
if [[ -z $bag ]]; then
  bag=$out/synthetic.bag
  if [[ ! -s $bag ]]; then
    rm -rf "$out/synthetic"
    "$ISM_BIN/generate_synthetic_drive" --output "$out/synthetic" --seed 42 --duration "${ISM_BENCH_DURATION:-30}" >"$out/generate.log" 2>&1
    drive=$(ls -d "$out"/synthetic/*/*_drive_*_sync | head -n 1)
    "$ISM_BIN/kitti2bag" --drive "$drive" --calib-dir "$(dirname "$drive")" --output "$bag.tmp.bag" \
      --gps-sigma-h 1.5 --gps-sigma-v 3 --gps-every 10 --seed 1 >"$out/kitti2bag.log" 2>&1
    mv "$bag.tmp.bag" "$bag"
  fi
fi
export ROS_MASTER_URI=http://localhost:${ISM_BENCH_PORT:-$((11900 + RANDOM % 90))} ROS_HOSTNAME=localhost
model=${ISM_BENCH_MODEL:-$ISM_ROOT/models/unet_synthetic.onnx}
echo "[bench] segmentation model: $model (ISM_BENCH_MODEL)"
exec /usr/bin/python3 "$ISM_ROOT/bench/realtime_pipeline.py" --bag "$bag" --rate "${ISM_BENCH_RATE:-1.0}" \
  --model "$model" --output-dir "${ISM_BENCH_OUTPUT:-$out}" --launch-args "${ISM_BENCH_LAUNCH_ARGS:-}"
