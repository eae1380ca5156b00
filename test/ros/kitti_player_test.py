#!/usr/bin/python3
"""Checks kitti_player against the raw OXTS text files it plays (see kitti_player.test)."""
import calendar
import os
import sys
import time
import unittest

import rospy
import rostest
import tf2_ros
from geometry_msgs.msg import TwistStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Imu, NavSatFix, NavSatStatus
from std_srvs.srv import SetBool, Trigger

PKG = 'inekf_semantic_mapping'


def stamp_ns(text):
    """'2011-09-26 13:02:25.964389445' -> ns since the epoch (UTC), independent of the C++."""
    date, clock = text.strip().split(' ')
    seconds, _, fraction = clock.partition('.')
    y, mo, d = (int(v) for v in date.split('-'))
    h, mi, s = (int(v) for v in seconds.split(':'))
    return calendar.timegm((y, mo, d, h, mi, s, 0, 0, 0)) * 10**9 + int(fraction.ljust(9, '0'))


class KittiPlayerTest(unittest.TestCase):
    def setUp(self):
        self.drive_dir = os.path.realpath(rospy.get_param('~drive_dir'))
        self.messages = {'imu': [], 'fix': [], 'vel': [], 'gt': []}

    def record(self, key):
        return lambda msg: self.messages[key].append(msg)

    def wait_for(self, condition, timeout_s):
        deadline = time.time() + timeout_s
        while time.time() < deadline and not rospy.is_shutdown():
            if condition():
                return True
            time.sleep(0.05)
        return condition()

    def test_plays_the_drive(self):
        oxts_dir = os.path.join(self.drive_dir, 'oxts')
        if not os.path.isdir(oxts_dir):
            print('\n*** SKIPPED kitti_player_test: shared data not found: %s\n' % oxts_dir,
                  file=sys.stderr)
            return
        with open(os.path.join(oxts_dir, 'timestamps.txt')) as f:
            stamps = [stamp_ns(line) for line in f if line.strip()]
        duration_ns = int(rospy.get_param('~duration_s') * 1e9)
        expected = [i for i, t in enumerate(stamps) if t < stamps[0] + duration_ns]

        def oxts_values(frame):
            with open(os.path.join(oxts_dir, 'data', '%010d.txt' % frame)) as f:
                return [float(v) for v in f.read().split()]

        rospy.Subscriber('/kitti/oxts/imu', Imu, self.record('imu'))
        rospy.Subscriber('/kitti/oxts/gps/fix', NavSatFix, self.record('fix'))
        rospy.Subscriber('/kitti/oxts/gps/vel', TwistStamped, self.record('vel'))
        rospy.Subscriber('/kitti/oxts/ground_truth', Odometry, self.record('gt'))
        rospy.wait_for_service('/kitti_player/step', timeout=30)
        tf_buffer = tf2_ros.Buffer()
        tf2_ros.TransformListener(tf_buffer)
        time.sleep(1.0)  # let the subscriptions connect before anything is published
        self.assertEqual(len(self.messages['imu']), 0, 'published while paused')

        # ~step while paused publishes exactly one OXTS frame.
        step = rospy.ServiceProxy('/kitti_player/step', Trigger)
        self.assertTrue(step().success)
        self.assertTrue(self.wait_for(lambda: len(self.messages['imu']) >= 1, 10.0))
        time.sleep(0.5)
        self.assertEqual(len(self.messages['imu']), 1)

        pause = rospy.ServiceProxy('/kitti_player/pause', SetBool)
        self.assertTrue(pause(False).success)
        self.assertTrue(self.wait_for(
            lambda: all(len(m) >= len(expected) for m in self.messages.values()), 30.0),
            {k: len(v) for k, v in self.messages.items()})
        time.sleep(0.5)  # nothing beyond the duration may follow
        for key, msgs in self.messages.items():
            self.assertEqual(len(msgs), len(expected), key)
            got = [m.header.stamp.to_nsec() for m in msgs]
            self.assertEqual(got, [stamps[i] for i in expected], key + ' stamps')
            self.assertTrue(all(a < b for a, b in zip(got, got[1:])), key + ' not increasing')

        self.assertTrue(all(m.header.frame_id == 'imu_link' for m in self.messages['imu']))
        self.assertTrue(all(m.header.frame_id == 'map' for m in self.messages['vel']))
        self.assertTrue(all(m.header.frame_id == 'map' and m.child_frame_id == 'base_link'
                            for m in self.messages['gt']))
        for frame in (0, 7, expected[-1]):
            v = oxts_values(frame)
            imu, fix, gt = (self.messages[k][frame] for k in ('imu', 'fix', 'gt'))
            # Body-frame ax ay az (fields 12..14) and wx wy wz (18..20), not af/wf.
            self.assertAlmostEqual(imu.linear_acceleration.x, v[11], places=9)
            self.assertAlmostEqual(imu.linear_acceleration.z, v[13], places=9)
            self.assertNotAlmostEqual(imu.linear_acceleration.x, v[14], places=3)
            self.assertAlmostEqual(imu.angular_velocity.x, v[17], places=9)
            self.assertAlmostEqual(imu.angular_velocity.z, v[19], places=9)
            self.assertAlmostEqual(fix.latitude, v[0], places=9)
            self.assertAlmostEqual(fix.longitude, v[1], places=9)
            self.assertAlmostEqual(fix.altitude, v[2], places=6)
            expected_status = (NavSatStatus.STATUS_NO_FIX if v[27] <= 0 else
                               NavSatStatus.STATUS_GBAS_FIX if v[27] >= 5 else
                               NavSatStatus.STATUS_SBAS_FIX if v[27] == 4 else
                               NavSatStatus.STATUS_FIX)
            self.assertEqual(fix.status.status, expected_status)
            self.assertEqual(fix.position_covariance_type,
                             NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN)
            self.assertAlmostEqual(fix.position_covariance[0], v[23] ** 2, places=9)
        self.assertAlmostEqual(self.messages['gt'][0].pose.pose.position.x, 0.0, places=9)
        # Frame 1 of drive 0001 by hand (devkit Mercator): 1.236 m west, 0.743 m south.
        self.assertAlmostEqual(self.messages['gt'][1].pose.pose.position.x, -1.23649, places=4)
        self.assertAlmostEqual(self.messages['gt'][1].pose.pose.position.y, -0.74311, places=4)

        # /tf_static: 2011_09_26 has calibration, so velodyne and cameras are on the tree.
        for parent, child in (('base_link', 'imu_link'), ('imu_link', 'velo_link'),
                              ('velo_link', 'camera_color_left')):
            self.assertTrue(tf_buffer.can_transform(parent, child, rospy.Time(0),
                                                    rospy.Duration(5.0)), parent + '->' + child)
        velo = tf_buffer.lookup_transform('imu_link', 'velo_link', rospy.Time(0))
        # calib_imu_to_velo T = (-0.81, 0.32, -0.80): the velodyne sits 0.81 m ahead, 0.80 m up.
        self.assertAlmostEqual(velo.transform.translation.x, 0.81, delta=0.01)
        self.assertAlmostEqual(velo.transform.translation.z, 0.80, delta=0.01)


if __name__ == '__main__':
    rospy.init_node('kitti_player_test')
    rostest.rosrun(PKG, 'kitti_player_test', KittiPlayerTest)
