#!/usr/bin/python3
"""rostest: semantic_octomap_node maps scans when no label image comes for a whole ~label_wait_s
(lidar-only runs); the voxels carry no class (PLY label 0, markers 'unlabeled')."""
import os
import shutil
import tempfile
import threading
import unittest

import rospy
import rostest
import tf2_ros
from sensor_msgs.msg import PointCloud2

from inekf_semantic_mapping.msg import SemanticMapInfo
from visualization_msgs.msg import MarkerArray

from inekf_semantic_mapping.srv import SaveMap
from semantic_octomap_node_test import read_ply, transform, wall_cloud

NODE = "/semantic_octomap_node"


class LidarOnlyTest(unittest.TestCase):
    def test_unlabeled_scans_are_mapped(self):
        rospy.init_node("semantic_octomap_lidar_only_test")
        lock = threading.Lock()
        state = {"info": None, "markers": None}

        def on_info(msg):
            with lock:
                state["info"] = msg

        def on_markers(msg):
            with lock:
                state["markers"] = msg

        rospy.Subscriber("/semantic_map/info", SemanticMapInfo, on_info)
        rospy.Subscriber("/semantic_map/markers", MarkerArray, on_markers)
        static_tf = tf2_ros.StaticTransformBroadcaster()
        static_tf.sendTransform([transform("map", "velo_link", (0.0, 0.0, 0.0), (0, 0, 0, 1))])
        cloud_pub = rospy.Publisher("/kitti/velo/pointcloud", PointCloud2, queue_size=5)
        rospy.wait_for_service(NODE + "/save_map", timeout=30)
        deadline = rospy.Time.now() + rospy.Duration(20)
        while cloud_pub.get_num_connections() < 2 and rospy.Time.now() < deadline:
            rospy.sleep(0.1)  # the node subscribes twice: synchronizer + lidar-only path
        for _ in range(3):
            cloud_pub.publish(wall_cloud(rospy.Time.now()))
            rospy.sleep(0.5)
        deadline = rospy.Time.now() + rospy.Duration(10)
        while rospy.Time.now() < deadline:
            with lock:
                if state["info"] and state["info"].scans_inserted >= 3:
                    break
            rospy.sleep(0.1)
        with lock:
            info = state["info"]
            markers = state["markers"]
        self.assertIsNotNone(info)
        self.assertGreaterEqual(info.scans_inserted, 3, info)
        self.assertEqual(info.scans_with_labels, 0, info)
        self.assertEqual(set(info.class_names), {"unlabeled"}, info)
        self.assertIn("unlabeled", {m.ns for m in markers.markers})

        out_dir = tempfile.mkdtemp(prefix="ism_lidar_only_")
        try:
            path = os.path.join(out_dir, "map.ply")
            response = rospy.ServiceProxy(NODE + "/save_map", SaveMap)(path, "ply")
            self.assertTrue(response.success, response.message)
            vertices = read_ply(path)
            self.assertGreater(len(vertices), 100)
            self.assertEqual({v[3] for v in vertices}, {0})
            for v in vertices:
                self.assertAlmostEqual(v[0], 10.0, delta=0.3)
        finally:
            shutil.rmtree(out_dir, ignore_errors=True)


if __name__ == "__main__":
    rostest.rosrun("inekf_semantic_mapping", "semantic_octomap_lidar_only_test", LidarOnlyTest)
