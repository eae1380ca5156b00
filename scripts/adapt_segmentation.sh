#!/usr/bin/env bash
# Fine-tunes a Cityscapes network on the KITTI camera and exports it for the C++ Segmenter:
#   scripts/adapt_segmentation.sh --shared ../shared [--output output/models/kitti]
#       [--minutes 40] [--device cpu|cuda] [--base espnetv2_s2|espnetv2_s1|enet] [...]
# Writes OUTPUT/kitti_adapted.onnx and its model card OUTPUT/kitti_adapted.yaml (which
# segment_image, segmentation_node, semantic_map_offline and evaluate_semantics load as they are),
# training.png (loss and validation accuracy), history.csv and summary.json.
# Every other option goes to training/adapt_segmentation.py (`--help` lists them).
# The result derives from non-commercial weights and data: keep it out of any commit.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
[[ ${ISM_SKIP_DEPS:-0} == 1 ]] || "$ISM_ROOT/scripts/install_deps.sh"
# The default --output (the repository's output/models/kitti) is adapt_segmentation.py's own, so
# that --output DIR, --output=DIR and its abbreviations all replace it.
exec /usr/bin/python3 -u "$ISM_ROOT/training/adapt_segmentation.py" "$@"
