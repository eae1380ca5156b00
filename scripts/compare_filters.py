#!/usr/bin/python3
"""Compares several runs (e.g. the left InEKF, the right InEKF and the quaternion ESKF) on the
same drive: one table of metrics, yaw error over time side by side, and the yaw error after a
convergence time (the issue's 90-deg initial-yaw test: "below 1.5 deg after the first 60 s").

Usage:
  compare_filters.py --truth TRUTH.txt [--timestamps TIMES.txt] [--after 60]
      [--json OUT.json] [--plot OUT.png] LABEL=POSES[,STATES.csv] [LABEL=POSES ...]

Each run is evaluated by evaluate_trajectory.py (same directory); time is in seconds from the
first frame when stamps are known (TUM files or --timestamps), else in frames.
"""

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.realpath(__file__)))
import evaluate_trajectory as et  # noqa: E402


def parse_run(text):
    label, separator, paths = text.partition("=")
    if not separator or not label or not paths:
        raise argparse.ArgumentTypeError("run %r: expected LABEL=POSES[,STATES.csv]" % text)
    poses, _, states = paths.partition(",")
    return label, poses, states or None


def yaw_after(series, after):
    """Max and RMS |yaw error| (deg) from time `after` on, and the first time after which it
    stays below 1.5 deg (None if it never settles)."""
    times, yaw = series["times"], np.abs(series["yaw_errors_deg"])
    late = times >= after
    above = np.nonzero(yaw >= 1.5)[0]
    if above.size == 0:
        settled = float(times[0])
    elif above[-1] + 1 < len(times):
        settled = float(times[above[-1] + 1])
    else:
        settled = None
    if not np.any(late):
        return None, None, settled
    return float(yaw[late].max()), et.rms(yaw[late]), settled


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=parse_run, help="LABEL=POSES[,STATES.csv]")
    parser.add_argument("--truth", required=True)
    parser.add_argument("--timestamps")
    parser.add_argument("--after", type=float, default=60.0,
                        help="convergence time for the yaw-after figures (s, or frames)")
    parser.add_argument("--json")
    parser.add_argument("--plot")
    args = parser.parse_args(argv)
    et.check_output_paths(parser, [args.json, args.plot])

    results, all_series = {}, {}
    try:
        for label, poses, states in args.runs:
            estimate, truth, stamps, state_rows = et.load_inputs(poses, args.truth, args.timestamps,
                                                                 states)
            result, series = et.evaluate(estimate, truth, stamps, state_rows, states or "")
            (result["yaw_max_after_deg"], result["yaw_rms_after_deg"],
             result["yaw_settled_below_1p5_deg_at"]) = yaw_after(series, args.after)
            result["after"] = args.after
            results[label], all_series[label] = result, series
    except et.TrajectoryFormatError as error:
        print("compare_filters: error: %s" % error, file=sys.stderr)
        return 2

    def figure(value, pattern):
        return "n/a" if value is None else pattern % value

    header = "%-14s %9s %9s %9s %9s %10s %10s %9s %9s" % (
        "run", "ATE[m]", "ATEal[m]", "rot[deg]", "yaw[deg]", "yaw>%g max" % args.after,
        "yaw>%g rms" % args.after, "settled", "NEES6")
    print(header)
    for label, r in results.items():
        print("%-14s %9.3f %9.3f %9.3f %9.3f %10s %10s %9s %9s" % (
            label, r["ate_unaligned_rmse_m"], r["ate_aligned_rmse_m"], r["rotation_rmse_deg"],
            r["yaw_rmse_deg"], figure(r["yaw_max_after_deg"], "%.3f"),
            figure(r["yaw_rms_after_deg"], "%.3f"), figure(r["yaw_settled_below_1p5_deg_at"], "%.1f"),
            figure(r.get("nees_pose", {}).get("average"), "%.2f")))
    if args.json:
        et.write_json_atomically(args.json, {"after": args.after, "runs": results})
    if args.plot:
        plot(args.plot, all_series, args.after)
    return 0


def plot(path, all_series, after):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (yaw_axis, position_axis) = plt.subplots(2, 1, figsize=(11, 8), sharex=True)
    for label, series in all_series.items():
        yaw_axis.semilogy(series["times"], np.maximum(np.abs(series["yaw_errors_deg"]), 1e-3),
                          lw=1.0, label=label)
        position_axis.plot(series["times"], series["position_errors"], lw=1.0, label=label)
    unit = next(iter(all_series.values()))["time_unit"]
    yaw_axis.axhline(1.5, color="k", ls="--", lw=0.8, label="1.5 deg")
    yaw_axis.axvline(after, color="gray", ls=":", lw=0.8)
    yaw_axis.set_ylabel("|yaw error| [deg]")
    yaw_axis.set_title("yaw error over time")
    yaw_axis.legend()
    position_axis.set_ylabel("position error [m]")
    position_axis.set_xlabel("time [%s]" % unit)
    position_axis.legend()
    figure.tight_layout()
    temporary = path + ".tmp.png"
    figure.savefig(temporary, dpi=110)
    plt.close(figure)
    os.replace(temporary, path)


if __name__ == "__main__":
    sys.exit(main())
