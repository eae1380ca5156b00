#!/usr/bin/python3
"""Evaluates an estimated trajectory against ground truth.

Metrics: ATE (unaligned and SE(3)-aligned, no scale), rotation and yaw RMSE, KITTI odometry
t_err / r_err (computed exactly as the KITTI devkit's evaluate_odometry.cpp), RPE over 1 and 10
frames, and NEES from a filter's states CSV. Writes a JSON summary and a PNG plot.

Trajectory files: KITTI (12 numbers per line, row-major 3x4 pose) or TUM
(`stamp tx ty tz qx qy qz qw`), detected per file from the column count. Estimate and truth must
hold one pose per frame, the same frames in the same order.

Usage:
  evaluate_trajectory.py --estimate POSES.txt --truth TRUTH.txt [--timestamps TIMES.txt]
      [--states STATES.csv] [--loops LOOPS.csv] [--json OUT.json] [--plot OUT.png] [--label NAME]

--loops takes inekf_offline's --output-loops CSV: the summary and the JSON count the accepted and
rejected loop candidates by reason, and the plot marks each at its later frame (accepted green,
rejected red) on the top view and the time axis.

Only numpy and matplotlib (Debian packages) are used.
"""

import argparse
import calendar
import csv
import datetime
import json
import math
import os
import re
import sys

import numpy as np

# KITTI devkit constants (evaluate_odometry.cpp).
KITTI_SEGMENT_LENGTHS_M = [100, 200, 300, 400, 500, 600, 700, 800]
KITTI_FIRST_FRAME_STEP = 10
# Exact chi-square quantiles (2.5 % and 97.5 %) for the per-sample NEES bands.
CHI2_95_BAND = {3: (0.215795, 9.348404), 6: (1.237344, 14.449375)}
STATES_POSE_COLUMNS = ["stamp", "px", "py", "pz", "qx", "qy", "qz", "qw"]


class TrajectoryFormatError(ValueError):
    """A malformed or inconsistent input file; the message names the file and line."""


# --------------------------------------------------------------------------------------------
# Rotations
# --------------------------------------------------------------------------------------------
def quaternion_to_rotation(qx, qy, qz, qw):
    norm = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    if not norm > 0.0:
        raise ValueError("zero quaternion")
    x, y, z, w = qx / norm, qy / norm, qz / norm, qw / norm
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def rotation_to_quaternion(rotation):
    """(qx, qy, qz, qw) of a rotation matrix (Shepperd's method, numerically safe)."""
    m = rotation
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        return ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s)
    if m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        return (0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s)
    if m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        return ((m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s)
    s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
    return ((m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s)


def so3_log(rotation):
    """Rotation vector (axis * angle) of a rotation matrix, robust near 0 and near pi."""
    cos_angle = max(-1.0, min(1.0, 0.5 * (np.trace(rotation) - 1.0)))
    angle = math.acos(cos_angle)
    skew = np.array([rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0],
                     rotation[1, 0] - rotation[0, 1]])
    if angle < 1e-6:
        return 0.5 * skew  # first order: R ~ I + [w]x
    if math.pi - angle < 1e-4:
        # sin(angle) ~ 0: take the axis from the symmetric part, R + I = 2 a a^T (near pi).
        symmetric = 0.5 * (rotation + np.eye(3))
        column = int(np.argmax(np.diag(symmetric)))
        axis = symmetric[:, column] / math.sqrt(max(symmetric[column, column], 1e-12))
        axis /= np.linalg.norm(axis)
        if np.dot(axis, skew) < 0:
            axis = -axis
        return angle * axis
    return angle / (2.0 * math.sin(angle)) * skew


def rotation_angle(rotation):
    """Geodesic angle (rad) of a rotation matrix, as the devkit's rotationError."""
    return math.acos(max(-1.0, min(1.0, 0.5 * (np.trace(rotation) - 1.0))))


def yaw_of(rotation):
    """Heading of the body x axis in the map x/y plane (rad)."""
    return math.atan2(rotation[1, 0], rotation[0, 0])


def wrap_angle(angle):
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------
def _content_lines(path):
    """(line number, stripped text) for every non-empty, non-comment line of a file."""
    if not os.path.isfile(path):
        raise TrajectoryFormatError("%s: no such file" % path)
    with open(path) as stream:
        for line_number, line in enumerate(stream, start=1):
            text = line.strip()
            if text and not text.startswith("#"):
                yield line_number, text


def _numeric_rows(path):
    """(line number, [floats]) for every non-empty, non-comment line of a file."""
    rows = []
    for line_number, text in _content_lines(path):
        try:
            values = [float(token) for token in text.replace(",", " ").split()]
        except ValueError:
            raise TrajectoryFormatError("%s:%d: not a list of numbers: %r" %
                                        (path, line_number, text[:80]))
        if not all(math.isfinite(v) for v in values):
            raise TrajectoryFormatError("%s:%d: NaN or infinite value" % (path, line_number))
        rows.append((line_number, values))
    if not rows:
        raise TrajectoryFormatError("%s: no poses" % path)
    return rows


class Trajectory:
    """Poses as arrays: positions (N,3), rotations (N,3,3), optional stamps (N,)."""

    def __init__(self, positions, rotations, stamps=None, source=""):
        self.positions = np.asarray(positions, dtype=float)
        self.rotations = np.asarray(rotations, dtype=float)
        self.stamps = None if stamps is None else np.asarray(stamps, dtype=float)
        self.source = source

    def __len__(self):
        return len(self.positions)

    def matrices(self):
        poses = np.tile(np.eye(4), (len(self), 1, 1))
        poses[:, :3, :3] = self.rotations
        poses[:, :3, 3] = self.positions
        return poses


def read_trajectory(path):
    """Reads a KITTI (12 columns) or TUM (8 columns) trajectory; the format is per file."""
    rows = _numeric_rows(path)
    columns = len(rows[0][1])
    if columns not in (8, 12):
        raise TrajectoryFormatError(
            "%s:%d: %d values; expected 12 (KITTI 3x4 pose) or 8 (TUM stamp x y z qx qy qz qw)" %
            (path, rows[0][0], columns))
    positions, rotations, stamps = [], [], []
    for line_number, values in rows:
        if len(values) != columns:
            raise TrajectoryFormatError("%s:%d: %d values, but the first pose line has %d" %
                                        (path, line_number, len(values), columns))
        if columns == 12:
            matrix = np.array(values).reshape(3, 4)
            rotations.append(matrix[:, :3])
            positions.append(matrix[:, 3])
        else:
            stamps.append(values[0])
            positions.append(values[1:4])
            try:
                rotations.append(quaternion_to_rotation(*values[4:8]))
            except ValueError:
                raise TrajectoryFormatError("%s:%d: zero quaternion" % (path, line_number))
    return Trajectory(positions, rotations, stamps if columns == 8 else None, source=path)


def read_timestamps(path):
    """Stamps (s) from a one-column file, a TUM file (first column) or KITTI's timestamps.txt."""
    stamps = []
    for line_number, text in _content_lines(path):
        if "-" in text.split()[0] and ":" in text:  # KITTI raw "2011-09-26 13:02:25.964389445"
            stamps.append(_kitti_datetime_seconds(text, path, line_number))
            continue
        try:
            stamps.append(float(text.replace(",", " ").split()[0]))
        except ValueError:
            raise TrajectoryFormatError("%s:%d: not a timestamp: %r" %
                                        (path, line_number, text[:80]))
    if not stamps:
        raise TrajectoryFormatError("%s: no timestamps" % path)
    return np.array(stamps)


def kitti_timestamp_parts(text):
    """(UNIX seconds, nanoseconds), UTC, of a KITTI raw timestamp "2011-09-26 13:02:25.964389445"
    (the Python side's one parser of the format; exact to the nanosecond, for ROS stamps).
    Raises ValueError when the text is not one."""
    day, clock = text.split()
    whole, _, fraction = clock.partition(".")
    if not fraction.isdigit() and fraction:
        raise ValueError("bad fraction %r" % fraction)
    moment = datetime.datetime.strptime(day + " " + whole, "%Y-%m-%d %H:%M:%S")
    return calendar.timegm(moment.timetuple()), int((fraction + "000000000")[:9])


def _kitti_datetime_seconds(text, path, line_number):
    """UNIX seconds (UTC, as inekf_offline's stamps) of a KITTI raw timestamp."""
    try:
        seconds, nanoseconds = kitti_timestamp_parts(text)
        return seconds + nanoseconds * 1e-9
    except ValueError:
        raise TrajectoryFormatError("%s:%d: not a KITTI timestamp: %r" % (path, line_number, text))


def read_states(path):
    """The filter's states CSV: dict with stamps (N,), positions (N,3), rotations (N,3,3) and
    pose covariances (N,6,6) (position in map, then body rotation error)."""
    if not os.path.isfile(path):
        raise TrajectoryFormatError("%s: no such file" % path)
    with open(path) as stream:
        lines = stream.read().splitlines()
    if not lines:
        raise TrajectoryFormatError("%s: empty file" % path)
    header = [name.strip() for name in lines[0].split(",")]
    covariance_names = ["c%d%d" % (r, c) for r in range(6) for c in range(6)]
    missing = [name for name in STATES_POSE_COLUMNS + covariance_names if name not in header]
    if missing:
        raise TrajectoryFormatError("%s:1: header lacks column(s) %s" % (path, ", ".join(missing)))
    index = {name: i for i, name in enumerate(header)}
    stamps, positions, rotations, covariances = [], [], [], []
    for line_number, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        fields = line.split(",")
        if len(fields) != len(header):
            raise TrajectoryFormatError("%s:%d: %d fields, the header has %d" %
                                        (path, line_number, len(fields), len(header)))
        try:
            values = [float(field) for field in fields]
        except ValueError:
            raise TrajectoryFormatError("%s:%d: a field is not a number" % (path, line_number))
        if not all(math.isfinite(v) for v in values):
            raise TrajectoryFormatError("%s:%d: NaN or infinite value" % (path, line_number))
        stamps.append(values[index["stamp"]])
        positions.append([values[index[name]] for name in ("px", "py", "pz")])
        try:
            rotations.append(quaternion_to_rotation(*[values[index[n]] for n in ("qx", "qy", "qz", "qw")]))
        except ValueError:
            raise TrajectoryFormatError("%s:%d: zero quaternion" % (path, line_number))
        covariances.append(np.array([values[index[name]] for name in covariance_names]).reshape(6, 6))
    if not stamps:
        raise TrajectoryFormatError("%s: no state rows" % path)
    return {"stamps": np.array(stamps), "positions": np.array(positions),
            "rotations": np.array(rotations), "covariances": np.array(covariances)}


# --------------------------------------------------------------------------------------------
# Metrics
# --------------------------------------------------------------------------------------------
def umeyama_alignment(source_points, target_points):
    """Rigid (R, t), no scale, minimizing sum |target - (R source + t)|^2 (Umeyama 1991)."""
    source_mean = source_points.mean(axis=0)
    target_mean = target_points.mean(axis=0)
    cross = (target_points - target_mean).T @ (source_points - source_mean) / len(source_points)
    u, _, vt = np.linalg.svd(cross)
    reflection = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        reflection[2, 2] = -1.0  # a proper rotation, never a mirror
    rotation = u @ reflection @ vt
    return rotation, target_mean - rotation @ source_mean


def rms(values):
    values = np.asarray(values, dtype=float)
    return float(math.sqrt(np.mean(values ** 2))) if values.size else float("nan")


def trajectory_distances(positions):
    """Cumulative path length per frame (the devkit's trajectoryDistances)."""
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)])


def overlaps_excluded(first, last, excluded):
    """True if frames first..last (inclusive) touch one of the excluded (a, b) ranges."""
    return any(first <= b and a <= last for a, b in excluded or ())


def kitti_odometry_errors(truth_poses, estimate_poses, frame_period_s=0.1, excluded=None):
    """Segment errors exactly as the KITTI devkit's calcSequenceErrors: per first frame (every
    10th) and segment length, the relative-pose error over the first frame whose truth path
    length exceeds the start's by the segment length. Returns t_err (%), r_err (deg/m) and a
    per-length breakdown; lengths longer than the drive are skipped, and so are segments that
    touch an `excluded` frame range (truth known to be wrong there)."""
    distances = trajectory_distances(truth_poses[:, :3, 3])
    segments = []
    for first_frame in range(0, len(truth_poses), KITTI_FIRST_FRAME_STEP):
        for length in KITTI_SEGMENT_LENGTHS_M:
            beyond = np.nonzero(distances[first_frame:] > distances[first_frame] + length)[0]
            if beyond.size == 0:
                continue
            last_frame = first_frame + int(beyond[0])
            if overlaps_excluded(first_frame, last_frame, excluded):
                continue
            delta_truth = np.linalg.inv(truth_poses[first_frame]) @ truth_poses[last_frame]
            delta_estimate = np.linalg.inv(estimate_poses[first_frame]) @ estimate_poses[last_frame]
            error = np.linalg.inv(delta_estimate) @ delta_truth
            segments.append((length, np.linalg.norm(error[:3, 3]) / length,
                             rotation_angle(error[:3, :3]) / length))
    if not segments:
        return {"t_err_percent": None, "r_err_deg_per_m": None, "segments": 0,
                "per_length": {}, "note": "drive shorter than the shortest segment (100 m)"}
    segments = np.array(segments)
    per_length = {}
    for length in KITTI_SEGMENT_LENGTHS_M:
        rows = segments[segments[:, 0] == length]
        if len(rows):
            per_length[str(length)] = {"t_err_percent": 100.0 * float(rows[:, 1].mean()),
                                       "r_err_deg_per_m": math.degrees(float(rows[:, 2].mean())),
                                       "segments": int(len(rows))}
    return {"t_err_percent": 100.0 * float(segments[:, 1].mean()),
            "r_err_deg_per_m": math.degrees(float(segments[:, 2].mean())),
            "segments": int(len(segments)), "per_length": per_length}


def relative_pose_errors(truth_poses, estimate_poses, frame_delta, excluded=None):
    """RMS translation (m) and rotation (deg) error of the motion over frame_delta frames."""
    translation_errors, rotation_errors = [], []
    for first in range(0, len(truth_poses) - frame_delta):
        if overlaps_excluded(first, first + frame_delta, excluded):
            continue
        delta_truth = np.linalg.inv(truth_poses[first]) @ truth_poses[first + frame_delta]
        delta_estimate = np.linalg.inv(estimate_poses[first]) @ estimate_poses[first + frame_delta]
        error = np.linalg.inv(delta_estimate) @ delta_truth
        translation_errors.append(np.linalg.norm(error[:3, 3]))
        rotation_errors.append(math.degrees(rotation_angle(error[:3, :3])))
    if not translation_errors:
        return None
    return {"frames": frame_delta, "pairs": len(translation_errors),
            "translation_rmse_m": rms(translation_errors),
            "rotation_rmse_deg": rms(rotation_errors)}


def chi2_quantile(probability, dof):
    """Wilson-Hilferty approximation of the chi-square quantile (good to <1 % for dof >= 3)."""
    z = _normal_quantile(probability)
    h = 2.0 / (9.0 * dof)
    return dof * (1.0 - h + z * math.sqrt(h)) ** 3


def _normal_quantile(probability):
    # Acklam's rational approximation is overkill here: the two values we need.
    table = {0.025: -1.959963985, 0.975: 1.959963985}
    return table[probability]


def nees_statistics(nees_values, dof):
    """Average NEES, its 95 % band for the average of N independent samples (chi2(N dof)/N),
    and the fraction of samples inside the per-sample 95 % band."""
    nees_values = np.asarray(nees_values)
    count = len(nees_values)
    low, high = CHI2_95_BAND[dof]
    return {"dof": dof, "samples": int(count), "average": float(nees_values.mean()),
            "average_band_95": [chi2_quantile(0.025, count * dof) / count,
                                chi2_quantile(0.975, count * dof) / count],
            "fraction_inside_band_95": float(np.mean((nees_values >= low) & (nees_values <= high))),
            "sample_band_95": [low, high], "median": float(np.median(nees_values))}


def compute_nees(states, truth, truth_stamps, states_path):
    """NEES of each state row against the truth pose of the same frame. Rows are matched to
    truth frames by stamp when stamps are known, else by row index."""
    count = len(states["stamps"])
    if truth_stamps is not None:
        frame_of_row = np.searchsorted(truth_stamps, states["stamps"])
        frame_of_row = np.clip(frame_of_row, 0, len(truth_stamps) - 1)
        previous = np.clip(frame_of_row - 1, 0, len(truth_stamps) - 1)
        closer_previous = (np.abs(truth_stamps[previous] - states["stamps"]) <
                           np.abs(truth_stamps[frame_of_row] - states["stamps"]))
        frame_of_row = np.where(closer_previous, previous, frame_of_row)
        mismatch = np.abs(truth_stamps[frame_of_row] - states["stamps"])
        if np.any(mismatch > 5e-3):
            row = int(np.argmax(mismatch > 5e-3))
            raise TrajectoryFormatError("%s:%d: stamp %.6f matches no truth stamp (nearest %.6f)" %
                                        (states_path, row + 2, states["stamps"][row],
                                         truth_stamps[frame_of_row[row]]))
    elif count == len(truth):
        frame_of_row = np.arange(count)
    else:
        raise TrajectoryFormatError(
            "%s: %d state rows but %d truth poses, and no timestamps to match them "
            "(give --timestamps)" % (states_path, count, len(truth)))
    nees6, nees3, times = [], [], []
    for row, frame in enumerate(frame_of_row):
        position_error = truth.positions[frame] - states["positions"][row]
        rotation_error = so3_log(states["rotations"][row].T @ truth.rotations[frame])
        error = np.concatenate([position_error, rotation_error])
        covariance = 0.5 * (states["covariances"][row] + states["covariances"][row].T)
        try:
            nees6.append(float(error @ np.linalg.solve(covariance, error)))
            nees3.append(float(position_error @ np.linalg.solve(covariance[:3, :3], position_error)))
        except np.linalg.LinAlgError:
            raise TrajectoryFormatError("%s:%d: singular pose covariance" % (states_path, row + 2))
        times.append(frame)
    return np.array(nees6), np.array(nees3), np.array(times)


def evaluate(estimate, truth, stamps=None, states=None, states_path="", excluded=None):
    """All metrics as a dict (JSON-ready) plus per-frame series for the plot. Frames in the
    `excluded` (first, last) ranges count in no metric (the plot still shows them)."""
    if len(estimate) != len(truth):
        raise TrajectoryFormatError("%s has %d poses but %s has %d: one pose per frame expected" %
                                    (estimate.source, len(estimate), truth.source, len(truth)))
    if stamps is not None and len(stamps) != len(truth):
        raise TrajectoryFormatError("timestamps: %d stamps for %d poses" % (len(stamps), len(truth)))
    kept = np.ones(len(truth), dtype=bool)
    for first, last in excluded or ():
        if first < 0 or last < first or last >= len(truth):
            raise TrajectoryFormatError("excluded frames %d:%d are outside the %d poses" %
                                        (first, last, len(truth)))
        kept[first:last + 1] = False
    if not kept.any():
        raise TrajectoryFormatError("every frame is excluded")
    position_errors = np.linalg.norm(estimate.positions - truth.positions, axis=1)
    alignment_rotation, alignment_translation = umeyama_alignment(estimate.positions[kept],
                                                                  truth.positions[kept])
    aligned_positions = estimate.positions @ alignment_rotation.T + alignment_translation
    aligned_errors = np.linalg.norm(aligned_positions - truth.positions, axis=1)
    rotation_errors_deg = np.array([math.degrees(rotation_angle(e.T @ t))
                                    for e, t in zip(estimate.rotations, truth.rotations)])
    yaw_errors_deg = np.array([math.degrees(wrap_angle(yaw_of(e) - yaw_of(t)))
                               for e, t in zip(estimate.rotations, truth.rotations)])
    truth_poses, estimate_poses = truth.matrices(), estimate.matrices()
    path_length = float(trajectory_distances(truth.positions)[-1])
    offsets = (estimate.positions - truth.positions)[kept]
    result = {
        "poses": int(kept.sum()),
        "excluded_frames": [[int(a), int(b)] for a, b in excluded or ()],
        "path_length_m": path_length,
        "ate_unaligned_rmse_m": rms(position_errors[kept]),
        "ate_unaligned_max_m": float(position_errors[kept].max()),
        "ate_aligned_rmse_m": rms(aligned_errors[kept]),
        "alignment_rotation_deg": math.degrees(rotation_angle(alignment_rotation)),
        "alignment_translation_m": [float(v) for v in alignment_translation],
        "horizontal_rmse_m": rms(np.linalg.norm(offsets[:, :2], axis=1)),
        "vertical_rmse_m": rms(offsets[:, 2]),
        "rotation_rmse_deg": rms(rotation_errors_deg[kept]),
        "rotation_max_deg": float(rotation_errors_deg[kept].max()),
        "yaw_rmse_deg": rms(yaw_errors_deg[kept]),
        "kitti": kitti_odometry_errors(truth_poses, estimate_poses, excluded=excluded),
        "rpe": [r for r in (relative_pose_errors(truth_poses, estimate_poses, 1, excluded),
                            relative_pose_errors(truth_poses, estimate_poses, 10, excluded)) if r],
    }
    times = stamps - stamps[0] if stamps is not None else np.arange(len(truth), dtype=float)
    series = {"times": times, "time_unit": "s" if stamps is not None else "frame",
              "position_errors": position_errors, "yaw_errors_deg": yaw_errors_deg,
              "rotation_errors_deg": rotation_errors_deg}
    if states is not None:
        nees6, nees3, frames = compute_nees(states, truth, stamps, states_path)
        result["nees_pose"] = nees_statistics(nees6, 6)
        result["nees_position"] = nees_statistics(nees3, 3)
        series["nees_times"] = times[frames]
        series["nees_pose"] = nees6
        series["nees_position"] = nees3
    return result, series


LOOP_COLUMNS = ["query_frame", "match_frame", "accepted", "reason"]


def read_loops(path, frames):
    """inekf_offline --output-loops: [(query_frame, match_frame, accepted, reason)]. Frames must
    index the trajectory (`frames` poses)."""
    loops = []
    try:
        with open(path, newline="") as stream:
            rows = list(csv.reader(stream))
    except OSError as error:
        raise TrajectoryFormatError("%s: cannot read (%s)" % (path, error.strerror))
    if not rows or any(column not in rows[0] for column in LOOP_COLUMNS):
        raise TrajectoryFormatError("%s:1: not a loops CSV (needs the columns %s)" %
                                    (path, ", ".join(LOOP_COLUMNS)))
    index = {name: rows[0].index(name) for name in LOOP_COLUMNS}
    for number, row in enumerate(rows[1:], start=2):
        if not row:
            continue
        try:
            query = int(row[index["query_frame"]])
            match = int(row[index["match_frame"]])
            accepted = int(row[index["accepted"]]) == 1
            reason = row[index["reason"]]
        except (ValueError, IndexError):
            raise TrajectoryFormatError("%s:%d: expected %d comma-separated fields with integer "
                                        "frames, got %r" % (path, number, len(rows[0]),
                                                            ",".join(row)))
        if not (0 <= query < frames and 0 <= match < frames):
            raise TrajectoryFormatError("%s:%d: frames %d / %d outside the trajectory's %d poses" %
                                        (path, number, query, match, frames))
        loops.append((query, match, accepted, reason))
    return loops


def summarize_loops(loops):
    """Counts by fate; rejections grouped by the reason's leading words (the numbers vary)."""
    rejected = {}
    for _, _, accepted, reason in loops:
        if not accepted:
            key = re.match(r"[^0-9:(]*", reason).group(0).strip() or "unknown"
            rejected[key] = rejected.get(key, 0) + 1
    return {"candidates": len(loops), "accepted": sum(1 for loop in loops if loop[2]),
            "rejected": sum(rejected.values()), "rejected_by_reason": rejected}


# --------------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------------
def output_path_problem(path):
    """Why `path` cannot be written (None if it can): checked before the work, so that a
    mistyped folder is said at once, not in a traceback after the metrics."""
    if os.path.isdir(path):
        return "%s is a directory" % path
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        return "cannot write %s: no directory %s" % (path, folder)
    if not os.access(folder, os.W_OK):
        return "cannot write %s: directory %s is not writable" % (path, folder)
    return None


def check_output_paths(parser, paths):
    """parser.error (exit status 2) naming the first output that cannot be written."""
    for path in paths:
        problem = path and output_path_problem(path)
        if problem:
            parser.error(problem)


def write_json_atomically(path, data):
    temporary = path + ".tmp"
    with open(temporary, "w") as stream:
        json.dump(data, stream, indent=2, sort_keys=True)
        stream.write("\n")
    os.replace(temporary, path)


def plot(path, label, estimate, truth, series, loops=()):
    import matplotlib
    matplotlib.use("Agg")  # no display on CI machines
    import matplotlib.pyplot as plt

    has_nees = "nees_pose" in series
    figure, axes = plt.subplots(1, 3 if has_nees else 2, figsize=(17 if has_nees else 12, 5.5))
    top = axes[0]
    top.plot(truth.positions[:, 0], truth.positions[:, 1], "k-", lw=1.5, label="truth")
    top.plot(estimate.positions[:, 0], estimate.positions[:, 1], "r-", lw=1.0, label=label)
    top.plot(truth.positions[0, 0], truth.positions[0, 1], "go", label="start")
    # A loop joins two passes of the same place, so its two ends nearly coincide on the map: each
    # is marked at its later (query) frame, and its frames shown on the time axis below.
    for fate, marker in ((True, "g^"), (False, "rx")):
        queries = [query for query, _, accepted, _ in loops if accepted == fate]
        if queries:
            top.plot(estimate.positions[queries, 0], estimate.positions[queries, 1], marker, ms=5,
                     label="loops %s (%d)" % ("accepted" if fate else "rejected", len(queries)))
    top.set_aspect("equal", adjustable="datalim")
    top.set_xlabel("x east [m]")
    top.set_ylabel("y north [m]")
    top.set_title("top-down trajectory")
    top.legend()
    errors = axes[1]
    errors.plot(series["times"], series["position_errors"], "b-", label="position error [m]")
    errors.set_xlabel("time [%s]" % series["time_unit"])
    errors.set_ylabel("position error [m]", color="b")
    yaw_axis = errors.twinx()
    yaw_axis.plot(series["times"], np.abs(series["yaw_errors_deg"]), "m-", lw=0.8)
    yaw_axis.set_ylabel("|yaw error| [deg]", color="m")
    for fate, marker in ((True, "g^"), (False, "rx")):
        queries = [query for query, _, accepted, _ in loops if accepted == fate]
        if queries and len(series["times"]) == len(estimate.positions):
            errors.plot(np.asarray(series["times"])[queries], np.zeros(len(queries)), marker, ms=5,
                        clip_on=False)
    errors.set_title("error over time" + (" (loops at their later frame)" if loops else ""))
    if has_nees:
        nees = axes[2]
        nees.semilogy(series["nees_times"], series["nees_pose"], "b.", ms=2, label="NEES pose (6)")
        nees.semilogy(series["nees_times"], series["nees_position"], "g.", ms=2,
                      label="NEES position (3)")
        for dof, color in ((6, "b"), (3, "g")):
            for bound in CHI2_95_BAND[dof]:
                nees.axhline(bound, color=color, ls="--", lw=0.8)
        nees.set_xlabel("time [%s]" % series["time_unit"])
        nees.set_title("NEES with per-sample 95 % bands")
        nees.legend()
    figure.suptitle(label)
    figure.tight_layout()
    temporary = path + ".tmp.png"
    figure.savefig(temporary, dpi=110)
    plt.close(figure)
    os.replace(temporary, path)


def format_summary(label, result):
    kitti = result["kitti"]
    lines = ["%s: %d poses, %.0f m" % (label, result["poses"], result["path_length_m"]),
             "  ATE unaligned %.3f m (max %.3f), aligned %.3f m" %
             (result["ate_unaligned_rmse_m"], result["ate_unaligned_max_m"], result["ate_aligned_rmse_m"]),
             "  rotation RMSE %.3f deg, yaw RMSE %.3f deg" %
             (result["rotation_rmse_deg"], result["yaw_rmse_deg"])]
    if kitti["t_err_percent"] is not None:
        lines.append("  KITTI t_err %.3f %%, r_err %.5f deg/m (%d segments)" %
                     (kitti["t_err_percent"], kitti["r_err_deg_per_m"], kitti["segments"]))
    else:
        lines.append("  KITTI t_err/r_err: n/a (%s)" % kitti["note"])
    for rpe in result["rpe"]:
        lines.append("  RPE %d frame(s): %.3f m, %.3f deg" %
                     (rpe["frames"], rpe["translation_rmse_m"], rpe["rotation_rmse_deg"]))
    if "loops" in result:
        loops = result["loops"]
        reasons = ", ".join("%d %s" % (count, reason)
                            for reason, count in sorted(loops["rejected_by_reason"].items()))
        lines.append("  loops: %d candidates, %d accepted, %d rejected%s" %
                     (loops["candidates"], loops["accepted"], loops["rejected"],
                      " (%s)" % reasons if reasons else ""))
    for key in ("nees_pose", "nees_position"):
        if key in result:
            nees = result[key]
            lines.append("  %s (dof %d): average %.2f (95%% band for the average %.2f..%.2f), "
                         "%.1f %% of samples inside the per-sample band" %
                         (key, nees["dof"], nees["average"], nees["average_band_95"][0],
                          nees["average_band_95"][1], 100.0 * nees["fraction_inside_band_95"]))
    return "\n".join(lines)


def load_inputs(estimate_path, truth_path, timestamps_path=None, states_path=None):
    """Reads the files and picks the stamps: --timestamps, else the estimate's or the truth's
    own TUM stamps."""
    estimate = read_trajectory(estimate_path)
    truth = read_trajectory(truth_path)
    if timestamps_path:
        stamps = read_timestamps(timestamps_path)
        if len(stamps) != len(truth):
            raise TrajectoryFormatError("%s: %d stamps but %s has %d poses" %
                                        (timestamps_path, len(stamps), truth_path, len(truth)))
    else:
        stamps = estimate.stamps if estimate.stamps is not None else truth.stamps
    states = read_states(states_path) if states_path else None
    return estimate, truth, stamps, states


def frame_range(text):
    """FIRST:LAST for --exclude-frames."""
    first, sep, last = text.partition(":")
    try:
        if not sep:
            raise ValueError
        first, last = int(first), int(last)
    except ValueError:
        raise argparse.ArgumentTypeError("'%s' is no FIRST:LAST frame range" % text)
    if first > last:
        raise argparse.ArgumentTypeError("'%s': FIRST is after LAST" % text)
    return first, last


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--estimate", required=True, help="estimated poses (KITTI or TUM)")
    parser.add_argument("--truth", required=True, help="ground-truth poses (KITTI or TUM)")
    parser.add_argument("--timestamps", help="one stamp per pose (plain, TUM or KITTI raw)")
    parser.add_argument("--states", help="filter states CSV with the 6x6 pose covariance (NEES)")
    parser.add_argument("--loops", help="inekf_offline --output-loops CSV: counted and plotted")
    parser.add_argument("--json", help="write the metrics here")
    parser.add_argument("--plot", help="write a PNG plot here")
    parser.add_argument("--label", help="name of the run (default: the estimate's file name)")
    parser.add_argument("--exclude-frames", action="append", default=[], metavar="FIRST:LAST",
                        type=frame_range,
                        help="leave frames FIRST..LAST (0-based, inclusive) out of every metric, "
                             "e.g. 769:1202 on 2011_09_30_drive_0028, where the OXTS truth is "
                             "wrong; KITTI segments and RPE pairs that touch them are skipped; "
                             "repeatable")
    args = parser.parse_args(argv)
    check_output_paths(parser, [args.json, args.plot])
    label = args.label or os.path.basename(args.estimate)
    try:
        estimate, truth, stamps, states = load_inputs(args.estimate, args.truth, args.timestamps,
                                                      args.states)
        result, series = evaluate(estimate, truth, stamps, states, args.states or "",
                                  args.exclude_frames)
        loops = read_loops(args.loops, len(estimate.positions)) if args.loops else []
    except TrajectoryFormatError as error:
        print("evaluate_trajectory: error: %s" % error, file=sys.stderr)
        return 2
    result["label"] = label
    result["estimate"] = os.path.abspath(args.estimate)
    result["truth"] = os.path.abspath(args.truth)
    if args.loops:
        result["loops"] = summarize_loops(loops)
    print(format_summary(label, result))
    if args.json:
        write_json_atomically(args.json, result)
    if args.plot:
        plot(args.plot, label, estimate, truth, series, loops)
    return 0


if __name__ == "__main__":
    sys.exit(main())
