#!/usr/bin/env bash
# The map teaches the camera: a second round of camera adaptation on a drive nobody labelled.
#   scripts/map_teaches_camera.sh --shared ../shared [--round1 output/models/kitti]
#       [--output output/models/kitti_round2] [--drive DRIVE_SYNC_DIR] [--minutes 40]
#       [--min-probability 0.6] [--no-evaluate] [-- more options for adapt_segmentation.py]
# 1. semantic_map_offline maps the drive with the first round's network (camera labels fused
#    over many views, with the lidar's geometry checks) and writes the map's classes at each
#    frame's lidar points as its camera sees them (--label-images): the pseudo-labels;
# 2. adapt_segmentation.py trains a second round from the first round's weights on the human
#    labels plus the pseudo-labels (the base network still teaches where no label is);
# 3. evaluate_semantics scores both rounds on SemanticKITTI 05 and 08 (never trained on) and
#    says which to keep: the second round only if it improves the map mIoU on both.
# Everything goes to OUTPUT (the models derive from non-commercial data: never commit them).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"

shared=""
round1=$ISM_ROOT/output/models/kitti
output=$ISM_ROOT/output/models/kitti_round2
drive=""
minutes=40
min_probability=0.6
evaluate=1
extra=()
while (($#)); do
  case $1 in
    --shared) shared=$2; shift 2 ;;
    --round1) round1=$2; shift 2 ;;
    --output) output=$2; shift 2 ;;
    --drive) drive=$2; shift 2 ;;
    --minutes) minutes=$2; shift 2 ;;
    --min-probability) min_probability=$2; shift 2 ;;
    --no-evaluate) evaluate=0; shift ;;
    --) shift; extra=("$@"); break ;;
    *) echo "map_teaches_camera: unknown option '$1' (see the header of $0)" >&2; exit 2 ;;
  esac
done
[[ -n $shared ]] || { echo "map_teaches_camera: --shared DIR is required" >&2; exit 2; }
[[ -n $drive ]] || drive=$shared/data/kitti_raw/2011_09_26/2011_09_26_drive_0013_sync
model=$round1/kitti_adapted.onnx
for f in "$model" "$round1/best.pt"; do
  [[ -f $f ]] || { echo "map_teaches_camera: $f not found (run scripts/adapt_segmentation.sh first)" >&2; exit 1; }
done
[[ -d $drive/image_02/data ]] || { echo "map_teaches_camera: $drive/image_02/data not found" >&2; exit 1; }
[[ -x $ISM_BIN/semantic_map_offline ]] || { echo "map_teaches_camera: build first (scripts/build.sh)" >&2; exit 1; }

mkdir -p "$output/pseudo"
echo "[map_teaches_camera] 1/3 mapping $drive with $model"
"$ISM_BIN/semantic_map_offline" --drive "$drive" --model "$model" \
  --output "$output/pseudo/map.ot" --label-images "$output/pseudo/labels_2" \
  --label-min-probability "$min_probability" 2>&1 | grep -v '^\[semantic_map_offline\] scan ' || true
[[ -n $(ls "$output/pseudo/labels_2" 2>/dev/null) ]] || { echo "map_teaches_camera: no label images written" >&2; exit 1; }

echo "[map_teaches_camera] 2/3 second round from $round1/best.pt, $minutes min"
/usr/bin/python3 -u "$ISM_ROOT/training/adapt_segmentation.py" --shared "$shared" \
  --output "$output" --init "$round1/best.pt" --minutes "$minutes" \
  --pseudo-labels "$output/pseudo/labels_2" --pseudo-images "$drive/image_02/data" "${extra[@]}"

((evaluate)) || exit 0
echo "[map_teaches_camera] 3/3 both rounds on SemanticKITTI 05 and 08"
sequences=()
for s in 05 08; do sequences+=(--sequence "$shared/data/semantickitti/sequences/$s"); done
for round in 1 2; do
  dir=$([[ $round == 1 ]] && echo "$round1" || echo "$output")
  "$ISM_BIN/evaluate_semantics" "${sequences[@]}" --model "$dir/kitti_adapted.onnx" \
    --json "$output/evaluation_round$round.json" >"$output/evaluation_round$round.log" 2>&1
done
/usr/bin/python3 - "$output" <<'PY'
import json, sys
out = sys.argv[1]
rounds = [json.load(open(f"{out}/evaluation_round{r}.json")) for r in (1, 2)]
keep = True
print("[map_teaches_camera] sequence  map mIoU round 1 -> round 2")
for seq in rounds[0]["sequences"]:
    a, b = (r["sequences"][seq]["map"]["miou"] for r in rounds)
    keep &= b > a
    print(f"[map_teaches_camera] {seq[-2:]}        {a:.3f} -> {b:.3f}")
print("[map_teaches_camera] keep the " + ("second round" if keep else "first round") +
      f" ({out if keep else 'round 1'}): " +
      ("it improves the map mIoU on every sequence" if keep else "the second round does not improve every sequence"))
PY
