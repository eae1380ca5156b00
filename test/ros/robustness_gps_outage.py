#!/usr/bin/python3
"""Robustness: a 30 s GPS outage (made with kitti2bag --gps-outage) through inekf_node.

During the outage the filter must keep publishing finite odometry whose position covariance
grows (it knows it is dead reckoning) and whose error stays bounded and covered by that
covariance; after the GPS returns, the error must come back down.
"""
import math
import time
import unittest

import numpy as np
import rospy
import rostest
from nav_msgs.msg import Odometry

import e2e_support as e2e

NAME = "robustness_gps_outage"


class GpsOutage(unittest.TestCase):
    def test_outage_is_survived_and_recovered(self):
        rospy.init_node("robustness_gps_outage_test")
        p = e2e.param
        duration = p("duration", 48.0)
        outage_start, outage_length = p("outage_start_s", 8.0), p("outage_length_s", 30.0)
        drive = e2e.synthetic_drive(duration, seed=p("seed", 11), generator_args=p("generator_args", "").split())
        bag_args = (e2e.PROTOCOL_BAG_ARGS.split() +
                    ["--gps-outage", "%g:%g" % (outage_start, outage_length)] +
                    p("bag_args", "").split())
        bag = e2e.kitti2bag(drive, bag_args)

        estimate, truth = [], []  # (stamp, x, y, z, sigma_horizontal)
        def on_estimate(msg):
            c = msg.pose.covariance
            pos = msg.pose.pose.position
            estimate.append((msg.header.stamp.to_sec(), pos.x, pos.y, pos.z,
                             math.sqrt(max(0.0, c[0]) + max(0.0, c[7]))))
        def on_truth(msg):
            pos = msg.pose.pose.position
            truth.append((msg.header.stamp.to_sec(), pos.x, pos.y, pos.z, 0.0))
        rospy.Subscriber("/inekf/odometry", Odometry, on_estimate, queue_size=1000)
        rospy.Subscriber("/kitti/oxts/ground_truth", Odometry, on_truth, queue_size=1000)
        self.assertTrue(e2e.wait_for_subscribers(["/kitti/oxts/imu", "/kitti/oxts/gps/fix"], 60),
                        "inekf_node did not subscribe")
        e2e.play_bag(bag, rate=p("rate", 4.0), timeout=duration + 120)
        time.sleep(1.0)

        self.assertGreater(len(estimate), 5 * duration, "too few odometry messages: %d" % len(estimate))
        est = np.array(estimate)
        gt = np.array(truth)
        self.assertTrue(np.all(np.isfinite(est)), "non-finite odometry")
        t0 = gt[0, 0]
        # Match by nearest stamp (both are on the OXTS / IMU clock).
        idx = np.clip(np.searchsorted(gt[:, 0], est[:, 0]), 0, len(gt) - 1)
        errors = np.linalg.norm(est[:, 1:3] - gt[idx, 1:3], axis=1)
        rel = est[:, 0] - t0
        during = (rel > outage_start + 1) & (rel < outage_start + outage_length)
        before = (rel > outage_start - 3) & (rel < outage_start)
        end_of_outage = (rel > outage_start + outage_length - 2) & (rel < outage_start + outage_length)
        recovered = rel > outage_start + outage_length + p("recovery_s", 8.0)
        for name, mask in (("before", before), ("during", during), ("end", end_of_outage),
                           ("recovered", recovered)):
            self.assertGreater(mask.sum(), 3, "no odometry %s the outage (stamps %.1f..%.1f s)"
                               % (name, rel.min(), rel.max()))
        gaps = np.diff(est[during, 0])
        self.assertLess(gaps.max(), 1.0, "odometry stopped during the outage (gap %.2f s)" % gaps.max())
        sigma_before, sigma_end = est[before, 4].mean(), est[end_of_outage, 4].mean()
        self.assertGreater(sigma_end, 2.0 * sigma_before,
                           "covariance did not grow during the outage: sigma %.2f -> %.2f m"
                           % (sigma_before, sigma_end))
        max_error = errors[during].max()
        self.assertLess(max_error, p("max_outage_error_m", 100.0), "diverged during the outage")
        end_error = errors[end_of_outage].mean()
        self.assertLess(end_error, 4.0 * sigma_end + 2.0,
                        "overconfident: error %.1f m at the end of the outage, sigma %.1f m"
                        % (end_error, sigma_end))
        recovered_error = errors[recovered].mean()
        self.assertLess(recovered_error, p("max_recovered_error_m", 4.0),
                        "did not recover after the outage: %.1f m" % recovered_error)
        rospy.loginfo("%s: sigma %.2f -> %.2f m, max error during %.1f m, end %.1f m, recovered %.2f m",
                      NAME, sigma_before, sigma_end, max_error, end_error, recovered_error)


if __name__ == "__main__":
    rostest.rosrun("inekf_semantic_mapping", NAME, GpsOutage)
