#!/usr/bin/python3
"""End-to-end localization on a real KITTI OXTS drive from ../shared (IMU + GPS only).

kitti2bag converts the drive with the evaluation protocol's GPS (1.5 m / 3 m noise, 1 Hz), the bag is
played through inekf_node, and the odometry is compared with the OXTS ground truth. Skips loudly
(and passes) when ../shared is absent, as in a fresh clone.
"""
import os
import tempfile
import time
import unittest

import rospy
import rostest

import e2e_support as e2e

NAME = "e2e_real_oxts"


class EndToEndRealOxts(unittest.TestCase):
    def test_inekf_on_real_oxts_drive(self):
        rospy.init_node("e2e_real_oxts_test")
        p = e2e.param
        drive = os.path.join(e2e.shared_dir(), "data", "kitti_raw", p("drive", "2011_09_26/2011_09_26_drive_0036_sync"))
        if not os.path.isdir(os.path.join(drive, "oxts")):
            e2e.skip_loudly(self, "%s not found (../shared absent): real-data e2e test not run" % drive)
        e2e.require_executables(self, "kitti2bag", "inekf_node")
        bag = e2e.kitti2bag(drive, ["--calib-dir", os.path.dirname(drive)] +
                            p("bag_args", e2e.PROTOCOL_BAG_ARGS).split())
        monitor = e2e.pipeline_monitor.PipelineMonitor()
        self.assertTrue(e2e.wait_for_subscribers(["/kitti/oxts/imu", "/kitti/oxts/gps/fix"], 60),
                        "inekf_node did not subscribe")
        e2e.play_bag(bag, rate=p("rate", 8.0), timeout=300)
        time.sleep(1.0)
        out_dir = tempfile.mkdtemp(prefix="ism_%s_" % NAME)
        monitor.write(out_dir)
        estimate = e2e.metrics.read_tum(os.path.join(out_dir, "estimate_tum.txt"))
        truth = e2e.metrics.read_tum(os.path.join(out_dir, "truth_tum.txt"))
        errors = e2e.metrics.trajectory_errors(estimate, truth)
        rospy.loginfo("%s on %s: %s", NAME, drive, errors)
        self.assertGreater(errors["matched_poses"], 0.8 * len(truth), errors)
        self.assertTrue(errors["finite"])
        self.assertLess(errors["ate_rmse_m"], p("max_ate_m", 3.5), errors)
        self.assertLess(errors["rotation_rmse_deg"], p("max_rotation_rmse_deg", 2.5), errors)


if __name__ == "__main__":
    rostest.rosrun("inekf_semantic_mapping", NAME, EndToEndRealOxts)
