#!/usr/bin/python3
"""rostest: two pipelines under two namespaces on one master (two_pipelines.test starts them).

Each pipeline gets its own bag, played with `rosbag play --prefix /<ns>` (its /tf, /tf_static and
sensor topics land in the namespace): car_a the 10 s synthetic drive, car_b its first 4 s. Each
map must hold exactly its own bag's scans (a map fed the other pipeline's data too would count
both), each filter must publish its own odometry, and /diagnostics must carry both pipelines'
statuses under their own names.
"""
import subprocess
import sys
import threading
import time
import unittest

import rosbag
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry

import e2e_support as e2e
from inekf_semantic_mapping.msg import SemanticMapInfo

NAMESPACES = ("car_a", "car_b")
VELODYNE = "/kitti/velo/pointcloud"


class TwoPipelines(unittest.TestCase):
    def test_each_map_fills_from_its_own_data_only(self):
        rospy.init_node("two_pipelines_test")
        p = e2e.param
        drive = e2e.synthetic_drive(p("duration", 10.0), seed=p("seed", 7),
                                    generator_args=p("generator_args", "").split())
        protocol = e2e.PROTOCOL_BAG_ARGS.split()
        bags = {"car_a": e2e.kitti2bag(drive, protocol),
                "car_b": e2e.kitti2bag(drive, protocol + ["--duration", str(p("duration_b", 4))])}
        scans_in_bag = {ns: rosbag.Bag(bag).get_message_count(topic_filters=[VELODYNE])
                        for ns, bag in bags.items()}
        self.assertNotEqual(scans_in_bag["car_a"], scans_in_bag["car_b"], scans_in_bag)

        lock = threading.Lock()
        info, odometry, diagnostics = {}, {ns: 0 for ns in NAMESPACES}, set()

        def on_info(message, ns):
            with lock:
                info[ns] = message

        def on_odometry(message, ns):
            with lock:
                odometry[ns] += 1

        def on_diagnostics(array):
            with lock:
                diagnostics.update(status.name for status in array.status)

        for ns in NAMESPACES:
            rospy.Subscriber("/%s/semantic_map/info" % ns, SemanticMapInfo, on_info, ns)
            rospy.Subscriber("/%s/inekf/odometry" % ns, Odometry, on_odometry, ns, queue_size=500)
        rospy.Subscriber("/diagnostics", DiagnosticArray, on_diagnostics, queue_size=50)
        needed = ["/%s%s" % (ns, topic) for ns in NAMESPACES
                  for topic in ("/kitti/oxts/imu", "/kitti/oxts/gps/fix", VELODYNE)]
        self.assertTrue(e2e.wait_for_subscribers(needed, timeout=60),
                        "the pipelines did not subscribe to %s" % needed)
        # car_b's bag without /clock (one clock per master: car_a's), started at the same instant:
        # both bags begin at the drive's first stamp. Both players wait 2 s after advertising
        # (rosbag's default 0.2 s): on a loaded machine the six subscriptions were not all
        # connected by then, and the first scans were lost before any node saw them.
        connect_s = "--delay=%g" % p("connect_delay_s", 2.0)
        player_b = subprocess.Popen(["rosbag", "play", "--quiet", connect_s, "--prefix", "/car_b",
                                     bags["car_b"]], stdout=subprocess.DEVNULL,
                                    stderr=subprocess.STDOUT)
        started = time.time()
        e2e.play_bag(bags["car_a"], extra_args=[connect_s, "--prefix", "/car_a"], timeout=120)
        player_b.wait(timeout=60)
        with e2e.ClockAfterBag(bags["car_a"]):
            # Lidar-only scans go in once label_wait_s (3 s) shows no label image will come.
            deadline = time.time() + 20
            while time.time() < deadline:
                with lock:
                    done = all(ns in info and info[ns].scans_inserted + info[ns].scans_without_pose
                               >= scans_in_bag[ns] for ns in NAMESPACES)
                if done:
                    break
                time.sleep(0.5)
            time.sleep(1.5)  # one more info message: nothing else arrives
        with lock:
            summary = {ns: (info[ns].scans_received, info[ns].scans_inserted,
                            info[ns].occupied_voxels) if ns in info else None
                       for ns in NAMESPACES}
            odometry_counts = dict(odometry)
            names = sorted(diagnostics)
        sys.stderr.write("two_pipelines: %.1f s of play; scans in bags %s; maps (received, "
                         "inserted, occupied voxels) %s; odometry %s; diagnostics %s\n"
                         % (time.time() - started, scans_in_bag, summary, odometry_counts, names))
        for ns in NAMESPACES:
            self.assertIsNotNone(summary[ns], "no /%s/semantic_map/info" % ns)
            received, inserted, voxels = summary[ns]
            self.assertEqual(received, scans_in_bag[ns], (ns, summary, scans_in_bag))
            self.assertGreaterEqual(inserted, 0.8 * scans_in_bag[ns], (ns, summary))
            self.assertGreater(voxels, 0, ns)
            self.assertGreater(odometry_counts[ns], 0, ns)
            for node in ("inekf_node", "semantic_octomap_node"):
                self.assertTrue(any(name.startswith("%s/%s:" % (ns, node)) or
                                    name.startswith("/%s/%s:" % (ns, node)) for name in names),
                                (ns, node, names))
        # car_b played 4 s of the 10: fewer poses than car_a.
        self.assertLess(odometry_counts["car_b"], odometry_counts["car_a"], odometry_counts)


if __name__ == "__main__":
    rostest.rosrun("inekf_semantic_mapping", "two_pipelines_test", TwoPipelines, sys.argv)
