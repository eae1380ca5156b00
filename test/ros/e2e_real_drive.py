#!/usr/bin/python3
"""End to end on a real KITTI drive with lidar and camera (../shared): kitti2bag -> inekf_node ->
segmentation_node (the Cityscapes ENet from ../shared) -> semantic_octomap_node, at rate 1.0.

Asserts that every scan updates the map (the map does not wait for segmentation), that the label
images segmentation published went into the map, and that the labels make sense for a street:
road is the most common class on the ground around the car, and road, building, vegetation and
car are all in the map. The pipeline is started by this node (not by the .test file) so that the
test can skip loudly, and pass as skipped, when ../shared or the ENet is absent: a node that
fails to load a missing model would otherwise end the launch as a failure.
"""
import os
import subprocess
import sys
import tempfile
import time
import unittest

import numpy as np
import rospy
import rostest

import e2e_support as e2e

NAME = "e2e_real_drive"
# Cityscapes labelIds (segmentation_node's output and the PLY's label column).
ROAD, VEGETATION, CAR = 7, 21, 26
# Classes every run maps on this drive (a road between vegetation, cars parked and driving).
# Buildings are few and far: whether one lands in a labelled frame depends on which images ENet
# had time for (2 to 130 voxels over runs), so they are not required.
CLASS_NAMES = {ROAD: "road", VEGETATION: "vegetation", CAR: "car"}


def first_oxts_fix(drive):
    """lat lon alt of the drive's first OXTS frame: the map origin of the ground truth."""
    first = sorted(os.listdir(os.path.join(drive, "oxts", "data")))[0]
    with open(os.path.join(drive, "oxts", "data", first)) as f:
        return f.read().split()[:3]


def ground_band_labels(vertices, trajectory, below_min_m, below_max_m, max_distance_m):
    """Labels of the map voxels that lie on the ground around the driven path: within
    max_distance_m (horizontally) of the nearest pose and between below_min_m and below_max_m
    below it (the OXTS unit rides about 0.93 m above the road). The poses must be the ones the
    map was built with (the estimate): the GPS's vertical noise moves the whole map up or down."""
    xyz = np.stack([vertices["x"], vertices["y"], vertices["z"]], axis=1).astype(float)
    poses = trajectory[:, 1:4]
    nearest = np.empty(len(xyz), dtype=int)
    best = np.full(len(xyz), np.inf)
    for i, pose in enumerate(poses):
        d = np.sum((xyz[:, :2] - pose[:2]) ** 2, axis=1)
        closer = d < best
        best[closer] = d[closer]
        nearest[closer] = i
    below = poses[nearest, 2] - xyz[:, 2]
    keep = (np.sqrt(best) < max_distance_m) & (below > below_min_m) & (below < below_max_m)
    return vertices["label"][keep].astype(int)


class EndToEndRealDrive(unittest.TestCase):
    def test_real_drive_through_the_whole_pipeline(self):
        rospy.init_node("e2e_real_drive_test")
        p = e2e.param
        drive = os.path.join(e2e.shared_dir(), "data", "kitti_raw",
                             p("drive", "2011_09_26/2011_09_26_drive_0013_sync"))
        model = os.path.join(e2e.shared_dir(), p("model", "models/enet-cityscapes/enet-model.net"))
        for needed in ("oxts", "velodyne_points", "image_02"):
            if not os.path.isdir(os.path.join(drive, needed)):
                e2e.skip_loudly(self, "%s not found (../shared absent?): real-drive e2e test not run" %
                     os.path.join(drive, needed))
        if not os.path.isfile(model):
            e2e.skip_loudly(self, "the Cityscapes ENet %s not found (third-party, not in the repository): "
                       "real-drive e2e test not run" % model)
        e2e.require_executables(self, "kitti2bag", "inekf_node", "segmentation_node",
                                "semantic_octomap_node")
        bag = e2e.kitti2bag(drive, ["--calib-dir", os.path.dirname(drive)] +
                            p("bag_args", e2e.PROTOCOL_BAG_ARGS).split())
        counts, bag_duration = e2e.metrics.bag_message_counts(bag)
        scans_played = counts.get(e2e.pipeline_monitor.SCAN_TOPIC, 0)
        self.assertGreater(scans_played, 0, "no scans in %s" % bag)

        out_dir = tempfile.mkdtemp(prefix="ism_%s_" % NAME)
        lat, lon, alt = first_oxts_fix(drive)
        launch_log = open(os.path.join(out_dir, "launch.log"), "w")
        launch = subprocess.Popen(
            ["roslaunch", os.path.join(e2e.REPO_ROOT, "launch", "include", "pipeline.launch"),
             "model:=" + model, "rviz:=false", "output:=screen", "required:=true",
             "origin_lat:=" + lat, "origin_lon:=" + lon, "origin_alt:=" + alt],
            stdout=launch_log, stderr=subprocess.STDOUT)

        self.addCleanup(e2e.stop_process, launch, launch_log)

        def launch_tail():
            launch_log.flush()
            with open(launch_log.name) as f:
                return f.read()[-3000:]

        monitor = e2e.pipeline_monitor.PipelineMonitor()
        diagnostics = e2e.DiagnosticsRecorder()
        needed = ["/kitti/oxts/imu", "/kitti/oxts/gps/fix", "/kitti/velo/pointcloud",
                  "/kitti/camera_color_left/image_raw", "/segmentation/labels"]
        self.assertTrue(e2e.wait_for_subscribers(needed, timeout=p("start_timeout_s", 40)),
                        "the nodes did not subscribe to %s; launch log:\n%s" % (needed, launch_tail()))
        started = time.time()
        # play_bag waits for the subscribers' connections after advertising: the first fix (the
        # filter's start) and the first scans would otherwise be lost.
        e2e.play_bag(bag, rate=p("rate", 1.0), timeout=10 * bag_duration + 60)
        play_wall_s = time.time() - started

        def labels_published():
            return monitor.summary()["topics"]["/segmentation/labels"]["messages"]

        with e2e.ClockAfterBag(bag):
            # The last images are still being segmented, the last scans wait (label_wait_s, data
            # time) for label images that will not come: wait until every scan is either in the
            # map or dropped and every label image published has reached the map node.
            def settled():
                info = monitor.latest_map_info()
                return (info is not None and
                        info["scans_inserted"] + info["scans_without_pose"] >= scans_played and
                        info["label_images_received"] >= labels_published())
            e2e.wait_until(settled, timeout=p("settle_timeout_s", 20.0), period=0.5)
            ply_path = os.path.join(out_dir, "semantic_map.ply")
            response = e2e.save_map(ply_path, "ply")
        statuses = diagnostics.summary()
        self.assertIsNone(launch.poll(), "a node died; launch log:\n" + launch_tail())
        self.assertTrue(response.success, response.message)
        summary = monitor.write(out_dir)
        info = summary["map_info"]
        labels = summary["topics"]["/segmentation/labels"]
        images = summary["topics"][e2e.pipeline_monitor.IMAGE_TOPIC]["messages"]

        # Figures for the record (the test log), whatever the assertions say.
        estimate = e2e.metrics.read_tum(os.path.join(out_dir, "estimate_tum.txt"))
        truth = e2e.metrics.read_tum(os.path.join(out_dir, "truth_tum.txt"))
        trajectory = e2e.metrics.trajectory_errors(estimate, truth)
        vertices = e2e.metrics.read_ply_vertices(ply_path)
        histogram = e2e.metrics.map_class_histogram(vertices)
        # The road surface under and beside the car: 0.65..1.25 m below the OXTS unit (not the
        # lower half of the cars ahead), within 4 m of the path (the lane driven and the next
        # one; the lawns beside this drive's road lie further out).
        ground = ground_band_labels(vertices, estimate, p("ground_below_min_m", 0.65),
                                    p("ground_below_max_m", 1.25), p("ground_max_distance_m", 4.0))
        ground_ids, ground_counts = np.unique(ground[ground != 0], return_counts=True)
        ground_histogram = {int(k): int(n) for k, n in zip(ground_ids, ground_counts)}
        record = {
            "play_wall_s": round(play_wall_s, 1), "scans_played": scans_played,
            "info": info,
            "camera_images": images, "labels_published": labels["messages"],
            "label_images_per_wall_s": labels.get("wall_rate_hz"),
            "scan_to_map_latency_s": summary.get("scan_to_map_latency_s"),
            "image_to_labels_latency_s": summary.get("image_to_labels_latency_s"),
            "trajectory": trajectory, "ply_voxels": int(len(vertices)),
            "map_classes": {e2e.metrics.CITYSCAPES_NAMES.get(k, k): n for k, n in histogram.items()},
            "ground_classes": {e2e.metrics.CITYSCAPES_NAMES.get(k, k): n
                               for k, n in ground_histogram.items()},
            "diagnostics": {name: (status["max_level"], status["min_values"])
                            for name, status in statuses.items()},
            "out_dir": out_dir,
        }
        rospy.loginfo("%s: %s", NAME, record)
        sys.stderr.write("\n%s figures: %s\n" % (NAME, record))

        self.assertIsNotNone(info, "no SemanticMapInfo on /semantic_map/info: %s" % record)
        # The map fills from every scan: it does not wait for (or depend on) segmentation.
        self.assertGreaterEqual(info["scans_received"], scans_played, record)
        self.assertGreaterEqual(info["scans_inserted"], p("min_inserted_fraction", 0.95) * scans_played,
                                record)
        # Segmentation ran, and what it published went into the map.
        self.assertGreater(labels["messages"], 0, "segmentation_node published no labels: %s" % record)
        self.assertGreater(info["label_images_used"], 0, record)
        self.assertGreater(info["scans_with_labels"], 0, record)
        self.assertGreaterEqual(info["label_images_received"], labels["messages"], record)
        # Every label image is used (late ones as class evidence only), except those of scans
        # that never had a pose (before inekf_node's first estimate) and so never went in.
        self.assertGreaterEqual(info["label_images_used"],
                                labels["messages"] - info["scans_without_pose"]
                                - p("max_label_images_unused", 0), record)
        # The labels make sense for a street.
        self.assertTrue(ground_histogram, "no labelled voxels on the ground around the path: %s" % record)
        most_common_on_ground = max(ground_histogram, key=ground_histogram.get)
        self.assertEqual(most_common_on_ground, ROAD,
                         "the ground around the car is mostly %s, not road: %s" % (
                             e2e.metrics.CITYSCAPES_NAMES.get(most_common_on_ground), record))
        min_voxels = p("min_class_voxels", 5)
        for label, name in sorted(CLASS_NAMES.items()):
            self.assertGreaterEqual(histogram.get(label, 0), min_voxels,
                                    "%s: %d voxels (< %d): %s" % (name, histogram.get(label, 0),
                                                                  min_voxels, record))
        # Each main node reports its health on /diagnostics: several figures, never ERROR on a
        # normal drive (WARN may come and go, e.g. labels late while ENet warms up).
        for node in ("inekf_node", "segmentation_node", "semantic_octomap_node"):
            mine = {name: st for name, st in statuses.items()
                    if name.lstrip("/").startswith(node + ":")}
            self.assertTrue(mine, "no /diagnostics status from %s: %s" % (node, sorted(statuses)))
            for name, status in mine.items():
                self.assertGreaterEqual(status["min_values"], 3, (name, status))
                self.assertLess(status["max_level"], 2, "%s at ERROR during the drive: %s"
                                % (name, record))
        # Localization is the same as in the other real-drive tests; a loose bound catches a
        # broken frame or origin, not a small regression.
        self.assertTrue(trajectory.get("finite"), record)
        self.assertGreater(trajectory["matched_poses"], 0.8 * len(truth), record)
        self.assertLess(trajectory["ate_rmse_m"], p("max_ate_m", 5.0), record)


if __name__ == "__main__":
    rostest.rosrun("inekf_semantic_mapping", NAME, EndToEndRealDrive)
