#!/usr/bin/python3
"""Checks training/enet.py's PyTorch ENet, with e-lab's Torch7 Cityscapes weights read by
training/torch7.py, against OpenCV dnn's Torch importer (what the C++ Segmenter runs), the C++
segment_image tool, ONNX export, speed and KITTI pixel accuracy.

Sections (--sections, comma separated; default all):
  agreement  on real KITTI images (SemanticKITTI 05 and 08, KITTI semantics), PyTorch vs
             cv2.dnn.readNetFromTorch (DNN_BACKEND_OPENCV, CPU) at the same input: the plain
             1024x512 resize (blobFromImage(bgr, 1/255, (1024, 512), swapRB=True)) and the
             built-in ENet card's input (gamma 0.7, colour standardisation to Cityscapes',
             scaled to height 416, reflect-padded right to a multiple of 16 and bottom to 512:
             1392x512 for 1242x375 / 1226x370 frames). Argmax agreement and max |logit diff|.
             A fresh OpenCV network per input size (OpenCV 4.6 keeps shapes from a net's first
             pass).
  cpp        the C++ segment_image (built-in card, --ids trainid) vs this module's labels with
             the same preprocessing, if the tool is built
  onnx       torch.onnx.export (opset 11) at 1392x512 and 1024x512, imported by
             cv2.dnn.readNetFromONNX, vs PyTorch and the Torch importer
  timing     forward at 1024x320 (eval, batch 1) and forward + backward (+ SGD step) of a
             4 x 3 x 320 x 640 batch in train mode, torch.set_num_threads(2); wall and CPU time
  accuracy   pixel accuracy (and mIoU) of the module with the card's preprocessing on the
             KITTI semantics frames with dense labels (Cityscapes labelIds -> trainIds,
             255 ignored)

Example:
  /usr/bin/python3 training/check_enet.py --images 3 --json /tmp/enet_check.json
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import subprocess
import sys
import tempfile
import time
from typing import Dict, List, Optional, Tuple

import cv2
import numpy as np
import torch

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from enet import ENet, build_enet_from_torch7  # noqa: E402

REPO = os.path.dirname(HERE)
SHARED = os.path.normpath(os.path.join(REPO, "..", "shared"))
DEFAULT_MODEL = os.path.join(SHARED, "models", "enet-cityscapes", "enet-model.net")
DEFAULT_SEGMENT_IMAGE = os.path.join(REPO, ".ws", "devel", "lib", "inekf_semantic_mapping",
                                     "segment_image")

# The built-in ENet card (src/perception/model_card.cpp: builtinEnetCityscapesCard).
CARD_GAMMA = 0.7
CITYSCAPES_RGB_MEAN = (73.16, 82.91, 72.39)
CITYSCAPES_RGB_STD = (47.68, 48.49, 47.74)
CARD_TILE = (1024, 512)  # input_width, input_height
CARD_BOTTOM_MARGIN = 96
CARD_TILE_MAX_WIDTH = 2048
CARD_TILE_MULTIPLE = 16

# Cityscapes labelId -> trainId (255: ignored).
LABEL_TO_TRAIN = np.full(256, 255, np.uint8)
for _label, _train in {7: 0, 8: 1, 11: 2, 12: 3, 13: 4, 17: 5, 19: 6, 20: 7, 21: 8, 22: 9,
                       23: 10, 24: 11, 25: 12, 26: 13, 27: 14, 28: 15, 31: 16, 32: 17,
                       33: 18}.items():
    LABEL_TO_TRAIN[_label] = _train
TRAIN_NAMES = ["road", "sidewalk", "building", "wall", "fence", "pole", "traffic light",
               "traffic sign", "vegetation", "terrain", "sky", "person", "rider", "car",
               "truck", "bus", "train", "motorcycle", "bicycle"]


# --- preprocessing (a replica of the C++ Segmenter with the built-in card) -----------------

def apply_gamma(bgr: np.ndarray, gamma: float = CARD_GAMMA) -> np.ndarray:
    table = np.clip(np.rint(255.0 * (np.arange(256) / 255.0) ** gamma), 0, 255).astype(np.uint8)
    return cv2.LUT(bgr, table)


def standardize_colors(bgr: np.ndarray) -> np.ndarray:
    mean, std = cv2.meanStdDev(bgr)
    out = np.empty_like(bgr)
    for c in range(3):  # BGR channel c is the network's (RGB) channel 2 - c
        gain = CITYSCAPES_RGB_STD[2 - c] / max(float(std[c]), 1.0)
        offset = CITYSCAPES_RGB_MEAN[2 - c] - gain * float(mean[c])
        out[..., c] = np.clip(np.rint(bgr[..., c].astype(np.float64) * gain + offset), 0, 255)
    return out


def card_network_image(bgr: np.ndarray) -> Tuple[np.ndarray, Tuple[int, int]]:
    """The card's single-tile network input (BGR uint8) and the (width, height) of the image
    inside it (top left)."""
    bgr = standardize_colors(apply_gamma(bgr))
    h, w = bgr.shape[:2]
    scale = max(CARD_TILE[0] / w, (CARD_TILE[1] - CARD_BOTTOM_MARGIN) / h)
    sw, sh = max(1, int(np.floor(w * scale + 0.5))), max(1, int(np.floor(h * scale + 0.5)))
    canvas = cv2.resize(bgr, (sw, sh), interpolation=cv2.INTER_AREA if scale < 1.0
                        else cv2.INTER_LINEAR)
    tile_w = CARD_TILE[0]
    if sw > tile_w:
        wide = (sw + CARD_TILE_MULTIPLE - 1) // CARD_TILE_MULTIPLE * CARD_TILE_MULTIPLE
        tile_w = min(CARD_TILE_MAX_WIDTH, wide)
    pad_right = max(0, tile_w - sw)
    pad_bottom = max(CARD_BOTTOM_MARGIN, CARD_TILE[1] - sh)
    reflect = pad_right < sw and pad_bottom < sh
    canvas = cv2.copyMakeBorder(canvas, 0, pad_bottom, 0, pad_right,
                                cv2.BORDER_REFLECT_101 if reflect else cv2.BORDER_REPLICATE)
    if canvas.shape[:2] != (CARD_TILE[1], tile_w):
        raise ValueError(f"image {w}x{h} needs more than one {tile_w}x{CARD_TILE[1]} tile "
                         f"(canvas {canvas.shape[1]}x{canvas.shape[0]}): not replicated here")
    return canvas, (sw, sh)


def blob(bgr: np.ndarray, size: Optional[Tuple[int, int]] = None) -> np.ndarray:
    return cv2.dnn.blobFromImage(bgr, 1.0 / 255.0, size if size else (bgr.shape[1],
                                                                        bgr.shape[0]),
                                 swapRB=True)


def labels_from_logits(logits: np.ndarray, valid: Tuple[int, int],
                       image_size: Tuple[int, int]) -> np.ndarray:
    """Card post-processing: argmax without the "unlabeled" channel 0 -> trainIds, cropped to
    the image, nearest-neighbour back to the image's size."""
    train = (logits[0, 1:].argmax(0)).astype(np.uint8)
    train = train[:valid[1], :valid[0]]
    if (train.shape[1], train.shape[0]) != image_size:
        train = cv2.resize(train, image_size, interpolation=cv2.INTER_NEAREST_EXACT)
    return train


# --- runners ---------------------------------------------------------------------------

def torch_forward(model: ENet, x: np.ndarray) -> np.ndarray:
    with torch.no_grad():
        return model(torch.from_numpy(x)).numpy()


def opencv_net(path: str, onnx: bool = False):
    net = cv2.dnn.readNetFromONNX(path) if onnx else cv2.dnn.readNetFromTorch(path)
    net.setPreferableBackend(cv2.dnn.DNN_BACKEND_OPENCV)
    net.setPreferableTarget(cv2.dnn.DNN_TARGET_CPU)
    return net


def opencv_forward(net, x: np.ndarray) -> np.ndarray:
    net.setInput(x)
    return net.forward()


def compare(a: np.ndarray, b: np.ndarray) -> Dict[str, float]:
    """Argmax agreement over all 20 channels, and without channel 0 (the card's argmax)."""
    return {"agree": float((a.argmax(1) == b.argmax(1)).mean()),
            "agree_no_unlabeled": float((a[:, 1:].argmax(1) == b[:, 1:].argmax(1)).mean()),
            "max_abs_diff": float(np.abs(a - b).max()),
            "p99_abs_diff": float(np.percentile(np.abs(a - b).max(1), 99))}


def kitti_images(n: int) -> List[str]:
    out = []
    for pattern in ("data/semantickitti/sequences/05/image_2/*.png",
                    "data/semantickitti/sequences/08/image_2/*.png",
                    "data/kitti_semantics/training/image_2/*.jpg"):
        files = sorted(glob.glob(os.path.join(SHARED, pattern)))
        if files:
            idx = np.linspace(0, len(files) - 1, min(n, len(files))).round().astype(int)
            out += [files[i] for i in sorted(set(idx))]
    return out


def short(path: str) -> str:
    return os.path.relpath(path, SHARED)


# --- sections --------------------------------------------------------------------------

def section_agreement(model: ENet, model_path: str, images: List[str]) -> Dict:
    results: Dict[str, Dict] = {}
    nets: Dict[Tuple[int, int], object] = {}  # one fresh OpenCV network per input size
    for path in images:
        bgr = cv2.imread(path, cv2.IMREAD_COLOR)
        card_img, _ = card_network_image(bgr)
        for mode, x in (("1024x512", blob(bgr, (1024, 512))), ("card", blob(card_img))):
            size = (x.shape[3], x.shape[2])
            if size not in nets:
                nets[size] = opencv_net(model_path)
            ref = opencv_forward(nets[size], x)
            out = torch_forward(model, x)
            r = compare(out, ref)
            r["size"] = f"{size[0]}x{size[1]}"
            results.setdefault(mode, {})[short(path)] = r
            print(f"  {mode:8s} {r['size']:9s} {short(path):60s} agree {r['agree']*100:.4f} % "
                  f"(no ch0 {r['agree_no_unlabeled']*100:.4f} %) max|d| {r['max_abs_diff']:.4f}"
                  f" p99 {r['p99_abs_diff']:.2e}", flush=True)
    summary = {}
    for mode, per in results.items():
        summary[mode] = {
            "min_agree": min(r["agree"] for r in per.values()),
            "mean_agree": float(np.mean([r["agree"] for r in per.values()])),
            "max_abs_diff": max(r["max_abs_diff"] for r in per.values()),
            "sizes": sorted({r["size"] for r in per.values()})}
        print(f"  {mode}: agreement min {summary[mode]['min_agree']*100:.4f} % mean "
              f"{summary[mode]['mean_agree']*100:.4f} %, max |logit diff| "
              f"{summary[mode]['max_abs_diff']:.4f}, sizes {summary[mode]['sizes']}")
    return {"per_image": results, "summary": summary}


def section_cpp(model: ENet, model_path: str, images: List[str], tool: str) -> Dict:
    if not os.access(tool, os.X_OK):
        print(f"  {tool} is not built: skipped")
        return {"skipped": f"{tool} not built"}
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for path in images:
            bgr = cv2.imread(path, cv2.IMREAD_COLOR)
            out_png = os.path.join(tmp, "labels.png")
            cmd = [tool, "--model", model_path, "--input", path, "--output", out_png,
                   "--ids", "trainid", "--threads", "2"]
            proc = subprocess.run(cmd, capture_output=True, text=True)
            if proc.returncode != 0:
                print(f"  segment_image failed on {short(path)}: {proc.stderr[-500:]}")
                results[short(path)] = {"error": proc.stderr[-500:]}
                continue
            cpp = cv2.imread(out_png, cv2.IMREAD_UNCHANGED)
            card_img, valid = card_network_image(bgr)
            ours = labels_from_logits(torch_forward(model, blob(card_img)), valid,
                                      (bgr.shape[1], bgr.shape[0]))
            agree = float((cpp == ours).mean())
            results[short(path)] = {"agree": agree}
            print(f"  {short(path):60s} C++ segment_image vs module: {agree*100:.4f} %",
                  flush=True)
    ok = [r["agree"] for r in results.values() if "agree" in r]
    return {"per_image": results, "min_agree": min(ok) if ok else None}


def section_onnx(model: ENet, model_path: str, images: List[str]) -> Dict:
    results = {}
    bgr = cv2.imread(images[0], cv2.IMREAD_COLOR)
    card_img, _ = card_network_image(bgr)
    with tempfile.TemporaryDirectory() as tmp:
        for name, x in (("card", blob(card_img)), ("1024x512", blob(bgr, (1024, 512)))):
            f = os.path.join(tmp, "enet.onnx")
            torch.onnx.export(model, torch.from_numpy(x), f, opset_version=11,
                              input_names=["input"], output_names=["output"])
            ops = sorted({n.op_type for n in _onnx_nodes(f)})
            try:
                y = opencv_forward(opencv_net(f, onnx=True), x)
            except cv2.error as e:
                results[name] = {"error": str(e)[-400:], "ops": ops}
                print(f"  {name}: OpenCV cannot import/run the ONNX: {str(e)[-300:]}")
                continue
            r_torch = compare(y, torch_forward(model, x))
            r_t7 = compare(y, opencv_forward(opencv_net(model_path), x))
            results[name] = {"size": f"{x.shape[3]}x{x.shape[2]}", "vs_pytorch": r_torch,
                             "vs_opencv_torch7": r_t7, "ops": ops,
                             "bytes": os.path.getsize(f)}
            print(f"  {name} {x.shape[3]}x{x.shape[2]}: OpenCV-ONNX vs PyTorch agree "
                  f"{r_torch['agree']*100:.4f} % max|d| {r_torch['max_abs_diff']:.2e}; vs "
                  f"OpenCV-Torch7 agree {r_t7['agree']*100:.4f} % max|d| "
                  f"{r_t7['max_abs_diff']:.4f}; ops {ops}", flush=True)
    return results


def _onnx_nodes(path: str):
    try:
        import onnx
    except ImportError:
        return []
    return onnx.load(path).graph.node


def _timed(fn, repeat: int) -> Dict[str, float]:
    fn()  # warm-up
    walls, cpus = [], []
    for _ in range(repeat):
        w, c = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - w)
        cpus.append(time.process_time() - c)
    return {"wall_s": float(np.median(walls)), "cpu_s": float(np.median(cpus)),
            "repeat": repeat}


def section_timing(model_path: str, repeat: int) -> Dict:
    model = build_enet_from_torch7(model_path)
    x = torch.rand(1, 3, 320, 1024)

    def forward():
        with torch.no_grad():
            model(x)

    res = {"forward_1024x320": _timed(forward, repeat)}
    model.train()
    opt = torch.optim.SGD(model.parameters(), lr=1e-4, momentum=0.9)
    xb = torch.rand(4, 3, 320, 640)
    yb = torch.randint(0, 20, (4, 320, 640))
    loss_fn = torch.nn.CrossEntropyLoss(ignore_index=255)

    def train_step():
        opt.zero_grad(set_to_none=True)
        loss = loss_fn(model(xb), yb)
        loss.backward()
        opt.step()

    res["train_step_4x320x640"] = _timed(train_step, repeat)
    res["load_average"] = os.getloadavg()
    for k, v in res.items():
        if isinstance(v, dict):
            print(f"  {k}: wall {v['wall_s']:.2f} s, process CPU {v['cpu_s']:.2f} s "
                  f"(median of {v['repeat']})")
    print(f"  load average {res['load_average']} (2 cores, shared)")
    return res


def section_accuracy(model: ENet) -> Dict:
    root = os.path.join(SHARED, "data", "kitti_semantics", "training")
    labels = sorted(glob.glob(os.path.join(root, "semantic", "*.png")))
    confusion = np.zeros((19, 19), np.int64)
    per_frame = []
    sizes = set()
    for lp in labels:
        stem = os.path.splitext(os.path.basename(lp))[0]
        ip = next((p for p in (os.path.join(root, "image_2", stem + e)
                               for e in (".png", ".jpg")) if os.path.exists(p)), None)
        if ip is None:
            continue
        bgr = cv2.imread(ip, cv2.IMREAD_COLOR)
        gt = LABEL_TO_TRAIN[cv2.imread(lp, cv2.IMREAD_UNCHANGED)]
        card_img, valid = card_network_image(bgr)
        sizes.add(f"{card_img.shape[1]}x{card_img.shape[0]}")
        pred = labels_from_logits(torch_forward(model, blob(card_img)), valid,
                                  (bgr.shape[1], bgr.shape[0]))
        keep = gt != 255
        per_frame.append(float((pred[keep] == gt[keep]).mean()))
        confusion += np.bincount(gt[keep].astype(np.int64) * 19 + pred[keep],
                                 minlength=19 * 19).reshape(19, 19)
        print(f"  {stem}: {per_frame[-1]*100:.2f} %", flush=True)
    tp = np.diag(confusion)
    union = confusion.sum(0) + confusion.sum(1) - tp
    present = confusion.sum(1) > 0
    iou = np.where(union > 0, tp / np.maximum(union, 1), np.nan)
    res = {"frames": len(per_frame), "network_sizes": sorted(sizes),
           "pixel_accuracy": float(tp.sum() / confusion.sum()),
           "mean_frame_accuracy": float(np.mean(per_frame)),
           "min_frame_accuracy": float(np.min(per_frame)),
           "miou_present_classes": float(np.nanmean(iou[present])),
           "iou": {TRAIN_NAMES[i]: (None if np.isnan(iou[i]) else round(float(iou[i]), 4))
                   for i in range(19) if present[i]}}
    print(f"  {res['frames']} frames: pixel accuracy {res['pixel_accuracy']*100:.2f} % "
          f"(frame mean {res['mean_frame_accuracy']*100:.2f} %, min "
          f"{res['min_frame_accuracy']*100:.2f} %), mIoU over present classes "
          f"{res['miou_present_classes']*100:.2f} %")
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", default=DEFAULT_MODEL)
    ap.add_argument("--sections", default="agreement,cpp,onnx,timing,accuracy")
    ap.add_argument("--images", type=int, default=3, help="images per KITTI source")
    ap.add_argument("--segment-image", default=DEFAULT_SEGMENT_IMAGE)
    ap.add_argument("--repeat", type=int, default=3, help="timing repetitions")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--json", help="write the results here")
    ap.add_argument("--min-agree", type=float, default=0.995,
                    help="agreement below this fails (exit 1)")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    cv2.setNumThreads(args.threads)

    sections = [s.strip() for s in args.sections.split(",") if s.strip()]
    model = build_enet_from_torch7(args.model)
    images = kitti_images(args.images)
    results: Dict[str, object] = {"model": args.model, "images": [short(p) for p in images]}
    ok = True
    for s in sections:
        print(f"[{s}]", flush=True)
        if s == "agreement":
            results[s] = r = section_agreement(model, args.model, images)
            ok &= all(v["min_agree"] >= args.min_agree for v in r["summary"].values())
        elif s == "cpp":
            results[s] = r = section_cpp(model, args.model, images, args.segment_image)
            ok &= r.get("min_agree") is None or r["min_agree"] >= args.min_agree
        elif s == "onnx":
            results[s] = section_onnx(model, args.model, images)
        elif s == "timing":
            results[s] = section_timing(args.model, args.repeat)
        elif s == "accuracy":
            results[s] = section_accuracy(model)
        else:
            ap.error(f"unknown section {s}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
