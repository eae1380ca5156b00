#!/usr/bin/python3
"""rostest: semantic_octomap_node when the sim clock stops, as at the end of `rosbag play
--clock`. A scan whose label image never came used to wait for one more second of data time,
that is for ever: it was missing from the map, and from a map saved then, until shutdown. Now it
goes in after two wall seconds of a stopped clock; its label image, when it still comes, is
added to it; a scan with no pose in tf waits on and the map diagnostics say so (WARN).
Wall-clock waits throughout: rospy's own sleeps would stop with the clock."""
import threading
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rosgraph_msgs.msg import Clock

from inekf_semantic_mapping.msg import SemanticMapInfo
from semantic_octomap_node_test import CameraRig, camera_info, label_image, wall_cloud

NODE = "/semantic_octomap_node"
MAP_STATUS = "semantic_octomap_node: map"


class ClockStoppedTest(unittest.TestCase):
    def test_scans_go_in_when_the_clock_stops_and_a_scan_without_pose_is_reported(self):
        rospy.init_node("semantic_octomap_clock_stopped_test")
        lock = threading.Lock()
        state = {"clock": 100.0, "info": None, "map_status": None, "stop": False}
        clock_pub = rospy.Publisher("/clock", Clock, queue_size=1)

        def run_clock():  # the clock as rosbag play --clock gives it, at 50 Hz wall
            while not state["stop"] and not rospy.is_shutdown():
                with lock:
                    now = state["clock"]
                clock_pub.publish(Clock(clock=rospy.Time.from_sec(now)))
                time.sleep(0.02)

        def on_info(msg):
            with lock:
                state["info"] = msg

        def on_diagnostics(msg):
            for status in msg.status:
                if status.name == MAP_STATUS:
                    with lock:
                        state["map_status"] = status

        clock_thread = threading.Thread(target=run_clock, daemon=True)
        clock_thread.start()
        self.addCleanup(state.update, stop=True)
        info_subscriber = rospy.Subscriber("/semantic_map/info", SemanticMapInfo, on_info)
        rospy.Subscriber("/diagnostics", DiagnosticArray, on_diagnostics)
        rig = CameraRig()
        info_pub, cloud_pub, labels_pub = rig.info_pub, rig.cloud_pub, rig.labels_pub

        def wait_until(predicate, timeout_s):
            deadline = time.time() + timeout_s
            while time.time() < deadline:
                with lock:
                    if predicate(state):
                        return True
                time.sleep(0.1)
            return False

        connected = lambda s: (cloud_pub.get_num_connections() > 0 and
                               labels_pub.get_num_connections() > 0)
        self.assertTrue(wait_until(connected, 30), "semantic_octomap_node did not subscribe")
        info_pub.publish(camera_info())
        time.sleep(0.5)
        stamp = rospy.Time.from_sec(100.0)
        cloud_pub.publish(wall_cloud(stamp))
        labels_pub.publish(label_image(stamp))
        self.assertTrue(wait_until(lambda s: s["info"] and s["info"].scans_inserted >= 1, 10),
                        "the first scan, with its labels, did not go in: %s" % state["info"])

        # The last scan of the "bag": its label image has not come when the clock stops.
        last = rospy.Time.from_sec(100.3)
        with lock:
            state["clock"] = 100.3
        cloud_pub.publish(wall_cloud(last))
        time.sleep(0.3)
        with lock:
            state["clock"] = 100.4  # and there it stays
        stopped_at = time.time()
        self.assertTrue(wait_until(lambda s: s["info"].scans_inserted >= 2, 8),
                        "the scan waiting for its label image stayed out of the map under a "
                        "stopped clock: %s" % state["info"])
        waited_s = time.time() - stopped_at
        self.assertGreater(waited_s, 1.0, "went in before the clock had stood still")
        with lock:
            self.assertEqual(state["info"].scans_with_labels, 1, state["info"])
        # Its label image, late (a segmentation still working on the last frames): added to it.
        labels_pub.publish(label_image(last))
        self.assertTrue(wait_until(lambda s: s["info"].label_images_late >= 1, 8),
                        "the late label image did not reach its scan: %s" % state["info"])
        with lock:
            self.assertEqual(state["info"].scans_with_labels, 2, state["info"])

        # A scan in a frame tf does not know: it waits for a pose, and the diagnostics say so.
        orphan = wall_cloud(rospy.Time.from_sec(100.4))
        orphan.header.frame_id = "velo_unknown"
        cloud_pub.publish(orphan)
        waiting = lambda s: (s["map_status"] is not None and
                             s["map_status"].level == DiagnosticStatus.WARN and
                             "1 scans waiting" in s["map_status"].message)
        self.assertTrue(wait_until(waiting, 10),
                        "no WARN for the scan waiting for its pose: %s" % state["map_status"])
        with lock:
            values = {v.key: v.value for v in state["map_status"].values}
            self.assertEqual(values["pending scans"], "1")
            self.assertGreater(float(values["oldest pending scan waiting (s)"]), 1.0)
            self.assertEqual(state["info"].scans_inserted, 2, state["info"])

        # The info is published only while someone listens: latched, a one-shot read after the
        # map changed unheard gave the old figures. Now a new subscriber gets the current ones.
        info_subscriber.unregister()
        cloud_pub.publish(wall_cloud(rospy.Time.from_sec(100.4)))
        time.sleep(4.0)  # a stopped clock: in after 2 s
        fresh = rospy.wait_for_message("/semantic_map/info", SemanticMapInfo, timeout=5)
        self.assertEqual(fresh.scans_inserted, 3, fresh)


if __name__ == "__main__":
    rostest.rosrun("inekf_semantic_mapping", "semantic_octomap_clock_stopped_test",
                   ClockStoppedTest)
