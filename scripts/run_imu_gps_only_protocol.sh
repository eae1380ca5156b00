#!/usr/bin/env bash
# The IMU + GPS only protocol on every KITTI raw drive in ../shared: the OXTS solution's attitude
# and velocity columns are dropped (inekf_offline --imu-gps-only: the filter starts levelled from
# gravity, yaw unknown), GPS = OXTS lat/lon/alt + N(0, 1.5 m) h / N(0, 3 m) v at 1 Hz, seed 1,
# config/inekf.yaml; the reference start (the OXTS attitude and velocity at the first fix) as
# the second column; the same with --smooth (IMU + GPS only also with --single-pass, the causal
# run's heading kept before the alignment); and a wrong reference heading (60 deg off, sigma
# 1 deg). 2011_09_30_drive_0028's bad-truth frames 769..1202 are left out of its metrics.
# Prints one Markdown table. Needs inekf_offline built: scripts/build.sh inekf_offline.
#   usage: scripts/run_imu_gps_only_protocol.sh [SHARED_DIR] [YAW_OFF_DEG]
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"

shared=${1:-$ISM_ROOT/../shared}
yaw_off=${2:-60}
offline=$ISM_BIN/inekf_offline
config=$ISM_ROOT/config/inekf.yaml
[[ -x $offline ]] || { echo "run_imu_gps_only_protocol: $offline not built" >&2; exit 1; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
protocol=(--gps-every 10 --gps-sigma-h 1.5 --gps-sigma-v 3 --seed 1 --config "$config")

# heading_convergence.py's "key value" pairs -> shell variables prefixed with $1.
convergence() {
  local prefix=$1 oxts=$2 exclude=$3
  /usr/bin/python3 "$ISM_ROOT/scripts/heading_convergence.py" "$work/p.txt" "$work/t.txt" "$oxts" \
    ${exclude:+--exclude-frames $exclude} | tr ' ' '\n' | paste - - | sed "s/^/${prefix}_/;s/\t/=/"
}
kitti_metrics() {  # t_err % and rotation RMSE deg of the smoothed run
  local exclude=$1
  /usr/bin/python3 "$ISM_ROOT/scripts/evaluate_trajectory.py" --estimate "$work/p.txt" \
    --truth "$work/t.txt" --json "$work/m.json" ${exclude:+--exclude-frames $exclude} > /dev/null
  /usr/bin/python3 -c "import json; d = json.load(open('$work/m.json')); t = d['kitti']['t_err_percent']; \
print('%.3f %s %.3f' % (d['ate_unaligned_rmse_m'], 'n/a' if t is None else '%.2f' % t, d['rotation_rmse_deg']))"
}
run() { "$offline" --oxts "$1" --output-kitti "$work/p.txt" --output-truth "$work/t.txt" \
  "${protocol[@]}" "${@:2}" | grep -E "heading monitor|gps offered" | tr '\n' ' '; }

echo "| drive | IMU+GPS only: ATE m / rot deg (all frames) | heading < 2 deg, s after motion / worst after 30 s | ATE / rot after motion + 30 s | reference start: ATE / rot (all) | reference: after motion + 30 s | smoothed IMU+GPS only: ATE / t_err % / rot | ... one pass (--single-pass) | smoothed reference | ${yaw_off} deg off (sigma 1): heading < 2 deg, s after motion / worst after 30 s / ATE after 30 s | heading events (aligned / recovered / re-opened) |"
echo "|---|---|---|---|---|---|---|---|---|---|---|"
for oxts in "$shared"/data/kitti_raw/*/*_sync/oxts; do
  drive=$(basename "$(dirname "$oxts")" _sync)
  exclude=""
  [[ $drive == 2011_09_30_drive_0028 ]] && exclude=769:1202
  line=$(run "$oxts" --imu-gps-only)
  events=$(sed -n 's/.*heading monitor: \([0-9]*\) aligned from the GPS track, \([0-9]*\) recovered, \([0-9]*\) re-opened.*/\1 \/ \2 \/ \3/p' <<< "$line")
  eval "$(convergence own "$oxts" "$exclude")"
  run "$oxts" > /dev/null
  eval "$(convergence ref "$oxts" "$exclude")"
  run "$oxts" --imu-gps-only --smooth > /dev/null
  read -r s_ate s_terr s_rot < <(kitti_metrics "$exclude")
  run "$oxts" --imu-gps-only --smooth --single-pass > /dev/null
  read -r o_ate o_terr o_rot < <(kitti_metrics "$exclude")
  run "$oxts" --smooth > /dev/null
  read -r r_ate r_terr r_rot < <(kitti_metrics "$exclude")
  line_off=$(run "$oxts" --init-yaw-error-deg "$yaw_off")
  events_off=$(sed -n 's/.*heading monitor: \([0-9]*\) aligned from the GPS track, \([0-9]*\) recovered, \([0-9]*\) re-opened.*/\1 \/ \2 \/ \3/p' <<< "$line_off")
  eval "$(convergence off "$oxts" "$exclude")"
  echo "| $drive | $own_ate_m / $own_rot_rmse_deg | $own_converged_after_motion_s / $own_worst_yaw_after_30s_deg | $own_ate_after_30s_m / $own_rot_after_30s_deg | $ref_ate_m / $ref_rot_rmse_deg | $ref_ate_after_30s_m / $ref_rot_after_30s_deg | $s_ate / $s_terr / $s_rot | $o_ate / $o_terr / $o_rot | $r_ate / $r_terr / $r_rot | $off_converged_after_motion_s / $off_worst_yaw_after_30s_deg / $off_ate_after_30s_m | $events; off: $events_off |"
done
