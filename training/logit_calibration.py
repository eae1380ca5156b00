"""Per-class logit offsets fitted on the held-out frames (bias calibration), baked into the
exported graph.

Why it is here: the fine-tuned network's class priors come from the training mix (class
weights, distillation towards the base network, images drawn by their rarest class), not from
what the KITTI camera sees. On the held-out frames an adapted network predicts sidewalk at four
fifths as many pixels as are sidewalk and calls a third of the sidewalk road, and every fit
measured lowers road against the other classes (docs/segmentation_adaptation.md). A constant
added to each class's logit moves its prior without touching the features: the offsets that
maximise the held-out frames' mIoU (the criterion the training keeps its weights by) are found
by coordinate ascent over a bounded grid, and the network exported with them, so the C++
Segmenter loads the model unchanged.

Only classes the held-out frames can measure (at least min_pixels labelled pixels) get an offset.
A class they never show would only be pushed down (each of its predictions there is a false
positive of another class), which is how a network forgets persons; the grid's bound keeps a
class with a few thousand pixels from moving the others far.
"""

import numpy as np

import labels
from scoring import Scorer

GRID = tuple(float(v) for v in np.arange(-1.0, 1.0001, 0.25))


def at_labelled_pixels(per_image_logits, targets):
    """The logits (channels x H x W per image) at every labelled pixel of its target, as
    (pixels x channels) float32, and the trainId at each."""
    logits, truth = [], []
    for image_logits, target in zip(per_image_logits, targets):
        keep = target != labels.IGNORE
        logits.append(np.moveaxis(image_logits, 0, -1)[keep])
        truth.append(target[keep].astype(np.int64))
    if not logits:
        return np.zeros((0, labels.NUM_CLASSES), np.float32), np.zeros(0, np.int64)
    return np.concatenate(logits).astype(np.float32), np.concatenate(truth)


def mean_iou(logits, truth, offsets):
    """mIoU over the trainIds present in truth of argmax(logits + offsets)."""
    scorer = Scorer()
    scorer.add(truth, (logits + offsets).argmax(1))
    return scorer.miou()


def fit_class_offsets(logits, truth, min_pixels=1000, grid=GRID, sweeps=2, min_gain=1e-4):
    """Coordinate ascent of the mIoU over one offset per measurable class (each tried at every
    grid value in turn, kept when it gains at least min_gain). Returns (offsets per channel,
    mIoU before, mIoU after); the offsets are all zero when nothing gains."""
    offsets = np.zeros(logits.shape[1], np.float32)
    before = mean_iou(logits, truth, offsets)
    counts = np.bincount(truth, minlength=labels.NUM_TRAIN_IDS)
    measurable = [c for c in range(labels.NUM_TRAIN_IDS) if counts[c] >= min_pixels]
    best = before
    for _ in range(sweeps):
        for c in measurable:
            current = offsets[c]
            for value in grid:
                if value == current:
                    continue
                offsets[c] = value
                score = mean_iou(logits, truth, offsets)
                if score >= best + min_gain:
                    best, current = score, value
            offsets[c] = current
    return offsets, before, best


def with_offsets(model, offsets, torch):
    """The model with the offsets added to its logits (a module that exports to ONNX as one Add
    of a constant, which OpenCV 4.6 imports)."""

    class LogitOffsets(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.model = model
            self.register_buffer("offsets", torch.tensor(offsets, dtype=torch.float32).view(
                1, -1, 1, 1))

        def forward(self, x):
            return self.model(x) + self.offsets

    return LogitOffsets()


def describe(offsets):
    """'road -1, building +0.25, ...': the non-zero offsets by class name."""
    names = labels.train_id_names()
    return ", ".join(f"{names[c]} {offsets[c]:+g}" for c in range(labels.NUM_TRAIN_IDS)
                     if offsets[c] != 0) or "none"
