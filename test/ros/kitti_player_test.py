#!/usr/bin/python3
"""Checks kitti_player against the raw OXTS text files it plays (see kitti_player.test)."""
import calendar
import contextlib
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import time
import unittest
import zlib

import rospy
import rostest
import tf2_ros
import roslib.packages
from geometry_msgs.msg import TwistStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import CameraInfo, Image, Imu, NavSatFix, NavSatStatus, PointCloud2
from tf2_msgs.msg import TFMessage
from std_srvs.srv import SetBool, Trigger

PKG = 'inekf_semantic_mapping'


def stamp_ns(text):
    """'2011-09-26 13:02:25.964389445' -> ns since the epoch (UTC), independent of the C++."""
    date, clock = text.strip().split(' ')
    seconds, _, fraction = clock.partition('.')
    y, mo, d = (int(v) for v in date.split('-'))
    h, mi, s = (int(v) for v in seconds.split(':'))
    return calendar.timegm((y, mo, d, h, mi, s, 0, 0, 0)) * 10**9 + int(fraction.ljust(9, '0'))


def write_png(path, width, height, rgb):
    """A solid-colour 8-bit RGB png (no OpenCV needed in the test)."""
    def chunk(kind, data):
        return (struct.pack('>I', len(data)) + kind + data +
                struct.pack('>I', zlib.crc32(kind + data) & 0xffffffff))
    rows = b''.join(b'\x00' + bytes(rgb) * width for _ in range(height))
    with open(path, 'wb') as f:
        f.write(b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', width, height, 8, 2, 0, 0, 0)) +
                chunk(b'IDAT', zlib.compress(rows)) + chunk(b'IEND', b''))


def write_synthetic_drive(root, frames=3):
    """<root>/2011_01_01/2011_01_01_drive_0001_sync: oxts, a 3-ring velodyne, image_02, calib."""
    import math
    date_dir = os.path.join(root, '2011_01_01')
    drive = os.path.join(date_dir, '2011_01_01_drive_0001_sync')
    stamps = ''.join('2011-01-01 10:00:00.%09d\n' % (100000000 * i) for i in range(frames))
    for sensor in ('oxts', 'velodyne_points', 'image_02'):
        os.makedirs(os.path.join(drive, sensor, 'data'))
        with open(os.path.join(drive, sensor, 'timestamps.txt'), 'w') as f:
            f.write(stamps)
    for i in range(frames):
        values = [49.0 + 1e-5 * i, 8.4, 100.0, 0.01, -0.02, 0.5, 1, 2, 0, 0, 0.1, 0.3 + i, -0.2,
                  9.8, -7, 0, 0, 0.01, 0.02, 0.03 * i, -5, 0, 0, 0.05, 0.01, 4, 8, 5, 5, 5]
        with open(os.path.join(drive, 'oxts', 'data', '%010d.txt' % i), 'w') as f:
            f.write(' '.join(repr(float(v)) if k < 25 else str(v) for k, v in enumerate(values)))
        points = b''
        for ring in range(3):
            for k in range(36):
                azimuth = math.radians(10 * k + 1)
                elevation = math.radians(2 - 2 * ring)
                points += struct.pack('<4f', 10 * math.cos(azimuth), 10 * math.sin(azimuth),
                                      10 * math.tan(elevation), 0.25 * ring)
        with open(os.path.join(drive, 'velodyne_points', 'data', '%010d.bin' % i), 'wb') as f:
            f.write(points)
        write_png(os.path.join(drive, 'image_02', 'data', '%010d.png' % i), 40, 30, (30, 20, 10))
    with open(os.path.join(date_dir, 'calib_imu_to_velo.txt'), 'w') as f:
        f.write('calib_time: x\nR: 1 0 0 0 1 0 0 0 1\nT: -0.8 0.3 -0.8\n')
    with open(os.path.join(date_dir, 'calib_velo_to_cam.txt'), 'w') as f:
        f.write('calib_time: x\nR: 0 -1 0 0 0 -1 1 0 0\nT: 0 -0.08 -0.27\n')
    with open(os.path.join(date_dir, 'calib_cam_to_cam.txt'), 'w') as f:
        for c in range(4):
            s = '_0%d: ' % c
            f.write('S%s40 30\nK%s400 0 20 0 400 15 0 0 1\nD%s0 0 0 0 0\n' % (s, s, s))
            f.write('R%s1 0 0 0 1 0 0 0 1\nT%s0 0 0\nS_rect%s40 30\n' % (s, s, s))
            f.write('R_rect%s1 0 0 0 1 0 0 0 1\n' % s)
            f.write('P_rect%s400 0 20 %d 0 400 15 0 0 0 1 0\n' % (s, 40 if c == 2 else 0))
    return drive


# The synthetic drive's three frame stamps.
SYNTHETIC_STAMPS = [stamp_ns('2011-01-01 10:00:00.%09d' % (10**8 * i)) for i in range(3)]


@contextlib.contextmanager
def synthetic_player(name, prefix, output=None, **params):
    """A second kitti_player, NAME, on a drive the test writes, its topics under /PREFIX/ (its
    stdout and stderr to the file OUTPUT when given); stopped and the drive removed afterwards."""
    root = tempfile.mkdtemp(prefix='ism_%s_' % name)
    drive = write_synthetic_drive(root)
    remaps = {'/kitti/velo/pointcloud': 'velo', '/kitti/camera_color_left/image_raw': 'image',
              '/kitti/camera_color_left/camera_info': 'info', '/kitti/oxts/imu': 'imu',
              '/kitti/oxts/gps/fix': 'fix', '/kitti/oxts/gps/vel': 'vel',
              '/kitti/oxts/ground_truth': 'gt', '/tf_static': 'tf_static', '/clock': 'clock'}
    player = subprocess.Popen(
        [roslib.packages.find_node(PKG, 'kitti_player')[0], '__name:=' + name,
         '_drive_dir:=' + drive] + ['_%s:=%s' % item for item in params.items()] +
        ['%s:=/%s/%s' % (topic, prefix, short) for topic, short in remaps.items()],
        stdout=output, stderr=subprocess.STDOUT if output else None)
    try:
        yield player
    finally:
        if player.poll() is None:
            player.terminate()
            player.wait()
        shutil.rmtree(root)


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

    def test_a_misspelt_parameter_stops_a_second_player_with_its_name(self):
        """Needs no ../shared: the parameters are checked before the drive is read."""
        from strict_parameters import run_with_parameters
        code, output = run_with_parameters("kitti_player", "misspelt_parameter_player",
                                           {"drive_dir": "/nonexistent", "rtae": 2.0})
        self.assertNotEqual(code, 0, output)
        self.assertIn("rtae", output)
        self.assertIn("misspelt_parameter_player", output)
        # A seed kitti2bag cannot take either (it was cast to a 64-bit one of its own).
        code, output = run_with_parameters("kitti_player", "negative_seed_player",
                                           {"drive_dir": "/nonexistent", "gps_seed": -1})
        self.assertNotEqual(code, 0, output)
        self.assertIn("'gps_seed' must be >= 0", output)

    def test_a_drive_its_calibration_cannot_place_is_refused_before_playing(self):
        """Needs no ../shared. Found by review: with another day's calibration every image was
        refused, one error a frame, and the drive played on without its camera, exit 0; without
        a calibration the clouds played with no imu_link -> velo_link. Both stop at the start,
        naming the file or the folder searched (kitti2bag and semantic_map_offline do the same)."""
        def refusal(spoil):
            root = tempfile.mkdtemp(prefix='ism_refused_player_')
            try:
                drive = write_synthetic_drive(root)
                spoil(os.path.dirname(drive))
                player = subprocess.run(
                    [roslib.packages.find_node(PKG, 'kitti_player')[0], '__name:=refused_player',
                     '_drive_dir:=' + drive, '_wait_for_subscribers_s:=0'],
                    stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=30,
                    universal_newlines=True)
                return player.returncode, player.stdout, os.path.dirname(drive)
            finally:
                shutil.rmtree(root)

        def other_size(date_dir):
            path = os.path.join(date_dir, 'calib_cam_to_cam.txt')
            with open(path) as f:
                text = f.read()
            with open(path, 'w') as f:
                f.write(text.replace('S_rect_02: 40 30', 'S_rect_02: 41 30'))

        code, output, _ = refusal(other_size)
        self.assertNotEqual(code, 0, output)
        self.assertIn("0000000000.png: 40x30, the calibration's rectified size (S_rect) says 41x30",
                      output)
        self.assertNotIn('skipping frame', output)

        def no_calibration(date_dir):
            for name in ('calib_imu_to_velo.txt', 'calib_velo_to_cam.txt', 'calib_cam_to_cam.txt'):
                os.remove(os.path.join(date_dir, name))

        code, output, date_dir = refusal(no_calibration)
        self.assertNotEqual(code, 0, output)
        self.assertIn('velodyne_points/ and image_02/ need the calibration to be placed, and there '
                      'is none (no calib_*.txt in %s)' % date_dir, output)

    def test_synthetic_drive_with_lidar_and_camera(self):
        """Needs no ../shared: a second player on a drive the test writes, topics remapped."""
        got = {'cloud': [], 'image': [], 'info': [], 'tf': [], 'imu': []}
        subscribers = [
            rospy.Subscriber('/synth/velo', PointCloud2, lambda m: got['cloud'].append(m)),
            rospy.Subscriber('/synth/image', Image, lambda m: got['image'].append(m)),
            rospy.Subscriber('/synth/info', CameraInfo, lambda m: got['info'].append(m)),
            rospy.Subscriber('/synth/tf_static', TFMessage, lambda m: got['tf'].append(m)),
            rospy.Subscriber('/synth/imu', Imu, lambda m: got['imu'].append(m))]
        with synthetic_player('kitti_player_synth', 'synth', rate=2.0, paused='true',
                              exit_when_done='true') as player:
            rospy.wait_for_service('/kitti_player_synth/pause', timeout=30)
            # The drive has 3 frames: unpausing before every subscriber is connected to the
            # player (slow on a loaded machine) would lose the first frame.
            self.assertTrue(self.wait_for(
                lambda: all(sub.get_num_connections() > 0 for sub in subscribers), 30.0),
                'the player did not connect to %s' %
                [sub.name for sub in subscribers if sub.get_num_connections() == 0])
            time.sleep(0.5)
            rospy.ServiceProxy('/kitti_player_synth/pause', SetBool)(False)
            self.assertTrue(self.wait_for(lambda: all(len(got[k]) >= 3 for k in
                                                      ('cloud', 'image', 'info', 'imu')), 30.0),
                            {k: len(v) for k, v in got.items()})
            self.assertEqual(player.wait(timeout=30), 0)
        for k in ('cloud', 'image', 'info', 'imu'):
            self.assertEqual([m.header.stamp.to_nsec() for m in got[k]], SYNTHETIC_STAMPS, k)
        cloud = got['cloud'][0]
        self.assertEqual(cloud.header.frame_id, 'velo_link')
        self.assertEqual([f.name for f in cloud.fields], ['x', 'y', 'z', 'intensity', 'ring'])
        self.assertEqual(cloud.width, 108)
        ring_offset = cloud.fields[4].offset
        rings = [struct.unpack_from('<H', cloud.data, i * cloud.point_step + ring_offset)[0]
                 for i in range(cloud.width)]
        self.assertEqual(rings, [i // 36 for i in range(108)])
        image = got['image'][0]
        self.assertEqual((image.encoding, image.width, image.height), ('bgr8', 40, 30))
        self.assertEqual(bytes(image.data[:3]), bytes((10, 20, 30)))  # RGB (30,20,10) as BGR
        self.assertEqual(image.header.frame_id, 'camera_color_left')
        info = got['info'][0]
        self.assertEqual((info.width, info.height, info.P[0], info.P[3]), (40, 30, 400.0, 0.0))
        self.assertEqual(got['tf'][0].transforms[-2].child_frame_id, 'camera_color_left')

    def test_an_unpaused_player_waits_for_its_subscribers(self):
        """Needs no ../shared. A message published before its subscriber connects is lost: a
        player that played at once lost the drive's first fix (and the filter's start)."""
        got = {'imu': [], 'fix': []}
        with synthetic_player('kitti_player_wait', 'wait', rate=2.0, exit_when_done='true',
                              wait_for_subscribers_s=30.0) as player:
            rospy.wait_for_service('/kitti_player_wait/pause', timeout=30)
            # Without the wait the 3 frames (1 s at rate 2) would be gone by now.
            time.sleep(2.0)
            rospy.Subscriber('/wait/imu', Imu, lambda m: got['imu'].append(m))
            rospy.Subscriber('/wait/fix', NavSatFix, lambda m: got['fix'].append(m))
            self.assertTrue(self.wait_for(lambda: all(len(v) >= 3 for v in got.values()), 30.0),
                            {k: len(v) for k, v in got.items()})
            self.assertEqual(player.wait(timeout=30), 0)
        for key, messages in got.items():
            self.assertEqual([m.header.stamp.to_nsec() for m in messages], SYNTHETIC_STAMPS, key)

    def test_with_the_cloud_waited_for_a_late_map_gets_the_first_scans(self):
        """Needs no ../shared. Found by review: a map nodelet subscribes only once the manager
        has loaded the nodelets before it (a network), after the filter's topics; the player
        started on the IMU and the fix alone and the map lost the drive's first scans."""
        got = {'imu': [], 'fix': [], 'cloud': []}
        with synthetic_player('kitti_player_cloud', 'cloud', rate=2.0, exit_when_done='true',
                              wait_for_subscribers_s=30.0,
                              wait_for_cloud_subscriber='true') as player:
            rospy.wait_for_service('/kitti_player_cloud/pause', timeout=30)
            subscribers = [rospy.Subscriber('/cloud/imu', Imu, lambda m: got['imu'].append(m)),
                           rospy.Subscriber('/cloud/fix', NavSatFix,
                                            lambda m: got['fix'].append(m))]
            time.sleep(2.0)  # the map registers late: without the wait its scans are gone
            subscribers.append(rospy.Subscriber('/cloud/velo', PointCloud2,
                                                lambda m: got['cloud'].append(m)))
            self.assertTrue(self.wait_for(lambda: all(len(v) >= 3 for v in got.values()), 30.0),
                            {k: len(v) for k, v in got.items()})
            self.assertEqual(player.wait(timeout=30), 0)
            for subscriber in subscribers:
                subscriber.unregister()
        self.assertEqual([m.header.stamp.to_nsec() for m in got['imu']], SYNTHETIC_STAMPS)
        self.assertEqual(len(got['cloud']), 3)

    def test_a_second_clock_publisher_is_named_and_the_drive_still_plays(self):
        """Needs no ../shared. Two players (or a player and rosbag play --clock) on one master:
        time jumps back and forth and every node clears its tf buffer, with no word of why."""
        from rosgraph_msgs.msg import Clock
        other_clock = rospy.Publisher('/second/clock', Clock, queue_size=1)
        self.addCleanup(other_clock.unregister)
        log = tempfile.NamedTemporaryFile(mode='w+', suffix='.log')
        self.addCleanup(log.close)
        with synthetic_player('kitti_player_second_clock', 'second', output=log, rate=5.0,
                              exit_when_done='true', publish_clock='true',
                              wait_for_subscribers_s=0) as player:
            self.assertEqual(player.wait(timeout=30), 0)
        log.seek(0)
        output = log.read()
        self.assertIn('/second/clock is also published by ' + rospy.get_name(), output)
        self.assertIn('finished (', output)

    def test_plays_the_drive(self):
        oxts_dir = os.path.join(self.drive_dir, 'oxts')
        if not os.path.isdir(oxts_dir):
            print('\n*** SKIPPED kitti_player_test: shared data not found: %s\n' % oxts_dir,
                  file=sys.stderr)
            self.skipTest('shared data not found: %s' % oxts_dir)
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
