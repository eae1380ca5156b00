#!/usr/bin/env bash
# The degraded-GPS evaluation protocol for all three filters on every KITTI raw drive in ../shared:
# GPS = OXTS lat/lon/alt + N(0, 1.5 m) horizontal / N(0, 3 m) vertical, once a second
# (--gps-every 10), seed 1, config/inekf.yaml; plus the 90-deg initial-yaw-error test on
# 2011_09_30_drive_0027 (--init-yaw-error-deg 90 --init-yaw-sigma-deg 180).
# Prints a Markdown table: unaligned ATE in m and rotation RMSE in deg of each filter over all
# frames, as inekf_offline reports them against the OXTS truth; then the left filter scored by
# scripts/evaluate_trajectory.py with 2011_09_30_drive_0028's wrong-truth frames 769..1202 left
# out (the other drives score as over all frames), causal and smoothed (--smooth).
# Needs inekf_offline built: scripts/build.sh inekf_offline.
#   usage: scripts/run_inekf_protocol.sh [SHARED_DIR]
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"

shared=${1:-$ISM_ROOT/../shared}
offline=$ISM_BIN/inekf_offline
config=$ISM_ROOT/config/inekf.yaml
[[ -x $offline ]] || { echo "run_inekf_protocol: $offline not built" >&2; exit 1; }
[[ -d $shared/data/kitti_raw ]] || { echo "run_inekf_protocol: no $shared/data/kitti_raw" >&2; exit 1; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
protocol=(--gps-every 10 --gps-sigma-h 1.5 --gps-sigma-v 3 --seed 1 --config "$config")

# "ATE rot" from inekf_offline's summary line.
errors() { sed -n 's/.*ATE \([0-9.]*\) m, rotation RMSE \([0-9.]*\) deg.*/\1 \2/p'; }
# "ATE / rot" of $work/p.txt against $work/t.txt, frames $1 (FIRST:LAST, may be empty) left out.
scored() {
  /usr/bin/python3 "$ISM_ROOT/scripts/evaluate_trajectory.py" --estimate "$work/p.txt" \
    --truth "$work/t.txt" --json "$work/m.json" ${1:+--exclude-frames $1} > /dev/null
  /usr/bin/python3 -c "import json; d = json.load(open('$work/m.json')); \
print('%.2f / %.2f' % (d['ate_unaligned_rmse_m'], d['rotation_rmse_deg']))"
}

echo "| drive | frames | left ATE (m) | left rot (deg) | right ATE | right rot | ekf ATE | ekf rot | left, bad truth out: ATE / rot | left smoothed: ATE / rot |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for oxts in "$shared"/data/kitti_raw/*/*_sync/oxts; do
  drive=$(basename "$(dirname "$oxts")" _sync)
  frames=$(wc -l < "$oxts/timestamps.txt")
  exclude=""
  [[ $drive == 2011_09_30_drive_0028 ]] && exclude=769:1202
  row="| $drive | $frames |"
  for filter in left right ekf; do
    read -r ate rot < <("$offline" --oxts "$oxts" --output-kitti "$work/p.txt" \
      --output-truth "$work/t.txt" --filter "$filter" "${protocol[@]}" | errors)
    row+=" $ate | $rot |"
    [[ $filter == left ]] && causal=$(scored "$exclude")
  done
  "$offline" --oxts "$oxts" --output-kitti "$work/p.txt" --output-truth "$work/t.txt" \
    --filter left --smooth "${protocol[@]}" > /dev/null
  echo "$row $causal | $(scored "$exclude") |"
done

yaw_drive=$shared/data/kitti_raw/2011_09_30/2011_09_30_drive_0027_sync/oxts
if [[ -d $yaw_drive ]]; then
  echo
  echo "90-deg initial yaw error on 2011_09_30_drive_0027 (initial yaw sigma 180 deg):"
  echo
  echo "| filter | yaw error at 20 s (deg) | at 60 s | max abs after 60 s |"
  echo "|---|---|---|---|"
  for filter in left right ekf; do
    "$offline" --oxts "$yaw_drive" --output-tum "$work/est.txt" --output-kitti "$work/p.txt" \
      --output-truth "$work/truth.txt" --filter "$filter" --init-yaw-error-deg 90 \
      --init-yaw-sigma-deg 180 "${protocol[@]}" > /dev/null
    /usr/bin/python3 - "$work/est.txt" "$work/p.txt" "$work/truth.txt" "$filter" <<'PY'
import math, sys
stamps = [float(line.split()[0]) for line in open(sys.argv[1])]
def yaws(path):
    out = []
    for line in open(path):
        v = [float(x) for x in line.split()]
        out.append(math.degrees(math.atan2(v[4], v[0])))  # atan2(R10, R00)
    return out
err = [((a - b + 180.0) % 360.0) - 180.0 for a, b in zip(yaws(sys.argv[2]), yaws(sys.argv[3]))]
t = [s - stamps[0] for s in stamps]
at = lambda sec: err[min(range(len(t)), key=lambda k: abs(t[k] - sec))]
after = max(abs(e) for e, s in zip(err, t) if s >= 60.0)
print("| %s | %.2f | %.2f | %.2f |" % (sys.argv[4], at(20.0), at(60.0), after))
PY
  done
fi
