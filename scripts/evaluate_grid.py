#!/usr/bin/python3
"""Scores the grids of semantic_map_offline --grid STEM against a synthetic drive's ground truth:
the labelled lidar points of every scan (ground_truth/velodyne_labels, placed with
ground_truth/poses_imu_map.txt) give each voxel its majority Cityscapes labelId, and each grid cell
takes the majority label of its column's voxels (a car on the road makes a car cell).

Prints, for the cells whose truth is drivable (road, parking by default) and for the others: how
many the drivable map knows (not unknown), and of those how many it marks drivable (0) or occupied
(100); and per class how many known cells the projected map marks occupied.

    scripts/evaluate_grid.py --drive OUT/2011_09_26/2011_09_26_drive_0001_sync --grid STEM
"""
import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import compute_demo_metrics as metrics  # noqa: E402

ROAD, PARKING = 7, 9  # Cityscapes labelIds


def read_map_server(stem):
    """(cells[iy, ix] as -1/0/100, resolution, origin_x, origin_y) of STEM.pgm / STEM.yaml."""
    info = {}
    with open(stem + ".yaml") as f:
        for line in f:
            key, _, value = line.partition(":")
            info[key.strip()] = value.strip()
    resolution = float(info["resolution"])
    origin = [float(v) for v in info["origin"].strip("[]").split(",")]
    with open(stem + ".pgm", "rb") as f:
        data = f.read()
    header = data.split(maxsplit=4)
    if header[0] != b"P5":
        raise ValueError("%s.pgm: not a binary PGM" % stem)
    width, height = int(header[1]), int(header[2])
    pixels = np.frombuffer(data[len(data) - width * height:], dtype=np.uint8).reshape(height, width)
    cells = np.full(pixels.shape, -1, dtype=np.int8)
    cells[pixels == 254] = 0
    cells[pixels == 0] = 100
    return cells[::-1], resolution, origin[0], origin[1]  # row 0 = smallest y


def score_grids(drivable, projected, resolution, origin_x, origin_y, ground_truth_dir, poses=None,
                drivable_ids=(ROAD, PARKING)):
    """The figures of a drivable and a projected grid (cells[iy, ix], row 0 = smallest y, values
    -1/0/100) against a synthetic drive's ground truth; poses: T_map_imu per OXTS frame to place
    the truth with (the poses the map was built with), None for the true ones."""
    height, width = drivable.shape
    # Voxels of the truth (majority label per voxel, every scan), then columns.
    keys, labels = metrics.ground_truth_voxels(ground_truth_dir, resolution, scan_step=1, poses=poses)
    bias = 1 << 20
    ix = ((keys >> 42) & ((1 << 21) - 1)) - bias
    iy = ((keys >> 21) & ((1 << 21) - 1)) - bias
    # Voxel index -> grid cell (the grid is aligned with the voxels: origin = a voxel corner).
    gx = ix - int(round(origin_x / resolution))
    gy = iy - int(round(origin_y / resolution))
    inside = (gx >= 0) & (gx < width) & (gy >= 0) & (gy < height)
    column = gy[inside] * width + gx[inside]
    column_keys, column_labels = metrics._majority_label(column, labels[inside])
    values = drivable.reshape(-1)[column_keys]
    truth_drivable = np.isin(column_labels, list(drivable_ids))
    result = {"resolution": resolution, "cells_with_truth": int(len(column_keys))}
    for name, mask in (("truth_drivable", truth_drivable), ("truth_not_drivable", ~truth_drivable)):
        v = values[mask]
        known = v != -1
        result[name] = {
            "cells": int(mask.sum()),
            "known": int(known.sum()),
            "known_fraction": float(known.mean()) if len(v) else 0.0,
            "marked_drivable_of_known": float((v[known] == 0).mean()) if known.any() else 0.0,
            "marked_occupied_of_known": float((v[known] == 100).mean()) if known.any() else 0.0,
        }
    occupied = projected.reshape(-1)[column_keys]
    result["projected_occupied_of_known"] = {}
    for label_id, name in ((7, "road"), (8, "sidewalk"), (22, "terrain"), (11, "building"),
                           (17, "pole"), (21, "vegetation"), (26, "car")):
        v = occupied[(column_labels == label_id) & (occupied != -1)]
        if len(v):
            result["projected_occupied_of_known"][name] = round(float((v == 100).mean()), 3)
    return result


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--drive", required=True, help="synthetic drive folder (..._sync)")
    parser.add_argument("--grid", required=True,
                        help="STEM of STEM_drivable.pgm/.yaml and STEM_projected.pgm/.yaml")
    parser.add_argument("--drivable-labels", default="%d,%d" % (ROAD, PARKING),
                        help="Cityscapes labelIds counted as drivable (default road, parking)")
    parser.add_argument("--json", help="also write the figures here")
    args = parser.parse_args()
    drivable, resolution, origin_x, origin_y = read_map_server(args.grid + "_drivable")
    projected, *_ = read_map_server(args.grid + "_projected")
    result = score_grids(drivable, projected, resolution, origin_x, origin_y,
                         os.path.join(args.drive, "ground_truth"),
                         drivable_ids=[int(v) for v in args.drivable_labels.split(",")])
    print(json.dumps(result, indent=2))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=2)


if __name__ == "__main__":
    main()
