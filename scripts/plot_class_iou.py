#!/usr/bin/python3
"""Plots the per-class IoU of networks side by side from evaluate_semantics --json results: one
panel per sequence and variant (the raw labels at every point, the map's voxel class at each
point), a bar per network and class, each class named with its labelled points in the sequence
(a mean over classes weighs a class of 100 points as much as the road), each network with its
mIoU.

    scripts/plot_class_iou.py NAME=RESULT.json [NAME=RESULT.json ...]
        [--variants raw,map] [--output class_iou.png]

RESULT.json: `evaluate_semantics --sequence SEQ [--sequence SEQ ...] --model M --json RESULT.json`
with the same sequences for every network.
"""

import argparse
import json
import os
import sys


def read_result(spec):
    """(name, {sequence: {variant: scores}}) of a NAME=PATH argument; SystemExit naming the
    argument or the file and what is wrong."""
    name, sep, path = spec.partition("=")
    if not sep or not name or not path:
        raise SystemExit(f"'{spec}': expected NAME=RESULT.json")
    try:
        with open(path, encoding="utf-8") as f:
            result = json.load(f)
    except OSError as e:
        raise SystemExit(f"{path}: {e.strerror}")
    except json.JSONDecodeError as e:
        raise SystemExit(f"{path}:{e.lineno}: not JSON ({e.msg})")
    sequences = result.get("sequences") if isinstance(result, dict) else None
    if not isinstance(sequences, dict) or not sequences:
        raise SystemExit(f"{path}: not an evaluate_semantics --json result (no 'sequences')")
    # The label variants (raw, each filter) and the map's scores ("map", "map_ceiling") as one
    # set of names.
    out = {}
    for seq, entry in sequences.items():
        if not isinstance(entry, dict) or not isinstance(entry.get("variants"), dict):
            raise SystemExit(f"{path}: sequence {seq} has no 'variants'")
        scored = dict(entry["variants"])
        scored.update({k: v for k, v in entry.items() if k.startswith("map")})
        out[seq] = scored
    return name, out


def panels(results, variants):
    """[(sequence, variant, classes, [(name, miou, [iou per class])], [points per class])] for
    every sequence of the first result and every variant; classes are those with labelled
    points in the first result's variant, counted in its raw variant (every point). SystemExit where a result lacks a sequence or a
    variant, naming both."""
    first_name, first = results[0]
    out = []
    for seq in first:
        for variant in variants:
            bars = []
            for name, result in results:
                if seq not in result:
                    raise SystemExit(f"{name}: no sequence {seq} (it has {', '.join(result)})")
                if variant not in result[seq]:
                    raise SystemExit(f"{name}: sequence {seq} has no variant '{variant}' (it "
                                     f"has {', '.join(result[seq])})")
                bars.append((name, result[seq][variant]))
            reference = bars[0][1]["classes"]
            classes = [c for c, v in reference.items() if v.get("truth", 0) > 0]
            # The points of each class in the sequence: the map's own count leaves out the
            # points in voxels without a class, which differ from network to network.
            counts = first[seq].get("raw", bars[0][1])["classes"]
            truth = [counts.get(c, reference[c])["truth"] for c in classes]
            rows = [(name, scores["miou"],
                     [scores["classes"].get(c, {}).get("iou") or 0.0 for c in classes])
                    for name, scores in bars]
            out.append((seq, variant, classes, rows, truth))
    return out


def plot(panel_list, output):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(panel_list), 1, figsize=(12, 3.2 * len(panel_list)),
                             squeeze=False)
    for ax, (seq, variant, classes, rows, truth) in zip(axes[:, 0], panel_list):
        width = 0.8 / len(rows)
        for i, (name, miou, ious) in enumerate(rows):
            ax.bar([c + (i - (len(rows) - 1) / 2) * width for c in range(len(classes))], ious,
                   width, label=f"{name} (mIoU {miou:.3f})")
        ax.set_xticks(range(len(classes)))
        ax.set_xticklabels([f"{c}\n{n}" for c, n in zip(classes, truth)], fontsize=8)
        ax.set_ylim(0, 1.3)  # room for the key above the bars
        ax.set_ylabel("IoU")
        ax.set_title(f"{os.path.basename(os.path.normpath(seq))}: {variant} (under each class "
                     "its labelled points)", fontsize=10)
        ax.grid(axis="y", alpha=0.3)
        ax.legend(fontsize=8, loc="upper center", ncol=len(rows))
    fig.tight_layout()
    tmp = output + ".tmp.png"
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    os.replace(tmp, output)  # a reader never sees half a figure


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("results", nargs="+", metavar="NAME=RESULT.json")
    p.add_argument("--variants", default="raw,map",
                   help="the variants to plot, comma-separated: raw, map, map_ceiling or a "
                        "filter's name as the JSON has it")
    p.add_argument("--output", default="class_iou.png")
    args = p.parse_args(argv)
    variants = [v for v in args.variants.split(",") if v]
    if not variants:
        raise SystemExit("--variants: name at least one")
    panel_list = panels([read_result(spec) for spec in args.results], variants)
    plot(panel_list, args.output)
    print(f"wrote {args.output} ({len(panel_list)} panels)", file=sys.stderr)


if __name__ == "__main__":
    main()
