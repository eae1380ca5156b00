#!/usr/bin/python3
"""End-to-end regression on a short synthetic drive (e2e_synthetic.test starts the nodes).

Generates a short synthetic drive, converts it with kitti2bag (GPS degraded as in the evaluation
protocol), plays it through inekf_node + segmentation_node + semantic_octomap_node, then
asserts: the odometry follows the ground truth, every stage produced output for most inputs,
~save_map writes a .ot and a .ply that load back with the expected classes, the map's mIoU
against the generator's ground truth is above a margin, and the 2D grids
(/semantic_map/drivable_map, /semantic_map/projected_map) call the true road drivable and the
true buildings occupied.
"""
import json
import os
import tempfile
import time
import unittest

import numpy as np
import rospy
import rostest
from nav_msgs.msg import OccupancyGrid

import e2e_support as e2e
import evaluate_grid  # scripts/ (on the path through e2e_support)

NAME = "e2e_synthetic"


class EndToEndSynthetic(unittest.TestCase):
    results = None
    failure = None

    @classmethod
    def setUpClass(cls):
        rospy.init_node("e2e_synthetic_test")
        try:
            cls.results = cls.run_pipeline()
        except Exception as error:  # pylint: disable=broad-except
            cls.failure = "%s: %s" % (type(error).__name__, error)

    @classmethod
    def run_pipeline(cls):
        p = e2e.param
        duration, drive, bag = e2e.synthetic_bag_from_params()
        out_dir = tempfile.mkdtemp(prefix="ism_%s_" % NAME)
        monitor = e2e.pipeline_monitor.PipelineMonitor()
        # The node builds the grids only while someone subscribes: subscribe before the bag.
        grids = {}
        for topic in ("/semantic_map/drivable_map", "/semantic_map/projected_map"):
            rospy.Subscriber(topic, OccupancyGrid,
                             lambda msg, topic=topic: grids.__setitem__(topic, msg))
        diagnostics = e2e.DiagnosticsRecorder()
        needed = ["/kitti/oxts/imu", "/kitti/oxts/gps/fix", "/kitti/velo/pointcloud",
                  "/kitti/camera_color_left/image_raw", "/segmentation/labels"]
        if not e2e.wait_for_subscribers(needed, timeout=60):
            raise RuntimeError("nodes did not subscribe to %s within 60 s" % needed)
        started = time.time()
        e2e.play_bag(bag, rate=p("rate", 1.0), timeout=10 * duration + 60)
        play_wall_s = time.time() - started
        results = {"drive": drive, "bag": bag, "out_dir": out_dir, "play_wall_s": play_wall_s,
                   "saves": {}}
        with e2e.ClockAfterBag(bag):
            time.sleep(p("settle_s", 3.0))  # let the last scans reach the map
            for fmt in ("ot", "ply"):
                path = os.path.join(out_dir, "semantic_map." + fmt)
                response = e2e.save_map(path, fmt)
                results["saves"][fmt] = {"path": path, "success": response.success,
                                         "message": response.message, "voxel_count": response.voxel_count}
        results["diagnostics"] = diagnostics.summary()
        summary = monitor.write(out_dir)
        results["monitor"] = summary
        estimate = e2e.metrics.read_tum(os.path.join(out_dir, "estimate_tum.txt"))
        truth = e2e.metrics.read_tum(os.path.join(out_dir, "truth_tum.txt"))
        results["trajectory"] = e2e.metrics.trajectory_errors(estimate, truth)
        bag_counts, _ = e2e.metrics.bag_message_counts(bag)
        results["messages"] = e2e.metrics.rates_and_drops(summary, bag_counts)
        ply = results["saves"]["ply"]["path"]
        if os.path.exists(ply):
            vertices = e2e.metrics.read_ply_vertices(ply)
            results["map_classes"] = e2e.metrics.map_class_histogram(vertices)
            gt_dir = e2e.ground_truth_dir(drive)
            # Ground-truth points placed with the poses the map was built with (the estimate).
            poses = e2e.metrics.estimated_frame_poses(estimate, truth)
            results["map_miou"] = (e2e.metrics.map_miou(results["saves"]["ot"]["path"], gt_dir,
                                                        poses=poses) if gt_dir else None)
            results["grids"] = cls.score_grids(grids, gt_dir, poses) if gt_dir else None
        with open(os.path.join(out_dir, "results.json"), "w") as f:
            json.dump(results, f, indent=2, default=str)
        rospy.loginfo("%s results: %s", NAME, json.dumps({k: results.get(k) for k in
                      ("trajectory", "map_miou", "grids", "saves", "play_wall_s")}, default=str))
        return results

    @staticmethod
    def score_grids(grids, gt_dir, poses):
        """evaluate_grid's figures of the last grids received (None if one never came)."""
        drivable = grids.get("/semantic_map/drivable_map")
        projected = grids.get("/semantic_map/projected_map")
        if drivable is None or projected is None:
            return None

        def cells(msg):
            return np.array(msg.data, dtype=np.int8).reshape(msg.info.height, msg.info.width)

        if (drivable.info.width, drivable.info.height) != (projected.info.width, projected.info.height):
            raise RuntimeError("the two grids differ in size")
        return evaluate_grid.score_grids(cells(drivable), cells(projected), drivable.info.resolution,
                                         drivable.info.origin.position.x,
                                         drivable.info.origin.position.y, gt_dir, poses=poses)

    def setUp(self):
        if self.failure:
            self.fail("pipeline run failed: " + self.failure)

    def test_odometry_follows_ground_truth(self):
        trajectory = self.results["trajectory"]
        self.assertGreater(trajectory["matched_poses"], 5 * rospy.get_param("~duration", 12.0),
                           "too few /inekf/odometry poses matched to the ground truth: %s" % trajectory)
        self.assertTrue(trajectory["finite"])
        self.assertLess(trajectory["ate_rmse_m"], rospy.get_param("~max_ate_m", 3.0), trajectory)
        self.assertLess(trajectory["rotation_rmse_deg"], rospy.get_param("~max_rotation_rmse_deg", 3.0),
                        trajectory)

    def test_every_stage_keeps_up(self):
        messages = self.results["messages"]
        topics = messages["topics"]
        scans = topics["/kitti/velo/pointcloud"]["messages"]
        images = topics["/kitti/camera_color_left/image_raw"]["messages"]
        self.assertGreater(scans, 0, "no scan reached the pipeline: %s" % messages)
        min_fraction = rospy.get_param("~min_processed_fraction", 0.5)
        # The segmentation node drops stale frames by design; the map needs labels for a scan.
        self.assertGreaterEqual(topics["/segmentation/labels"]["messages"], min_fraction * images, messages)
        self.assertGreaterEqual(topics["/semantic_map/labeled_cloud"]["messages"], min_fraction * scans * 0.5,
                                messages)
        self.assertEqual(messages["dropped"].get("scans_in_bag_not_received", 0), 0, messages)

    def test_every_node_reports_its_health_on_diagnostics(self):
        statuses = self.results["diagnostics"]
        for node in ("inekf_node", "segmentation_node", "semantic_octomap_node"):
            mine = {name: s for name, s in statuses.items() if name.startswith("/" + node + ":")
                    or name.startswith(node + ":")}
            self.assertTrue(mine, "no /diagnostics status from %s: %s" % (node, sorted(statuses)))
            for name, status in mine.items():
                self.assertGreaterEqual(status["min_values"], 3, (name, status))
                self.assertLess(status["max_level"], 2, "%s at ERROR during the run: %s"
                                % (name, status))

    def test_saved_maps_load_back(self):
        for fmt, save in self.results["saves"].items():
            self.assertTrue(save["success"], "save_map %s failed: %s" % (fmt, save["message"]))
            self.assertGreater(save["voxel_count"], 1000, save)
            self.assertTrue(os.path.getsize(save["path"]) > 0)
        header = e2e.check_ot_file(self.results["saves"]["ot"]["path"])
        self.assertGreater(header["size"], 0)
        vertices = e2e.metrics.read_ply_vertices(self.results["saves"]["ply"]["path"])
        self.assertEqual(len(vertices), self.results["saves"]["ply"]["voxel_count"])
        for field in ("x", "y", "z", "label", "red", "green", "blue"):
            self.assertIn(field, vertices.dtype.names)

    def test_map_has_expected_classes(self):
        classes = self.results["map_classes"]
        total = sum(classes.values())
        # Cityscapes labelIds: road 7, building 11, vegetation 21 are large in every synthetic town.
        for label_id, name in ((7, "road"), (11, "building"), (21, "vegetation")):
            self.assertGreater(classes.get(label_id, 0), 0.01 * total,
                               "class %s (labelId %d) missing from the map: %s" % (name, label_id, classes))

    def test_map_miou_above_margin(self):
        miou = self.results.get("map_miou")
        if miou is None:
            e2e.skip_loudly(self, "no synthetic ground truth to compute map mIoU")
        self.assertGreater(miou["miou"], rospy.get_param("~min_miou", 0.35), miou)
        self.assertGreater(miou["accuracy"], rospy.get_param("~min_accuracy", 0.75), miou)
        # Scans that went in without labels leave their voxels classless: fewer points covered.
        self.assertGreater(miou["coverage"], rospy.get_param("~min_coverage", 0.3), miou)
        self.assertGreater(miou["map_voxels_hit"], 0.4 * miou["map_voxels"],
                           "most map voxels should sit where labeled ground-truth points are: %s" % miou)


    def test_grids_call_the_road_drivable_and_the_buildings_occupied(self):
        if not e2e.ground_truth_dir(self.results["drive"]):
            e2e.skip_loudly(self, "no synthetic ground truth to score the grids")
        grids = self.results.get("grids")
        self.assertIsNotNone(grids, "no /semantic_map/drivable_map or /semantic_map/projected_map")
        road, other = grids["truth_drivable"], grids["truth_not_drivable"]
        self.assertGreater(road["known"], 1000, grids)
        self.assertGreater(road["marked_drivable_of_known"], rospy.get_param("~min_road_drivable", 0.5),
                           grids)
        self.assertGreater(other["marked_occupied_of_known"],
                           rospy.get_param("~min_other_not_drivable", 0.85), grids)
        self.assertGreater(grids["projected_occupied_of_known"].get("building", 0.0),
                           rospy.get_param("~min_building_occupied", 0.4), grids)
        self.assertLess(grids["projected_occupied_of_known"].get("road", 1.0),
                        rospy.get_param("~max_road_occupied", 0.25), grids)


if __name__ == "__main__":
    rostest.rosrun("inekf_semantic_mapping", NAME, EndToEndSynthetic)
