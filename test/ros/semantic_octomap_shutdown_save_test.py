#!/usr/bin/python3
"""rostest: semantic_octomap_node stopped with SIGINT (Ctrl-C) while three scans wait for label
images that will never come (the end of a bag: the clock stops). The autosave written at shutdown
must hold them: a map of the wall they see, not an empty file or none.

Parameters (private): `stop_node`, the node to send SIGINT (the map node itself by default, or the
nodelet manager that runs it); `stderr_log`, where that process's stderr goes: when given, its
last lines must say what went into the map and where it was saved (a manager's Ctrl-C shuts
rosconsole down before it unloads the nodelet)."""
import os
import signal
import time
import unittest

import rospy
import rostest

import e2e_support as e2e
from semantic_octomap_node_test import CameraRig, camera_info, label_image, wall_cloud

NODE = "/semantic_octomap_node"


class ShutdownSaveTest(unittest.TestCase):
    def test_scans_waiting_at_shutdown_are_in_the_autosave(self):
        rospy.init_node("semantic_octomap_shutdown_save_test")
        stop_node = rospy.get_param("~stop_node", NODE)
        stderr_log = rospy.get_param("~stderr_log", "")
        path = rospy.get_param(NODE + "/autosave_path")
        self.addCleanup(lambda: os.path.exists(path) and os.remove(path))
        rig = CameraRig()
        info_pub, cloud_pub, labels_pub = rig.info_pub, rig.cloud_pub, rig.labels_pub
        rospy.wait_for_service(NODE + "/save_map", timeout=30)
        deadline = time.time() + 20
        while (cloud_pub.get_num_connections() == 0 or labels_pub.get_num_connections() == 0) \
                and time.time() < deadline:
            time.sleep(0.1)
        info_pub.publish(camera_info())
        time.sleep(0.5)
        # A label image first: the node now expects one per scan and holds the later scans for
        # theirs (label_wait_s 30 s).
        labels_pub.publish(label_image(rospy.Time.now()))
        time.sleep(0.3)
        for _ in range(3):
            cloud_pub.publish(wall_cloud(rospy.Time.now()))
            time.sleep(0.2)
        time.sleep(1.0)
        before = e2e.save_map(path + ".before.ot", "ot")
        self.addCleanup(lambda: os.path.exists(path + ".before.ot")
                        and os.remove(path + ".before.ot"))
        self.assertTrue(before.success, before.message)
        self.assertEqual(before.voxel_count, 0,
                         "the scans should still be waiting for their label images: "
                         + before.message)
        self.assertFalse(os.path.exists(path), "autosave before shutdown (period 0 = none)")

        e2e.kill_node(stop_node, signal.SIGINT)
        deadline = time.time() + 30
        while not os.path.exists(path) and time.time() < deadline:
            time.sleep(0.1)
        self.assertTrue(os.path.exists(path), "no autosave at shutdown: " + path)
        saved = e2e.check_ot_file(path)  # the save is atomic: complete once it is there
        # The wall (8 m x 2.5 m at 0.2 m) is about 500 occupied voxels; the tree's inner nodes
        # come on top.
        self.assertGreater(saved["size"], 400, saved)
        if stderr_log:
            self.addCleanup(lambda: os.path.exists(stderr_log) and os.remove(stderr_log))
            expected = ["finishing: 3 of 3 waiting scans put in the map",
                        "map saved to %s (3 scans)" % path]
            deadline = time.time() + 10
            text = ""
            while time.time() < deadline:
                with open(stderr_log) as log:
                    text = log.read()
                if all(line in text for line in expected):
                    break
                time.sleep(0.1)
            for line in expected:
                self.assertIn(line, text, "the last lines of %s's stderr" % stop_node)


if __name__ == "__main__":
    rostest.rosrun("inekf_semantic_mapping", "semantic_octomap_shutdown_save_test",
                   ShutdownSaveTest)
