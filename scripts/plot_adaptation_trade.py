#!/usr/bin/python3
"""Plots the raw camera accuracy on SemanticKITTI 05 against 08 of every network in a runs table
(docs/adaptation_runs.csv: label, kind, raw_05, raw_08, section), with the target corner, so
that what each adaptation lever traded is seen at a glance.

    scripts/plot_adaptation_trade.py [--runs docs/adaptation_runs.csv]
        [--output docs/adaptation_trade.png] [--target 0.88]
"""

import argparse
import csv
import os
import sys

STYLE = {  # kind -> marker, colour
    "base": ("s", "black"),
    "adapted": ("o", "tab:blue"),
    "interpolated": ("D", "tab:orange"),
    "student": ("^", "tab:green"),
    "flip-averaged": ("v", "tab:purple"),  # an adapted network with its mirror image averaged
    "weight-averaged": ("P", "tab:brown"),  # the mean of the weights of a run's steps or of runs
    "calibrated": ("*", "tab:red"),  # a network exported with logit offsets (--calibrate-offsets)
    "ensemble": ("X", "tab:gray"),  # two networks' logits averaged in one graph
}


def read_runs(path):
    """The table's rows as dicts with float accuracies; SystemExit naming the file and line of a
    malformed row."""
    try:
        with open(path, newline="") as f:
            lines = [(n, line) for n, line in enumerate(f, start=1) if not line.startswith("#")]
    except OSError as e:
        raise SystemExit(f"{path}: {e.strerror}")
    reader = csv.DictReader(line for _, line in lines)
    rows, labels = [], {}
    for (number, _), row in zip(lines[1:], reader):
        if None in row:
            raise SystemExit(f"{path}:{number}: more fields than the header names")
        try:
            row["raw_05"], row["raw_08"] = float(row["raw_05"]), float(row["raw_08"])
        except (TypeError, ValueError):
            raise SystemExit(f"{path}:{number}: raw_05 and raw_08 must be numbers")
        if row.get("kind") not in STYLE:
            raise SystemExit(f"{path}:{number}: kind '{row.get('kind')}' is not one of "
                             f"{', '.join(STYLE)}")
        # 'from' (optional): the label of an earlier row this network was made from (an arrow).
        origin = row.get("from") or None
        if origin is not None and origin not in labels:
            raise SystemExit(f"{path}:{number}: from '{origin}' is not the label of an earlier "
                             "row")
        row["from"] = labels.get(origin)
        labels[row["label"]] = len(rows)
        rows.append(row)
    if not rows:
        raise SystemExit(f"{path}: no runs")
    return rows


def plot(rows, output, target):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # Tall enough for the key's lines (7.5 pt type, about 0.13 inch a line): past 49 runs a fixed
    # height cut the key off.
    height = max(6.5, 0.13 * len(rows) + 0.8)
    fig, (ax, key) = plt.subplots(1, 2, figsize=(12, height),
                                  gridspec_kw={"width_ratios": [3, 2]})
    ax.fill_between([target, 1.0], target, 1.0, color="tab:green", alpha=0.12,
                    label=f"target (>= {target:g} on each)")
    for kind, (marker, colour) in STYLE.items():
        mine = [r for r in rows if r["kind"] == kind]
        if mine:
            ax.scatter([r["raw_05"] for r in mine], [r["raw_08"] for r in mine], marker=marker,
                       color=colour, label=kind, zorder=3)
    for r in rows:
        if r["from"] is not None:
            origin = rows[r["from"]]
            ax.annotate("", (r["raw_05"], r["raw_08"]), (origin["raw_05"], origin["raw_08"]),
                        arrowprops=dict(arrowstyle="->", color="tab:red", alpha=0.6, lw=0.8))
    # Numbers beside the points, their labels in a key: the points lie too close for names.
    for number, r in enumerate(rows, start=1):
        ax.annotate(str(number), (r["raw_05"], r["raw_08"]), fontsize=7, xytext=(4, 2),
                    textcoords="offset points")
    key.axis("off")
    key.text(0, 1, "\n".join(f"{n:2d}  {r['label']}" for n, r in enumerate(rows, start=1)),
             va="top", fontsize=7.5, family="monospace", transform=key.transAxes)
    xs = [r["raw_05"] for r in rows] + [target]
    ys = [r["raw_08"] for r in rows] + [target]
    ax.set_xlim(min(xs) - 0.01, max(max(xs), target) + 0.03)
    ax.set_ylim(min(ys) - 0.01, max(max(ys), target) + 0.02)
    ax.set_xlabel("raw camera accuracy at all points, SemanticKITTI 05")
    ax.set_ylabel("raw camera accuracy at all points, SemanticKITTI 08")
    ax.set_title("Every network measured: what 05 gains, 08 loses")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper center", fontsize=8)
    fig.tight_layout()
    tmp = output + ".tmp.png"
    fig.savefig(tmp, dpi=110)
    os.replace(tmp, output)  # a reader never sees half a file
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    here = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))
    p.add_argument("--runs", default=os.path.join(here, "docs", "adaptation_runs.csv"))
    p.add_argument("--output", default=os.path.join(here, "docs", "adaptation_trade.png"))
    p.add_argument("--target", type=float, default=0.88)
    args = p.parse_args(argv)
    rows = read_runs(args.runs)
    plot(rows, args.output, args.target)
    print(f"[plot_adaptation_trade] {len(rows)} runs -> {args.output}")


if __name__ == "__main__":
    sys.exit(main())
