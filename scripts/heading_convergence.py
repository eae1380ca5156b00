#!/usr/bin/env python3
"""Heading convergence of an inekf_offline run: yaw error against the OXTS truth over time.

usage: heading_convergence.py POSES.txt TRUTH.txt OXTS_DIR [--exclude-frames A:B]

POSES / TRUTH: inekf_offline --output-kitti / --output-truth (map frame, 12 numbers a line).
Prints: the motion start (first frame at >= 3 m/s, from the OXTS vn/ve), how long after it the
yaw error stays below 2 deg for good, the worst yaw error from motion + 30 s on, and ATE /
rotation RMSE over all frames and over the frames from motion + 30 s on.
"""
import math
import sys


def read_poses(path):
    poses = []
    with open(path) as f:
        for line_number, line in enumerate(f, 1):
            v = [float(x) for x in line.split()]
            if len(v) != 12:
                sys.exit(f"{path}:{line_number}: expected 12 numbers, got {len(v)}")
            poses.append(([[v[0], v[1], v[2]], [v[4], v[5], v[6]], [v[8], v[9], v[10]]],
                          [v[3], v[7], v[11]]))
    return poses


def rotation_angle_deg(a, b):
    # angle of a^T b
    trace = sum(a[k][i] * b[k][i] for i in range(3) for k in range(3))
    return math.degrees(math.acos(max(-1.0, min(1.0, (trace - 1.0) / 2.0))))


def main():
    args = sys.argv[1:]
    exclude = None
    if "--exclude-frames" in args:
        i = args.index("--exclude-frames")
        a, b = args[i + 1].split(":")
        exclude = (int(a), int(b))
        if exclude[0] > exclude[1]:
            sys.exit(f"--exclude-frames {args[i + 1]}: FIRST is after LAST")
        del args[i:i + 2]
    if len(args) != 3:
        sys.exit(__doc__)
    est, truth, oxts = read_poses(args[0]), read_poses(args[1]), args[2]
    if len(est) != len(truth):
        sys.exit(f"{args[0]} has {len(est)} poses, {args[1]} {len(truth)}")
    with open(f"{oxts}/timestamps.txt") as f:
        stamps = []
        for line in f:
            hms = line.split()[1].split(":")
            stamps.append(int(hms[0]) * 3600 + int(hms[1]) * 60 + float(hms[2]))
    t = [s - stamps[0] for s in stamps]
    motion = None
    for k in range(len(est)):
        with open(f"{oxts}/data/{k:010d}.txt") as f:
            v = [float(x) for x in f.read().split()]
        if math.hypot(v[6], v[7]) >= 3.0:
            motion = t[k]
            break
    keep = [not (exclude and exclude[0] <= k <= exclude[1]) for k in range(len(est))]
    # frames before the start repeat the start pose: skip the leading identical ones
    first = 0
    while first + 1 < len(est) and est[first + 1] == est[0]:
        first += 1
    yaw_err = []
    for k in range(len(est)):
        ye = math.atan2(est[k][0][1][0], est[k][0][0][0]) - math.atan2(truth[k][0][1][0], truth[k][0][0][0])
        yaw_err.append(abs(math.degrees(math.atan2(math.sin(ye), math.cos(ye)))))
    last_bad = motion
    worst_after = 0.0
    for k in range(first, len(est)):
        if not keep[k] or t[k] < motion:
            continue
        if yaw_err[k] >= 2.0:
            last_bad = t[k]
        if t[k] >= motion + 30.0:
            worst_after = max(worst_after, yaw_err[k])

    def errors(frames):
        frames = [k for k in frames if keep[k]]
        if not frames:
            return float("nan"), float("nan")
        ate = math.sqrt(sum(sum((est[k][1][i] - truth[k][1][i]) ** 2 for i in range(3)) for k in frames) / len(frames))
        rot = math.sqrt(sum(rotation_angle_deg(est[k][0], truth[k][0]) ** 2 for k in frames) / len(frames))
        return ate, rot

    all_ate, all_rot = errors(range(first, len(est)))
    after_ate, after_rot = errors([k for k in range(first, len(est)) if t[k] >= motion + 30.0])
    print(f"motion_s {motion:.1f} converged_after_motion_s {last_bad - motion:.1f} "
          f"worst_yaw_after_30s_deg {worst_after:.2f} ate_m {all_ate:.3f} rot_rmse_deg {all_rot:.3f} "
          f"ate_after_30s_m {after_ate:.3f} rot_after_30s_deg {after_rot:.3f} "
          f"max_yaw_deg {max(yaw_err[first:]):.1f}")


if __name__ == "__main__":
    main()
