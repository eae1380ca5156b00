#!/usr/bin/python3
"""Standalone check of training/espnetv2.py with the shared EdgeNets Cityscapes weights.

  1. strict loading of s=2.0 and s=1.0;
  2. export-friendly EfficientPyrPool / avg-pool vs the literal original ops (F.adaptive_avg_pool2d, channel
     shuffle + grouped conv, F.avg_pool2d): max abs logit difference and argmax agreement on real images;
  3. pixel accuracy on the Cityscapes sample (labelTrainIds) at 1024x512 input;
  4. pixel accuracy / mIoU on the 39 dense KITTI frames (Cityscapes labelIds -> trainIds) at 1024x320 input;
  5. ONNX export at 1024x320 and 1248x384, OpenCV 4.6 parity (argmax agreement, max abs diff) and
     cv2.dnn forward time with 2 threads.

Run:  /usr/bin/python3 training/check_espnetv2.py [--quick] [--out DIR]
Keep it to 2 threads (torch and cv2): the machine is shared.
"""

from __future__ import annotations

import argparse
import glob
import os
import sys
import tempfile
import time

import numpy as np

os.environ.setdefault("OMP_NUM_THREADS", "2")
import cv2  # noqa: E402
import torch  # noqa: E402
import torch.nn.functional as F  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from espnetv2 import build_normalized_espnetv2, set_reference_mode  # noqa: E402
from onnx_export import check_onnx_against_torch, export_onnx, time_opencv_forward  # noqa: E402

SHARED = os.path.normpath(os.path.join(HERE, "..", "..", "shared"))
if not os.path.isdir(SHARED):
    SHARED = "/work/shared"
WEIGHTS = os.path.join(SHARED, "models", "espnetv2-cityscapes", "espnetv2_s_{}_city_1024x512.pth")
CITY_IMG = os.path.join(SHARED, "data/cityscapes/leftImg8bit/val/frankfurt/frankfurt_000000_000294_leftImg8bit.png")
CITY_LAB = os.path.join(SHARED, "data/cityscapes/gtFine/val/frankfurt/frankfurt_000000_000294_gtFine_labelTrainIds.png")
SK05 = os.path.join(SHARED, "data/semantickitti/sequences/05/image_2/*.png")
KS_IMG = os.path.join(SHARED, "data/kitti_semantics/training/image_2/*.jpg")
KS_LAB = os.path.join(SHARED, "data/kitti_semantics/training/semantic")

CLASS_NAMES = ["road", "sidewalk", "building", "wall", "fence", "pole", "light", "sign", "vegetation", "terrain",
               "sky", "person", "rider", "car", "truck", "bus", "train", "motorcycle", "bicycle"]
# Cityscapes labelId -> trainId (official table); everything else is ignored (255).
LABELID_TO_TRAINID = {7: 0, 8: 1, 11: 2, 12: 3, 13: 4, 17: 5, 19: 6, 20: 7, 21: 8, 22: 9, 23: 10, 24: 11, 25: 12,
                      26: 13, 27: 14, 28: 15, 31: 16, 32: 17, 33: 18}
_LUT = np.full(256, 255, np.uint8)
for _k, _v in LABELID_TO_TRAINID.items():
    _LUT[_k] = _v


def to_tensor(img_bgr: np.ndarray, w: int, h: int, interp=cv2.INTER_AREA) -> torch.Tensor:
    if img_bgr.shape[1] != w or img_bgr.shape[0] != h:
        img_bgr = cv2.resize(img_bgr, (w, h), interpolation=interp)
    rgb = img_bgr[:, :, ::-1].astype(np.float32) / 255.0
    return torch.from_numpy(np.ascontiguousarray(rgb.transpose(2, 0, 1)))[None]


def predict(net, img_bgr, w, h, label_hw, interp=cv2.INTER_AREA) -> np.ndarray:
    with torch.no_grad():
        logits = net(to_tensor(img_bgr, w, h, interp))
        logits = F.interpolate(logits, size=label_hw, mode="bilinear", align_corners=False)
    return logits.argmax(1)[0].numpy().astype(np.uint8)


def confusion(pred: np.ndarray, gt: np.ndarray, n: int = 19) -> np.ndarray:
    """n x (n+1) confusion matrix (rows: ground-truth trainId, columns: predicted 0..n, n = background)."""
    v = gt < n
    idx = (n + 1) * gt[v].astype(np.int64) + np.minimum(pred[v], n).astype(np.int64)
    return np.bincount(idx, minlength=n * (n + 1)).reshape(n, n + 1)


def summarise(conf: np.ndarray):
    """pixel accuracy, mIoU over classes with ground truth, per-class IoU, fraction predicted 'background'."""
    n = conf.shape[0]
    tp = np.diag(conf[:, :n]).astype(np.float64)
    gt = conf.sum(1).astype(np.float64)
    pred = conf[:, :n].sum(0).astype(np.float64)
    acc = tp.sum() / max(gt.sum(), 1)
    present = gt > 0
    iou = np.where(present, tp / np.maximum(gt + pred - tp, 1), np.nan)
    bg = conf[:, n].sum() / max(gt.sum(), 1)
    return acc, float(np.nanmean(iou)), iou, bg


def reference_agreement(net, tensors):
    """export-friendly path vs literal original ops, same weights, same inputs."""
    max_d, agree, tot = 0.0, 0, 0
    with torch.no_grad():
        for t in tensors:
            a = net(t)
            set_reference_mode(net, True)
            b = net(t)
            set_reference_mode(net, False)
            max_d = max(max_d, float((a - b).abs().max()))
            same = a.argmax(1) == b.argmax(1)
            agree += int(same.sum())
            tot += same.numel()
    return max_d, agree / tot


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer images, fewer timing repeats")
    ap.add_argument("--out", default=None, help="keep the ONNX files here (default: a temp dir)")
    ap.add_argument("--scales", default="2.0,1.0")
    args = ap.parse_args()
    torch.set_num_threads(2)
    cv2.setNumThreads(2)
    out_dir = args.out or tempfile.mkdtemp(prefix="espnetv2_check_")
    os.makedirs(out_dir, exist_ok=True)

    sk_imgs = sorted(glob.glob(SK05))
    ks_imgs = sorted(glob.glob(KS_IMG))
    n_par = 3 if args.quick else 6
    parity_imgs = sk_imgs[:n_par // 2] + ks_imgs[: n_par - n_par // 2]
    city_img = cv2.imread(CITY_IMG)
    city_lab = cv2.imread(CITY_LAB, cv2.IMREAD_UNCHANGED)

    rows = []
    for s in [float(x) for x in args.scales.split(",")]:
        r = {"scale": s}
        t0 = time.time()
        net = build_normalized_espnetv2(s, weights=WEIGHTS.format(s)).eval()   # strict=True inside
        r["params"] = sum(p.numel() for p in net.parameters())
        print(f"[s={s}] loaded strictly, {r['params']} parameters", flush=True)

        # 2. export-friendly vs original ops
        tens = [to_tensor(cv2.imread(p), 1024, 320) for p in parity_imgs[:2]]
        tens.append(to_tensor(city_img, 1024, 512, cv2.INTER_LINEAR))
        r["ref_maxdiff"], r["ref_agree"] = reference_agreement(net, tens)
        print(f"[s={s}] fixed ops vs adaptive/shuffle reference: max|d| {r['ref_maxdiff']:.2e}, "
              f"argmax agreement {r['ref_agree']:.6f}", flush=True)

        # 3. Cityscapes sample at 1024x512 (upscaled from 256x128), scored at label size
        pred = predict(net, city_img, 1024, 512, city_lab.shape, cv2.INTER_LINEAR)
        r["city_acc"], r["city_miou"], _, _ = summarise(confusion(pred, city_lab))
        pred = predict(net, city_img, 256, 128, city_lab.shape, cv2.INTER_LINEAR)
        r["city_acc_256"] = summarise(confusion(pred, city_lab))[0]
        print(f"[s={s}] Cityscapes sample: pixel acc {r['city_acc']:.4f} (1024x512 input), "
              f"{r['city_acc_256']:.4f} (native 256x128)", flush=True)

        # 4. KITTI dense frames at 1024x320
        conf = np.zeros((19, 20), np.int64)
        frames = ks_imgs[:8] if args.quick else ks_imgs
        for p in frames:
            lab = cv2.imread(os.path.join(KS_LAB, os.path.basename(p)[:-4] + ".png"), cv2.IMREAD_UNCHANGED)
            gt = _LUT[lab]
            conf += confusion(predict(net, cv2.imread(p), 1024, 320, gt.shape), gt)
        r["kitti_acc"], r["kitti_miou"], iou, r["kitti_bg"] = summarise(conf)
        r["kitti_n"] = len(frames)
        print(f"[s={s}] KITTI {len(frames)} dense frames @1024x320: pixel acc {r['kitti_acc']:.4f}, "
              f"mIoU {r['kitti_miou']:.4f}, predicted background {r['kitti_bg']:.4f}", flush=True)
        print("        per-class IoU: " + ", ".join(f"{n} {v:.2f}" for n, v in zip(CLASS_NAMES, iou)
                                                   if not np.isnan(v)), flush=True)

        # 5. export, parity, timing
        for (w, h) in ((1024, 320), (1248, 384)):
            path = os.path.join(out_dir, f"espnetv2_s{s}_{w}x{h}.onnx")
            export_onnx(net, path, w, h)
            par = check_onnx_against_torch(net, path, parity_imgs, w, h, threads=2)
            tm = time_opencv_forward(path, w, h, threads=2, repeats=3 if args.quick else 5)
            r[f"{w}x{h}"] = (par, tm)
            print(f"[s={s}] {w}x{h}: OpenCV parity agreement {par['argmax_agreement']:.6f} "
                  f"(min/image {par['min_image_agreement']:.6f}), max|d| {par['max_abs_diff']:.2e}, "
                  f"cv2.dnn {tm['median_ms']:.0f} ms (2 threads)", flush=True)
        r["time_s"] = time.time() - t0
        rows.append(r)
        del net

    print("\n=== ESPNetv2 summary (ONNX in %s) ===" % out_dir)
    hdr = (f"{'s':>4} {'params':>8} {'ref agree':>10} {'ref max|d|':>10} {'city acc':>9} {'kitti acc':>9} "
           f"{'kitti mIoU':>10} {'size':>9} {'cv agree':>9} {'cv max|d|':>9} {'cv ms':>7}")
    print(hdr)
    print("-" * len(hdr))
    for r in rows:
        for i, size in enumerate(("1024x320", "1248x384")):
            par, tm = r[size]
            head = (f"{r['scale']:>4} {r['params']:>8} {r['ref_agree']:>10.6f} {r['ref_maxdiff']:>10.2e} "
                    f"{r['city_acc']:>9.4f} {r['kitti_acc']:>9.4f} {r['kitti_miou']:>10.4f}") if i == 0 else \
                " " * 75
            print(f"{head} {size:>9} {par['argmax_agreement']:>9.6f} {par['max_abs_diff']:>9.2e} "
                  f"{tm['median_ms']:>7.0f}")
    ok = all(r[sz][0]["argmax_agreement"] >= 0.999 for r in rows for sz in ("1024x320", "1248x384"))
    print("\nOpenCV parity target (>= 99.9 % argmax agreement):", "PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
