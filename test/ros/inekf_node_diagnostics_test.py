#!/usr/bin/python3
"""rostest: inekf_node's /diagnostics status goes OK -> WARN -> ERROR while IMU messages come and
no GPS fix ever does (the timeouts are the .test file's diagnostics/* parameters)."""
import sys
import threading
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import Imu

PKG = "inekf_semantic_mapping"
STATUS = "inekf_node: localization"


class InekfNodeDiagnostics(unittest.TestCase):
    def test_without_fixes_the_status_turns_warn_then_error(self):
        rospy.init_node("inekf_node_diagnostics_test")
        lock = threading.Lock()
        seen = []  # (wall time, level, message, number of values)

        def on_diagnostics(array):
            for status in array.status:
                # (diagnostic_updater's placeholder "Node starting up" has no values)
                if status.name.endswith(STATUS) and status.message != "Node starting up":
                    with lock:
                        seen.append((time.time(), status.level, status.message, len(status.values)))

        rospy.Subscriber("/diagnostics", DiagnosticArray, on_diagnostics, queue_size=50)
        imu = rospy.Publisher("/kitti/oxts/imu", Imu, queue_size=50)
        deadline = time.time() + 20
        while imu.get_num_connections() == 0 and time.time() < deadline:
            time.sleep(0.1)
        self.assertGreater(imu.get_num_connections(), 0, "inekf_node did not subscribe")
        message = Imu()
        message.header.frame_id = "imu_link"
        message.orientation.w = 1.0
        message.linear_acceleration.z = 9.81
        stamp = [rospy.Time.now()]

        def play(seconds, until=lambda: False):
            """IMU at 10 Hz of data time, paced by the wall clock, for `seconds` or until
            `until()`."""
            began = time.time()
            while time.time() - began < seconds and not until():
                message.header.stamp = stamp[0]
                imu.publish(message)
                stamp[0] += rospy.Duration(0.1)
                time.sleep(0.1)

        def error_seen():
            with lock:
                return any(level == DiagnosticStatus.ERROR for _, level, _, _ in seen)

        start = time.time()
        play(15, until=error_seen)
        with lock:
            record = list(seen)
        levels = [level for _, level, _, _ in record]
        sys.stderr.write("inekf_node diagnostics: %s\n" % [(round(t - start, 1), l, m)
                                                          for t, l, m, _ in record])
        self.assertTrue(record, "no %s status on /diagnostics" % STATUS)
        self.assertGreaterEqual(min(n for _, _, _, n in record), 3)
        self.assertIn(DiagnosticStatus.WARN, levels)
        self.assertIn(DiagnosticStatus.ERROR, levels)
        self.assertLess(levels.index(DiagnosticStatus.WARN), levels.index(DiagnosticStatus.ERROR))
        error_message = [m for _, l, m, _ in record if l == DiagnosticStatus.ERROR][0]
        self.assertIn("no accepted GPS fix", error_message)
        # ~diagnostic_period 0.25 s (was ignored: always 1 s).
        intervals = sorted(b[0] - a[0] for a, b in zip(record, record[1:]))
        self.assertGreaterEqual(len(intervals), 3, record)
        self.assertLess(intervals[len(intervals) // 2], 0.6, intervals)

        # A period set while running is followed (it was read once, at the start).
        rospy.set_param("/inekf_node/diagnostic_period", 1.5)
        time.sleep(1.0)  # the old period's tick reads the new value
        with lock:
            del seen[:]
        play(6.5)
        with lock:
            stamps = [t for t, _, _, _ in seen]
        intervals = sorted(b - a for a, b in zip(stamps, stamps[1:]))
        sys.stderr.write("after ~diagnostic_period 1.5: intervals %s\n" % intervals)
        self.assertGreaterEqual(len(intervals), 2, stamps)
        self.assertGreater(intervals[len(intervals) // 2], 1.2, intervals)


if __name__ == "__main__":
    rostest.rosrun(PKG, "inekf_node_diagnostics_test", InekfNodeDiagnostics, sys.argv)
