#!/usr/bin/python3
"""Metrics of one end-to-end run (demo, benchmark, rostests): trajectory accuracy, rates and
dropped messages, and the semantic map's classes and mIoU.

  scripts/compute_demo_metrics.py --monitor-dir output/demo --bag output/demo/drive.bag \
      --map-ply output/demo/semantic_map.ply [--ground-truth DRIVE/ground_truth] \
      --output output/demo/metrics.json [--plot output/demo/trajectory.png]

The functions are imported by test/ros/e2e_*.py, so the tests and the demo compute the same
figures the same way.
"""
import argparse
import json
import math
import os
import sys

import numpy as np

# One definition of each trajectory metric and pose format: evaluate_trajectory's (beside this).
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import evaluate_trajectory as trajectory_metrics  # noqa: E402

SCAN_TOPIC = "/kitti/velo/pointcloud"
IMAGE_TOPIC = "/kitti/camera_color_left/image_raw"
# Cityscapes labelIds (the map's PLY label, class_set cityscapes), for printing.
CITYSCAPES_NAMES = {
    0: "unlabeled", 1: "ego vehicle", 2: "rectification border", 3: "out of roi", 4: "static",
    5: "dynamic", 6: "ground", 7: "road", 8: "sidewalk", 9: "parking", 10: "rail track",
    11: "building", 12: "wall", 13: "fence", 14: "guard rail", 15: "bridge", 16: "tunnel",
    17: "pole", 18: "polegroup", 19: "traffic light", 20: "traffic sign", 21: "vegetation",
    22: "terrain", 23: "sky", 24: "person", 25: "rider", 26: "car", 27: "truck", 28: "bus",
    29: "caravan", 30: "trailer", 31: "train", 32: "motorcycle", 33: "bicycle"}


# ----------------------------------------------------------------------------------------------
# Trajectories
# ----------------------------------------------------------------------------------------------
def read_tum(path):
    """N x 8 array: stamp x y z qx qy qz qw (empty file: 0 x 8)."""
    rows = []
    with open(path) as f:
        for line_number, line in enumerate(f, 1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            values = line.split()
            if len(values) != 8:
                raise ValueError("%s:%d: expected 8 values (TUM), got %d" % (path, line_number, len(values)))
            rows.append([float(v) for v in values])
    return np.array(rows, dtype=float).reshape(-1, 8)


def quaternion_to_matrix(q):
    return trajectory_metrics.quaternion_to_rotation(*q)


def associate(estimate, truth, max_dt=0.02):
    """Pairs (estimate row, truth row) with the nearest truth stamp within max_dt.

    A bag played in a loop repeats stamps: only the last pass (after the last jump back in time)
    of each trajectory is used."""
    def last_pass(traj):
        if len(traj) < 2:
            return traj
        jumps = np.nonzero(np.diff(traj[:, 0]) < -1.0)[0]
        return traj[jumps[-1] + 1:] if len(jumps) else traj
    estimate, truth = last_pass(estimate), last_pass(truth)
    if len(estimate) == 0 or len(truth) == 0:
        return estimate[:0], truth[:0]
    order = np.argsort(truth[:, 0])
    truth = truth[order]
    idx = np.clip(np.searchsorted(truth[:, 0], estimate[:, 0]), 1, len(truth) - 1)
    left, right = truth[idx - 1, 0], truth[idx, 0]
    idx = np.where(np.abs(estimate[:, 0] - left) <= np.abs(estimate[:, 0] - right), idx - 1, idx)
    if len(truth) == 1:
        idx = np.zeros(len(estimate), dtype=int)
    keep = np.abs(truth[idx, 0] - estimate[:, 0]) <= max_dt
    return estimate[keep], truth[idx[keep]]


def trajectory_errors(estimate, truth, max_dt=0.02):
    """Unaligned errors in the map frame (both trajectories are there by construction)."""
    est, gt = associate(estimate, truth, max_dt)
    if len(est) == 0:
        return {"matched_poses": 0}
    tm = trajectory_metrics
    position_errors = np.linalg.norm(est[:, 1:4] - gt[:, 1:4], axis=1)
    rotation_errors_deg, yaw_errors_deg = [], []
    for e, g in zip(est, gt):
        Re, Rg = quaternion_to_matrix(e[4:8]), quaternion_to_matrix(g[4:8])
        rotation_errors_deg.append(math.degrees(tm.rotation_angle(Re.T @ Rg)))
        yaw_errors_deg.append(math.degrees(tm.wrap_angle(tm.yaw_of(Re) - tm.yaw_of(Rg))))
    return {
        "matched_poses": int(len(est)),
        "duration_s": float(est[-1, 0] - est[0, 0]),
        "ate_rmse_m": tm.rms(position_errors),
        "position_error_max_m": float(position_errors.max()),
        "position_error_final_m": float(position_errors[-1]),
        "rotation_rmse_deg": tm.rms(np.array(rotation_errors_deg)),
        "yaw_rmse_deg": tm.rms(np.array(yaw_errors_deg)),
        "path_length_m": float(np.sum(np.linalg.norm(np.diff(gt[:, 1:4], axis=0), axis=1))),
        "finite": bool(np.all(np.isfinite(est))),
    }


def plot_trajectories(estimate, truth, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    est, gt = associate(estimate, truth)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 5))
    ax1.plot(truth[:, 1], truth[:, 2], "g-", label="ground truth (OXTS)")
    ax1.plot(estimate[:, 1], estimate[:, 2], "r--", label="InEKF estimate")
    ax1.set_xlabel("x east [m]"); ax1.set_ylabel("y north [m]"); ax1.axis("equal"); ax1.legend()
    if len(est):
        ax2.plot(est[:, 0] - est[0, 0], np.linalg.norm(est[:, 1:4] - gt[:, 1:4], axis=1))
    ax2.set_xlabel("time [s]"); ax2.set_ylabel("position error [m]"); ax2.grid(True)
    fig.tight_layout()
    tmp = path + ".tmp.png"
    fig.savefig(tmp, dpi=90)
    os.replace(tmp, path)


# ----------------------------------------------------------------------------------------------
# Message counts (dropped scans / images)
# ----------------------------------------------------------------------------------------------
def bag_message_counts(bag_path):
    import rosbag
    with rosbag.Bag(bag_path) as bag:
        info = bag.get_type_and_topic_info()
        counts = {topic: t.message_count for topic, t in info.topics.items()}
        return counts, bag.get_end_time() - bag.get_start_time()


def rates_and_drops(monitor, bag_counts=None):
    """Per pipeline stage: how many inputs were received and how many outputs came out."""
    topics = monitor["topics"]
    def n(topic):
        return topics.get(topic, {}).get("messages", 0)
    result = {topic: {k: v for k, v in entry.items() if k in ("messages", "rate_hz", "wall_rate_hz")}
              for topic, entry in topics.items()}
    drops = {
        "images_without_segmentation": n(IMAGE_TOPIC) - n("/segmentation/labels"),
        "scans_without_map_update": n(SCAN_TOPIC) - n("/semantic_map/labeled_cloud"),
    }
    if bag_counts:
        drops["scans_in_bag_not_received"] = bag_counts.get(SCAN_TOPIC, 0) - n(SCAN_TOPIC)
        drops["images_in_bag_not_received"] = bag_counts.get(IMAGE_TOPIC, 0) - n(IMAGE_TOPIC)
    return {"topics": result, "dropped": drops,
            "scan_to_map_latency_s": monitor.get("scan_to_map_latency_s"),
            "image_to_labels_latency_s": monitor.get("image_to_labels_latency_s")}


# ----------------------------------------------------------------------------------------------
# Semantic map (PLY of occupied voxels: x y z label red green blue)
# ----------------------------------------------------------------------------------------------
PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
             "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4",
             "uint32": "u4", "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def read_ply_vertices(path):
    """Structured numpy array of the vertex element (ascii or binary little/big endian)."""
    with open(path, "rb") as f:
        if f.readline().strip() != b"ply":
            raise ValueError("%s: not a PLY file (first line is not 'ply')" % path)
        fmt, count, props, in_vertex = None, 0, [], False
        while True:
            line = f.readline()
            if not line:
                raise ValueError("%s: PLY header has no end_header" % path)
            words = line.decode("ascii", "replace").split()
            if not words:
                continue
            if words[0] == "format":
                fmt = words[1]
            elif words[0] == "element":
                in_vertex = words[1] == "vertex"
                if in_vertex:
                    count = int(words[2])
            elif words[0] == "property" and in_vertex:
                if words[1] == "list":
                    raise ValueError("%s: list properties in vertex element are not supported" % path)
                props.append((words[2], PLY_TYPES[words[1]]))
            elif words[0] == "end_header":
                break
        if fmt == "ascii":
            data = np.loadtxt(f, max_rows=count, ndmin=2) if count else np.zeros((0, len(props)))
            out = np.zeros(count, dtype=[(n, t) for n, t in props])
            for i, (name, _) in enumerate(props):
                out[name] = data[:, i]
            return out
        endian = "<" if fmt == "binary_little_endian" else ">"
        dtype = np.dtype([(n, endian + t) for n, t in props])
        out = np.frombuffer(f.read(dtype.itemsize * count), dtype=dtype, count=count)
        if len(out) != count:
            raise ValueError("%s: PLY truncated: %d of %d vertices" % (path, len(out), count))
        return out


def ply_resolution(path):
    """The map resolution from the PLY header comment '... resolution R m' (None if absent)."""
    with open(path, "rb") as f:
        for raw in f:
            line = raw.decode("ascii", "replace").split()
            if line[:1] == ["end_header"]:
                return None
            if line[:1] == ["comment"] and "resolution" in line:
                try:
                    return float(line[line.index("resolution") + 1])
                except (IndexError, ValueError):
                    return None
    return None


def read_kitti_poses(path):
    """N x 4 x 4 from a KITTI 12-numbers-per-line pose file."""
    poses = trajectory_metrics.read_trajectory(path)
    if poses.stamps is not None:
        raise ValueError("%s: expected 12 numbers per line (KITTI poses), got a TUM file" % path)
    return poses.matrices()


def read_calib_rigid(path):
    """4x4 from a KITTI calib file with 'R:' (9 numbers) and 'T:' (3 numbers) lines."""
    values = {}
    with open(path) as f:
        for line in f:
            key, _, rest = line.partition(":")
            values[key.strip()] = rest.split()
    try:
        transform = np.eye(4)
        transform[:3, :3] = np.array(values["R"], dtype=float).reshape(3, 3)
        transform[:3, 3] = np.array(values["T"], dtype=float)
    except (KeyError, ValueError) as error:
        raise ValueError("%s: no valid R:/T: lines (%s)" % (path, error))
    return transform


# Cityscapes labelIds 0..6 are void (unlabeled, ego vehicle, ..., ground): not evaluated.
FIRST_EVALUATED_LABEL_ID = 7


def _voxel_keys(points, resolution):
    index = np.floor(points / resolution).astype(np.int64) + (1 << 20)
    return (index[:, 0] << 42) | (index[:, 1] << 21) | index[:, 2]


def _majority_label(keys, labels):
    """Unique keys and the most frequent label of each (keys use all 63 bits: no packing)."""
    order = np.lexsort((labels, keys))
    keys, labels = keys[order], labels[order]
    run_start = np.ones(len(keys), dtype=bool)
    run_start[1:] = (keys[1:] != keys[:-1]) | (labels[1:] != labels[:-1])
    starts = np.nonzero(run_start)[0]
    counts = np.diff(np.append(starts, len(keys)))
    run_keys, run_labels = keys[starts], labels[starts]
    best = np.lexsort((-counts, run_keys))  # by key, most counts first
    run_keys, run_labels = run_keys[best], run_labels[best]
    first = np.ones(len(run_keys), dtype=bool)
    first[1:] = run_keys[1:] != run_keys[:-1]
    return run_keys[first], run_labels[first]


def ground_truth_voxels(ground_truth_dir, resolution, scan_step=2, max_range_m=None, poses=None):
    """Voxel keys and majority labelIds of the generator's labeled lidar points in the map frame
    (velodyne_points + ground_truth/velodyne_labels + poses_imu_map + calib_imu_to_velo).

    poses: T_map_imu per OXTS frame to place the scans with instead of the true ones (None
    entries: frame skipped), e.g. the estimate the map was built with."""
    drive_dir = os.path.dirname(os.path.abspath(ground_truth_dir))
    if poses is None:
        poses = read_kitti_poses(os.path.join(ground_truth_dir, "poses_imu_map.txt"))
    velo_from_imu = read_calib_rigid(os.path.join(os.path.dirname(drive_dir), "calib_imu_to_velo.txt"))
    imu_from_velo = np.linalg.inv(velo_from_imu)
    all_keys, all_labels = [], []
    for frame in range(0, len(poses), scan_step):
        if poses[frame] is None:
            continue
        scan_path = os.path.join(drive_dir, "velodyne_points", "data", "%010d.bin" % frame)
        label_path = os.path.join(ground_truth_dir, "velodyne_labels", "%010d.label" % frame)
        if not (os.path.exists(scan_path) and os.path.exists(label_path)):
            continue
        points = np.fromfile(scan_path, dtype=np.float32).reshape(-1, 4)[:, :3].astype(float)
        labels = (np.fromfile(label_path, dtype=np.uint32) & 0xFFFF).astype(np.int64)
        if len(labels) != len(points):
            raise ValueError("%s: %d labels for %d points" % (label_path, len(labels), len(points)))
        if max_range_m:
            keep = np.linalg.norm(points, axis=1) <= max_range_m
            points, labels = points[keep], labels[keep]
        map_from_velo = poses[frame] @ imu_from_velo
        world = points @ map_from_velo[:3, :3].T + map_from_velo[:3, 3]
        evaluated = labels >= FIRST_EVALUATED_LABEL_ID
        all_keys.append(_voxel_keys(world[evaluated], resolution))
        all_labels.append(labels[evaluated])
    if not all_keys:
        raise ValueError("%s: no labeled scans found" % ground_truth_dir)
    return _majority_label(np.concatenate(all_keys), np.concatenate(all_labels))


def find_tool(name):
    """A C++ tool of the package: $ISM_BIN/NAME, else lib/inekf_semantic_mapping/NAME under each
    CMAKE_PREFIX_PATH entry (a sourced workspace, rostest), else NAME on PATH."""
    candidates = []
    if os.environ.get("ISM_BIN"):
        candidates.append(os.path.join(os.environ["ISM_BIN"], name))
    for prefix in os.environ.get("CMAKE_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            candidates.append(os.path.join(prefix, "lib", "inekf_semantic_mapping", name))
    for path in candidates:
        if os.access(path, os.X_OK):
            return path
    import shutil
    found = shutil.which(name)
    if not found:
        raise OSError("%s not found (build the package and source its workspace, or set ISM_BIN)" % name)
    return found


def map_miou(map_ot, ground_truth_dir, poses=None, scan_step=2):
    """The package's one map metric, computed by the evaluate_map tool (the C++ function
    evaluate_semantics scores SemanticKITTI maps with): every labelled ground-truth lidar point of
    every scan_step-th frame, placed in the map with the poses the map was built with, takes the
    most likely class of its voxel; accuracy and IoU per class over the covered points (a point
    whose voxel is missing, free or classless is not covered), mIoU over the scored classes present
    in the truth. Returns evaluate_map's JSON (miou, accuracy, coverage, classes, map_voxels,
    map_voxels_hit...).

    poses: T_map_imu per OXTS frame (None entries: frame skipped), e.g. the estimate the map was
    built with; None: the drive's true poses."""
    import subprocess
    import tempfile
    drive_dir = os.path.dirname(os.path.abspath(ground_truth_dir))
    command = [find_tool("evaluate_map"), "--map", map_ot, "--drive", drive_dir,
               "--labels", os.path.join(ground_truth_dir, "velodyne_labels"),
               "--scan-step", str(scan_step)]
    with tempfile.TemporaryDirectory(prefix="ism_map_miou_") as work:
        if poses is not None:
            frames = [i for i, pose in enumerate(poses) if pose is not None]
            if not frames:
                raise ValueError("no frame has a pose to place its scan with")
            with open(os.path.join(work, "poses.txt"), "w") as f:
                for i in frames:
                    f.write(" ".join("%.9g" % v for v in poses[i][:3, :].reshape(-1)) + "\n")
            with open(os.path.join(work, "frames.txt"), "w") as f:
                f.write("".join("%d\n" % i for i in frames))
            command += ["--poses", os.path.join(work, "poses.txt"),
                        "--frames", os.path.join(work, "frames.txt")]
        else:
            command += ["--poses", os.path.join(ground_truth_dir, "poses_imu_map.txt")]
        run = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             universal_newlines=True)
    if run.returncode != 0:
        raise ValueError("evaluate_map failed (%d): %s" % (run.returncode, run.stderr.strip()))
    result_lines = [l for l in run.stdout.splitlines() if l.startswith("RESULT ")]
    if not result_lines:
        raise ValueError("evaluate_map printed no RESULT line: %s" % run.stdout[-500:])
    return json.loads(result_lines[-1][len("RESULT "):])


def estimated_frame_poses(estimate, truth, max_dt=0.02):
    """T_map_imu of the estimate at each ground-truth (= OXTS frame) stamp, in frame order; None
    where the filter had no pose (before its first fix). Uses the last pass of a looped bag."""
    est, gt = associate(estimate, truth, max_dt)
    truth_last = associate(truth, truth, 0.0)[0]
    by_stamp = {round(g[0], 6): e for e, g in zip(est, gt)}
    poses = []
    for row in truth_last[np.argsort(truth_last[:, 0])]:
        e = by_stamp.get(round(row[0], 6))
        if e is None:
            poses.append(None)
            continue
        pose = np.eye(4)
        pose[:3, :3] = quaternion_to_matrix(e[4:8])
        pose[:3, 3] = e[1:4]
        poses.append(pose)
    return poses


def map_class_histogram(vertices):
    labels, counts = np.unique(vertices["label"].astype(int), return_counts=True)
    return {int(l): int(c) for l, c in zip(labels, counts)}


def run_evaluate_trajectory(script, estimate, truth, work_dir, plot_path):
    """Runs the localization evaluation (evaluate_trajectory.py) on pose pairs matched by stamp
    (it wants one pose per frame in both files). Returns (its JSON or an error, plotted)."""
    import subprocess
    est, gt = associate(estimate, truth)
    if len(est) < 2:
        return {"error": "fewer than 2 matched poses"}, False
    paths = {name: os.path.join(work_dir, name) for name in
             ("estimate_matched_tum.txt", "truth_matched_tum.txt", "evaluate_trajectory.json")}
    for name, poses in (("estimate_matched_tum.txt", est), ("truth_matched_tum.txt", gt)):
        np.savetxt(paths[name], poses, fmt="%.9f")
    command = [sys.executable, script, "--estimate", paths["estimate_matched_tum.txt"],
               "--truth", paths["truth_matched_tum.txt"], "--json", paths["evaluate_trajectory.json"],
               "--label", "inekf_node"]
    if plot_path:
        command += ["--plot", plot_path]
    result = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if result.returncode != 0:
        return {"error": "%s exited %d: %s" % (script, result.returncode, result.stdout[-800:])}, False
    with open(paths["evaluate_trajectory.json"]) as f:
        return json.load(f), bool(plot_path and os.path.exists(plot_path))


def write_json_atomic(path, data):
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(data, f, indent=2, sort_keys=True)
    os.replace(tmp, path)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--monitor-dir", required=True, help="pipeline_monitor.py output folder")
    parser.add_argument("--bag", help="the input bag (for message counts)")
    parser.add_argument("--map-ply", help="the saved semantic map PLY")
    parser.add_argument("--map-ot", help="the saved semantic map .ot (map mIoU with --ground-truth)")
    parser.add_argument("--ground-truth", help="synthetic drive ground_truth/ folder (map mIoU)")
    parser.add_argument("--map-poses", choices=("estimate", "truth"), default="estimate",
                        help="the poses the map was built with (use_ground_truth_pose: truth)")
    parser.add_argument("--output", required=True)
    parser.add_argument("--plot", help="trajectory PNG")
    parser.add_argument("--evaluate-trajectory",
                        help="scripts/evaluate_trajectory.py: also run it on the matched poses")
    parser.add_argument("--extra", action="append", default=[], help="KEY=JSON value added to the output")
    args = parser.parse_args()

    with open(os.path.join(args.monitor_dir, "monitor.json")) as f:
        monitor = json.load(f)
    estimate = read_tum(os.path.join(args.monitor_dir, "estimate_tum.txt"))
    truth = read_tum(os.path.join(args.monitor_dir, "truth_tum.txt"))
    metrics = {"trajectory": trajectory_errors(estimate, truth)}
    bag_counts, bag_duration = (bag_message_counts(args.bag) if args.bag else (None, None))
    metrics["messages"] = rates_and_drops(monitor, bag_counts)
    metrics["map_info"] = monitor.get("map_info")
    if bag_counts:
        metrics["messages"]["bag"] = {"counts": bag_counts, "duration_s": bag_duration}
    if args.map_ply and os.path.exists(args.map_ply):
        vertices = read_ply_vertices(args.map_ply)
        metrics["map"] = {"occupied_voxels": int(len(vertices)), "classes": map_class_histogram(vertices)}
        if args.ground_truth and args.map_ot:
            try:
                poses = (estimated_frame_poses(estimate, truth) if args.map_poses == "estimate" else None)
                metrics["map"]["semantic"] = map_miou(args.map_ot, args.ground_truth, poses=poses)
                metrics["map"]["semantic"]["scans_placed_with"] = args.map_poses
            except (OSError, ValueError) as error:
                metrics["map"]["semantic"] = {"error": str(error)}
    for item in args.extra:
        key, value = item.split("=", 1)
        metrics[key] = json.loads(value)
    plotted = False
    if args.evaluate_trajectory:
        metrics["trajectory_evaluation"], plotted = run_evaluate_trajectory(
            args.evaluate_trajectory, estimate, truth, args.monitor_dir, args.plot)
    if args.plot and not plotted and len(estimate) and len(truth):
        plot_trajectories(estimate, truth, args.plot)
    write_json_atomic(args.output, metrics)
    print(summary_text(metrics))
    return 0


def summary_text(metrics):
    """The figures a run is judged by, one per line (the demo prints them)."""
    lines = []
    t = metrics.get("trajectory", {})
    if t.get("matched_poses"):
        lines.append("trajectory vs ground truth: ATE %.2f m, rotation RMSE %.2f deg, final error %.2f m "
                     "(%d poses, %.0f s, %.0f m driven)" % (
                         t["ate_rmse_m"], t["rotation_rmse_deg"], t["position_error_final_m"],
                         t["matched_poses"], t["duration_s"], t["path_length_m"]))
    else:
        lines.append("trajectory vs ground truth: no pose matched")
    m = metrics.get("messages", {})
    topics = m.get("topics", {})
    def count(topic):
        return topics.get(topic, {}).get("messages", 0)
    played = m.get("bag", {}).get("counts", {}).get(SCAN_TOPIC)
    info = metrics.get("map_info")
    if info:
        lines.append("scans: %s in the bag, %d received by the map node, %d in the map (%d with labels), "
                     "%d without a pose" % (played if played is not None else "?", info["scans_received"],
                                            info["scans_inserted"], info["scans_with_labels"],
                                            info["scans_without_pose"]))
    else:
        lines.append("scans: %s in the bag, %d received (no /semantic_map/info)" % (
            played if played is not None else "?", count(SCAN_TOPIC)))
    labels = topics.get("/segmentation/labels", {})
    wall_rate = labels.get("wall_rate_hz")
    lines.append("label images: %d of %d camera images segmented%s%s" % (
        count("/segmentation/labels"), count(IMAGE_TOPIC),
        ", %.2f per second (wall clock)" % wall_rate if wall_rate else "",
        "; %d used by the map" % info["label_images_used"] if info else ""))
    for name, key in (("scan-to-map latency", "scan_to_map_latency_s"),
                      ("image-to-labels latency", "image_to_labels_latency_s")):
        lat = m.get(key)
        if lat:
            lines.append("%s: p50 %.2f s, p95 %.2f s, max %.2f s (%d matched)" % (
                name, lat["p50"], lat["p95"], lat["max"], lat["matched"]))
    mp = metrics.get("map")
    if mp:
        total = max(1, mp["occupied_voxels"])
        ranked = sorted(mp.get("classes", {}).items(), key=lambda item: -item[1])[:6]
        lines.append("map: %d occupied voxels; most common: %s" % (mp["occupied_voxels"], ", ".join(
            "%s %.0f %%" % (CITYSCAPES_NAMES.get(int(label), str(label)), 100.0 * n / total)
            for label, n in ranked)))
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
