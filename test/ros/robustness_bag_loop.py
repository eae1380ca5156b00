#!/usr/bin/python3
"""Robustness: the same bag played twice in a row, so /clock jumps back by the bag's length.

inekf_node must reset and localize the second pass as well as the first; the semantic map node
must keep inserting scans, and its saved map must load back.
"""
import os
import tempfile
import time
import unittest

import rospy
import rostest
from inekf_semantic_mapping.msg import FilterStatus

import e2e_support as e2e

NAME = "robustness_bag_loop"


class BagLoop(unittest.TestCase):
    def test_second_pass_after_time_jump(self):
        rospy.init_node("robustness_bag_loop_test")
        p = e2e.param
        duration, _, bag = e2e.synthetic_bag_from_params()
        monitor = e2e.pipeline_monitor.PipelineMonitor()
        statuses = []
        # The monitor subscribes to every topic as AnyMsg, and rospy shares one subscription a
        # topic: the messages may come raw.
        rospy.Subscriber("/inekf/status", FilterStatus,
                         lambda m: statuses.append(m if isinstance(m, FilterStatus)
                                                   else FilterStatus().deserialize(m._buff)),
                         queue_size=100)
        self.assertTrue(e2e.wait_for_subscribers(["/kitti/oxts/imu", "/kitti/velo/pointcloud"], 60),
                        "nodes did not subscribe")
        e2e.play_bag(bag, rate=p("rate", 1.0), timeout=10 * duration + 60)
        with e2e.ClockAfterBag(bag):
            time.sleep(1.0)
        first = monitor.summary()
        clouds_after_first = first["topics"]["/semantic_map/labeled_cloud"]["messages"]
        odometry_after_first = first["topics"]["/inekf/odometry"]["messages"]
        e2e.play_bag(bag, rate=p("rate", 1.0), timeout=10 * duration + 60)
        clock = e2e.ClockAfterBag(bag).__enter__()
        self.addCleanup(clock.__exit__)
        time.sleep(2.0)
        out_dir = tempfile.mkdtemp(prefix="ism_%s_" % NAME)
        summary = monitor.write(out_dir)

        self.assertGreater(summary["estimate_time_jumps_back"], 0,
                           "no /inekf/odometry after the clock jumped back")
        second_pass_odometry = summary["topics"]["/inekf/odometry"]["messages"] - odometry_after_first
        self.assertGreater(second_pass_odometry, 0.5 * odometry_after_first,
                           "inekf_node stopped after the time jump: %d then %d poses"
                           % (odometry_after_first, second_pass_odometry))
        estimate = e2e.metrics.read_tum(os.path.join(out_dir, "estimate_tum.txt"))
        truth = e2e.metrics.read_tum(os.path.join(out_dir, "truth_tum.txt"))
        second = e2e.metrics.trajectory_errors(estimate, truth)  # last pass only
        self.assertTrue(second.get("finite", False), second)
        self.assertGreater(second["matched_poses"], 5 * duration, second)
        self.assertLess(second["ate_rmse_m"], p("max_ate_m", 3.0),
                        "second pass not localized (did the filter reset?): %s" % second)
        # One loop, one reset: the clock's jump and the stamps' are the same event (each reset
        # clears the filter and the path; two or three a loop lost the new loop's start).
        self.assertTrue(statuses, "no /inekf/status")
        self.assertEqual(statuses[-1].resets, 1, "resets after one loop")
        clouds_second = summary["topics"]["/semantic_map/labeled_cloud"]["messages"] - clouds_after_first
        self.assertGreater(clouds_second, 0, "semantic_octomap_node stopped after the time jump")

        path = os.path.join(out_dir, "after_loop.ply")
        response = e2e.save_map(path, "ply")
        self.assertTrue(response.success, response.message)
        vertices = e2e.metrics.read_ply_vertices(path)
        self.assertEqual(len(vertices), response.voxel_count)
        self.assertGreater(len(vertices), 0)
        rospy.loginfo("%s: second pass %s, clouds %d + %d", NAME, second, clouds_after_first, clouds_second)


if __name__ == "__main__":
    rostest.rosrun("inekf_semantic_mapping", NAME, BagLoop)
