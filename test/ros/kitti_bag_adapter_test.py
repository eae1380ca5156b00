#!/usr/bin/python3
"""kitti_bag_adapter on a bag in the Python kitti2bag's conventions: the levelled GPS velocity
(vf, vl, vu) goes out in the map frame with the heading of the IMU message of its own stamp,
whichever of the two messages arrives first. rosbag play sends them on separate connections:
a velocity that came before its IMU message used to be dropped ("before any IMU orientation")
or turned with the previous frame's heading; frame 0's dropped made inekf_node start a frame
later (47 of 50 scans in the map).

The adapter is started by this node on a small bag written here (it reads the bag's topics and
tf frames first); the test then publishes on the remapped inputs as kitti_bag.launch's rosbag
play would, in a chosen order.
"""
import math
import os
import subprocess
import tempfile
import time
import unittest

import rosbag
import rospy
import rostest
from geometry_msgs.msg import TransformStamped, TwistStamped
from sensor_msgs.msg import Imu, NavSatFix
from tf2_msgs.msg import TFMessage

import e2e_support as e2e

NAME = "kitti_bag_adapter_test"
T0 = 1317035451.0


def yaw_quaternion(yaw):
    return 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)


def imu_message(stamp_s, yaw):
    imu = Imu()
    imu.header.stamp = rospy.Time.from_sec(stamp_s)
    imu.header.frame_id = "imu_link"
    (imu.orientation.x, imu.orientation.y, imu.orientation.z,
     imu.orientation.w) = yaw_quaternion(yaw)
    imu.linear_acceleration.z = 9.81
    return imu


def velocity_message(stamp_s, forward_mps):
    velocity = TwistStamped()
    velocity.header.stamp = rospy.Time.from_sec(stamp_s)
    velocity.header.frame_id = "imu_link"
    velocity.twist.linear.x = forward_mps
    return velocity


def write_bag(path):
    """The frames and topics that make a bag the Python kitti2bag's (detectBagConvention)."""
    with rosbag.Bag(path, "w") as bag:
        stamp = rospy.Time.from_sec(T0)
        static = TransformStamped()
        static.header.stamp, static.header.frame_id, static.child_frame_id = stamp, "base_link", "imu_link"
        static.transform.translation.x, static.transform.translation.y = -1.405, 0.32
        static.transform.translation.z, static.transform.rotation.w = 0.93, 1.0
        bag.write("/tf_static", TFMessage([static]), t=stamp)
        world = TransformStamped()
        world.header.stamp, world.header.frame_id, world.child_frame_id = stamp, "world", "base_link"
        world.transform.rotation.w = 1.0
        bag.write("/tf", TFMessage([world]), t=stamp)
        bag.write("/kitti/oxts/imu", imu_message(T0, 0.0), t=stamp)
        fix = NavSatFix()
        fix.header.stamp = stamp
        bag.write("/kitti/oxts/gps/fix", fix, t=stamp)
        bag.write("/kitti/oxts/gps/vel", velocity_message(T0, 10.0), t=stamp)


class KittiBagAdapterOrder(unittest.TestCase):
    def test_velocity_takes_the_heading_of_its_own_instant_in_either_order(self):
        rospy.init_node(NAME)
        e2e.require_executables(self, "kitti_bag_adapter")
        out_dir = tempfile.mkdtemp(prefix="ism_%s_" % NAME)
        bag_path = os.path.join(out_dir, "kitti2bag_py.bag")
        write_bag(bag_path)
        received = []
        subscriber = rospy.Subscriber("/kitti/oxts/gps/vel", TwistStamped, received.append,
                                      queue_size=50)
        imu_out = rospy.Publisher("/kitti_bag/oxts/imu", Imu, queue_size=50)
        velocity_out = rospy.Publisher("/kitti_bag/oxts/gps/vel", TwistStamped, queue_size=50)
        log_path = os.path.join(out_dir, "adapter.log")
        log = open(log_path, "w")
        adapter = subprocess.Popen(["rosrun", "inekf_semantic_mapping", "kitti_bag_adapter",
                                    "_bag:=" + bag_path], stdout=log, stderr=subprocess.STDOUT)
        self.addCleanup(lambda: e2e.stop_process(adapter, log))
        e2e.wait_until(lambda: (imu_out.get_num_connections() > 0 and
                                velocity_out.get_num_connections() > 0 and
                                subscriber.get_num_connections() > 0) or adapter.poll() is not None,
                       timeout=30.0)
        self.assertIsNone(adapter.poll(), open(log_path).read())
        time.sleep(0.5)

        def send(message, publisher):
            publisher.publish(message)
            time.sleep(0.2)  # one at a time: the order of arrival is the order sent

        # Frame 0: the velocity first (before any IMU message), heading north (yaw 90 deg).
        send(velocity_message(T0, 10.0), velocity_out)
        send(imu_message(T0, math.pi / 2), imu_out)
        # Frame 1: the IMU first (heading west), then frame 2's IMU (heading south) before
        # frame 1's velocity: frame 1's heading, not the newest.
        send(imu_message(T0 + 0.1, math.pi), imu_out)
        send(imu_message(T0 + 0.2, -math.pi / 2), imu_out)
        send(velocity_message(T0 + 0.1, 10.0), velocity_out)
        # Frame 3: the velocity first again, heading east.
        send(velocity_message(T0 + 0.3, 10.0), velocity_out)
        send(imu_message(T0 + 0.3, 0.0), imu_out)
        e2e.wait_until(lambda: len(received) >= 3, timeout=5.0)
        time.sleep(0.5)

        expected = {0: (0.0, 10.0), 1: (-10.0, 0.0), 3: (10.0, 0.0)}
        got = {int(round((m.header.stamp.to_sec() - T0) * 10)): m for m in received}
        self.assertEqual(sorted(got), sorted(expected), "velocities out: %s\nadapter log:\n%s" % (
            [(m.header.stamp.to_sec() - T0, m.twist.linear.x, m.twist.linear.y) for m in received],
            open(log_path).read()[-2000:]))
        for frame, (east, north) in expected.items():
            message = got[frame]
            self.assertEqual(message.header.frame_id, "map")
            self.assertAlmostEqual(message.twist.linear.x, east, places=6, msg="frame %d" % frame)
            self.assertAlmostEqual(message.twist.linear.y, north, places=6, msg="frame %d" % frame)
        self.assertNotIn("dropped", open(log_path).read())


if __name__ == "__main__":
    rostest.rosrun("inekf_semantic_mapping", NAME, KittiBagAdapterOrder)
