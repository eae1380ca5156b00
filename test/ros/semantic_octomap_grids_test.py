#!/usr/bin/python3
"""rostest for semantic_octomap_node's 2D grids: the lidar 1.73 m above a flat road (x 4..12 m,
|y| <= 3 m, velo_link) with a building wall at x = 14 m; the label image calls the rows that see
the road "road" and the rows above them "building". Checks /semantic_map/projected_map (the wall
occupied, free air between lidar and wall, nothing occupied over the road) and
/semantic_map/drivable_map (road cells drivable, wall cells occupied, unseen space unknown), that
that a late subscriber gets both in the map frame at the map's resolution, that the markers keep
coming, and that a subscriber after a reset nobody saw gets the empty map, not the old one."""
import threading
import unittest

import rospy
import rostest
import tf2_ros
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import OccupancyGrid
from sensor_msgs import point_cloud2
from sensor_msgs.msg import CameraInfo, Image, PointCloud2, PointField
from std_srvs.srv import Empty
from visualization_msgs.msg import MarkerArray

PKG = "inekf_semantic_mapping"
WIDTH, HEIGHT = 200, 100
ROAD, BUILDING = 7, 11  # Cityscapes labelIds
SENSOR_HEIGHT = 1.73  # grid.sensor_height_m of config/semantic_mapping.yaml
MAP_Y_OFFSET = 2.0  # map -> velo_link translation along y
WALL_X = 14.0
# Image rows: v = 50 + 100 * (-z / x); the road (z = -1.73, x <= 12) is at v >= 64.4, the wall's
# foot (x = 14) at v = 62.4.
FIRST_ROAD_ROW = 63


def transform(parent, child, translation, quaternion_xyzw):
    t = TransformStamped()
    t.header.stamp = rospy.Time.now()
    t.header.frame_id = parent
    t.child_frame_id = child
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = translation
    (t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
     t.transform.rotation.w) = quaternion_xyzw
    return t


def street_cloud(stamp):
    points = []
    for ix in range(161):  # road, 5 cm spacing
        for iy in range(121):
            points.append((4.0 + 0.05 * ix, -3.0 + 0.05 * iy, -SENSOR_HEIGHT, 0.5))
    for iy in range(121):  # wall from the road up to 1.5 m above the lidar
        for iz in range(65):
            points.append((WALL_X, -3.0 + 0.05 * iy, -SENSOR_HEIGHT + 0.05 * iz, 0.5))
    header = rospy.Header(stamp=stamp, frame_id="velo_link")
    fields = [PointField(name, 4 * i, PointField.FLOAT32, 1) for i, name in enumerate("xyz")]
    fields.append(PointField("intensity", 12, PointField.FLOAT32, 1))
    return point_cloud2.create_cloud(header, fields, points)


def label_image(stamp):
    msg = Image()
    msg.header.stamp = stamp
    msg.header.frame_id = "camera_color_left"
    msg.height, msg.width = HEIGHT, WIDTH
    msg.encoding = "mono8"
    msg.step = WIDTH
    msg.data = (bytes([BUILDING] * WIDTH) * FIRST_ROAD_ROW +
                bytes([ROAD] * WIDTH) * (HEIGHT - FIRST_ROAD_ROW))
    return msg


def camera_info():
    msg = CameraInfo()
    msg.header.frame_id = "camera_color_left"
    msg.width, msg.height = WIDTH, HEIGHT
    msg.K = [100.0, 0, 100.0, 0, 100.0, 50.0, 0, 0, 1]
    msg.P = [100.0, 0, 100.0, 0, 0, 100.0, 50.0, 0, 0, 0, 1, 0]
    msg.R = [1.0, 0, 0, 0, 1, 0, 0, 0, 1]
    return msg


def cells(grid, x_range, y_range):
    """Values of the cells whose centres lie in the map-frame box."""
    res = grid.info.resolution
    x0, y0 = grid.info.origin.position.x, grid.info.origin.position.y
    values = []
    for iy in range(grid.info.height):
        y = y0 + (iy + 0.5) * res
        if not y_range[0] <= y <= y_range[1]:
            continue
        for ix in range(grid.info.width):
            x = x0 + (ix + 0.5) * res
            if x_range[0] <= x <= x_range[1]:
                values.append(grid.data[iy * grid.info.width + ix])
    return values


def fraction(values, wanted):
    return sum(v == wanted for v in values) / float(len(values)) if values else 0.0


class SemanticOctomapGridsTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("semantic_octomap_grids_test")
        cls.lock = threading.Lock()
        cls.grids = {}
        cls.markers = None
        # Subscribed before anything is inserted: the grids that arrive later must reflect the
        # scans (the node republishes when the map changed).
        cls.subscribers = [
            rospy.Subscriber(topic, OccupancyGrid, cls.on_grid, callback_args=topic)
            for topic in ("/semantic_map/projected_map", "/semantic_map/drivable_map")]
        cls.subscribers.append(
            rospy.Subscriber("/semantic_map/markers", MarkerArray, cls.on_markers))
        cls.static_tf = tf2_ros.StaticTransformBroadcaster()
        cls.static_tf.sendTransform([
            transform("map", "velo_link", (0.0, MAP_Y_OFFSET, 0.0), (0, 0, 0, 1)),
            transform("velo_link", "camera_color_left", (0.0, 0.0, 0.0), (-0.5, 0.5, -0.5, 0.5)),
        ])
        cls.info_pub = rospy.Publisher("/kitti/camera_color_left/camera_info", CameraInfo,
                                       queue_size=1, latch=True)
        cls.cloud_pub = rospy.Publisher("/kitti/velo/pointcloud", PointCloud2, queue_size=5)
        cls.labels_pub = rospy.Publisher("/segmentation/labels", Image, queue_size=5)
        deadline = rospy.Time.now() + rospy.Duration(30)
        while (cls.cloud_pub.get_num_connections() == 0 or cls.labels_pub.get_num_connections() == 0) \
                and rospy.Time.now() < deadline:
            rospy.sleep(0.1)
        cls.info_pub.publish(camera_info())
        rospy.sleep(0.5)
        for _ in range(3):
            stamp = rospy.Time.now()
            cls.cloud_pub.publish(street_cloud(stamp))
            cls.labels_pub.publish(label_image(stamp))
            rospy.sleep(0.5)

    @classmethod
    def on_grid(cls, msg, topic):
        with cls.lock:
            cls.grids[topic] = msg

    @classmethod
    def on_markers(cls, msg):
        with cls.lock:
            cls.markers = msg

    def wait_for_grid(self, topic, predicate, timeout=20.0):
        deadline = rospy.Time.now() + rospy.Duration(timeout)
        while rospy.Time.now() < deadline:
            with self.lock:
                grid = self.grids.get(topic)
            if grid is not None and predicate(grid):
                return grid
            rospy.sleep(0.1)
        with self.lock:
            return self.grids.get(topic)

    def wall(self, grid):
        # The wall's points (x = 14.0) lie in the voxels [14.0, 14.2].
        return cells(grid, (WALL_X, WALL_X + 0.2), (MAP_Y_OFFSET - 2.5, MAP_Y_OFFSET + 2.5))

    def road(self, grid):
        return cells(grid, (5.0, 11.0), (MAP_Y_OFFSET - 2.5, MAP_Y_OFFSET + 2.5))

    def test_1_projected_map(self):
        grid = self.wait_for_grid("/semantic_map/projected_map",
                                  lambda g: fraction(self.wall(g), 100) > 0.9)
        self.assertIsNotNone(grid, "no /semantic_map/projected_map")
        self.assertEqual(grid.header.frame_id, "map")
        self.assertAlmostEqual(grid.info.resolution, 0.2, places=5)
        self.assertEqual(len(grid.data), grid.info.width * grid.info.height)
        # Drawn at the ground (the road, 1.73 m below the lidar), not through the map.
        self.assertAlmostEqual(grid.info.origin.position.z, -SENSOR_HEIGHT, delta=0.15)
        self.assertGreater(fraction(self.wall(grid), 100), 0.9, self.wall(grid))
        # The road is below the band [0.5, 2.0] m above the ground: never occupied; the rays to
        # the wall cross the band over it: free there.
        road = self.road(grid)
        self.assertEqual(fraction(road, 100), 0.0)
        self.assertGreater(fraction(road, 0), 0.5, road)
        # Behind the wall nothing was seen.
        behind = cells(grid, (WALL_X + 0.5, 1e9), (-1e9, 1e9))
        self.assertTrue(all(v in (-1, 0) for v in behind))
        self.assertEqual(fraction(behind, 100), 0.0)

    def test_2_drivable_map(self):
        grid = self.wait_for_grid("/semantic_map/drivable_map",
                                  lambda g: fraction(self.road(g), 0) > 0.9)
        self.assertIsNotNone(grid, "no /semantic_map/drivable_map")
        self.assertEqual(grid.header.frame_id, "map")
        road = self.road(grid)
        self.assertGreater(fraction(road, 0), 0.9, road)
        wall = self.wall(grid)
        self.assertGreater(fraction(wall, 100), 0.9, wall)
        # Between the lidar and the road's start only free air was seen: unknown surface.
        near = cells(grid, (0.5, 3.0), (MAP_Y_OFFSET - 1.0, MAP_Y_OFFSET + 1.0))
        self.assertEqual(fraction(near, 0), 0.0, near)

    def test_3_a_late_subscriber_gets_the_grids(self):
        got = []
        sub = rospy.Subscriber("/semantic_map/drivable_map", OccupancyGrid, got.append)
        deadline = rospy.Time.now() + rospy.Duration(5)
        while not got and rospy.Time.now() < deadline:
            rospy.sleep(0.1)
        sub.unregister()
        self.assertTrue(got, "a late subscriber got no drivable map")
        self.assertGreater(fraction(self.road(got[0]), 0), 0.9)

    def test_4_markers_keep_working(self):
        deadline = rospy.Time.now() + rospy.Duration(10)
        names = set()
        while rospy.Time.now() < deadline:
            with self.lock:
                names = {m.ns for m in self.markers.markers} if self.markers else set()
            if {"road", "building"} <= names:
                break
            rospy.sleep(0.1)
        self.assertTrue({"road", "building"} <= names, names)

    def test_5_after_a_reset_nobody_saw_a_new_subscriber_gets_the_empty_map(self):
        # Latched, the grids and markers were the last ones published: a reset with nobody
        # listening left the old map there for a `rostopic echo -n1`.
        for subscriber in self.subscribers:
            subscriber.unregister()
        rospy.sleep(1.0)
        rospy.wait_for_service("/semantic_octomap_node/reset", timeout=10)
        rospy.ServiceProxy("/semantic_octomap_node/reset", Empty)()
        rospy.sleep(1.0)
        grid = rospy.wait_for_message("/semantic_map/drivable_map", OccupancyGrid, timeout=10)
        self.assertEqual(fraction(self.road(grid), 0), 0.0, "the old map's road after the reset")
        markers = rospy.wait_for_message("/semantic_map/markers", MarkerArray, timeout=10)
        cubes = sum(len(m.points) for m in markers.markers)
        self.assertEqual(cubes, 0, [m.ns for m in markers.markers])


if __name__ == "__main__":
    rostest.rosrun(PKG, "semantic_octomap_grids_test", SemanticOctomapGridsTest)
