#!/usr/bin/python3
"""rostest for semantic_octomap_node: a wall 10 m ahead of the lidar, its left half labeled
building and its right half car in the label image, seen in three synchronized scans. Checks
that per-class markers and the labeled cloud appear, that ~save_map writes a SemanticOcTree .ot
and a PLY whose labels sit on the right side of the map, that an unwritable path returns
success=False with the node still serving, that ~reset empties the map and that ~load_map
refuses a corrupt file and restores a saved one."""
import os
import shutil
import tempfile
import threading
import unittest

import rospy
import rostest
import tf2_ros
from geometry_msgs.msg import TransformStamped
from sensor_msgs import point_cloud2
from sensor_msgs.msg import CameraInfo, Image, PointCloud2, PointField
from std_srvs.srv import Empty
from visualization_msgs.msg import MarkerArray

from inekf_semantic_mapping.msg import SemanticMapInfo
from inekf_semantic_mapping.srv import LoadMap, SaveMap

PKG = "inekf_semantic_mapping"
NODE = "/semantic_octomap_node"
WIDTH, HEIGHT = 200, 100
BUILDING, CAR = 11, 26  # Cityscapes labelIds
MAP_Y_OFFSET = 2.0  # map -> velo_link translation along y
# Where the localization's map frame lies (inekf_node's ~map_origin_in_use): the first launch's,
# and another launch's own first fix 3.7 m away.
ORIGIN_PARAM = "/inekf_node/map_origin_in_use"
ORIGIN_A = {"lat": 49.0131623, "lon": 8.4378408, "alt": 117.818}
ORIGIN_B = {"lat": 49.013137, "lon": 8.4378193, "alt": 115.934}


def transform(parent, child, translation, quaternion_xyzw):
    t = TransformStamped()
    t.header.stamp = rospy.Time.now()
    t.header.frame_id = parent
    t.child_frame_id = child
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = translation
    (t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
     t.transform.rotation.w) = quaternion_xyzw
    return t


def wall_cloud(stamp, behind=False):
    """A wall at x = 10 m (y -4..4, z -1..1.5) in velo_link, 5 cm spacing; with `behind`, also
    a wall at x = -10 m that the camera cannot see."""
    points = []
    for iy in range(161):
        for iz in range(51):
            points.append((10.0, -4.0 + 0.05 * iy, -1.0 + 0.05 * iz, 0.5))
            if behind:
                points.append((-10.0, -4.0 + 0.05 * iy, -1.0 + 0.05 * iz, 0.5))
    header = rospy.Header(stamp=stamp, frame_id="velo_link")
    fields = [PointField(name, 4 * i, PointField.FLOAT32, 1) for i, name in enumerate("xyz")]
    fields.append(PointField("intensity", 12, PointField.FLOAT32, 1))
    return point_cloud2.create_cloud(header, fields, points)


def label_image(stamp):
    """Left half of the image (u < 100, velo y > 0) building, right half car."""
    row = bytes([BUILDING] * (WIDTH // 2) + [CAR] * (WIDTH - WIDTH // 2))
    msg = Image()
    msg.header.stamp = stamp
    msg.header.frame_id = "camera_color_left"
    msg.height, msg.width = HEIGHT, WIDTH
    msg.encoding = "mono8"
    msg.step = WIDTH
    msg.data = row * HEIGHT
    return msg


def camera_info():
    msg = CameraInfo()
    msg.header.frame_id = "camera_color_left"
    msg.width, msg.height = WIDTH, HEIGHT
    msg.K = [100.0, 0, 100.0, 0, 100.0, 50.0, 0, 0, 1]
    msg.P = [100.0, 0, 100.0, 0, 0, 100.0, 50.0, 0, 0, 0, 1, 0]
    msg.R = [1.0, 0, 0, 0, 1, 0, 0, 0, 1]
    return msg


class CameraRig:
    """The map node's inputs for a lidar at the map's origin with the camera on it, as the
    rostests publish them: the static tf, camera_info (latched), clouds and label images."""

    def __init__(self):
        self.static_tf = tf2_ros.StaticTransformBroadcaster()  # kept: its transforms stay sent
        self.static_tf.sendTransform([
            transform("map", "velo_link", (0.0, 0.0, 0.0), (0, 0, 0, 1)),
            transform("velo_link", "camera_color_left", (0.0, 0.0, 0.0), (-0.5, 0.5, -0.5, 0.5)),
        ])
        self.info_pub = rospy.Publisher("/kitti/camera_color_left/camera_info", CameraInfo,
                                        queue_size=1, latch=True)
        self.cloud_pub = rospy.Publisher("/kitti/velo/pointcloud", PointCloud2, queue_size=5)
        self.labels_pub = rospy.Publisher("/segmentation/labels", Image, queue_size=5)


def read_ply(path):
    with open(path) as f:
        lines = f.read().splitlines()
    end = lines.index("end_header")
    assert "property uint label" in lines[:end], lines[:end]
    vertices = [line.split() for line in lines[end + 1:] if line.strip()]
    return [(float(v[0]), float(v[1]), float(v[2]), int(v[3])) for v in vertices]


class SemanticOctomapNodeTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("semantic_octomap_node_test")
        cls.lock = threading.Lock()
        cls.markers = None
        cls.info = None
        cls.labeled_clouds = []
        rospy.Subscriber("/semantic_map/markers", MarkerArray, cls.on_markers)
        rospy.Subscriber("/semantic_map/info", SemanticMapInfo, cls.on_info)
        rospy.Subscriber("/semantic_map/labeled_cloud", PointCloud2, cls.on_cloud)
        cls.static_tf = tf2_ros.StaticTransformBroadcaster()
        # velo_link -> camera_color_left: camera z = velo x, camera x = -velo y, camera y = -velo z.
        cls.static_tf.sendTransform([
            transform("map", "velo_link", (0.0, MAP_Y_OFFSET, 0.0), (0, 0, 0, 1)),
            transform("velo_link", "camera_color_left", (0.0, 0.0, 0.0), (-0.5, 0.5, -0.5, 0.5)),
        ])
        cls.info_pub = rospy.Publisher("/kitti/camera_color_left/camera_info", CameraInfo,
                                       queue_size=1, latch=True)
        cls.cloud_pub = rospy.Publisher("/kitti/velo/pointcloud", PointCloud2, queue_size=5)
        cls.labels_pub = rospy.Publisher("/segmentation/labels", Image, queue_size=5)
        rospy.wait_for_service(NODE + "/save_map", timeout=30)
        deadline = rospy.Time.now() + rospy.Duration(20)
        while (cls.cloud_pub.get_num_connections() == 0 or cls.labels_pub.get_num_connections() == 0) \
                and rospy.Time.now() < deadline:
            rospy.sleep(0.1)
        cls.info_pub.publish(camera_info())
        rospy.set_param(ORIGIN_PARAM, ORIGIN_A)
        rospy.sleep(0.5)
        for i in range(3):
            stamp = rospy.Time.now()
            cls.cloud_pub.publish(wall_cloud(stamp, behind=True))
            cls.labels_pub.publish(label_image(stamp))
            rospy.sleep(0.5)
        cls.save = rospy.ServiceProxy(NODE + "/save_map", SaveMap)
        cls.reset = rospy.ServiceProxy(NODE + "/reset", Empty)
        cls.load = rospy.ServiceProxy(NODE + "/load_map", LoadMap)
        cls.out_dir = tempfile.mkdtemp(prefix="ism_semantic_octomap_node_")

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.out_dir, ignore_errors=True)

    @classmethod
    def on_markers(cls, msg):
        with cls.lock:
            cls.markers = msg

    @classmethod
    def on_info(cls, msg):
        with cls.lock:
            cls.info = msg

    @classmethod
    def on_cloud(cls, msg):
        with cls.lock:
            cls.labeled_clouds.append(msg)

    def wait_for(self, predicate, timeout=10.0):
        deadline = rospy.Time.now() + rospy.Duration(timeout)
        while rospy.Time.now() < deadline:
            with self.lock:
                if predicate():
                    return True
            rospy.sleep(0.1)
        return False

    def test_1_markers_per_class_on_the_right_side(self):
        def has_both():
            names = {m.ns for m in self.markers.markers} if self.markers else set()
            return {"building", "car"} <= names
        self.assertTrue(self.wait_for(has_both), "no building/car markers: %s" % (
            [m.ns for m in self.markers.markers] if self.markers else None))
        with self.lock:
            by_ns = {m.ns: m for m in self.markers.markers if m.ns}
        for ns, sign in (("building", 1.0), ("car", -1.0)):
            marker = by_ns[ns]
            self.assertEqual(marker.type, marker.CUBE_LIST)
            self.assertEqual(marker.header.frame_id, "map")
            self.assertGreater(len(marker.points), 50)
            on_its_side = [p for p in marker.points if sign * (p.y - MAP_Y_OFFSET) > 0]
            self.assertGreater(len(on_its_side), 0.9 * len(marker.points), ns)
            for p in marker.points:
                self.assertAlmostEqual(p.x, 10.0, delta=0.3)

    def test_2_labeled_cloud_and_info(self):
        self.assertTrue(self.wait_for(lambda: len(self.labeled_clouds) >= 3), "no labeled clouds")
        with self.lock:
            cloud = self.labeled_clouds[-1]
        self.assertEqual(cloud.header.frame_id, "map")
        self.assertEqual([f.name for f in cloud.fields], ["x", "y", "z", "rgb", "label"])
        points = list(point_cloud2.read_points(cloud, field_names=("x", "y", "label")))
        self.assertEqual(len(points), 161 * 51)
        for x, y, label in points:
            self.assertAlmostEqual(x, 10.0, delta=1e-3)
            if abs(y - MAP_Y_OFFSET) > 0.3:  # away from the image's centre column
                self.assertEqual(label, BUILDING if y > MAP_Y_OFFSET else CAR, (x, y, label))
        self.assertTrue(self.wait_for(lambda: self.info is not None and self.info.scans_inserted >= 3),
                        "info: %s" % self.info)
        with self.lock:
            info = self.info
        self.assertGreater(info.occupied_voxels, 100, info)
        self.assertEqual(info.scans_with_labels, 3, info)
        self.assertEqual(info.label_images_used, 3, info)
        self.assertIn("building", info.class_names)
        self.assertIn("car", info.class_names)

    def test_3_scan_without_pose_is_skipped(self):
        with self.lock:
            scans_before = self.info.scans_inserted
        stamp = rospy.Time.now()
        cloud = wall_cloud(stamp)
        cloud.header.frame_id = "frame_without_tf"
        self.cloud_pub.publish(cloud)
        self.labels_pub.publish(label_image(stamp))
        # Nothing blocks on the missing pose: the scan waits (label_wait_s + pose_wait_s), then it is
        # dropped and counted.
        self.assertTrue(self.wait_for(lambda: self.info.scans_without_pose >= 1, timeout=10),
                        "info: %s" % self.info)
        with self.lock:
            self.assertEqual(self.info.scans_inserted, scans_before, "a scan without a pose was inserted")
        # An older driver's "/velo_link": tf2 refuses the slash, and every such scan was dropped
        # "without a pose". It is the frame velo_link.
        slashed = wall_cloud(rospy.Time.now())
        slashed.header.frame_id = "/velo_link"
        self.cloud_pub.publish(slashed)
        self.assertTrue(self.wait_for(lambda: self.info.scans_inserted > scans_before, timeout=10),
                        "a scan in '/velo_link' was not mapped: %s" % self.info)

    def test_4_save_map_ot_and_ply(self):
        ot_path = os.path.join(self.out_dir, "map.ot")
        response = self.save(ot_path, "ot")
        self.assertTrue(response.success, response.message)
        self.assertGreater(response.voxel_count, 100)
        with open(ot_path, "rb") as f:
            header = f.read(200)
        self.assertTrue(header.startswith(b"# Octomap OcTree file"), header)
        self.assertIn(b"id SemanticOcTree", header)
        ply_path = os.path.join(self.out_dir, "map.ply")
        response = self.save(ply_path, "")  # format from the extension
        self.assertTrue(response.success, response.message)
        vertices = read_ply(ply_path)
        self.assertEqual(len(vertices), response.voxel_count)
        labels = {v[3] for v in vertices}
        self.assertTrue({BUILDING, CAR} <= labels, labels)
        building_y = [v[1] for v in vertices if v[3] == BUILDING]
        car_y = [v[1] for v in vertices if v[3] == CAR]
        self.assertGreater(sum(y > MAP_Y_OFFSET for y in building_y), 0.9 * len(building_y))
        self.assertGreater(sum(y < MAP_Y_OFFSET for y in car_y), 0.9 * len(car_y))
        # insert_points_outside_image is false: the wall behind the camera is not in the map.
        self.assertEqual([v for v in vertices if v[0] < 0], [])
        self.assertEqual([f for f in os.listdir(self.out_dir) if ".tmp" in f], [])

    def test_5_unwritable_path_fails_cleanly(self):
        bad = "/nonexistent_ism_dir/map.ot"
        response = self.save(bad, "ot")
        self.assertFalse(response.success)
        self.assertIn(bad, response.message)
        response = self.save(os.path.join(self.out_dir, "again.ot"), "ot")
        self.assertTrue(response.success, "node did not survive the failed save: " + response.message)
        # A folder is refused before anything is written; an extension that is neither .ot nor
        # .ply without a format (a .bt is octomap's own format) is refused; a relative path is
        # the node's working directory's, and the reply says which file that is.
        response = self.save(self.out_dir, "ot")
        self.assertFalse(response.success)
        self.assertIn("is a directory", response.message)
        response = self.save(os.path.join(self.out_dir, "map.bt"), "")
        self.assertFalse(response.success)
        self.assertIn("'.bt' is not .ot or .ply", response.message)
        response = self.save(os.path.join(self.out_dir, "text.ot"), "ply")
        self.assertFalse(response.success)
        self.assertIn("format 'ply' under the extension '.ot'", response.message)
        self.assertEqual([f for f in os.listdir(self.out_dir) if ".tmp" in f or f == "map.bt"], [])
        relative = "ism_semantic_octomap_node_test_%d.ot" % os.getpid()
        response = self.save(relative, "ot")
        self.assertTrue(response.success, response.message)
        written = response.message.split()[1]
        self.assertTrue(os.path.isabs(written) and written.endswith("/" + relative), response.message)
        self.assertTrue(os.path.isfile(written), written)
        os.remove(written)

    def test_6_reset_empties_the_map_and_load_map_restores_it(self):
        saved = os.path.join(self.out_dir, "before_reset.ot")
        before = self.save(saved, "ot")
        self.assertTrue(before.success, before.message)
        self.reset()
        response = self.save(os.path.join(self.out_dir, "empty.ply"), "ply")
        self.assertTrue(response.success, response.message)
        self.assertEqual(response.voxel_count, 0)
        # A corrupt file is refused and the (empty) map is kept; the saved one loads back.
        with open(saved, "rb") as f:
            data = bytearray(f.read())
        data[-10] ^= 0x5A
        corrupt = os.path.join(self.out_dir, "corrupt.ot")
        with open(corrupt, "wb") as f:
            f.write(bytes(data))
        refused = self.load(corrupt)
        self.assertFalse(refused.success)
        self.assertIn("corrupt", refused.message)
        loaded = self.load(saved)
        self.assertTrue(loaded.success, loaded.message)
        again = self.save(os.path.join(self.out_dir, "after_load.ot"), "ot")
        self.assertEqual(again.voxel_count, before.voxel_count)

    def test_7_a_misspelt_parameter_stops_a_second_node_with_its_name(self):
        # The strict reader refuses the key; the fatal message must reach the terminal (it used
        # to be lost: rosconsole was shut down with the node's last NodeHandle) and the node must
        # exit non-zero.
        import subprocess

        import roslib.packages

        executable = roslib.packages.find_node(PKG, "semantic_octomap_node")[0]
        result = subprocess.run([executable, "__name:=misspelt_parameter_node",
                                 "_resolutoin:=0.2"], stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True, timeout=60)
        self.assertNotEqual(result.returncode, 0, result.stdout)
        self.assertIn("resolutoin", result.stdout)

    def test_8_the_nodes_own_keys_are_checked_under_old_names_too(self):
        # A log period of 0 wrote thousands of lines a second; the old names autosave_period and
        # log_period were announced as still read and then ignored.
        from strict_parameters import run_with_parameters
        cases = [({"log_period_s": 0}, "'log_period_s' must be in (0, "),
                 # A mistyped folder was found at shutdown, when the whole map was lost.
                 ({"autosave_path": "/nonexistent_ism_dir/map.ot"},
                  "cannot write '/nonexistent_ism_dir/map.ot': no directory /nonexistent_ism_dir"),
                 ({"log_period": 0}, "'log_period' (now 'log_period_s') must be in (0, "),
                 ({"marker_depth": 40}, "'marker_depth' must be an integer in [1, 16]"),
                 ({"camera_index": 7}, "'camera_index' must be an integer in [0, 3]"),
                 ({"max_display_cpu_fraction": -3}, "'max_display_cpu_fraction' must be in [0, 1]"),
                 # The launch files load the node's YAML with rosparam and name it in
                 # ~loaded_from: a key misspelt there is reported with the file.
                 ({"loaded_from": "/home/user/my_mapping.yaml", "label_wiat_s": 2},
                  "(loaded from /home/user/my_mapping.yaml): key 'label_wiat_s' is not a known key")]
        for i, (parameters, message) in enumerate(cases):
            # A node of its own for each: private parameters stay on the server after a node.
            code, output = run_with_parameters("semantic_octomap_node",
                                               "checked_parameter_node_%d" % i, parameters)
            self.assertNotEqual(code, 0, output)
            self.assertIn(message, output)

    def publish_scans(self, count):
        for _ in range(count):
            stamp = rospy.Time.now()
            self.cloud_pub.publish(wall_cloud(stamp))
            self.labels_pub.publish(label_image(stamp))
            rospy.sleep(0.5)

    def test_9_a_map_resumed_under_another_origin_maps_no_scans(self):
        # The map took the localization's origin A (setUpClass) and saves it. A new launch takes
        # its own first fix as origin B: the resumed map's scans would be mapped again, shifted.
        saved = os.path.join(self.out_dir, "origin_a.ot")
        self.assertTrue(self.save(saved, "ot").success)
        rospy.set_param(ORIGIN_PARAM, ORIGIN_B)
        try:
            loaded = self.load(saved)
            self.assertTrue(loaded.success, loaded.message)
            self.assertTrue(self.wait_for(lambda: self.info.scans_inserted == 0), self.info)
            self.publish_scans(3)
            rospy.sleep(2.0)  # past label_wait_s: they would be in by now
            with self.lock:
                self.assertEqual(self.info.scans_inserted, 0, "scans went into a map of origin A")
            # An empty map takes origin B, and maps again.
            self.reset()
            self.publish_scans(2)
            self.assertTrue(self.wait_for(lambda: self.info.scans_inserted >= 1),
                            "no scan mapped after the reset: %s" % self.info)
        finally:
            rospy.set_param(ORIGIN_PARAM, ORIGIN_A)


if __name__ == "__main__":
    rostest.rosrun(PKG, "semantic_octomap_node_test", SemanticOctomapNodeTest)
