#!/usr/bin/python3
"""Fine-tunes a Cityscapes segmentation network on the KITTI camera and exports it for the C++
Segmenter (ONNX + model card). The front is scripts/adapt_segmentation.sh.

Data (../shared, read its README): dense human labels (data/kitti_semantics), the human lidar
labels projected into both cameras (data/semantickitti_train: sparse), optionally CamVid; or the
same layouts elsewhere (--dense-root, --sparse-root: make_camera_labels writes the sparse one
from SemanticKITTI sequences). SemanticKITTI 05 and 08 are the evaluation frames: this script
refuses them.

Losses: cross-entropy on the human labels (each image weighs the same, sparse or dense), plus
distillation from the base network where no human label is (by default its whole class
distribution, KL at a temperature, at every unlabelled pixel: between the lidar's beams and above
them in the sparse images, the unlabelled pixels of the dense ones), so that the sky, building
tops and the rare classes it knew are not forgotten; optionally the Lovasz-softmax (a surrogate
of 1 - IoU per class) beside the cross-entropy. Batch normalisation keeps the base
network's statistics by default (small KITTI batches would replace them).

Training runs at the network's input scale (the images resized to input width x height, as the
Segmenter does at run time), so inference needs no upscaling. Deterministic for a given seed and
step count on one thread count (the time budget decides the step count: --max-steps pins it).
"""

import argparse
import atexit
import csv
import json
import math
import signal
import os
import random
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.realpath(__file__))
sys.path.insert(0, HERE)

import augment  # noqa: E402
import base_networks  # noqa: E402
import datasets  # noqa: E402
import labels  # noqa: E402
import logit_calibration  # noqa: E402
import lovasz  # noqa: E402
import preprocess  # noqa: E402
from scoring import Scorer  # noqa: E402
import semantickitti_download  # noqa: E402
import teacher_store  # noqa: E402
import weight_average  # noqa: E402


def log(message):
    print(f"[adapt_segmentation] {message}", flush=True)


# The repository's output/models/kitti, wherever the command runs from (scripts/env.sh's
# ISM_ROOT/output/models/kitti for scripts/adapt_segmentation.sh).
DEFAULT_OUTPUT = os.path.join(os.path.dirname(HERE), "output", "models", "kitti")

# --distill-labelled-weight when not given: soft distillation also teaches at the human-labelled
# pixels at this weight; hard distillation (a label of its own) only where no human label is.
DEFAULT_SOFT_LABELLED_WEIGHT = 0.3


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--shared", required=True, help="the shared data folder (../shared)")
    p.add_argument("--output", default=DEFAULT_OUTPUT, help="output folder")
    p.add_argument("--base", default="espnetv2_s2", choices=base_networks.names(),
                   help="the Cityscapes network to start from")
    p.add_argument("--minutes", type=float, default=40.0,
                   help="training time budget (0 and no --max-steps: export the base network)")
    p.add_argument("--max-steps", type=int, default=0, help="stop after this many steps (0: time)")
    p.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    p.add_argument("--threads", type=int, default=2, help="CPU threads")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--input", default="1024x320", help="network input WxH (multiples of 32)")
    p.add_argument("--export-input", default="832x256",
                   help="the exported model's input WxH (multiples of 32; 'same': --input). "
                        "Smaller is faster: 832x256 labels SemanticKITTI 05 / 08 as well as "
                        "1024x320 at 0.7x the time (docs/segmentation_adaptation.md)")
    p.add_argument("--crop", default="320x640", help="training crop HxW")
    p.add_argument("--batch", type=int, default=4)
    p.add_argument("--lr", type=float, default=2e-4)
    p.add_argument("--encoder-lr-scale", type=float, default=1.0,
                   help="the base network's encoder learns at this times --lr (its decoder at "
                        "--lr); 0 freezes the encoder: only the decoder adapts to the camera")
    p.add_argument("--bn-stats", default="frozen", choices=["frozen", "update"],
                   help="frozen: batch normalisation keeps the base network's statistics (the "
                        "affine terms still train); update: they follow the KITTI batches")
    p.add_argument("--weight-decay", type=float, default=1e-4)
    p.add_argument("--distill", default="soft", choices=["soft", "hard"],
                   help="soft: the base network's whole class distribution (KL at --temperature) "
                        "at every pixel of the zone; hard: its confident argmax as a label")
    p.add_argument("--temperature", type=float, default=2.0,
                   help="soft distillation temperature (> 0)")
    p.add_argument("--distill-weight", type=float, default=1.0)
    p.add_argument("--distill-zone", default="unlabelled", choices=["outside-lidar", "unlabelled"],
                   help="where the base network teaches in the sparse images: above the lidar's "
                        "top beam only, or at every pixel without a human label")
    p.add_argument("--distill-labelled-weight", type=float, default=argparse.SUPPRESS,
                   help="soft distillation also at the human-labelled pixels, at this weight "
                        "against 1 in the zone (0: only in the zone); the base network's view "
                        "of the classes the KITTI labels rarely show keeps pulling there too. "
                        f"Default {DEFAULT_SOFT_LABELLED_WEIGHT:g} with --distill soft, 0 with "
                        "--distill hard (which teaches only in the zone: a weight above 0 needs "
                        "--distill soft)")
    p.add_argument("--rare-repeat", type=float, default=0.3,
                   help="repeat-factor sampling (Gupta et al. 2019): an image is drawn "
                        "max(1, sqrt(t / f)) times per epoch, f the share of training images "
                        "holding its rarest class; this is t (0: every image once)")
    p.add_argument("--paste-rare", type=float, default=0.5,
                   help="probability that a training crop gets one or two objects of the rare "
                        "classes (person, rider, truck, bus, train, motorcycle, bicycle), cut "
                        "from the dense training frames, pasted in (simple copy-paste, Ghiasi et "
                        "al. 2021; 0: never)")
    p.add_argument("--teacher-confidence", type=float, default=0.7,
                   help="the base network's labels below this softmax confidence teach nothing")
    p.add_argument("--teacher-store", default="auto", choices=teacher_store.MODES,
                   help="where the teacher's distributions are held while training (about 14 MB "
                        "an image at 1024x320): memory, or disk (memory-mapped files in "
                        "OUTPUT/teacher_cache, removed at the end: for hundreds of images); "
                        "auto: disk once they would take more than a quarter of the available "
                        "memory")
    p.add_argument("--class-weight-power", type=float, default=0.25,
                   help="class weights (median frequency / frequency)^power, 0: none")
    p.add_argument("--lovasz-weight", type=float, default=0.0,
                   help="weight of the Lovasz-softmax loss (a surrogate of 1 - IoU per class, "
                        "training/lovasz.py) on the human labels beside their cross-entropy; "
                        "0: none")
    p.add_argument("--dense-root", default="",
                   help="a folder of KITTI frames with dense labels (image_2/, semantic/: the "
                        "KITTI semantics benchmark's training/ layout); default "
                        "SHARED/data/kitti_semantics/training")
    p.add_argument("--sparse-root", default="",
                   help="a folder of sequences/NN/ with image_{2,3}/ and labels_{2,3}/ (16-bit "
                        "SemanticKITTI classes, 0 where none): ../shared's semantickitti_train "
                        "or what make_camera_labels writes from your SemanticKITTI sequences; "
                        "default SHARED/data/semantickitti_train")
    p.add_argument("--semantickitti", default="",
                   help="a SemanticKITTI download (the dataset/ folder: sequences/NN with "
                        "velodyne/, labels/, image_2/, image_3/): every labelled sequence but "
                        "05 and 08 is turned into camera labels (make_camera_labels, into "
                        "OUTPUT/camera_labels) and trained on instead of --sparse-root and "
                        "--sparse-sequences, --val-sequence held out (the last one where it is "
                        "missing)")
    p.add_argument("--semantickitti-every", type=int, default=50,
                   help="with --semantickitti: every N-th frame of each sequence (consecutive "
                        "frames are 0.1 s apart and nearly equal)")
    p.add_argument("--sparse-sequences", default="01,02,03,09",
                   help="sequences of --sparse-root to train on")
    p.add_argument("--sparse-weight", type=float, default=1.0,
                   help="weight of the projected lidar labels' loss against the dense frames' "
                        "(each image's mean; 0: those images teach by distillation only)")
    p.add_argument("--sparse-parking", default="road", choices=["road", "ignore"],
                   help="SemanticKITTI's parking points in the sparse training labels: road (as "
                        "the evaluation scores them) or unlabelled (left to the distillation)")
    p.add_argument("--val-sequence", default="06",
                   help="the sequence of --sparse-root held out for validation (not one of "
                        "--sparse-sequences; '': the dense frames' held-out ones alone)")
    p.add_argument("--dense-val-every", type=int, default=7,
                   help="every N-th dense frame is held out for validation (1 or more)")
    p.add_argument("--camvid", type=int, default=0, help="CamVid frames to add (0: none)")
    p.add_argument("--pseudo-labels", default="",
                   help="the fused map's labels of a drive nobody labelled (semantic_map_offline "
                        "--label-images DIR), trained on as sparse labels")
    p.add_argument("--pseudo-images", default="",
                   help="the images of --pseudo-labels (the drive's image_02/data)")
    p.add_argument("--teacher", default="",
                   help="the network that teaches by distillation, when not the base network: a "
                        "base network's name (a larger one teaching a smaller student, e.g. "
                        "--base espnetv2_s1 --teacher espnetv2_s2)")
    p.add_argument("--teacher-init", default="",
                   help="the teacher's weights (a best.pt of an adapted run of --teacher) instead "
                        "of its Cityscapes ones")
    p.add_argument("--init", default="",
                   help="start from these weights (a best.pt of an earlier round) instead of "
                        "the base network's; the base network still teaches")
    p.add_argument("--interpolate", default="1",
                   help="weight-space ensembling with the base network (WiSE-FT, Wortsman et al. "
                        "2022): for each a of this comma list, the weights base + a * (adapted - "
                        "base) are validated on the held-out frames at the export size and the "
                        "best is exported (1: the adapted weights; 0: the base network's)")
    p.add_argument("--calibrate-offsets", default="on", choices=["on", "off"],
                   help="fit one logit offset per class on the held-out frames at the export "
                        "size (the mIoU's coordinate ascent, training/logit_calibration.py) and "
                        "export the network with them; kept only when they raise that mIoU")
    p.add_argument("--max-images", type=int, default=0,
                   help="use at most this many images of each source (0: all; CI uses a few)")
    p.add_argument("--average-weights", type=float, default=0.0,
                   help="average the weights of every step in the last FRACTION of the budget "
                        "(stochastic weight averaging); the mean competes with the best "
                        "validated step on the held-out frames (0: off)")
    p.add_argument("--val-interval", type=float, default=5.0, help="minutes between validations")
    p.add_argument("--keep", default="best", choices=["best", "last"],
                   help="which weights are exported: the best validated (the base network "
                        "itself when no step beats it on the held-out frames) or the last step's "
                        "(their mean with --average-weights), whatever the validation says")
    p.add_argument("--gamma", type=float, default=0.7, help="the card's tone curve")
    p.add_argument("--no-standardize", action="store_true",
                   help="no per-image colour standardisation in the card")
    args = p.parse_args(argv)
    if not hasattr(args, "distill_labelled_weight"):
        args.distill_labelled_weight = (DEFAULT_SOFT_LABELLED_WEIGHT if args.distill == "soft"
                                        else 0.0)
    return args


def check_sequences(args):
    """--sparse-sequences and --val-sequence: neither names SemanticKITTI 05 or 08, however it is
    spelt (datasets.sequence_id), and the validation sequence is not trained on."""
    val_sequence = [args.val_sequence] if args.val_sequence else []
    sparse_train = [s for s in args.sparse_sequences.split(",") if s]
    for option, sequences in (("--sparse-sequences", sparse_train),
                              ("--val-sequence", val_sequence)):
        for seq in sequences:
            if datasets.is_evaluation_sequence(seq):
                raise SystemExit(f"{option} {seq}: SemanticKITTI {datasets.sequence_id(seq):02d} "
                                 "is an evaluation sequence: never trained or validated on")
    trained = {datasets.sequence_id(s) for s in sparse_train}
    if val_sequence and datasets.sequence_id(args.val_sequence) in trained:
        raise SystemExit(f"--val-sequence {args.val_sequence} is also in --sparse-sequences "
                         f"{args.sparse_sequences}: the validation (and the logit calibration) "
                         "would score frames the network trained on; name another validation "
                         "sequence or leave it out of --sparse-sequences")


def without_nan(value):
    """`value` (nested dicts, lists, numbers) with every non-finite float as None."""
    if isinstance(value, dict):
        return {k: without_nan(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [without_nan(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def check_options(args):
    """The option checks that need no data and no PyTorch, right after parsing: each error
    names the option and what is wrong with it."""
    if args.dense_val_every < 1:
        raise SystemExit(f"--dense-val-every {args.dense_val_every}: must be 1 or more (every "
                         "N-th dense frame is held out for validation)")
    if not args.temperature > 0:
        raise SystemExit(f"--temperature {args.temperature}: must be above 0")
    if args.max_images < 0:
        raise SystemExit(f"--max-images {args.max_images}: must be 0 (all images) or more")
    # A negative step count never ended the run, whatever --minutes said.
    if args.max_steps < 0:
        raise SystemExit(f"--max-steps {args.max_steps}: must be 0 (the --minutes budget) or "
                         "more")
    for option, value in (("--batch", args.batch), ("--threads", args.threads)):
        if value < 1:
            raise SystemExit(f"{option} {value}: must be 1 or more")
    if not args.distill_labelled_weight >= 0:
        raise SystemExit(f"--distill-labelled-weight {args.distill_labelled_weight}: must be 0 "
                         "or more")
    if args.distill_labelled_weight > 0 and args.distill != "soft":
        raise SystemExit(f"--distill-labelled-weight {args.distill_labelled_weight:g} needs "
                         "--distill soft (hard distillation teaches only where no human label "
                         "is): leave the option out or give 0 with --distill hard")
    if args.pseudo_labels and not args.pseudo_images:
        raise SystemExit("--pseudo-labels needs --pseudo-images (the drive's image_02/data)")
    if not args.semantickitti:  # --semantickitti chooses the sequences itself
        check_sequences(args)
    if not args.val_sequence and args.max_images and args.max_images < args.dense_val_every:
        raise SystemExit(empty_validation_message(args))


def empty_validation_message(args, dense_frames=None):
    loaded = (f" over the {dense_frames} dense frames loaded" if dense_frames is not None
              else "")
    return (f"no validation images: --val-sequence '{args.val_sequence}' and --dense-val-every "
            f"{args.dense_val_every}{loaded} (--max-images {args.max_images}) hold nothing out: "
            "name a --val-sequence, or give a --dense-val-every no larger than the number of "
            "dense frames (or a larger --max-images)")


def load_init(path, model, base_name, torch):
    """The --init weights, read and checked against the model's tensors (names and shapes) before
    any data is loaded; None without --init. Each error names the option and the file."""
    if not path:
        return None
    if not os.path.isfile(path):
        raise SystemExit(f"--init {path}: no such file")
    try:
        state = torch.load(path, map_location="cpu")
    except Exception as e:  # torch raises pickle, zip and runtime errors for a foreign file
        first = str(e).strip().splitlines()[0] if str(e).strip() else ""
        raise SystemExit(f"--init {path}: not a PyTorch weights file ({type(e).__name__}"
                         + (f": {first})" if first else ")"))
    expected = model.state_dict()
    if not isinstance(state, dict) or not all(hasattr(v, "shape") for v in state.values()):
        raise SystemExit(f"--init {path}: not a state dict of tensors (a best.pt of an earlier "
                         "round is one)")
    missing = [k for k in expected if k not in state]
    unexpected = [k for k in state if k not in expected]
    wrong = [k for k in expected
             if k in state and tuple(state[k].shape) != tuple(expected[k].shape)]
    if missing or unexpected or wrong:
        detail = "; ".join(f"{what} {len(keys)} tensors (e.g. {keys[0]})" for what, keys in
                           (("missing", missing), ("unexpected", unexpected),
                            ("wrong shape of", wrong)) if keys)
        raise SystemExit(f"--init {path}: not weights of --base {base_name} ({detail})")
    return state


def interpolation_factors(text):
    """The --interpolate list as floats in [0, 1], in the order given."""
    try:
        factors = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise SystemExit(f"--interpolate {text}: not a comma-separated list of numbers")
    if not factors or any(not 0.0 <= a <= 1.0 for a in factors):
        raise SystemExit(f"--interpolate {text}: each factor must be in [0, 1]")
    return factors


def interpolate_weights(base_state, adapted_state, alpha):
    """base + alpha (adapted - base) for every floating-point tensor (weights, biases, batch
    normalisation statistics); integer buffers (the batch counters) are the adapted ones."""
    out = {}
    for key, adapted in adapted_state.items():
        if key not in base_state or base_state[key].shape != adapted.shape:
            raise ValueError(f"the base network has no tensor {key} of shape "
                             f"{tuple(adapted.shape)}")
        base = base_state[key]
        out[key] = base + alpha * (adapted - base) if adapted.is_floating_point() else adapted
    return out


def choose_interpolation(model, torch, base_state, val, factors):
    """Loads each interpolation of the model's (adapted) weights with the base network's, scores
    it on the validation samples, logs it; leaves the model at the best (validation mIoU, the
    first given on a tie) and returns (its scores with its factor, every factor's scores)."""
    adapted = {k: v.clone() for k, v in model.state_dict().items()}
    scored = []
    for alpha in factors:
        model.load_state_dict(interpolate_weights(base_state, adapted, alpha))
        scores = dict(alpha=alpha, **validate(model, torch, val))
        scored.append(scores)
        log(f"interpolated at {alpha:g} towards the adapted weights: validation " + ", ".join(
            f"{k} {scores[k]:.4f}" for k in ("dense_pixel_accuracy", "sparse_point_accuracy",
                                             "miou")))
    best = max(scored, key=lambda s: s["miou"])  # max keeps the first of equals
    model.load_state_dict(interpolate_weights(base_state, adapted, best["alpha"]))
    return best, scored


def seed_everything(seed, threads, torch):
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)
    torch.set_num_threads(threads)
    torch.use_deterministic_algorithms(False)


def size_arg(text, name):
    try:
        a, b = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise SystemExit(f"--{name} '{text}': expected AxB (integers)")
    if a < 1 or b < 1:  # 0x0 and -32x160 passed the multiple-of-32 check into OpenCV's resize
        raise SystemExit(f"--{name} '{text}': both sizes must be positive")
    return a, b


def lidar_zone_mask(target, margin_px=6, column_window=41):
    """True where a sparse image's pixel lies at or below the lidar's top beam in its column
    (the top beam's row, smoothed over neighbouring columns, less a margin)."""
    h, w = target.shape
    labelled = target != labels.IGNORE
    top = np.where(labelled.any(axis=0), labelled.argmax(axis=0), h)
    # Columns between scan points: the highest beam nearby.
    pad = column_window // 2
    padded = np.pad(top, pad, mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, column_window)
    top = windows.min(axis=1) - margin_px
    return np.arange(h)[:, None] >= top[None, :]


def distillation_zone(sample, outside_lidar_only):
    """True where the base network may teach: no human label, and for a sparse image with
    outside_lidar_only, above the lidar's top beam."""
    zone = sample.target == labels.IGNORE
    if sample.kind == "sparse" and outside_lidar_only:
        zone &= ~lidar_zone_mask(sample.target)
    return zone


def distillation_weights(sample, outside_lidar_only, labelled_weight):
    """Per-pixel weight of the soft distillation: 1 in the zone, labelled_weight at the
    human-labelled pixels, 0 elsewhere (outside the lidar zone's limit)."""
    weights = distillation_zone(sample, outside_lidar_only).astype(np.float32)
    if labelled_weight > 0:
        weights[sample.target != labels.IGNORE] = labelled_weight
    return weights


def repeat_factors(samples, threshold, min_pixels=50):
    """Repeat-factor sampling (Gupta et al. 2019, LVIS): each image's class set (classes with at
    least min_pixels human labels), f_c the share of images holding class c, and the image's
    factor max(1, max over its classes of sqrt(threshold / f_c)). All ones for threshold 0."""
    if threshold <= 0 or not samples:
        return np.ones(len(samples))
    present = np.zeros((len(samples), labels.NUM_TRAIN_IDS), bool)
    for i, s in enumerate(samples):
        counts = np.bincount(s.target[s.target != labels.IGNORE].ravel(),
                             minlength=labels.NUM_TRAIN_IDS)[:labels.NUM_TRAIN_IDS]
        present[i] = counts >= min_pixels
    share = present.mean(axis=0)
    per_class = np.sqrt(threshold / np.maximum(share, 1e-9))
    return np.array([max(1.0, per_class[p].max()) if p.any() else 1.0 for p in present])


RARE_CLASS_NAMES = ("person", "rider", "truck", "bus", "train", "motorcycle", "bicycle")


def rare_object_paster(samples, probability):
    """The crop's paste step for --paste-rare: None at probability 0 (the random draws of a run
    without it stay as they were), else a function that pastes one or two objects of the rare
    classes cut from the dense samples into a crop with the given probability."""
    if probability == 0:
        return None
    names = labels.train_id_names()
    ids = [names.index(n) for n in RARE_CLASS_NAMES]
    objects = augment.cut_objects(samples, ids)
    if not objects:
        log("--paste-rare: the dense training frames hold no object of the rare classes; "
            "nothing is pasted")
        return None
    per_class = np.bincount(np.concatenate([
        np.unique(o.target[o.target != labels.IGNORE]) for o in objects]),
        minlength=labels.NUM_TRAIN_IDS)
    log(f"--paste-rare {probability:g}: {len(objects)} objects cut from "
        f"{len({o.source for o in objects})} dense frames ("
        + ", ".join(f"{names[c]} {per_class[c]}" for c in ids if per_class[c]) + ")")

    def paste(image, target, teacher, rng):
        if rng.random() < probability:
            augment.paste_objects(image, target, teacher, objects, rng, 1 + rng.integers(2))
    return paste


def epoch_order(factors, rng):
    """One epoch's draw order: image i floor(r_i) times plus once more with probability
    frac(r_i), shuffled (stochastic rounding keeps the expected count r_i)."""
    if np.all(factors == 1):
        return list(rng.permutation(len(factors)))  # the draw of runs without repeats
    counts = np.floor(factors).astype(int)
    counts += rng.random(len(factors)) < (factors - counts)
    return list(rng.permutation(np.repeat(np.arange(len(factors)), counts)))


def same_size_batches(images, batch):
    """(start, end) index ranges of consecutive images, at most batch long, each of one image
    size (CamVid's 4:3 frames and KITTI's cannot share a tensor): a run of equal sizes is cut
    every batch images as before, and a change of size starts a new batch."""
    start = 0
    while start < len(images):
        end = start + 1
        while (end < len(images) and end - start < batch
               and images[end].shape == images[start].shape):
            end += 1
        yield start, end
        start = end


def teacher_targets(samples, model, torch, confidence, outside_lidar_only, soft, batch=2,
                    labelled_weight=0.0, store=None):
    """What the base network teaches in its zone. Hard: its labels where its softmax confidence
    is >= confidence (H x W trainIds, IGNORE elsewhere). Soft: its logits with the per-pixel
    weight as a last channel (H x W x (C + 1), float16: the whole distribution, confident or
    not; distillation_weights). store (a teacher_store.TeacherStore) decides where each image's
    targets are held; without one, in memory."""
    keep = store.keep if store is not None else (lambda index, array: array)
    model.eval()
    start = last_line = time.time()
    with torch.no_grad():
        for i, end in same_size_batches([s.image for s in samples], batch):
            if time.time() - last_line >= 30:  # hundreds of images take minutes
                last_line = time.time()
                rate = i / (last_line - start)
                log(f"teacher: {i} of {len(samples)} images, {(len(samples) - i) / rate:.0f} s "
                    "left")
            chunk = samples[i:end]
            x = preprocess.to_tensor_rgb01(np.stack([s.image for s in chunk]))
            logits = model(x)
            if soft:
                for j, (s, z) in enumerate(zip(chunk, logits.numpy())):
                    weights = distillation_weights(s, outside_lidar_only, labelled_weight)
                    s.teacher = keep(i + j, np.concatenate(
                        [z.transpose(1, 2, 0), weights[..., None]], axis=2).astype(np.float16))
                continue
            prob = torch.softmax(logits, dim=1)
            conf, arg = prob.max(dim=1)
            for j, (s, c, a) in enumerate(zip(chunk, conf.numpy(), arg.numpy().astype(np.uint8))):
                t = np.where((c >= confidence) & (a != labels.BACKGROUND_CHANNEL), a, labels.IGNORE)
                t = t.astype(np.uint8)
                t[~distillation_zone(s, outside_lidar_only)] = labels.IGNORE
                s.teacher = keep(i + j, t)


def build_teacher(args, base, model, shared, torch):
    """The network whose outputs are distilled, and its name for the log: the base network itself
    (model, before any training) unless --teacher / --teacher-init name another."""
    if not args.teacher and not args.teacher_init:
        return model, f"the base network ({base.name})"
    spec = base_networks.get(args.teacher or base.name)
    teacher = spec.build(os.path.join(shared, spec.weights))
    name = spec.name
    if args.teacher_init:
        if not os.path.isfile(args.teacher_init):
            raise SystemExit(f"--teacher-init {args.teacher_init}: no such file")
        try:
            teacher.load_state_dict(torch.load(args.teacher_init, map_location="cpu"))
        except RuntimeError as e:
            raise SystemExit(f"--teacher-init {args.teacher_init}: not weights of {spec.name} "
                             f"({str(e).splitlines()[0]})")
        name += f" from {args.teacher_init}"
    return teacher.eval(), f"the teacher ({name})"


def freeze_batchnorm_statistics(model, torch):
    """Batch normalisation layers in eval mode: their running statistics stay the base
    network's (re-estimating them on KITTI batches, AdaBN, lowered the ENet card's accuracy)."""
    for m in model.modules():
        if isinstance(m, torch.nn.modules.batchnorm._BatchNorm):
            m.eval()


def soft_distillation_loss(logits, teacher, temperature, F):
    """Per-image weighted mean of KL(teacher || student) at the temperature, times T^2 (Hinton
    et al. 2015); teacher is N x (C + 1) x H x W, the last channel the per-pixel weight (the
    zone: 1 inside, 0 outside)."""
    zone = teacher[:, -1]
    t = temperature
    kl = F.kl_div(F.log_softmax(logits / t, dim=1), F.softmax(teacher[:, :-1] / t, dim=1),
                  reduction="none").sum(1) * (t * t)
    return ((kl * zone).flatten(1).sum(1) / zone.flatten(1).sum(1).clamp(min=1)).mean()


def per_image_label_loss(ce, target, image_weights):
    """The human-label loss: each image's mean cross-entropy over its labelled pixels (a sparse
    image's few thousand labels weigh as much as a dense frame's), scaled by the image's weight,
    averaged over the batch. ce and target are N x H x W, image_weights N. The hard
    distillation takes the same mean over the teacher's confident pixels."""
    labelled = (target != labels.IGNORE).flatten(1)
    ce_sum = (ce.flatten(1) * labelled).sum(1)
    return (image_weights * ce_sum / labelled.sum(1).clamp(min=1)).mean()


def parameter_groups(model, is_encoder, encoder_lr_scale):
    """The optimizer's parameter groups: the decoder's parameters at the full learning rate and
    the encoder's (is_encoder of the parameter's name) at encoder_lr_scale times it, each group
    with its "lr_scale". At 0 the encoder is frozen instead (requires_grad off: the backward pass
    then stops at the decoder, and AdamW's weight decay cannot move it either). encoder_lr_scale
    is >= 0 (main checks the option)."""
    encoder, decoder = [], []
    for name, parameter in model.named_parameters():
        (encoder if is_encoder(name) else decoder).append(parameter)
    if not encoder or not decoder:
        raise SystemExit(f"--encoder-lr-scale: the network's parameters do not split into an "
                         f"encoder and a decoder ({len(encoder)} / {len(decoder)} tensors)")
    groups = [{"params": decoder, "lr_scale": 1.0}]
    if encoder_lr_scale > 0:
        groups.append({"params": encoder, "lr_scale": encoder_lr_scale})
    else:
        for parameter in encoder:
            parameter.requires_grad_(False)
    return groups


def class_weights(samples, power):
    freq = np.zeros(labels.NUM_CLASSES)
    for s in samples:
        counts = np.bincount(s.target[s.target != labels.IGNORE].ravel(),
                             minlength=labels.NUM_CLASSES)[:labels.NUM_CLASSES]
        if counts.sum():
            freq += counts / counts.sum()  # each image weighs the same
    weights = np.ones(labels.NUM_CLASSES)
    if power > 0:
        seen = freq > 0
        median = np.median(freq[seen])
        weights[seen] = np.clip((median / freq[seen]) ** power, 0.5, 2.5)
    return weights


def batched_logits(model, torch, images, batch=2):
    """The model's logits for the images, a batch of one image size at a time
    (same_size_batches) on the model's device, with the background channel never winning (as
    the card's suppress_unlabeled)."""
    model.eval()
    device = next(model.parameters()).device  # validation runs where training does
    with torch.no_grad():
        for i, end in same_size_batches(images, batch):
            logits = model(preprocess.to_tensor_rgb01(np.stack(images[i:end])).to(device))
            logits[:, labels.BACKGROUND_CHANNEL] = -1e9
            yield logits


def predict(model, torch, images, batch=2):
    """argmax trainIds of each image (background never wins)."""
    return [labels_ for logits in batched_logits(model, torch, images, batch)
            for labels_ in logits.argmax(dim=1).cpu().numpy().astype(np.uint8)]


def validate(model, torch, val):
    scores = {"dense": Scorer(), "sparse": Scorer(), "all": Scorer()}
    predictions = predict(model, torch, [s.image for s in val])
    for s, p in zip(val, predictions):
        scores[s.kind].add(s.target, p)
        scores["all"].add(s.target, p)
    return {
        "dense_pixel_accuracy": scores["dense"].accuracy(),
        "sparse_point_accuracy": scores["sparse"].accuracy(),
        "miou": scores["all"].miou(),
    }


def cityscapes_sample_accuracy(model, torch, shared, gamma, standardize):
    """Pixel accuracy on the shared Cityscapes frame at the networks' Cityscapes scale (1024x512):
    whether the adapted network still knows the city it came from. None without the sample."""
    import cv2

    root = os.path.join(shared, "data", "cityscapes")
    images = sorted(glob_files(root, "_leftImg8bit.png"))
    truths = sorted(glob_files(root, "_gtFine_labelTrainIds.png"))
    if not images or len(images) != len(truths):
        return None
    scorer = Scorer()
    for image_path, truth_path in zip(images, truths):
        image = cv2.imread(image_path, cv2.IMREAD_COLOR)
        truth = cv2.imread(truth_path, cv2.IMREAD_GRAYSCALE)
        prepared = cv2.resize(preprocess.card_colors(image, gamma, standardize), (1024, 512),
                              interpolation=cv2.INTER_LINEAR)
        predicted = predict(model, torch, [prepared])[0]
        predicted = cv2.resize(predicted, (truth.shape[1], truth.shape[0]),
                               interpolation=cv2.INTER_NEAREST_EXACT)
        scorer.add(truth, predicted)
    return scorer.accuracy()


def glob_files(root, suffix):
    out = []
    for folder, _, files in os.walk(root):
        out += [os.path.join(folder, f) for f in files if f.endswith(suffix)]
    return out


def validate_and_keep(model, torch, val, step, history, best, best_path):
    """Scores the model on the validation images, logs it, and saves its weights when they beat
    the best so far; returns the best scores."""
    scores = dict(step=step, **validate(model, torch, val))
    history["val"].append(scores)
    log(f"validation at step {step}: " + ", ".join(
        f"{k} {v:.4f}" for k, v in scores.items() if k != "step"))
    if scores["miou"] > best["miou"]:
        torch.save(model.state_dict(), best_path)
        return scores
    return best


def keep_last_weights(model, torch, last_scores, averaged, best_path):
    """--keep last: saves the model's weights as best_path whatever the validation said (the last
    step's, or their mean, which keep_average_if_better has loaded, when they were averaged);
    returns their scores."""
    torch.save(model.state_dict(), best_path)
    return averaged if averaged is not None else last_scores


def kept_weights_note(best, steps, base_miou):
    """The log line naming the weights that are exported; a warning when a run that trained
    exports the base network unchanged because no validated step beat it."""
    if best.get("steps_averaged"):
        return (f"kept the mean of the last {best['steps_averaged']} steps' weights (validation "
                f"mIoU {best['miou']:.4f})")
    note = f"kept the weights of step {best['step']} (validation mIoU {best['miou']:.4f})"
    if best["step"] == 0 and steps > 0:
        note += (f"\nWARNING: none of the {steps} steps beat the base network on the held-out "
                 f"frames (validation mIoU {base_miou:.4f}): the exported model is the base "
                 "network as it came. Train longer (--minutes, --max-steps), or export the last "
                 "step's weights anyway with --keep last.")
    return note


def keep_average_if_better(model, torch, val, averager, step, best, best_path, averaged_path):
    """Loads the averaged weights into the model, saves them to averaged_path, scores them on the
    validation samples and, when they beat the best step, saves them as best_path too. Returns
    (the best scores, the average's scores with the number of steps averaged)."""
    model.load_state_dict(averager.state_dict())
    torch.save(model.state_dict(), averaged_path)
    averaged = dict(step=step, steps_averaged=averager.count, **validate(model, torch, val))
    log(f"mean of the last {averager.count} steps' weights: validation " + ", ".join(
        f"{k} {averaged[k]:.4f}" for k in ("dense_pixel_accuracy", "sparse_point_accuracy",
                                           "miou")))
    if averaged["miou"] > best["miou"]:
        torch.save(model.state_dict(), best_path)
        return averaged, averaged
    return best, averaged


def calibrate_offsets(model, torch, val):
    """Fits the per-class logit offsets on the validation samples (logit_calibration) and logs
    them; returns what the summary records (the offsets as a list per channel)."""
    t0 = time.time()
    per_image = (o for logits in batched_logits(model, torch, [s.image for s in val])
                 for o in logits.cpu().numpy())
    logits, truth = logit_calibration.at_labelled_pixels(per_image, [s.target for s in val])
    offsets, before, after = logit_calibration.fit_class_offsets(logits, truth)
    kept = after > before
    described = logit_calibration.describe(offsets)
    log(f"logit offsets fitted on {len(truth)} held-out pixels in {time.time() - t0:.0f} s: "
        f"{described}; validation mIoU {before:.4f} -> {after:.4f}"
        + ("" if kept else " (none kept)"))
    return {"offsets": [float(v) for v in offsets], "offsets_by_class": described,
            "miou_before": before, "miou_after": after, "kept": kept,
            "pixels": int(len(truth))}


def remove_files(*paths):
    for path in paths:
        if os.path.exists(path):
            os.remove(path)


# The share of pixels whose argmax the ONNX graph (OpenCV dnn) and PyTorch must agree on.
PARITY_MIN_AGREEMENT = 0.995


def write_card(path, base, width, height, gamma, standardize, summary, write_to=None):
    """The model card of path[:-5].onnx, written as path (or as write_to: the caller renames it
    into place)."""
    lines = [
        f"# Model card for {os.path.basename(path)[:-5]}.onnx, written by",
        "# training/adapt_segmentation.py (scripts/adapt_segmentation.sh). The network was",
        f"# fine-tuned from {base.description} on the KITTI camera at "
        f"{summary['training_input'][0]}x{summary['training_input'][1]} (with scale jitter):",
        "# the Segmenter gives it each image resized to input width x height after the same",
        "# tone curve and colour standardisation as in training.",
        f"# Distillation teacher: {summary['teacher']}"
        + (f" ({summary['teacher_init']})" if summary["teacher_init"] else "") + ".",
    ]
    steps_averaged = summary["best_validation"].get("steps_averaged")
    if steps_averaged:
        lines.append(f"# Weights: the mean of the last {steps_averaged} steps' "
                     "(--average-weights), which validated above every single step.")
    if summary.get("interpolation"):
        lines.append(f"# Weights: the base network's + {summary['interpolation']['chosen']:g} x "
                     "(adapted - base), chosen on the held-out frames (--interpolate).")
    calibration = summary.get("logit_offsets")
    if calibration and calibration["kept"]:
        lines.append("# Logits: one offset per class in the graph, fitted on the held-out frames "
                     f"(--calibrate-offsets): {calibration['offsets_by_class']}.")
    lines += [
        f"name: kitti_adapted_{base.name}",
        f"input: {{width: {width}, height: {height}}}",
        "resize_policy: pad_to_multiple  # INTER_AREA to the input size (the training resize)",
        "pad_multiple: 32",
        "mean: [0, 0, 0]  # the network normalises inside (ImageNet mean / std)",
        "scale: 0.00392156862745098  # 1/255",
        "swap_rb: true  # the network takes RGB",
        f"gamma: {gamma}",
        f"color_normalization: {'standardize' if standardize else 'none'}",
        "color_mean: [{:.2f}, {:.2f}, {:.2f}]".format(*preprocess.CITYSCAPES_RGB_MEAN),
        "color_std: [{:.2f}, {:.2f}, {:.2f}]".format(*preprocess.CITYSCAPES_RGB_STD),
        "suppress_unlabeled: true  # the last channel is Cityscapes' void",
        "label_filter: {min_confidence: 0.6, boundary_radius_px: 2}",
        f"num_output_channels: {labels.NUM_CLASSES}",
        "output_label_ids: [{}]  # channel -> Cityscapes labelId".format(
            ", ".join(str(v) for v in labels.train_id_to_label_id())),
        f"validation_miou: {summary['validation_at_export_size']['miou']:.4f}",
    ]
    target = write_to or path
    tmp = target + ".tmp"
    with open(tmp, "w") as f:
        f.write("\n".join(lines) + "\n")
    os.replace(tmp, target)


def plot_history(history, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    steps = [h["step"] for h in history["train"]]
    a.plot(steps, [h["loss"] for h in history["train"]], lw=0.8, label="total")
    a.plot(steps, [h["label_loss"] for h in history["train"]], lw=0.8, label="human labels")
    a.plot(steps, [h["distill_loss"] for h in history["train"]], lw=0.8, label="distillation")
    a.set_xlabel("step")
    a.set_ylabel("loss (running mean)")
    a.legend()
    a.grid(alpha=0.3)
    vsteps = [v["step"] for v in history["val"]]
    for key, name in (("dense_pixel_accuracy", "dense pixel accuracy"),
                      ("sparse_point_accuracy", "lidar point accuracy"), ("miou", "mIoU")):
        b.plot(vsteps, [v[key] for v in history["val"]], marker="o", label=name)
    b.set_xlabel("step")
    b.set_ylabel("validation (held-out KITTI frames)")
    b.legend()
    b.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path + ".tmp.png", dpi=110)
    os.replace(path + ".tmp.png", path)
    plt.close(fig)


def use_semantickitti_download(args):
    """--semantickitti: converts the download's labelled sequences (make_camera_labels) into
    OUTPUT/camera_labels and points --sparse-root, --sparse-sequences and --val-sequence at
    them."""
    if args.sparse_root:
        raise SystemExit("--semantickitti and --sparse-root: give one (--semantickitti writes "
                         "its own sparse root)")
    if args.semantickitti_every < 1:
        raise SystemExit(f"--semantickitti-every {args.semantickitti_every}: must be 1 or more")
    out_root = os.path.join(args.output, "camera_labels")
    try:
        sequences = semantickitti_download.trainable_sequences(args.semantickitti)
        tool = semantickitti_download.find_make_camera_labels(os.path.dirname(HERE))
        semantickitti_download.convert(args.semantickitti, sequences, out_root,
                                       args.semantickitti_every, tool, log)
    except semantickitti_download.DownloadError as e:
        raise SystemExit(f"[adapt_segmentation] --semantickitti: {e}")
    train, val = semantickitti_download.split_validation(sequences, args.val_sequence)
    args.sparse_root, args.sparse_sequences, args.val_sequence = out_root, ",".join(train), val
    log(f"SemanticKITTI {args.semantickitti}: training on sequences {args.sparse_sequences}, "
        f"validating on {val or 'the dense frames alone'} (one frame in "
        f"{args.semantickitti_every}, labels in {out_root})")


def load_samples(args, shared, width, height, standardize, limit):
    """The training and validation samples at width x height (the card's preparation applied):
    the dense frames (every dense_val_every-th held out), the sparse sequences, the validation
    sequence, CamVid and the map's pseudo-labels as the arguments ask. Returns (train, val,
    counts per source). Raises datasets.DatasetError naming a missing or malformed file."""
    check_sequences(args)  # check_options did unless --semantickitti chose them; other callers
    val_sequence = [args.val_sequence] if args.val_sequence else []
    sparse_train = [s for s in args.sparse_sequences.split(",") if s]
    sparse_root = args.sparse_root or os.path.join(shared, "data", "semantickitti_train")
    dense_root = args.dense_root or os.path.join(shared, "data", "kitti_semantics", "training")
    dense = datasets.load_dense(dense_root, width, height, args.gamma, standardize, limit)
    sparse = datasets.load_sparse(sparse_root, sparse_train, width, height, args.gamma,
                                  standardize, limit, args.sparse_parking == "road")
    for s in sparse:
        s.label_weight = args.sparse_weight
    sparse_val = datasets.load_sparse(sparse_root, val_sequence, width, height, args.gamma,
                                      standardize, limit) if val_sequence else []
    camvid = datasets.load_camvid(os.path.join(shared, "data", "camvid"), width, height,
                                  args.gamma, standardize, args.camvid) if args.camvid else []
    pseudo = []
    if args.pseudo_labels:
        if not args.pseudo_images:
            raise SystemExit("--pseudo-labels needs --pseudo-images (the drive's image_02/data)")
        pseudo = datasets.load_pseudo(args.pseudo_labels, args.pseudo_images, width, height,
                                      args.gamma, standardize, limit)
    train, val = datasets.split_validation(dense, args.dense_val_every)
    counts = {"dense": len(dense), "sparse": len(sparse), "pseudo": len(pseudo),
              "camvid": len(camvid)}
    return train + sparse + pseudo + camvid, val + sparse_val, counts


def build_base(base, shared):
    """The base network with its Cityscapes weights from the shared folder (an error naming the
    file where they are missing)."""
    path = os.path.join(shared, base.weights)
    if not os.path.isfile(path):
        raise SystemExit(f"--base {base.name}: its weights {path} are missing (--shared "
                         f"{shared}: ../shared, read its README)")
    return base.build(path)


def main(argv=None):
    args = parse_args(argv)
    check_options(args)
    # A SIGTERM (a job scheduler, `kill`) ends the run through SystemExit, so that the atexit
    # cleanups (the teacher cache, a half-written export) run: they were left, gigabytes of it.
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))
    import torch
    import torch.nn.functional as F

    seed_everything(args.seed, args.threads, torch)
    device = torch.device(args.device)
    if args.device == "cuda" and not torch.cuda.is_available():
        raise SystemExit("--device cuda: this PyTorch sees no CUDA device")
    width, height = size_arg(args.input, "input")
    crop_h, crop_w = size_arg(args.crop, "crop")
    if width % 32 or height % 32:
        raise SystemExit(f"--input {args.input}: width and height must be multiples of 32")
    crop_h, crop_w = min(crop_h, height), min(crop_w, width)
    export_width, export_height = ((width, height) if args.export_input == "same" else
                                   size_arg(args.export_input, "export-input"))
    if export_width % 32 or export_height % 32:
        raise SystemExit(f"--export-input {args.export_input}: width and height must be "
                         "multiples of 32")
    interpolate_at = interpolation_factors(args.interpolate)
    for option, value in (("--sparse-weight", args.sparse_weight),
                          ("--lovasz-weight", args.lovasz_weight),
                          ("--encoder-lr-scale", args.encoder_lr_scale)):
        if not value >= 0:
            raise SystemExit(f"{option} {value}: must be 0 or more")
    if not 0.0 <= args.paste_rare <= 1.0:
        raise SystemExit(f"--paste-rare {args.paste_rare}: a probability in [0, 1]")
    if not 0.0 <= args.average_weights < 1.0:
        raise SystemExit(f"--average-weights {args.average_weights}: a fraction of the budget "
                         "in [0, 1)")
    standardize = not args.no_standardize
    base = base_networks.get(args.base)
    shared = os.path.abspath(args.shared)
    output = os.path.realpath(args.output)
    if os.path.commonpath([output, os.path.realpath(shared)]) == os.path.realpath(shared):
        raise SystemExit(f"--output {args.output}: inside --shared {args.shared}, the third-party "
                         "data (read-only; the model is written elsewhere, e.g. output/models/kitti)")
    limit = args.max_images or None
    # Built before the data is loaded, which draws no random numbers: --init is checked against
    # it before minutes of loading.
    model = build_base(base, shared)
    init_state = load_init(args.init, model, base.name, torch)
    try:  # a folder under a file, or one this user may not write: said now, not minutes later
        os.makedirs(args.output, exist_ok=True)
    except OSError as e:
        raise SystemExit(f"--output {args.output}: cannot make the folder: {e.strerror}")
    if not os.access(args.output, os.W_OK):
        raise SystemExit(f"--output {args.output}: the folder is not writable")
    compared = datasets.refuse_evaluation_frames(shared)
    log(f"evaluation frames refused by content: {compared} images of SemanticKITTI "
        f"{' and '.join(datasets.EVALUATION_SEQUENCES)} compared with" if compared else
        f"no SemanticKITTI 05 / 08 images under {shared}: the evaluation frames are refused by "
        "their sequence and drive names only")

    if args.semantickitti:
        use_semantickitti_download(args)  # its sequences are checked by load_samples
    t0 = time.time()
    try:
        train, val, counts = load_samples(args, shared, width, height, standardize, limit)
    except datasets.DatasetError as e:
        raise SystemExit(f"[adapt_segmentation] {e}")
    log(f"{len(train)} training images ({sum(s.kind == 'dense' for s in train)} dense, "
        f"{counts['sparse']} sparse, {counts['pseudo']} map pseudo-labels, "
        f"{counts['camvid']} CamVid), "
        f"{len(val)} validation images, at {width}x{height}, loaded in {time.time() - t0:.0f} s")
    if not val:
        raise SystemExit("[adapt_segmentation] " + empty_validation_message(
            args, counts["dense"]))

    teacher_t0 = time.time()
    # --minutes 0 without --max-steps: the base network exported with the card, untrained (the
    # starting point, measured by the same tools as the adapted one).
    train_at_all = args.max_steps > 0 or args.minutes > 0
    soft = args.distill == "soft"
    store = teacher_store.TeacherStore(args.teacher_store,
                                       os.path.join(args.output, "teacher_cache"), len(train),
                                       teacher_store.available_memory_bytes())
    atexit.register(store.close)  # a run stopped by an error leaves no cache behind
    if train_at_all:
        teacher, teacher_name = build_teacher(args, base, model, shared, torch)
        teacher_targets(train, teacher, torch, args.teacher_confidence,
                        args.distill_zone == "outside-lidar", soft,
                        labelled_weight=args.distill_labelled_weight, store=store)
        log(f"{teacher_name}'s labels for distillation in {time.time() - teacher_t0:.0f} s "
            f"({store.describe()})")
        del teacher
    if init_state is not None:
        model.load_state_dict(init_state)
        log(f"starting from {args.init}")
    before = validate(model, torch, val)
    log("before fine-tuning: " + ", ".join(f"{k} {v:.4f}" for k, v in before.items()))

    weights_np = class_weights(train, args.class_weight_power)
    if args.class_weight_power > 0:
        names = labels.train_id_names()
        log(f"class weights (median / frequency)^{args.class_weight_power:g}: " + ", ".join(
            f"{names[c]} {weights_np[c]:.2f}" for c in range(labels.NUM_TRAIN_IDS)))
    weights = torch.tensor(weights_np, dtype=torch.float32, device=device)
    if args.lovasz_weight > 0:
        log(f"the label loss adds the Lovasz-softmax at weight {args.lovasz_weight:g}")
    model.to(device)
    groups = parameter_groups(model, base.is_encoder, args.encoder_lr_scale)
    if args.encoder_lr_scale != 1.0:
        log(f"the encoder learns at {args.encoder_lr_scale:g} x the learning rate"
            + (" (frozen: only the decoder adapts)" if args.encoder_lr_scale == 0 else ""))
    optimizer = torch.optim.AdamW(groups, lr=args.lr, weight_decay=args.weight_decay)
    rng = np.random.default_rng(args.seed)
    factors = repeat_factors(train, args.rare_repeat)
    if args.rare_repeat > 0:
        log(f"repeat-factor sampling at t = {args.rare_repeat}: {len(train)} images drawn "
            f"{factors.sum():.0f} times per epoch, most repeated x{factors.max():.1f} "
            f"({int((factors > 1).sum())} images above 1)")
    paste = rare_object_paster(train, args.paste_rare)
    history = {"train": [], "val": [dict(step=0, **before)]}
    best = dict(step=0, **before)
    best_path = os.path.join(args.output, "best.pt")
    torch.save(model.state_dict(), best_path)

    averager = weight_average.WeightAverage() if args.average_weights > 0 else None
    budget_s = args.minutes * 60.0
    start = time.time()
    last_val = start
    step = 0
    running = None
    order = []
    while train_at_all:
        elapsed = time.time() - start
        progress = elapsed / budget_s if not args.max_steps else step / args.max_steps
        if progress >= 1.0:
            break
        # Linear warm-up over 20 steps, then cosine decay to 5 % over the budget.
        lr = args.lr * min(1.0, (step + 1) / 20) * (0.05 + 0.95 * 0.5 * (1 + math.cos(
            math.pi * min(progress, 1.0))))
        for group in optimizer.param_groups:
            group["lr"] = lr * group["lr_scale"]
        images, targets, teachers, label_weights = [], [], [], []
        for _ in range(args.batch):
            if not order:
                order = epoch_order(factors, rng)
            s = train[order.pop()]
            label_weights.append(s.label_weight)
            image, target, teacher = augment.random_crop(
                s, rng, crop_h, crop_w, teacher_dtype=np.float32 if soft else None,
                paste=paste)
            images.append(image)
            targets.append(target)
            teachers.append(teacher)
        x = preprocess.to_tensor_rgb01(np.stack(images)).to(device)
        image_weights = torch.tensor(label_weights, dtype=torch.float32, device=device)
        target = torch.from_numpy(np.stack(targets).astype(np.int64)).to(device)
        if soft:
            teacher = torch.from_numpy(np.stack(teachers).transpose(0, 3, 1, 2).copy()).to(device)
        else:
            teacher = torch.from_numpy(np.stack(teachers).astype(np.int64)).to(device)
        model.train()
        if args.bn_stats == "frozen":
            freeze_batchnorm_statistics(model, torch)
        logits = model(x)
        ce = F.cross_entropy(logits, target, weight=weights, ignore_index=labels.IGNORE,
                             reduction="none")
        label_loss = per_image_label_loss(ce, target, image_weights)
        if args.lovasz_weight > 0:
            label_loss = label_loss + args.lovasz_weight * lovasz.lovasz_softmax(
                F.softmax(logits, dim=1), target, labels.IGNORE, torch)
        if soft:
            distill_loss = soft_distillation_loss(logits, teacher, args.temperature, F)
        else:
            kd = F.cross_entropy(logits, teacher, ignore_index=labels.IGNORE, reduction="none")
            distill_loss = per_image_label_loss(kd, teacher, torch.ones_like(image_weights))
        loss = label_loss + args.distill_weight * distill_loss
        if not torch.isfinite(loss):
            raise SystemExit(f"[adapt_segmentation] step {step}: loss is {loss.item()}")
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        step += 1
        if averager is not None and progress >= 1.0 - args.average_weights:
            averager.add(model.state_dict())
        values = np.array([loss.item(), label_loss.item(), distill_loss.item()])
        running = values if running is None else 0.95 * running + 0.05 * values
        if step % 10 == 0 or step == 1:
            history["train"].append(dict(step=step, loss=running[0], label_loss=running[1],
                                         distill_loss=running[2], lr=lr))
            elapsed = time.time() - start
            left = (f"{(budget_s - elapsed) / 60:.1f} min left" if not args.max_steps else
                    f"{args.max_steps - step} steps left")
            log(f"step {step}: loss {running[0]:.3f} (labels {running[1]:.3f}, distillation "
                f"{running[2]:.3f}), lr {lr:.2e}, {elapsed / step:.2f} s/step, {left}")
        if time.time() - last_val >= args.val_interval * 60:
            best = validate_and_keep(model, torch, val, step, history, best, best_path)
            last_val = time.time()  # the interval is of training time, not of validations
            plot_history(history, os.path.join(args.output, "training.png"))

    for s in train:
        s.teacher = None  # the maps into the cache are closed before the cache goes
    store.close()
    if history["val"][-1]["step"] != step:
        best = validate_and_keep(model, torch, val, step, history, best, best_path)
    averaged = None
    if averager is not None and averager.count:
        best, averaged = keep_average_if_better(model, torch, val, averager, step, best,
                                                best_path,
                                                os.path.join(args.output, "averaged.pt"))
    if args.keep == "last":
        best = keep_last_weights(model, torch, history["val"][-1], averaged, best_path)
    model.load_state_dict(torch.load(best_path, map_location="cpu"))
    model.to("cpu").eval()
    log(kept_weights_note(best, step, history["val"][0]["miou"]))

    import onnx_export

    stem = os.path.join(args.output, "kitti_adapted")
    resized_export = (export_width, export_height) != (width, height)
    # The held-out frames prepared at the exported size, as the Segmenter will give them.
    val_export = (load_samples(args, shared, export_width, export_height, standardize, limit)[1]
                  if resized_export else val)
    interpolation, chosen = None, None
    if interpolate_at != [1.0]:
        base_state = build_base(base, shared).state_dict()
        chosen, scored = choose_interpolation(model, torch, base_state, val_export,
                                              interpolate_at)
        interpolation = {"factors": scored, "chosen": chosen["alpha"]}
        log(f"exporting base + {chosen['alpha']:g} (adapted - base)")
    # The weights in the ONNX graph (best.pt stays the adapted ones, to re-export from).
    torch.save(model.state_dict(), os.path.join(args.output, "exported.pt"))
    calibration = None
    exported = model
    # The base network exported untrained (--minutes 0 without --init) is the starting point
    # that the adapted one is measured against: it stays as it came.
    if args.calibrate_offsets == "on" and (train_at_all or args.init):
        calibration = calibrate_offsets(model, torch, val_export)
        if calibration["kept"]:
            exported = logit_calibration.with_offsets(model, calibration["offsets"], torch)
    # The model and its card are written under other names and take theirs (where the tools and
    # tests look) only once the ONNX graph agrees with PyTorch.
    partial = stem + ".partial"
    atexit.register(remove_files, partial + ".onnx", partial + ".yaml")
    onnx_export.export_onnx(exported, partial + ".onnx", export_width, export_height)
    try:
        parity = onnx_export.check_onnx_against_torch(exported, partial + ".onnx",
                                                      [s.image for s in val_export],
                                                      export_width, export_height, args.threads)
    except ValueError as e:
        raise SystemExit(f"[adapt_segmentation] the ONNX check of {stem}.onnx: {e}")
    log(f"ONNX through OpenCV dnn against PyTorch on {parity['n_images']} validation images: "
        f"argmax agreement {parity['argmax_agreement']:.5f}, max |logit difference| "
        f"{parity['max_abs_diff']:.2e}")
    parity_passed = parity["argmax_agreement"] >= PARITY_MIN_AGREEMENT
    at_export_size = best
    if exported is not model:
        at_export_size = dict(step=best["step"], **validate(exported, torch, val_export))
    elif chosen is not None:  # scored on these frames already
        at_export_size = dict(step=best["step"], **{k: v for k, v in chosen.items()
                                                    if k != "alpha"})
    elif resized_export:
        at_export_size = dict(step=best["step"], **validate(model, torch, val_export))
    if resized_export or interpolation is not None or exported is not model:
        log(f"exported at {export_width}x{export_height} (trained at {width}x{height}): "
            "validation " + ", ".join(f"{k} {at_export_size[k]:.4f}" for k in
                                      ("dense_pixel_accuracy", "sparse_point_accuracy", "miou")))
    cityscapes = cityscapes_sample_accuracy(exported, torch, shared, args.gamma, standardize)
    if cityscapes is not None:
        log(f"the shared Cityscapes frame at 1024x512: pixel accuracy {cityscapes:.4f}")
    summary = {
        "cityscapes_sample_pixel_accuracy": cityscapes,
        "base": base.name,
        "teacher": args.teacher or base.name,
        "teacher_init": args.teacher_init,
        "input": [export_width, export_height],
        "training_input": [width, height],
        "seed": args.seed,
        "steps": step,
        "minutes": (time.time() - start) / 60,
        "train_images": len(train),
        "val_images": len(val),
        "before": before,
        "best_validation": best,
        "validation_at_export_size": at_export_size,
        "onnx_parity": parity,
        "interpolation": interpolation,
        "averaged": averaged,
        "logit_offsets": calibration,
        "args": vars(args),
    }
    if parity_passed:
        write_card(stem + ".yaml", base, export_width, export_height, args.gamma, standardize,
                   summary, write_to=partial + ".yaml")
    with open(os.path.join(args.output, "history.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "loss", "label_loss", "distill_loss", "lr"])
        for h in history["train"]:
            w.writerow([h["step"], h["loss"], h["label_loss"], h["distill_loss"], h["lr"]])
    with open(os.path.join(args.output, "summary.json"), "w") as f:
        # Standard JSON (null, not NaN: a figure with nothing to score, e.g. no dense frame held
        # out), which every parser reads.
        json.dump(without_nan(summary), f, indent=2, allow_nan=False)
    plot_history(history, os.path.join(args.output, "training.png"))
    if not parity_passed:
        # No model where the tools look: this run's is set aside, an earlier run's removed (its
        # best.pt and exported.pt are gone already).
        os.replace(partial + ".onnx", stem + ".rejected.onnx")
        remove_files(stem + ".onnx", stem + ".yaml")
        raise SystemExit("[adapt_segmentation] the ONNX export disagrees with PyTorch on "
                         f"{1 - parity['argmax_agreement']:.2%} of the validation pixels (below "
                         f"{1 - PARITY_MIN_AGREEMENT:.1%} needed): left as {stem}.rejected.onnx, "
                         f"no {stem}.onnx / .yaml written (history.csv, summary.json, "
                         "training.png say how the run went)")
    os.replace(partial + ".yaml", stem + ".yaml")
    os.replace(partial + ".onnx", stem + ".onnx")
    remove_files(stem + ".rejected.onnx")  # an earlier run's
    log(f"wrote {stem}.onnx, {stem}.yaml, training.png, summary.json in {args.output}")
    return summary


if __name__ == "__main__":
    main()
