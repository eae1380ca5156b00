#!/usr/bin/python3
"""Unit tests of scripts/evaluate_trajectory.py on synthetic trajectories whose answers are
known. Runs standalone (`test/ros/test_evaluate_trajectory.py`) or as the test node of
test/ros/evaluate_trajectory.test (rostest, which records the result for catkin)."""

import argparse
import contextlib
import io
import json
import math
import os
import sys
import tempfile
import unittest

import numpy as np

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.realpath(__file__))))
sys.path.insert(0, os.path.join(REPO_ROOT, "scripts"))
import evaluate_trajectory as et  # noqa: E402
import compare_filters as cf  # noqa: E402


def rotation_z(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_about(axis, angle):
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    skew = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * skew + (1 - math.cos(angle)) * skew @ skew


def curved_drive(frames=600, speed=10.0, period=0.1):
    """A car-like drive: forward along the heading, the heading turning slowly, z wavy."""
    positions, rotations = [], []
    heading, position = 0.3, np.zeros(3)
    for k in range(frames):
        heading += 0.004 * math.sin(0.01 * k)
        rotations.append(rotation_z(heading))
        positions.append(position.copy())
        position = position + speed * period * np.array([math.cos(heading), math.sin(heading), 0.0])
        position[2] = 2.0 * math.sin(0.005 * k)
    return et.Trajectory(positions, rotations, source="synthetic")


def straight_line(length_m, spacing_m=1.0, scale=1.0):
    count = int(length_m / spacing_m) + 1
    positions = [[scale * spacing_m * k, 0.0, 0.0] for k in range(count)]
    return et.Trajectory(positions, [np.eye(3)] * count, source="line")


def write_kitti(path, trajectory):
    with open(path, "w") as stream:
        for position, rotation in zip(trajectory.positions, trajectory.rotations):
            matrix = np.hstack([rotation, position.reshape(3, 1)])
            stream.write(" ".join("%.9f" % v for v in matrix.reshape(-1)) + "\n")


def write_tum(path, trajectory, stamps):
    with open(path, "w") as stream:
        for stamp, position, rotation in zip(stamps, trajectory.positions, trajectory.rotations):
            stream.write("%.6f %.9f %.9f %.9f %.12f %.12f %.12f %.12f\n" %
                         ((stamp,) + tuple(position) + et.rotation_to_quaternion(rotation)))


def write_states(path, stamps, positions, rotations, covariances):
    header = ["stamp", "px", "py", "pz", "qx", "qy", "qz", "qw", "vx", "vy", "vz",
              "bgx", "bgy", "bgz", "bax", "bay", "baz"]
    header += ["c%d%d" % (r, c) for r in range(6) for c in range(6)]
    with open(path, "w") as stream:
        stream.write(",".join(header) + "\n")
        for stamp, position, rotation, covariance in zip(stamps, positions, rotations, covariances):
            values = [stamp] + list(position) + list(et.rotation_to_quaternion(rotation))
            values += [0.0] * 9 + list(covariance.reshape(-1))
            stream.write(",".join("%.12g" % v for v in values) + "\n")


def perturbed_states(truth, covariance, rng):
    """States whose errors e = [p_true - p_est; Log(R_est^T R_true)] are drawn from covariance."""
    cholesky = np.linalg.cholesky(covariance)
    positions, rotations = [], []
    for position, rotation in zip(truth.positions, truth.rotations):
        error = cholesky @ rng.standard_normal(6)
        positions.append(position - error[:3])
        # R_true = R_est Exp(delta)  =>  R_est = R_true Exp(-delta)
        angle = np.linalg.norm(error[3:])
        rotations.append(rotation @ rotation_about(error[3:], -angle))
    return np.array(positions), np.array(rotations)


class RotationTest(unittest.TestCase):
    def test_quaternion_round_trip(self):
        rng = np.random.default_rng(1)
        for _ in range(200):
            rotation = rotation_about(rng.standard_normal(3), rng.uniform(0, math.pi))
            back = et.quaternion_to_rotation(*et.rotation_to_quaternion(rotation))
            np.testing.assert_allclose(back, rotation, atol=1e-12)

    def test_log_inverts_exp_including_near_pi(self):
        rng = np.random.default_rng(2)
        for angle in [0.0, 1e-9, 1e-3, 0.5, 2.0, math.pi - 1e-3, math.pi - 1e-6]:
            axis = rng.standard_normal(3)
            axis /= np.linalg.norm(axis)
            vector = et.so3_log(rotation_about(axis, angle))
            self.assertAlmostEqual(np.linalg.norm(vector), angle, places=5)
            if angle > 1e-6:
                np.testing.assert_allclose(vector / np.linalg.norm(vector), axis, atol=1e-4)


class TrajectoryMetricsTest(unittest.TestCase):
    def test_identical_trajectories_have_zero_error(self):
        truth = curved_drive()
        result, _ = et.evaluate(truth, truth)
        self.assertLess(result["ate_unaligned_rmse_m"], 1e-9)
        self.assertLess(result["ate_aligned_rmse_m"], 1e-9)
        self.assertLess(result["rotation_rmse_deg"], 1e-5)
        self.assertLess(result["kitti"]["t_err_percent"], 1e-6)

    def test_constant_offset_is_ate_unaligned_and_vanishes_when_aligned(self):
        truth = curved_drive()
        offset = np.array([3.0, -4.0, 12.0])  # |offset| = 13 m
        estimate = et.Trajectory(truth.positions + offset, truth.rotations)
        result, series = et.evaluate(estimate, truth)
        self.assertAlmostEqual(result["ate_unaligned_rmse_m"], 13.0, places=6)
        self.assertAlmostEqual(result["horizontal_rmse_m"], 5.0, places=6)
        self.assertAlmostEqual(result["vertical_rmse_m"], 12.0, places=6)
        self.assertLess(result["ate_aligned_rmse_m"], 1e-6)
        np.testing.assert_allclose(result["alignment_translation_m"], -offset, atol=1e-6)
        self.assertLess(result["rotation_rmse_deg"], 1e-5)
        # A pure translation keeps every relative motion: KITTI errors and RPE are zero.
        self.assertLess(result["kitti"]["t_err_percent"], 1e-6)
        self.assertLess(result["rpe"][0]["translation_rmse_m"], 1e-6)
        np.testing.assert_allclose(series["position_errors"], 13.0, atol=1e-6)

    def test_rotated_copy(self):
        truth = curved_drive()
        yaw = math.radians(10.0)
        rotation = rotation_z(yaw)
        estimate = et.Trajectory(truth.positions @ rotation.T + [5.0, 0.0, 0.0],
                                 [rotation @ r for r in truth.rotations])
        result, _ = et.evaluate(estimate, truth)
        self.assertGreater(result["ate_unaligned_rmse_m"], 10.0)
        self.assertLess(result["ate_aligned_rmse_m"], 1e-6)
        self.assertAlmostEqual(result["alignment_rotation_deg"], 10.0, places=5)
        self.assertAlmostEqual(result["rotation_rmse_deg"], 10.0, places=5)
        self.assertAlmostEqual(result["yaw_rmse_deg"], 10.0, places=5)
        # A rigid motion of the whole drive leaves its relative poses unchanged.
        self.assertLess(result["kitti"]["t_err_percent"], 1e-5)
        self.assertLess(result["kitti"]["r_err_deg_per_m"], 1e-6)

    def test_yaw_error_wraps_around_pi(self):
        truth = et.Trajectory([[0, 0, 0], [1, 0, 0]], [rotation_z(math.radians(179.0))] * 2)
        estimate = et.Trajectory([[0, 0, 0], [1, 0, 0]], [rotation_z(math.radians(-179.0))] * 2)
        result, _ = et.evaluate(estimate, truth)
        self.assertAlmostEqual(result["yaw_rmse_deg"], 2.0, places=6)

    def test_one_percent_scale_error_gives_one_percent_t_err(self):
        truth = straight_line(1000.0)
        estimate = straight_line(1000.0, scale=1.01)
        kitti = et.evaluate(estimate, truth)[0]["kitti"]
        # As the devkit, a segment ends at the first frame whose distance EXCEEDS the length:
        # with 1 m frames that is L + 1 m, so the error is 1 % of (L + 1) per metre of L.
        for length, stats in kitti["per_length"].items():
            self.assertAlmostEqual(stats["t_err_percent"], (int(length) + 1.0) / int(length),
                                   places=9)
        self.assertAlmostEqual(kitti["t_err_percent"], 1.0, delta=0.01)
        self.assertLess(kitti["r_err_deg_per_m"], 1e-9)
        self.assertEqual(sorted(int(k) for k in kitti["per_length"]), et.KITTI_SEGMENT_LENGTHS_M)

    def test_segments_longer_than_the_drive_are_skipped(self):
        truth = straight_line(250.0)
        kitti = et.evaluate(truth, truth)[0]["kitti"]
        self.assertEqual(sorted(kitti["per_length"]), ["100", "200"])
        # First frames 0, 10, .., 140 have a frame beyond +100 m; 0..40 beyond +200 m.
        self.assertEqual(kitti["per_length"]["100"]["segments"], 15)
        self.assertEqual(kitti["per_length"]["200"]["segments"], 5)
        short = et.evaluate(straight_line(50.0), straight_line(50.0))[0]["kitti"]
        self.assertIsNone(short["t_err_percent"])

    def test_heading_drift_gives_rotation_error_per_metre(self):
        # The estimate's heading drifts by 0.01 deg per metre along a straight 1 km road.
        truth = straight_line(1000.0)
        drift = [rotation_z(math.radians(0.01 * x)) for x in truth.positions[:, 0]]
        estimate = et.Trajectory(truth.positions, drift)
        kitti = et.evaluate(estimate, truth)[0]["kitti"]
        self.assertAlmostEqual(kitti["r_err_deg_per_m"], 0.01, delta=2e-4)

    def test_rpe_of_a_one_frame_jump(self):
        truth = straight_line(100.0)
        positions = truth.positions.copy()
        positions[50:] += [0.0, 0.5, 0.0]  # one 0.5 m sideways jump between frames 49 and 50
        result, _ = et.evaluate(et.Trajectory(positions, truth.rotations), truth)
        one_frame = result["rpe"][0]
        self.assertEqual(one_frame["pairs"], 100)
        self.assertAlmostEqual(one_frame["translation_rmse_m"], math.sqrt(0.25 / 100), places=9)

    def test_excluded_frames_leave_every_metric(self):
        # The truth climbs 10 m over frames 300..399 (as the OXTS truth of 0028 does); the
        # estimate does not. Left out, that stretch costs nothing; counted, it dominates.
        estimate = straight_line(1000.0)
        positions = estimate.positions.copy()
        positions[300:400, 2] += 10.0
        truth = et.Trajectory(positions, estimate.rotations)
        counted = et.evaluate(estimate, truth)[0]
        self.assertGreater(counted["ate_unaligned_rmse_m"], 2.0)
        self.assertGreater(counted["kitti"]["t_err_percent"], 0.5)
        excluded, _ = et.evaluate(estimate, truth, excluded=[(300, 399)])
        self.assertEqual(excluded["poses"], len(truth) - 100)
        self.assertLess(excluded["ate_unaligned_rmse_m"], 1e-9)
        self.assertLess(excluded["ate_aligned_rmse_m"], 1e-6)
        self.assertLess(excluded["kitti"]["t_err_percent"], 1e-9)
        self.assertLess(excluded["rpe"][1]["translation_rmse_m"], 1e-9)
        # A segment that merely starts before the stretch and ends after it is skipped too.
        self.assertLess(excluded["kitti"]["segments"], counted["kitti"]["segments"] - 10)
        with self.assertRaises(et.TrajectoryFormatError):
            et.evaluate(estimate, truth, excluded=[(900, 1200)])
        self.assertEqual(et.frame_range("860:1080"), (860, 1080))
        # A reversed range was "outside the poses"; it is said for what it is.
        with self.assertRaisesRegex(argparse.ArgumentTypeError, "FIRST is after LAST"):
            et.frame_range("10:5")


class NeesTest(unittest.TestCase):
    def setUp(self):
        self.truth = curved_drive(frames=2000)
        self.stamps = 100.0 + 0.1 * np.arange(len(self.truth))
        self.directory = tempfile.mkdtemp(prefix="ism_eval_")
        rng = np.random.default_rng(7)
        factor = rng.standard_normal((6, 6))
        self.covariance = factor @ factor.T * 0.05 + np.diag([1.0, 1.0, 4.0, 1e-4, 1e-4, 4e-4])
        self.positions, self.rotations = perturbed_states(self.truth, self.covariance, rng)

    def nees_of(self, covariance_scale):
        path = os.path.join(self.directory, "states.csv")
        write_states(path, self.stamps, self.positions, self.rotations,
                     [self.covariance * covariance_scale] * len(self.stamps))
        result, _ = et.evaluate(self.truth, self.truth, self.stamps, et.read_states(path), path)
        return result

    def test_consistent_covariance_gives_nees_near_the_dof(self):
        result = self.nees_of(1.0)
        pose, position = result["nees_pose"], result["nees_position"]
        self.assertEqual(pose["samples"], 2000)
        self.assertGreater(pose["average"], pose["average_band_95"][0])
        self.assertLess(pose["average"], pose["average_band_95"][1])
        self.assertAlmostEqual(pose["average"], 6.0, delta=0.4)
        self.assertAlmostEqual(position["average"], 3.0, delta=0.25)
        self.assertAlmostEqual(pose["fraction_inside_band_95"], 0.95, delta=0.02)

    def test_overconfident_covariance_is_detected(self):
        pose = self.nees_of(0.1)["nees_pose"]
        self.assertAlmostEqual(pose["average"], 60.0, delta=5.0)
        self.assertGreater(pose["average"], pose["average_band_95"][1])
        self.assertLess(pose["fraction_inside_band_95"], 0.5)

    def test_states_are_matched_to_truth_by_stamp(self):
        # Only every 5th frame has a state row: stamps pick the truth frame, not the row index.
        path = os.path.join(self.directory, "sparse.csv")
        rows = slice(3, None, 5)
        write_states(path, self.stamps[rows], self.positions[rows], self.rotations[rows],
                     [self.covariance] * len(self.stamps[rows]))
        result, _ = et.evaluate(self.truth, self.truth, self.stamps, et.read_states(path), path)
        self.assertEqual(result["nees_pose"]["samples"], len(self.stamps[rows]))
        self.assertAlmostEqual(result["nees_pose"]["average"], 6.0, delta=1.0)

    def test_chi2_band_approximation(self):
        # Exact values (scipy.stats.chi2.ppf) for the band of an average of 100 6-dof samples.
        self.assertAlmostEqual(et.chi2_quantile(0.025, 600) / 100, 5.3402, delta=0.002)
        self.assertAlmostEqual(et.chi2_quantile(0.975, 600) / 100, 6.6977, delta=0.002)
        self.assertAlmostEqual(et.chi2_quantile(0.975, 6), 14.449, delta=0.05)


class FilesAndErrorsTest(unittest.TestCase):
    def setUp(self):
        self.directory = tempfile.mkdtemp(prefix="ism_eval_")
        self.truth = curved_drive(frames=1200)

    def path(self, name):
        return os.path.join(self.directory, name)

    def test_command_line_writes_json_and_plot(self):
        stamps = 10.0 + 0.1 * np.arange(len(self.truth))
        estimate = et.Trajectory(self.truth.positions + [1.0, 0.0, 0.0], self.truth.rotations)
        write_kitti(self.path("truth.txt"), self.truth)
        write_tum(self.path("estimate.tum"), estimate, stamps)
        covariance = np.diag([1.0, 1.0, 1.0, 1e-4, 1e-4, 1e-4])
        write_states(self.path("states.csv"), stamps, estimate.positions, estimate.rotations,
                     [covariance] * len(stamps))
        code = et.main(["--estimate", self.path("estimate.tum"), "--truth", self.path("truth.txt"),
                        "--states", self.path("states.csv"), "--json", self.path("out.json"),
                        "--plot", self.path("out.png"), "--label", "offset"])
        self.assertEqual(code, 0)
        with open(self.path("out.json")) as stream:
            result = json.load(stream)
        self.assertEqual(result["label"], "offset")
        self.assertAlmostEqual(result["ate_unaligned_rmse_m"], 1.0, places=6)
        # A 1 m x error against a 1 m^2 covariance: position NEES is exactly 1 everywhere.
        self.assertAlmostEqual(result["nees_position"]["average"], 1.0, places=5)
        self.assertGreater(os.path.getsize(self.path("out.png")), 10000)

    def test_an_output_in_a_missing_folder_is_an_error_before_the_work(self):
        # It was a traceback after the metrics had been computed and printed.
        write_kitti(self.path("truth.txt"), self.truth)
        missing = self.path("no_such_folder/out.json")
        stderr = io.StringIO()
        with self.assertRaises(SystemExit) as stop, contextlib.redirect_stderr(stderr):
            et.main(["--estimate", self.path("truth.txt"), "--truth", self.path("truth.txt"),
                     "--json", missing])
        self.assertEqual(stop.exception.code, 2)
        self.assertIn("no directory " + os.path.dirname(missing), stderr.getvalue())
        with self.assertRaises(SystemExit), contextlib.redirect_stderr(io.StringIO()):
            cf.main(["--truth", self.path("truth.txt"), "a=" + self.path("truth.txt"),
                     "--plot", self.directory])  # a folder, not a file
        self.assertFalse(os.path.exists(missing))

    def test_malformed_line_is_reported_with_file_and_line(self):
        write_kitti(self.path("truth.txt"), self.truth)
        with open(self.path("truth.txt")) as stream:
            lines = stream.readlines()
        lines[6] = lines[6].replace(" ", " x", 1)
        with open(self.path("bad.txt"), "w") as stream:
            stream.writelines(lines)
        with self.assertRaisesRegex(et.TrajectoryFormatError, r"bad\.txt:7: not a list"):
            et.read_trajectory(self.path("bad.txt"))
        lines[6] = "1 2 3\n"
        with open(self.path("short.txt"), "w") as stream:
            stream.writelines(lines)
        with self.assertRaisesRegex(et.TrajectoryFormatError, r"short\.txt:7: 3 values"):
            et.read_trajectory(self.path("short.txt"))

    def test_loops_are_counted_by_reason_plotted_and_checked(self):
        write_kitti(self.path("truth.txt"), self.truth)
        header = ("query_frame,match_frame,time_gap_s,distance_m,distance_sigma_m,registered,"
                  "fitness_m2,correction_m,correction_deg,chi2_estimate,chi2_final,accepted,"
                  "reason\n")
        rows = ['900,100,80.0,0.5,1.0,1,0.05,0.3,0.2,3.1,1.2,1,"accepted"\n',
                '950,150,80.0,0.4,1.0,1,0.04,0.2,0.1,2.0,0.8,1,"accepted"\n',
                '1000,200,80.0,0.6,1.0,1,0.30,0.2,0.1,0.0,0.0,0,"fitness 0.300 m^2 > 0.200"\n',
                '1050,250,80.0,0.6,1.0,1,0.01,7.6,9.6,28.7,0.0,0,'
                '"inconsistent with the estimate: chi2 28.7 > 22.5 (7.60 m, 9.64 deg)"\n',
                '1100,300,80.0,0.6,1.0,1,0.02,0.3,0.2,5.0,40.1,0,'
                '"residual after the optimization: chi2 40.1 > 16.8"\n']
        with open(self.path("loops.csv"), "w") as stream:
            stream.writelines([header] + rows)
        code = et.main(["--estimate", self.path("truth.txt"), "--truth", self.path("truth.txt"),
                        "--loops", self.path("loops.csv"), "--json", self.path("out.json"),
                        "--plot", self.path("out.png")])
        self.assertEqual(code, 0)
        with open(self.path("out.json")) as stream:
            loops = json.load(stream)["loops"]
        self.assertEqual((loops["candidates"], loops["accepted"], loops["rejected"]), (5, 2, 3))
        self.assertEqual(loops["rejected_by_reason"],
                         {"fitness": 1, "inconsistent with the estimate": 1,
                          "residual after the optimization": 1})
        self.assertGreater(os.path.getsize(self.path("out.png")), 10000)
        # A frame beyond the trajectory, and a row that is not numbers: errors naming the line.
        for bad_row, message in (('5000,100,1,1,1,1,0.1,0,0,0,0,1,"accepted"\n', "outside"),
                                 ('x,100,1,1,1,1,0.1,0,0,0,0,1,"accepted"\n', "integer")):
            with open(self.path("bad.csv"), "w") as stream:
                stream.writelines([header, rows[0], bad_row])
            with self.assertRaisesRegex(et.TrajectoryFormatError, r"bad\.csv:3: .*" + message):
                et.read_loops(self.path("bad.csv"), len(self.truth))
            self.assertEqual(et.main(["--estimate", self.path("truth.txt"),
                                      "--truth", self.path("truth.txt"),
                                      "--loops", self.path("bad.csv")]), 2)

    def test_mismatched_lengths_are_an_error(self):
        write_kitti(self.path("truth.txt"), self.truth)
        shorter = et.Trajectory(self.truth.positions[:-5], self.truth.rotations[:-5])
        write_kitti(self.path("estimate.txt"), shorter)
        with self.assertRaisesRegex(et.TrajectoryFormatError, r"estimate\.txt has 1195 poses"):
            et.evaluate(et.read_trajectory(self.path("estimate.txt")),
                        et.read_trajectory(self.path("truth.txt")))
        self.assertEqual(et.main(["--estimate", self.path("estimate.txt"),
                                  "--truth", self.path("truth.txt")]), 2)

    def test_kitti_raw_timestamps_give_seconds(self):
        with open(self.path("timestamps.txt"), "w") as stream:
            stream.write("2011-09-30 12:40:25.563828560\n2011-09-30 12:40:25.663884440\n"
                         "2011-09-30 12:41:00.000000000\n")
        stamps = et.read_timestamps(self.path("timestamps.txt"))
        self.assertAlmostEqual(stamps[0], 1317386425.563828560, places=5)  # UTC, as the OXTS runs
        self.assertAlmostEqual(stamps[1] - stamps[0], 0.10005588, places=6)
        self.assertAlmostEqual(stamps[2] - stamps[0], 34.43617144, places=6)
        with open(self.path("times.txt"), "w") as stream:
            stream.write("12.5\nnot-a-time\n")
        with self.assertRaisesRegex(et.TrajectoryFormatError, r"times\.txt:2: not a timestamp"):
            et.read_timestamps(self.path("times.txt"))

    def test_states_header_and_rows_are_checked(self):
        with open(self.path("states.csv"), "w") as stream:
            stream.write("stamp,px,py,pz\n1,2,3,4\n")
        with self.assertRaisesRegex(et.TrajectoryFormatError, r"states\.csv:1: header lacks"):
            et.read_states(self.path("states.csv"))

    def test_compare_filters_reports_yaw_after_convergence(self):
        stamps = 0.1 * np.arange(len(self.truth))
        write_kitti(self.path("truth.txt"), self.truth)
        runs = []
        for name, decay_s in (("fast", 5.0), ("slow", 40.0)):
            # Yaw error 90 deg decaying exponentially: the slow one is still off at 60 s.
            rotations = [rotation_z(math.radians(90.0) * math.exp(-t / decay_s)) @ r
                         for t, r in zip(stamps, self.truth.rotations)]
            write_tum(self.path(name + ".tum"), et.Trajectory(self.truth.positions, rotations), stamps)
            runs.append("%s=%s" % (name, self.path(name + ".tum")))
        code = cf.main(["--truth", self.path("truth.txt"), "--after", "60", "--json",
                        self.path("compare.json"), "--plot", self.path("compare.png")] + runs)
        self.assertEqual(code, 0)
        with open(self.path("compare.json")) as stream:
            result = json.load(stream)
        fast, slow = result["runs"]["fast"], result["runs"]["slow"]
        self.assertAlmostEqual(fast["yaw_max_after_deg"], 90.0 * math.exp(-60.0 / 5.0), delta=1e-3)
        self.assertAlmostEqual(slow["yaw_max_after_deg"], 90.0 * math.exp(-60.0 / 40.0), delta=0.05)
        self.assertGreater(os.path.getsize(self.path("compare.png")), 10000)


if __name__ == "__main__":
    if "--gtest_output" in " ".join(sys.argv) or any(a.startswith("__name:=") for a in sys.argv):
        import rostest
        rostest.rosrun("inekf_semantic_mapping", "evaluate_trajectory", "__main__")
    else:
        unittest.main()
