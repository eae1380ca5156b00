#!/usr/bin/python3
"""Camera label accuracy of one class by range: where a network loses a class.

usage: camera_labels_by_range.py --sequence DIR --model MODEL [--model MODEL ...]
           [--class sidewalk] [--bins 0,8,12,20,100] [--segment-image PATH]

DIR is a SemanticKITTI sequence folder (velodyne/, labels/, image_2/, calib.txt). Each frame is
labelled by the C++ Segmenter (segment_image, with the model's card) and every human-labelled
lidar point of the class in the left camera's view is scored by its horizontal distance from
the lidar: the share labelled with that class, per range bin, and the class that takes the
rest. The truth goes through the project's SemanticKITTI -> Cityscapes table, as
evaluate_semantics scores it. Prints one Markdown table.
"""
import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))
sys.path.insert(0, os.path.join(REPO_ROOT, "training"))
import labels  # noqa: E402


def read_calibration(path):
    values = {}
    with open(path) as f:
        for line_number, line in enumerate(f, 1):
            if not line.strip():
                continue
            key, sep, rest = line.partition(":")
            if not sep:
                sys.exit(f"{path}:{line_number}: expected 'KEY: numbers'")
            values[key.strip()] = np.array(rest.split(), float)
    for key in ("P2", "Tr"):
        if key not in values or values[key].size != 12:
            sys.exit(f"{path}: no 3x4 '{key}'")
    velo_to_cam = np.vstack([values["Tr"].reshape(3, 4), [0, 0, 0, 1]])
    return values["P2"].reshape(3, 4), velo_to_cam


def segment(segment_image, model, image_path, out_path):
    run = subprocess.run([segment_image, "--model", model, "--input", image_path, "--output",
                          out_path, "--ids", "trainid", "--threads", "2"],
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if run.returncode != 0:
        sys.exit(f"segment_image failed on {image_path} with {model}:\n{run.stdout[-2000:]}")


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sequence", required=True)
    p.add_argument("--model", action="append", required=True)
    p.add_argument("--class", dest="class_name", default="sidewalk")
    p.add_argument("--bins", default="0,8,12,20,100", help="range bin edges (m)")
    p.add_argument("--segment-image", default=os.path.join(
        os.environ.get("ISM_BIN", os.path.join(REPO_ROOT, ".ws/devel/lib/inekf_semantic_mapping")),
        "segment_image"))
    args = p.parse_args()
    import cv2

    names = labels.train_id_names()  # trainId -> name
    if args.class_name not in names:
        sys.exit(f"--class {args.class_name}: not a Cityscapes class ({', '.join(names)})")
    class_id = names.index(args.class_name)
    bins = np.array([float(b) for b in args.bins.split(",")])
    if len(bins) < 2 or np.any(np.diff(bins) <= 0):
        sys.exit(f"--bins {args.bins}: expected increasing edges")
    if not os.access(args.segment_image, os.X_OK):
        sys.exit(f"{args.segment_image}: not built (scripts/build.sh segment_image)")
    seq = args.sequence
    projection, velo_to_cam = read_calibration(os.path.join(seq, "calib.txt"))
    to_train = labels.semantickitti_to_train_id_lut()
    frames = sorted(f[:-4] for f in os.listdir(os.path.join(seq, "image_2")) if f.endswith(".png"))
    if not frames:
        sys.exit(f"{seq}/image_2: no frames")
    n_bins = len(bins) - 1
    total = np.zeros(n_bins)
    # Per model and range bin: how many of the class's points got each trainId (256: uint8).
    counts = np.zeros((len(args.model), n_bins, 256), np.int64)
    with tempfile.TemporaryDirectory() as tmp:
        for frame in frames:
            image_path = os.path.join(seq, "image_2", frame + ".png")
            image = cv2.imread(image_path)
            if image is None:
                sys.exit(f"{image_path}: not an image")
            height, width = image.shape[:2]
            points = np.fromfile(os.path.join(seq, "velodyne", frame + ".bin"),
                                 np.float32).reshape(-1, 4)[:, :3]
            truth = np.fromfile(os.path.join(seq, "labels", frame + ".label"), np.uint32)
            if truth.size != len(points):
                sys.exit(f"{seq}/labels/{frame}.label: {truth.size} labels for {len(points)} points")
            truth = to_train[truth & 0xFFFF]
            uvw = (np.c_[points, np.ones(len(points))] @ velo_to_cam.T) @ projection.T
            z = np.maximum(uvw[:, 2], 1e-6)
            u, v = uvw[:, 0] / z, uvw[:, 1] / z
            keep = (uvw[:, 2] > 0.5) & (u >= 0) & (u < width) & (v >= 0) & (v < height)
            keep &= truth == class_id
            distance = np.linalg.norm(points[keep, :2], axis=1)
            which = np.digitize(distance, bins) - 1
            inside = (which >= 0) & (which < n_bins)
            total += np.bincount(which[inside], minlength=n_bins)[:n_bins]
            for m, model in enumerate(args.model):
                out = os.path.join(tmp, f"{m}.png")
                segment(args.segment_image, model, image_path, out)
                predicted = cv2.imread(out, cv2.IMREAD_GRAYSCALE)
                at = predicted[v[keep].astype(int), u[keep].astype(int)]
                np.add.at(counts[m], (which[inside], at[inside]), 1)
    header = " | ".join(f"{bins[b]:g}-{bins[b + 1]:g} m ({int(total[b])} points)"
                        for b in range(n_bins))
    print(f"{args.class_name} in {seq}, share labelled {args.class_name} (most of the rest):\n")
    print(f"| model | {header} |")
    print("|---|" + "---|" * n_bins)
    for m, model in enumerate(args.model):
        cells = []
        for b in range(n_bins):
            share = counts[m, b, class_id] / total[b] if total[b] else float("nan")
            others = counts[m, b].copy()
            others[class_id] = 0
            rest = int(others.argmax())
            cells.append(f"{share:.2f}" + (f" ({names[rest] if rest < len(names) else 'void'})"
                                           if others[rest] else ""))
        print(f"| {model} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
