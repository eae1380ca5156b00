#!/usr/bin/python3
"""rostest node for inekf_node (test/ros/inekf_node*.test).

Plays a real KITTI OXTS drive from ../shared into inekf_node the way kitti_player does
(/kitti/oxts/imu with the OXTS orientation, /kitti/oxts/gps/fix degraded by Gaussian noise and
used every N-th frame, STATUS_NO_FIX where posmode <= 0, /kitti/oxts/gps/vel), faster than real
time, and checks what the node publishes against the OXTS truth of the same frames:
RMS position error under a margin, no NaN, a symmetric positive-definite pose covariance, tf
map -> base_link, FilterStatus. Optionally injects a duplicate and an out-of-order IMU message
(~inject_faults) and replays the start of the drive (~loop_frames: time jumps back as in a bag
loop: the node must reset and localize again). Skips loudly (and passes) without ../shared.

With ~source:=kitti_player the test publishes nothing: kitti_player (started paused by the
.test) plays the drive, the test resumes it through ~pause and compares /inekf/odometry with
/kitti/oxts/ground_truth at the same stamps.

With ~imu_mount_yaw_deg the IMU is mounted turned by that angle about base_link's z axis (frame
imu_turned; the .test publishes the tf): its rates, accelerations, orientation and body-frame
velocity are those of the turned axes (the velocity's in base_link's with ~velocity_in_base). With ~antenna_in_base ([x, y, z] m) the fixes are of a GPS
antenna there (frame gps_antenna; the .test publishes the tf), not of the IMU. With
~imu_orientation false the IMU messages carry no orientation (the heading is unknown until the GPS
track aligns it): errors count after ~settle_s, and tf map -> base_link must wait for the heading.

Parameters (private): source (self | kitti_player), drive, first_frame, frames, rate, gps_every,
gps_sigma_h, gps_sigma_v, seed, max_rms_m, inject_faults, loop_frames, player_frames,
imu_mount_yaw_deg, antenna_in_base, velocity_in_base, imu_orientation, settle_s.
"""

import math
import os
import sys
import time
import unittest

import numpy as np
import rospy
import tf2_ros
from geometry_msgs.msg import TwistStamped
from nav_msgs.msg import Odometry, Path
from sensor_msgs.msg import Imu, NavSatFix, NavSatStatus
from std_srvs.srv import SetBool, Trigger

from inekf_semantic_mapping.msg import FilterStatus

PACKAGE = "inekf_semantic_mapping"
REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.realpath(__file__))))
sys.path.insert(0, os.path.join(REPO_ROOT, "scripts"))
from evaluate_trajectory import kitti_timestamp_parts  # noqa: E402  (the one KITTI stamp parser)
EARTH_RADIUS_M = 6378137.0  # the KITTI devkit's er


def shared_dir():
    return os.environ.get("ISM_SHARED_DIR") or os.path.join(os.path.dirname(REPO_ROOT), "shared")


def rotation_rpy(roll, pitch, yaw):
    """Rz(yaw) Ry(pitch) Rx(roll): the OXTS body -> map rotation (KITTI devkit)."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def quaternion_rpy(roll, pitch, yaw):
    """(x, y, z, w) of Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


class OxtsDrive:
    """The frames of a KITTI raw oxts/ folder and their truth positions in the map frame (devkit
    Mercator at frame 0; the .test sets inekf_node's origin to that same fix)."""

    def __init__(self, oxts_dir, first_frame, frames):
        with open(os.path.join(oxts_dir, "timestamps.txt")) as stream:
            stamps = [kitti_timestamp_parts(line) for line in stream if line.strip()]
        last = min(len(stamps), first_frame + frames)
        self.records, self.stamps = [], []
        for index in range(first_frame, last):
            with open(os.path.join(oxts_dir, "data", "%010d.txt" % index)) as stream:
                self.records.append([float(v) for v in stream.read().split()])
            self.stamps.append(rospy.Time(*stamps[index]))
        lat0, lon0, alt0 = self.records[0][:3]
        self.scale = math.cos(math.radians(lat0))
        self.origin = self.mercator(lat0, lon0, alt0)
        self.truth = {stamp.to_nsec(): self.mercator(*record[:3]) - self.origin
                      for stamp, record in zip(self.stamps, self.records)}
        self.origin_fix = (lat0, lon0, alt0)

    def mercator(self, lat, lon, alt):
        return np.array([self.scale * math.radians(lon) * EARTH_RADIUS_M,
                         self.scale * EARTH_RADIUS_M * math.log(math.tan(math.radians(90.0 + lat) / 2)),
                         alt])


class InekfNodeTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("inekf_node_test", anonymous=True)
        cls.drive_name = rospy.get_param("~drive", "2011_09_30/2011_09_30_drive_0027_sync")
        cls.oxts_dir = os.path.join(shared_dir(), "data", "kitti_raw", cls.drive_name, "oxts")
        cls.odometry, cls.paths, cls.statuses = [], [], []
        rospy.Subscriber("/inekf/odometry", Odometry, cls.odometry.append, queue_size=1000)
        rospy.Subscriber("/inekf/path", Path, cls.paths.append, queue_size=10)
        rospy.Subscriber("/inekf/status", FilterStatus, cls.statuses.append, queue_size=1000)
        cls.imu_publisher = rospy.Publisher("/kitti/oxts/imu", Imu, queue_size=100)
        cls.fix_publisher = rospy.Publisher("/kitti/oxts/gps/fix", NavSatFix, queue_size=100)
        cls.velocity_publisher = rospy.Publisher("/kitti/oxts/gps/vel", TwistStamped, queue_size=100)
        cls.ground_truth = {}
        rospy.Subscriber("/kitti/oxts/ground_truth", Odometry, cls.on_ground_truth, queue_size=1000)
        cls.tf_buffer = tf2_ros.Buffer(cache_time=rospy.Duration(1e6))
        cls.tf_listener = tf2_ros.TransformListener(cls.tf_buffer)
        # base_link -> the IMU frame (the OXTS body is base_link).
        cls.mount_yaw = math.radians(rospy.get_param("~imu_mount_yaw_deg", 0.0))
        cls.imu_frame = "imu_turned" if cls.mount_yaw != 0.0 else "imu_link"
        cls.base_from_imu = rotation_rpy(0.0, 0.0, cls.mount_yaw)
        cls.antenna_in_base = np.array(rospy.get_param("~antenna_in_base", [0.0, 0.0, 0.0]))
        cls.imu_orientation = rospy.get_param("~imu_orientation", True)
        cls.velocity_in_base = rospy.get_param("~velocity_in_base", False)

    def in_imu_axes(self, vector):
        return self.base_from_imu.T.dot(np.array(vector))

    def setUp(self):
        if self._testMethodName.startswith("test_0_"):
            return  # needs no data
        if not os.path.isdir(self.oxts_dir):
            sys.stderr.write("\n*** SKIPPED: shared data not found: %s\n*** (put the shared/ data "
                             "folder beside the repository to run this test)\n" % self.oxts_dir)
            self.skipTest("shared data not found: %s" % self.oxts_dir)

    @classmethod
    def on_ground_truth(cls, message):
        p = message.pose.pose.position
        cls.ground_truth[message.header.stamp.to_nsec()] = np.array([p.x, p.y, p.z])

    # ---------------------------------------------------------------------------------------
    def wait_for_node(self, timeout_s=30.0):
        deadline = time.time() + timeout_s
        while time.time() < deadline and not rospy.is_shutdown():
            if (self.imu_publisher.get_num_connections() > 0 and
                    self.fix_publisher.get_num_connections() > 0):
                time.sleep(0.5)  # let the node's other subscriptions connect too
                return
            time.sleep(0.1)
        self.fail("inekf_node did not subscribe to /kitti/oxts/imu and /kitti/oxts/gps/fix "
                  "within %.0f s" % timeout_s)

    def imu_message(self, record, stamp):
        message = Imu()
        message.header.stamp = stamp
        message.header.frame_id = self.imu_frame
        (message.angular_velocity.x, message.angular_velocity.y,
         message.angular_velocity.z) = self.in_imu_axes(record[17:20])
        (message.linear_acceleration.x, message.linear_acceleration.y,
         message.linear_acceleration.z) = self.in_imu_axes(record[11:14])
        roll, pitch, yaw = record[3:6]
        if self.mount_yaw != 0.0:
            r = rotation_rpy(roll, pitch, yaw).dot(self.base_from_imu)
            roll, pitch, yaw = (math.atan2(r[2, 1], r[2, 2]), math.asin(-r[2, 0]),
                                math.atan2(r[1, 0], r[0, 0]))
        q = quaternion_rpy(roll, pitch, yaw)
        message.orientation.x, message.orientation.y, message.orientation.z, message.orientation.w = q
        message.orientation_covariance = [1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4]
        if not self.imu_orientation:
            message.orientation.x = message.orientation.y = message.orientation.z = 0.0
            message.orientation.w = 1.0
            message.orientation_covariance = [-1.0, 0, 0, 0, 0, 0, 0, 0, 0]  # sensor_msgs: none
        return message

    def fix_message(self, record, stamp, noise_m, sigma_h, sigma_v):
        message = NavSatFix()
        message.header.stamp = stamp
        message.header.frame_id = "imu_link"
        lat, lon, alt = record[:3]
        if self.antenna_in_base.any():
            # The antenna, not the OXTS unit (base_link): its lever arm turned into east-north-up.
            message.header.frame_id = "gps_antenna"
            noise_m = np.asarray(noise_m) + rotation_rpy(*record[3:6]).dot(self.antenna_in_base)
        # Noise in metres (east, north, up) turned into degrees on the local sphere.
        message.latitude = lat + math.degrees(noise_m[1] / EARTH_RADIUS_M)
        message.longitude = lon + math.degrees(noise_m[0] / (EARTH_RADIUS_M * math.cos(math.radians(lat))))
        message.altitude = alt + noise_m[2]
        message.status.service = NavSatStatus.SERVICE_GPS
        message.status.status = NavSatStatus.STATUS_FIX if record[27] > 0 else NavSatStatus.STATUS_NO_FIX
        message.position_covariance = [sigma_h ** 2, 0, 0, 0, sigma_h ** 2, 0, 0, 0, sigma_v ** 2]
        message.position_covariance_type = NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
        return message

    def velocity_message(self, record, stamp):
        message = TwistStamped()
        message.header.stamp = stamp
        message.header.frame_id = self.imu_frame  # kitti2bag: body-frame vf, vl, vu
        (message.twist.linear.x, message.twist.linear.y,
         message.twist.linear.z) = self.in_imu_axes(record[8:11])
        if self.velocity_in_base:  # the OXTS body is base_link
            message.header.frame_id = "base_link"
            message.twist.linear.x, message.twist.linear.y, message.twist.linear.z = record[8:11]
        return message

    def play(self, drive, rate, gps_every, sigma_h, sigma_v, rng, frames=None, faults=False,
             fix_before_imu=False, fix_delay_frames=0, reset_at_frame=0):
        """Publishes the drive's frames at `rate` times real time. With faults: a duplicate of
        frame 100's IMU message, at frame 120 an IMU message and a fix with a NaN, and at frame
        150 the IMU message of frame 145 (out of order). With fix_before_imu: frame 0's fix
        reaches the node well before frame 0's IMU and velocity messages (which of the
        connections delivers first is otherwise a race). With fix_delay_frames: each fix after
        the first is published that many frames after its own (a GPS receiver or link that is
        slower than the IMU). With reset_at_frame: the node's ~reset service is called before
        that frame; its response is kept in self.reset_response."""
        count = len(drive.records) if frames is None else min(frames, len(drive.records))
        delayed_fixes = []  # (frame index to publish at, message)
        for index in range(count):
            if rospy.is_shutdown():
                return
            record, stamp = drive.records[index], drive.stamps[index]
            first_fix_early = fix_before_imu and index == 0
            if first_fix_early:
                noise = rng.standard_normal(3) * [sigma_h, sigma_h, sigma_v]
                self.fix_publisher.publish(self.fix_message(record, stamp, noise, sigma_h, sigma_v))
                time.sleep(0.3)
            if reset_at_frame and index == reset_at_frame:
                time.sleep(0.3)  # the frames before it through first (another connection)
                self.reset_response = rospy.ServiceProxy("/inekf_node/reset", Trigger)()
            imu = self.imu_message(record, stamp)
            self.velocity_publisher.publish(self.velocity_message(record, stamp))
            self.imu_publisher.publish(imu)
            if faults and index == 100:
                self.imu_publisher.publish(imu)  # duplicate stamp
            if faults and index == 150:
                self.imu_publisher.publish(self.imu_message(drive.records[145], drive.stamps[145]))
            if faults and index == 120:
                broken = self.imu_message(record, stamp + rospy.Duration(0.01))
                broken.linear_acceleration.y = float("nan")  # must be ignored, never integrated
                self.imu_publisher.publish(broken)
                broken_fix = self.fix_message(record, stamp, [0, 0, 0], sigma_h, sigma_v)
                broken_fix.latitude = float("nan")
                self.fix_publisher.publish(broken_fix)
            if index % gps_every == 0 and not first_fix_early:
                noise = rng.standard_normal(3) * [sigma_h, sigma_h, sigma_v]
                fix = self.fix_message(record, stamp, noise, sigma_h, sigma_v)
                delayed_fixes.append((index + (fix_delay_frames if index > 0 else 0), fix))
            while delayed_fixes and delayed_fixes[0][0] <= index:
                self.fix_publisher.publish(delayed_fixes.pop(0)[1])
            if index + 1 < count:
                time.sleep(max(0.0, (drive.stamps[index + 1] - stamp).to_sec() / rate))
        time.sleep(1.0)  # let the last messages through

    def position_errors(self, drive, odometry):
        errors = []
        for message in odometry:
            # The node republishes the IMU message's stamp: exact (a rounded one would be a bug).
            truth = drive.truth.get(message.header.stamp.to_nsec())
            self.assertIsNotNone(truth, "odometry stamp %s is not a frame stamp" % message.header.stamp)
            p = message.pose.pose.position
            errors.append(np.linalg.norm(np.array([p.x, p.y, p.z]) - truth))
        return np.array(errors)

    def max_yaw_error_deg(self, drive, odometry):
        """Largest |yaw error| against the OXTS yaw (KITTI: 0 = east, counterclockwise = map)."""
        truth_yaw = {stamp.to_nsec(): record[5] for stamp, record in zip(drive.stamps, drive.records)}
        worst = 0.0
        for message in odometry:
            q = message.pose.pose.orientation
            yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y ** 2 + q.z ** 2))
            error = yaw - truth_yaw[message.header.stamp.to_nsec()]
            worst = max(worst, abs(math.degrees(math.atan2(math.sin(error), math.cos(error)))))
        return worst

    def check_odometry_messages(self, odometry):
        for message in odometry:
            p, q = message.pose.pose.position, message.pose.pose.orientation
            values = [p.x, p.y, p.z, q.x, q.y, q.z, q.w] + list(message.pose.covariance)
            self.assertTrue(all(math.isfinite(v) for v in values), "NaN in %s" % message.header)
            self.assertAlmostEqual(q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2, 1.0, places=6)
            self.assertEqual(message.header.frame_id, "map")
            self.assertEqual(message.child_frame_id, "base_link")
            covariance = np.array(message.pose.covariance).reshape(6, 6)
            np.testing.assert_allclose(covariance, covariance.T, atol=1e-9 * np.abs(covariance).max())
            self.assertGreater(np.linalg.eigvalsh(covariance).min(), 0.0,
                               "pose covariance not positive definite at %s" % message.header.stamp)

    # ---------------------------------------------------------------------------------------
    def test_0_a_misspelt_parameter_stops_a_second_node_with_its_name(self):
        from strict_parameters import run_with_parameters
        code, output = run_with_parameters("inekf_node", "misspelt_parameter_inekf_node",
                                           {"filtr": "left"})
        self.assertNotEqual(code, 0, output)
        self.assertIn("filtr", output)
        self.assertIn("misspelt_parameter_inekf_node", output)
        # The filter's name is `filter`; the old spelling is still read, but not beside the new
        # one (which of the two would win?).
        code, output = run_with_parameters("inekf_node", "filter_type_inekf_node",
                                           {"filter_type": "left", "filter": "right"})
        self.assertNotEqual(code, 0, output)
        self.assertIn("renamed to 'filter', which is set too", output)
        # The parameters that override the file's keys get the file's checks (they were taken
        # as they came: a negative sigma started the node).
        code, output = run_with_parameters("inekf_node", "negative_sigma_inekf_node",
                                           {"default_fix_sigma_horizontal_m": -1})
        self.assertNotEqual(code, 0, output)
        self.assertIn("'default_fix_sigma_horizontal_m' must be in (0, ", output)

    def test_localizes_a_real_drive(self):
        if rospy.get_param("~source", "self") == "kitti_player":
            self.check_drive_played_by_kitti_player()
        else:
            self.check_drive_played_by_this_test()

    def check_drive_played_by_kitti_player(self):
        max_rms_m = rospy.get_param("~max_rms_m", 5.0)
        player_frames = rospy.get_param("~player_frames", 450)
        self.wait_for_node_to_subscribe("/kitti/oxts/imu")
        rospy.wait_for_service("/kitti_player/pause", timeout=30.0)
        rospy.ServiceProxy("/kitti_player/pause", SetBool)(False)  # start playing
        # Played once (no loop): done when odometry stops arriving.
        deadline, last_count, quiet_since = time.time() + 75.0, -1, time.time()
        while time.time() < deadline and not rospy.is_shutdown():
            if len(self.odometry) != last_count:
                last_count, quiet_since = len(self.odometry), time.time()
            elif last_count > 0 and time.time() - quiet_since > 2.0:
                break
            time.sleep(0.2)
        odometry = list(self.odometry)
        self.assertGreater(len(odometry), 0.8 * player_frames,
                           "%d odometry messages for about %d frames" % (len(odometry), player_frames))
        self.check_odometry_messages(odometry)
        errors = []
        for message in odometry:
            truth = self.ground_truth.get(message.header.stamp.to_nsec())
            self.assertIsNotNone(truth, "no ground truth at the odometry stamp %s" % message.header.stamp)
            p = message.pose.pose.position
            errors.append(np.linalg.norm(np.array([p.x, p.y, p.z]) - truth))
        errors = np.array(errors)
        rms = float(np.sqrt(np.mean(errors ** 2)))
        sys.stderr.write("\n[inekf_node_test] kitti_player %s: position RMS %.2f m (max %.2f m) "
                         "over %d poses\n" % (self.drive_name, rms, errors.max(), len(errors)))
        self.assertLess(rms, max_rms_m)
        self.tf_buffer.lookup_transform("map", "base_link", rospy.Time(0), rospy.Duration(2.0))
        self.assertTrue(self.statuses, "no FilterStatus on /inekf/status")
        self.assertGreater(self.statuses[-1].gps_fixes_used, 0)

    def wait_for_node_to_subscribe(self, topic, timeout_s=30.0):
        import rosgraph
        master = rosgraph.Master(rospy.get_name())
        deadline = time.time() + timeout_s
        while time.time() < deadline and not rospy.is_shutdown():
            _, subscribers, _ = master.getSystemState()
            if any(name == topic and "/inekf_node" in nodes for name, nodes in subscribers):
                return
            time.sleep(0.2)
        self.fail("inekf_node did not subscribe to %s within %.0f s" % (topic, timeout_s))

    def check_drive_played_by_this_test(self):
        first_frame = rospy.get_param("~first_frame", 0)
        frames = rospy.get_param("~frames", 450)
        rate = rospy.get_param("~rate", 10.0)
        gps_every = rospy.get_param("~gps_every", 10)
        sigma_h = rospy.get_param("~gps_sigma_h", 1.5)
        sigma_v = rospy.get_param("~gps_sigma_v", 3.0)
        max_rms_m = rospy.get_param("~max_rms_m", 5.0)
        inject_faults = rospy.get_param("~inject_faults", False)
        loop_frames = rospy.get_param("~loop_frames", 0)
        fix_before_imu = rospy.get_param("~first_fix_before_imu", False)
        fix_delay_frames = rospy.get_param("~fix_delay_frames", 0)
        max_yaw_error_deg = rospy.get_param("~max_yaw_error_deg", 5.0)
        settle_s = rospy.get_param("~settle_s", 0.0)
        reset_at_frame = rospy.get_param("~reset_at_frame", 0)
        rng = np.random.default_rng(rospy.get_param("~seed", 1))
        drive = OxtsDrive(self.oxts_dir, first_frame, frames)
        self.wait_for_node()

        if reset_at_frame:
            rospy.wait_for_service("/inekf_node/reset", timeout=10.0)
        self.play(drive, rate, gps_every, sigma_h, sigma_v, rng, faults=inject_faults,
                  fix_before_imu=fix_before_imu, fix_delay_frames=fix_delay_frames,
                  reset_at_frame=reset_at_frame)
        first_pass = list(self.odometry)
        self.assertGreater(len(first_pass), 0.8 * len(drive.records),
                           "inekf_node published %d odometry messages for %d IMU frames" %
                           (len(first_pass), len(drive.records)))
        self.check_odometry_messages(first_pass)
        settled = [m for m in first_pass
                   if (m.header.stamp - first_pass[0].header.stamp).to_sec() >= settle_s]
        errors = self.position_errors(drive, settled)
        rms = float(np.sqrt(np.mean(errors ** 2)))
        yaw_error = self.max_yaw_error_deg(drive, settled)
        rospy.loginfo("inekf_node_test: %s frames %d..%d: %d odometry messages, position RMS "
                      "%.2f m, max %.2f m, max |yaw error| %.2f deg", self.drive_name, first_frame,
                      first_frame + frames - 1, len(first_pass), rms, errors.max(), yaw_error)
        sys.stderr.write("\n[inekf_node_test] %s: position RMS %.2f m (max %.2f m) over %d poses, "
                         "max |yaw error| %.2f deg\n" %
                         (self.drive_name, rms, errors.max(), len(errors), yaw_error))
        self.assertLess(rms, max_rms_m)
        self.assertLess(yaw_error, max_yaw_error_deg)
        # The node kept publishing up to the end of the drive.
        self.assertEqual(first_pass[-1].header.stamp, drive.stamps[-1])

        transform = self.tf_buffer.lookup_transform("map", "base_link", rospy.Time(0),
                                                    rospy.Duration(2.0))
        last = first_pass[-1].pose.pose.position
        self.assertAlmostEqual(transform.transform.translation.x, last.x, places=6)
        self.assertAlmostEqual(transform.transform.translation.y, last.y, places=6)
        if not self.imu_orientation:
            # tf waited while the heading was unknown (the odometry says so in its yaw variance):
            # none at the first pose, from the first pose whose heading sigma is below 10 deg on.
            def heading_sigma_deg(message):
                return math.degrees(math.sqrt(max(0.0, message.pose.covariance[35])))
            self.assertGreater(heading_sigma_deg(first_pass[0]), 10.0)
            self.assertFalse(self.tf_buffer.can_transform("map", "base_link",
                                                          first_pass[0].header.stamp))
            known = next(m for m in first_pass if heading_sigma_deg(m) <= 10.0)
            self.assertTrue(self.tf_buffer.can_transform("map", "base_link", known.header.stamp))
            sys.stderr.write("[inekf_node_test] heading known %.1f s after the first pose: tf "
                             "from then on\n" % (known.header.stamp - first_pass[0].header.stamp).to_sec())

        self.assertTrue(self.statuses, "no FilterStatus on /inekf/status")
        status = self.statuses[-1]
        expected_fixes = len(range(0, len(drive.records), gps_every))
        self.assertGreater(status.gps_fixes_used, 0.5 * expected_fixes)
        self.assertGreater(status.imu_samples, 0.8 * len(drive.records))
        for bias in (status.gyro_bias, status.accel_bias):
            self.assertTrue(all(math.isfinite(v) for v in (bias.x, bias.y, bias.z)))
        if inject_faults:
            self.assertGreaterEqual(status.imu_samples_dropped, 3,
                                    "the duplicate, NaN and out-of-order IMU messages were not counted")
            self.assertGreaterEqual(status.gps_fixes_rejected, 1, "the NaN fix was not counted")
        self.assertTrue(self.paths and len(self.paths[-1].poses) > 0, "no path on /inekf/path")
        if reset_at_frame:
            # ~reset: the filter started over at the next fix and went on; the path holds only
            # poses from then on.
            self.assertTrue(self.reset_response.success, self.reset_response.message)
            self.assertEqual(status.resets, 1)
            reset_stamp = drive.stamps[reset_at_frame - 1]
            self.assertGreater(self.paths[-1].poses[0].header.stamp, reset_stamp)
            after = [m for m in first_pass if m.header.stamp > reset_stamp]
            restart = after[0].header.stamp
            self.assertLessEqual((restart - reset_stamp).to_sec(), gps_every * 0.1 + 0.15,
                                 "no start at the first fix after the reset")
            sys.stderr.write("[inekf_node_test] ~reset before frame %d: started again %.2f s "
                             "later\n" % (reset_at_frame, (restart - reset_stamp).to_sec()))

        if loop_frames > 0:
            # Time jumps back to the start of the drive: the node must reset and localize again.
            del self.odometry[:]
            del self.paths[:]
            self.play(drive, rate, gps_every, sigma_h, sigma_v, rng, frames=loop_frames,
                      fix_delay_frames=fix_delay_frames)
            second_pass = list(self.odometry)
            self.assertGreater(len(second_pass), 0.8 * loop_frames,
                               "inekf_node stopped publishing after the time jump back")
            self.check_odometry_messages(second_pass)
            loop_errors = self.position_errors(drive, second_pass)
            loop_rms = float(np.sqrt(np.mean(loop_errors ** 2)))
            sys.stderr.write("[inekf_node_test] after the loop: position RMS %.2f m over %d poses\n" %
                             (loop_rms, len(loop_errors)))
            self.assertLess(loop_rms, max_rms_m)
            # The path was cleared: it holds only poses of the second pass.
            self.assertTrue(self.paths, "no path after the loop")
            path = self.paths[-1]
            self.assertLessEqual(len(path.poses), loop_frames)
            self.assertLessEqual(path.poses[-1].header.stamp, drive.stamps[loop_frames - 1])


if __name__ == "__main__":
    import rostest
    rostest.rosrun(PACKAGE, "inekf_node_test", InekfNodeTest)
