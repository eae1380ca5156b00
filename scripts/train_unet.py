#!/usr/bin/python3
"""Trains the project's U-Net for semantic segmentation and exports it as ONNX + model card.

The network is the seed's U-Net (Ronneberger et al.): a contracting path of 3x3 conv + BatchNorm
+ ReLU blocks and 2x2 max-pooling, an expansive path of 2x2 transposed convolutions whose output
is concatenated with the skip connection. Width (--base) and depth (--depth) are configurable.
The model has no size logic inside forward() (no F.pad / F.interpolate: OpenCV 4.6 cannot
import those); inputs are reflect-padded to a multiple of 2**depth outside it and the output
cropped, exactly what the C++ Segmenter does (card: resize_policy pad_to_multiple).

Datasets (labels are Cityscapes labelIds everywhere; classes not trained are ignored):
  synthetic        <drive>/image_02/data/*.png + <drive>/ground_truth/image_02_labels/*.png
  cityscapes       <root>/leftImg8bit/<split>/<city>/*_leftImg8bit.png + gtFine/..._labelIds.png
  kitti_semantics  <root>/training/image_2/*.png + <root>/training/semantic/*.png
  camvid           <root>:<split> -> <root>/<split>/*.jpg|png + <root>/<split>annot/*.png: the
                   SegNet CamVid (11 classes, 480x360), mapped to Cityscapes labelIds: sky 23,
                   building 11, pole 17, road 7, pavement 8, tree 21, sign-symbol 20, fence 13,
                   car 26, pedestrian 24, bicyclist 25 (rider), 11 unlabelled -> ignored
  enet_pseudo      <root>/image_2/*.png + <root>/labels/*.png (labelIds) [+ <root>/confidence/
                   *.png]: pseudo-labels of another network (e.g. segment_image with the ENet)
                   on real images; pixels under --pseudo-min-confidence are ignored; traffic
                   light -> traffic sign, truck/bus -> car (as CamVid's sign-symbol and car)

A --train / --val spec may name its own dataset and image scale: [DATASET=]SPEC[@SCALE], e.g.
camvid=/data/camvid:train@1.0 next to enet_pseudo=/tmp/pseudo@0.5 (SCALE overrides
--resize-factor for that spec; the card's resize_factor stays --resize-factor).

Examples:
  # The default model (models/unet_synthetic.onnx): train on one synthetic seed, validate on
  # another, half resolution, 25 minutes on 2 CPU threads.
  scripts/train_unet.py --dataset synthetic --train /tmp/syn_train --val /tmp/syn_val \\
      --resize-factor 0.5 --base 8 --minutes 25 --output models/unet_synthetic.onnx
  # Real road scenes: CamVid's human labels plus ENet pseudo-labels on KITTI frames
  # that are NOT the SemanticKITTI 05/08 evaluation frames (raw drive 0013: 50 frames for
  # training; the 2 kitti_object frames, pseudo-labelled the same way, for validation):
  for f in ../shared/data/kitti_raw/2011_09_26/2011_09_26_drive_0013_sync/image_02/data/*.png; do
    ln -sf $f /tmp/pseudo/image_2/$(basename $f)
    segment_image --model ../shared/models/enet-cityscapes/enet-model.net --input $f \\
        --output /tmp/pseudo/labels/$(basename $f) \\
        --confidence /tmp/pseudo/confidence/$(basename $f)
  done
  scripts/train_unet.py --train camvid=../shared/data/camvid:train@1.0 \\
      --train enet_pseudo=/tmp/pseudo@0.5 --repeat-pseudo 5 --pseudo-min-confidence 0.5 \\
      --val camvid=../shared/data/camvid:val@1.0 --val enet_pseudo=/tmp/pseudo_val@0.5 \\
      --val-every 10 --classes 7,8,11,13,17,20,21,22,23,24,25,26 --resize-factor 0.5 \\
      --base 8 --depth 4 --crop 128x288 --batch 4 --augment --class-weighting --lr 3e-3 \\
      --threads 1 --minutes 55 --output /tmp/unet/unet_camvid_kitti.onnx \\
      --licence "CC BY-NC 4.0 (research use only): CamVid and ENet pseudo-labels"
    # 55 min on one shared CPU thread (6852 steps) gave, with evaluate_semantics on SemanticKITTI
    # 05 / 08, raw camera accuracy 0.579 / 0.553 (ENet: 0.817 / 0.708) and map mIoU 0.209 /
    # 0.178 (label filter 0.6 / 2 px; ENet 0.390 / 0.464) at 75-97 ms per KITTI image: too weak
    # to ship (the domain gap: white walls and shaded vegetation become car). A model trained
    # this way is for research use only (CC BY-NC).
  # Cityscapes (19 trainId classes), full network width, on a GPU:
  scripts/train_unet.py --dataset cityscapes --train CS_ROOT:train --val CS_ROOT:val \\
      --base 64 --crop 512x1024 --batch 8 --steps 40000 --output cityscapes_unet.onnx
"""
import argparse
import glob
import math
import os
import random
import shlex
import sys
import time

import cv2
import numpy as np
import torch
import torch.nn as nn

NUM_LABEL_IDS = 34
IGNORE_INDEX = 255
# Cityscapes labelIds that have a trainId (the 19 evaluated classes), in trainId order.
CITYSCAPES_TRAIN_LABEL_IDS = [7, 8, 11, 12, 13, 17, 19, 20, 21, 22, 23, 24, 25, 26, 27, 28,
                              31, 32, 33]


# ----------------------------------------------------------------------------------------------
# Model
# ----------------------------------------------------------------------------------------------
def double_conv(in_channels, out_channels):
    return nn.Sequential(
        nn.Conv2d(in_channels, out_channels, 3, padding=1, bias=False),
        nn.BatchNorm2d(out_channels), nn.ReLU(inplace=True),
        nn.Conv2d(out_channels, out_channels, 3, padding=1, bias=False),
        nn.BatchNorm2d(out_channels), nn.ReLU(inplace=True))


class UNet(nn.Module):
    def __init__(self, num_classes, base=8, depth=4, in_channels=3):
        super().__init__()
        widths = [base * 2 ** i for i in range(depth + 1)]
        self.down = nn.ModuleList()
        previous = in_channels
        for width in widths:
            self.down.append(double_conv(previous, width))
            previous = width
        self.pool = nn.MaxPool2d(2)
        self.up = nn.ModuleList()
        self.up_conv = nn.ModuleList()
        for width in reversed(widths[:-1]):
            self.up.append(nn.ConvTranspose2d(previous, width, 2, stride=2))
            self.up_conv.append(double_conv(2 * width, width))
            previous = width
        self.head = nn.Conv2d(previous, num_classes, 1)
        for module in self.modules():  # He init: an untrained net is not one class everywhere
            if isinstance(module, (nn.Conv2d, nn.ConvTranspose2d)):
                nn.init.kaiming_normal_(module.weight, nonlinearity="relu")

    def forward(self, x):
        skips = []
        for i, block in enumerate(self.down):
            x = block(x)
            if i < len(self.down) - 1:
                skips.append(x)
                x = self.pool(x)
        for up, conv, skip in zip(self.up, self.up_conv, reversed(skips)):
            x = conv(torch.cat([up(x), skip], dim=1))
        return self.head(x)


# ----------------------------------------------------------------------------------------------
# Data
# ----------------------------------------------------------------------------------------------
def synthetic_pairs(drive):
    images = sorted(glob.glob(os.path.join(drive, "image_02", "data", "*.png")))
    pairs = []
    for image in images:
        label = os.path.join(drive, "ground_truth", "image_02_labels", os.path.basename(image))
        if os.path.exists(label):
            pairs.append((image, label))
    return pairs


def cityscapes_pairs(spec):
    root, _, split = spec.partition(":")
    split = split or "train"
    pairs = []
    for image in sorted(glob.glob(os.path.join(root, "leftImg8bit", split, "*", "*_leftImg8bit.png"))):
        city = os.path.basename(os.path.dirname(image))
        stem = os.path.basename(image)[: -len("_leftImg8bit.png")]
        label = os.path.join(root, "gtFine", split, city, stem + "_gtFine_labelIds.png")
        if os.path.exists(label):
            pairs.append((image, label))
    return pairs


def kitti_semantics_pairs(root):
    base = os.path.join(root, "training") if os.path.isdir(os.path.join(root, "training")) else root
    pairs = []
    for image in sorted(glob.glob(os.path.join(base, "image_2", "*.png"))):
        label = os.path.join(base, "semantic", os.path.basename(image))
        if os.path.exists(label):
            pairs.append((image, label))
    return pairs


# CamVid (SegNet's 11 classes) -> Cityscapes labelId; 11 (unlabelled) and above -> ignored.
CAMVID_TO_LABEL_ID = [23, 11, 17, 7, 8, 21, 20, 13, 26, 24, 25]


def camvid_lut():
    lut = np.full(256, IGNORE_INDEX, dtype=np.uint8)
    lut[: len(CAMVID_TO_LABEL_ID)] = CAMVID_TO_LABEL_ID
    return lut


def camvid_pairs(spec):
    root, _, split = spec.partition(":")
    split = split or "train"
    pairs = []
    images = sorted(glob.glob(os.path.join(root, split, "*.jpg")) +
                    glob.glob(os.path.join(root, split, "*.png")))
    for image in images:
        stem = os.path.splitext(os.path.basename(image))[0]
        label = os.path.join(root, split + "annot", stem + ".png")
        if os.path.exists(label):
            pairs.append({"image": image, "label": label, "lut": camvid_lut()})
    return pairs


# Pseudo-labels: labelIds of the classes CamVid merges are merged the same way.
PSEUDO_MERGE = {19: 20, 27: 26, 28: 26}  # traffic light -> sign, truck/bus -> car


def enet_pseudo_pairs(root):
    lut = np.arange(256, dtype=np.uint8)
    for source, target in PSEUDO_MERGE.items():
        lut[source] = target
    pairs = []
    for image in sorted(glob.glob(os.path.join(root, "image_2", "*.png"))):
        name = os.path.basename(image)
        label = os.path.join(root, "labels", name)
        confidence = os.path.join(root, "confidence", name)
        if os.path.exists(label):
            pairs.append({"image": image, "label": label, "lut": lut, "pseudo": True,
                          "confidence": confidence if os.path.exists(confidence) else None})
    return pairs


LOADERS = {"synthetic": synthetic_pairs, "cityscapes": cityscapes_pairs,
           "kitti_semantics": kitti_semantics_pairs, "camvid": camvid_pairs,
           "enet_pseudo": enet_pseudo_pairs}


def parse_spec(default_dataset, spec):
    """[DATASET=]SPEC[@SCALE] -> (dataset, spec, scale or None)."""
    dataset = default_dataset
    head, eq, tail = spec.partition("=")
    if eq and head in LOADERS:
        dataset, spec = head, tail
    scale = None
    body, at, factor = spec.rpartition("@")
    if at:
        try:
            scale = float(factor)
            spec = body
        except ValueError:
            pass
    return dataset, spec, scale


def collect_pairs(dataset, specs, every, resize_factor, pseudo_repeat=1):
    pairs = []
    for raw_spec in specs:
        spec_dataset, spec, scale = parse_spec(dataset, raw_spec)
        found = LOADERS[spec_dataset](spec)
        if not found:
            sys.exit(f"train_unet: no image/label pairs for dataset '{spec_dataset}' in {spec}")
        found = [p if isinstance(p, dict) else {"image": p[0], "label": p[1]} for p in found]
        for pair in found:
            pair["scale"] = resize_factor if scale is None else scale
        repeat = pseudo_repeat if spec_dataset == "enet_pseudo" else 1
        pairs.extend(found[::every] * repeat)
        print(f"  {spec_dataset} {spec}: {len(found[::every])} frames x {repeat}, "
              f"scale {pairs[-1]['scale']}")
    return pairs


def load_pair(pair, min_confidence=0.0):
    image, label = load_frame(pair["image"], pair["label"], pair["scale"])
    if pair.get("lut") is not None:
        label = pair["lut"][label]
    if pair.get("pseudo") and pair.get("confidence") and min_confidence > 0:
        confidence = cv2.imread(pair["confidence"], cv2.IMREAD_GRAYSCALE)
        if pair["scale"] != 1.0:
            confidence = cv2.resize(confidence, (label.shape[1], label.shape[0]),
                                    interpolation=cv2.INTER_AREA)
        label = label.copy()
        label[confidence < min_confidence * 255.0] = IGNORE_INDEX
    return image, label


def load_frame(image_path, label_path, resize_factor):
    image = cv2.imread(image_path, cv2.IMREAD_COLOR)
    label = cv2.imread(label_path, cv2.IMREAD_UNCHANGED)
    if image is None or label is None:
        sys.exit(f"train_unet: cannot read {image_path} or {label_path}")
    if label.ndim != 2 or label.dtype != np.uint8:
        sys.exit(f"train_unet: {label_path} is not a mono8 labelId image")
    if label.shape != image.shape[:2]:
        sys.exit(f"train_unet: {label_path} size {label.shape} != image size {image.shape[:2]}")
    if resize_factor != 1.0:
        size = (round(image.shape[1] * resize_factor), round(image.shape[0] * resize_factor))
        image = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
        label = cv2.resize(label, size, interpolation=cv2.INTER_NEAREST_EXACT)
    # RGB: the C++ Segmenter feeds RGB (card swap_rb: true).
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB), label


def label_lut(class_label_ids):
    lut = np.full(256, IGNORE_INDEX, dtype=np.uint8)
    for index, label_id in enumerate(class_label_ids):
        lut[label_id] = index
    return lut


def to_tensor(images):
    """N x H x W x 3 uint8 RGB -> N x 3 x H x W float in [0, 1] (card: scale 1/255, mean 0)."""
    return torch.from_numpy(np.ascontiguousarray(images)).permute(0, 3, 1, 2).float() / 255.0


def pad_to_multiple(image, multiple):
    """Reflect-pads H x W x C bottom/right to a multiple (the C++ Segmenter does the same)."""
    height, width = image.shape[:2]
    pad_h = (-height) % multiple
    pad_w = (-width) % multiple
    return cv2.copyMakeBorder(image, 0, pad_h, 0, pad_w, cv2.BORDER_REFLECT_101)


def random_batch(frames, batch, crop_h, crop_w, rng, augment=False, strong_color=False):
    images, labels = [], []
    for _ in range(batch):
        image, label = frames[rng.randrange(len(frames))]
        height, width = label.shape
        # --augment: a random scale (0.75 .. 1.33, as far as the frame allows) and colour.
        scale = math.exp(rng.uniform(math.log(0.75), math.log(1.33))) if augment else 1.0
        scale = max(scale, crop_h / height, crop_w / width)
        src_h, src_w = min(height, round(crop_h / scale)), min(width, round(crop_w / scale))
        top = rng.randrange(height - src_h + 1)
        left = rng.randrange(width - src_w + 1)
        image = image[top:top + src_h, left:left + src_w]
        label = label[top:top + src_h, left:left + src_w]
        if (src_h, src_w) != (crop_h, crop_w):
            image = cv2.resize(image, (crop_w, crop_h), interpolation=cv2.INTER_LINEAR)
            label = cv2.resize(label, (crop_w, crop_h), interpolation=cv2.INTER_NEAREST_EXACT)
        if augment:
            gain = np.array([rng.uniform(0.9, 1.1) for _ in range(3)], np.float32)
            contrast, brightness = rng.uniform(0.7, 1.3), rng.uniform(-30, 30)
            image = image.astype(np.float32)
            if strong_color:  # exposure / camera changes: gamma, saturation, wider contrast
                contrast = rng.uniform(0.5, 1.6)
                image = 255.0 * (image / 255.0) ** rng.uniform(0.6, 1.6)
                gray = image.mean(2, keepdims=True)
                image = gray + (image - gray) * rng.uniform(0.4, 1.5)
            mean = image.reshape(-1, 3).mean(0)
            image = np.clip((image - mean) * contrast * gain + mean + brightness, 0,
                            255).astype(np.uint8)
        if rng.random() < 0.5:
            image, label = image[:, ::-1], label[:, ::-1]
        images.append(image)
        labels.append(label)
    return to_tensor(np.stack(images)), torch.from_numpy(np.ascontiguousarray(np.stack(labels))).long()


# ----------------------------------------------------------------------------------------------
# Evaluation
# ----------------------------------------------------------------------------------------------
@torch.no_grad()
def predict(model, image, multiple, device):
    padded = pad_to_multiple(image, multiple)
    scores = model(to_tensor(padded[None]).to(device))
    return scores[0, :, : image.shape[0], : image.shape[1]].argmax(0).cpu().numpy()


def confusion(predicted, truth, num_classes):
    valid = truth != IGNORE_INDEX
    return np.bincount(num_classes * truth[valid].astype(np.int64) + predicted[valid],
                       minlength=num_classes ** 2).reshape(num_classes, num_classes)


def iou_report(matrix, class_label_ids):
    """Per-class IoU over classes that occur in the ground truth; mIoU is their mean."""
    intersection = np.diag(matrix).astype(np.float64)
    truth_count = matrix.sum(1)
    union = truth_count + matrix.sum(0) - intersection
    ious = {}
    for index, label_id in enumerate(class_label_ids):
        if truth_count[index] > 0:
            ious[label_id] = intersection[index] / union[index]
    miou = float(np.mean(list(ious.values()))) if ious else 0.0
    pixel_accuracy = intersection.sum() / max(1, matrix.sum())
    return ious, miou, pixel_accuracy


def evaluate(model, frames, class_label_ids, multiple, device):
    model.eval()
    matrix = np.zeros((len(class_label_ids), len(class_label_ids)), dtype=np.int64)
    for image, label in frames:
        matrix += confusion(predict(model, image, multiple, device), label, len(class_label_ids))
    model.train()
    return iou_report(matrix, class_label_ids)


def print_report(title, ious, miou, pixel_accuracy):
    names = label_names()
    print(f"{title}: mIoU {miou:.4f}, pixel accuracy {pixel_accuracy:.4f}")
    for label_id, iou in sorted(ious.items()):
        print(f"    {label_id:2d} {names.get(label_id, '?'):20s} IoU {iou:.4f}")
    sys.stdout.flush()


def label_names():
    """labelId -> name, from the C++ header (the project's single table)."""
    header = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "include",
                          "inekf_semantic_mapping", "perception", "cityscapes.h")
    names = {}
    try:
        with open(header) as f:
            for line in f:
                line = line.strip()
                if line.startswith("{") and '"' in line:
                    label_id = int(line[1:].split(",")[0])
                    names[label_id] = line.split('"')[1]
    except OSError:
        pass
    return names


# ----------------------------------------------------------------------------------------------
# Export
# ----------------------------------------------------------------------------------------------
def export_onnx(model, path, sample_image, multiple, num_threads):
    """Exports, then checks that OpenCV's dnn reads it and computes what torch computes."""
    model = model.cpu().eval()
    padded = pad_to_multiple(sample_image, multiple)
    x = to_tensor(padded[None])
    tmp_path = path + ".tmp"
    torch.onnx.export(model, x, tmp_path, opset_version=11, do_constant_folding=True,
                      input_names=["image"], output_names=["scores"],
                      dynamic_axes={"image": {2: "height", 3: "width"},
                                    "scores": {2: "height", 3: "width"}})
    with torch.no_grad():
        expected = model(x).numpy()
    cv2.setNumThreads(num_threads)
    net = cv2.dnn.readNetFromONNX(tmp_path)
    blob = cv2.dnn.blobFromImage(cv2.cvtColor(padded, cv2.COLOR_RGB2BGR), 1.0 / 255.0,
                                 swapRB=True)
    net.setInput(blob)
    got = net.forward()
    max_error = float(np.abs(got - expected).max())
    agreement = float((got.argmax(1) == expected.argmax(1)).mean())
    print(f"ONNX check (OpenCV {cv2.__version__} vs torch): max |diff| {max_error:.2e}, "
          f"argmax agreement {agreement:.6f}")
    if got.shape != expected.shape or agreement < 0.999:
        os.remove(tmp_path)
        sys.exit("train_unet: OpenCV's output of the exported model differs from torch's")
    os.replace(tmp_path, path)


def write_card(path, name, class_label_ids, resize_factor, multiple, command, miou, note,
               licence=None):
    tmp_path = path + ".tmp"
    ids = ", ".join(str(i) for i in class_label_ids)
    with open(tmp_path, "w") as f:
        f.write(f"# Model card for {os.path.basename(path)[:-5]}.onnx, written by scripts/train_unet.py.\n")
        f.write(f"# Trained with: {command}\n")
        f.write(f"# {note}\n")
        if licence:
            f.write(f"# Licence: {licence}\n")
        f.write(f"name: {name}\n")
        f.write("input: {width: 0, height: 0}  # 0 x 0: the image's own size (times resize_factor)\n")
        f.write(f"resize_factor: {resize_factor}  # the network was trained at this image scale\n")
        f.write("resize_policy: pad_to_multiple\n")
        f.write(f"pad_multiple: {multiple}  # reflect-pad to this multiple, crop the output\n")
        f.write("mean: [0, 0, 0]\n")
        f.write("scale: 0.00392156862745098  # 1/255\n")
        f.write("swap_rb: true  # the network takes RGB\n")
        f.write(f"num_output_channels: {len(class_label_ids)}\n")
        f.write(f"output_label_ids: [{ids}]  # output channel index -> Cityscapes labelId\n")
        f.write(f"validation_miou: {miou:.4f}\n")
    os.replace(tmp_path, path)


# ----------------------------------------------------------------------------------------------
def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--dataset", choices=sorted(LOADERS), default="synthetic")
    parser.add_argument("--train", action="append", required=True,
                        help="drive folder / dataset root (cityscapes: ROOT[:split]); repeatable")
    parser.add_argument("--val", action="append", required=True,
                        help="held-out drive folder / dataset root; repeatable")
    parser.add_argument("--train-every", type=int, default=1, help="use every n-th train frame")
    parser.add_argument("--val-every", type=int, default=5, help="use every n-th val frame")
    parser.add_argument("--classes", default="auto",
                        help="comma-separated labelIds; auto: those in the synthetic train labels, "
                             "or the 19 Cityscapes trainId classes")
    parser.add_argument("--resize-factor", type=float, default=1.0)
    parser.add_argument("--base", type=int, default=8)
    parser.add_argument("--depth", type=int, default=4)
    parser.add_argument("--crop", default="192x320", help="HxW training crop (after resizing)")
    parser.add_argument("--batch", type=int, default=4)
    parser.add_argument("--class-weighting", action="store_true",
                        help="weight the loss by (median class frequency / frequency)^0.5: small "
                             "classes (poles, signs) are learned sooner")
    parser.add_argument("--augment", action="store_true",
                        help="random scale (0.75..1.33) and colour (contrast, brightness, gain)")
    parser.add_argument("--strong-color", action="store_true",
                        help="with --augment: also gamma (0.6..1.6), saturation (0.4..1.5) and a "
                             "wider contrast range (0.5..1.6), against the camera domain gap")
    parser.add_argument("--pseudo-min-confidence", type=float, default=0.0,
                        help="enet_pseudo: ignore pixels whose confidence image is below this")
    parser.add_argument("--repeat-pseudo", type=int, default=1,
                        help="enet_pseudo: sample each frame this many times as often")
    parser.add_argument("--licence", help="a licence line for the model card")
    parser.add_argument("--lr", type=float, default=2e-3)
    parser.add_argument("--steps", type=int, default=100000)
    parser.add_argument("--minutes", type=float, default=25.0, help="wall-clock training budget")
    parser.add_argument("--eval-interval", type=int, default=200)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--init-from", help="a .pt state dict (saved beside every export) to "
                        "continue training from; classes/base/depth must match")
    parser.add_argument("--output", required=True, help="ONNX path; the card goes to <name>.yaml")
    args = parser.parse_args()

    command = "scripts/train_unet.py " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    rng = random.Random(args.seed)
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    multiple = 2 ** args.depth
    crop_h, crop_w = (int(v) for v in args.crop.lower().split("x"))

    train_pairs = collect_pairs(args.dataset, args.train, args.train_every, args.resize_factor,
                                args.repeat_pseudo)
    val_pairs = collect_pairs(args.dataset, args.val, args.val_every, args.resize_factor)
    print(f"{len(train_pairs)} training frames, {len(val_pairs)} validation frames, device {device}")
    loaded = {}
    def cached(pair):  # repeated frames share their arrays
        key = (pair["image"], pair["scale"])
        if key not in loaded:
            loaded[key] = load_pair(pair, args.pseudo_min_confidence)
        return loaded[key]
    train_raw = [cached(p) for p in train_pairs]
    val_raw = [cached(p) for p in val_pairs]

    if args.classes != "auto":
        class_label_ids = [int(v) for v in args.classes.split(",")]
    elif args.dataset == "synthetic":
        present = np.zeros(256, dtype=bool)
        for _, label in train_raw:
            present[np.unique(label)] = True
        class_label_ids = [i for i in range(NUM_LABEL_IDS) if present[i]]
    else:
        class_label_ids = CITYSCAPES_TRAIN_LABEL_IDS
    print(f"classes (output index -> labelId): {class_label_ids}")
    lut = label_lut(class_label_ids)
    train_frames = [(image, lut[label]) for image, label in train_raw]
    val_frames = [(image, lut[label]) for image, label in val_raw]
    crop_h = min(crop_h, min(l.shape[0] for _, l in train_frames) // multiple * multiple)
    crop_w = min(crop_w, min(l.shape[1] for _, l in train_frames) // multiple * multiple)

    model = UNet(len(class_label_ids), args.base, args.depth).to(device)
    print(f"U-Net base {args.base} depth {args.depth}: "
          f"{sum(p.numel() for p in model.parameters())} parameters; crops {crop_h}x{crop_w}")
    if args.init_from:
        model.load_state_dict(torch.load(args.init_from, map_location=device))
        print(f"continuing from {args.init_from}")
    optimizer = torch.optim.Adam(model.parameters(), lr=args.lr)
    weights = None
    if args.class_weighting:
        counts = np.zeros(len(class_label_ids), dtype=np.float64)
        for _, label in train_frames:
            counts += np.bincount(label[label != IGNORE_INDEX], minlength=len(class_label_ids))
        frequency = counts / counts.sum()
        present = frequency > 0
        weights = np.ones_like(frequency)
        weights[present] = np.clip((np.median(frequency[present]) / frequency[present]) ** 0.5,
                                   0.2, 10.0)
        print("class weights: " + ", ".join(f"{i}:{w:.2f}" for i, w in zip(class_label_ids, weights)))
        weights = torch.tensor(weights, dtype=torch.float32, device=device)
    loss_function = nn.CrossEntropyLoss(weight=weights, ignore_index=IGNORE_INDEX)
    budget_s = args.minutes * 60.0
    # Cosine decay over the time budget (or the step budget, whichever is shorter).
    start = time.time()
    step = 0
    while step < args.steps and time.time() - start < budget_s:
        progress = max((time.time() - start) / budget_s, step / args.steps)
        for group in optimizer.param_groups:
            group["lr"] = args.lr * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * min(1.0, progress))))
        images, labels = random_batch(train_frames, args.batch, crop_h, crop_w, rng, args.augment,
                                      args.strong_color)
        loss = loss_function(model(images.to(device)), labels.to(device))
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        step += 1
        if step % 20 == 0:
            print(f"step {step} loss {loss.item():.4f} ({time.time() - start:.0f} s)", flush=True)
        if step % 500 == 0:  # a checkpoint to continue from (--init-from) if stopped
            torch.save(model.state_dict(), os.path.splitext(args.output)[0] + ".pt")
        if step % args.eval_interval == 0:
            print_report(f"step {step} validation", *evaluate(model, val_frames[::4],
                                                              class_label_ids, multiple, device))
    print(f"trained {step} steps in {time.time() - start:.0f} s")

    ious, miou, pixel_accuracy = evaluate(model, val_frames, class_label_ids, multiple, device)
    print_report(f"final validation on {len(val_frames)} held-out frames", ious, miou,
                 pixel_accuracy)
    # The torch weights, to continue training later (--init-from); not committed with the model.
    torch.save(model.state_dict(), os.path.splitext(args.output)[0] + ".pt")
    export_onnx(model, args.output, val_frames[0][0], multiple, args.threads)
    card_path = os.path.splitext(args.output)[0] + ".yaml"
    note = (f"Held-out validation ({len(val_frames)} frames of {', '.join(args.val)}): "
            f"mIoU {miou:.4f}, pixel accuracy {pixel_accuracy:.4f}; {step} steps")
    write_card(card_path, os.path.splitext(os.path.basename(args.output))[0], class_label_ids,
               args.resize_factor, multiple, command, miou, note, args.licence)
    print(f"wrote {args.output} and {card_path}")


if __name__ == "__main__":
    main()
