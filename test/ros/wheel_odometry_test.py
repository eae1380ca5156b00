#!/usr/bin/python3
"""rostest for inekf_node's wheel odometry (nav_msgs/Odometry on ~wheel_odom), live on the wall
clock.

The robot of simulated_robot.py (IMU at 100 Hz turned 90 deg without orientation, 5 Hz fixes of an
antenna 1.0 m ahead and 1.5 m up) drives a circle of 40 m radius at 8 m/s. Its wheel odometry
(20 Hz, 0.05 m/s of noise) is stated in the frame wheels_reversed, turned 180 deg from base_link:
the node must turn it through tf (its twist's x is minus the forward speed). From GPS_END_S the
fixes stop for OUTAGE_S and the accelerometer's forward bias steps by BIAS_STEP_MPS2, as a
warming MEMS sensor's may (on the circle the bias turns with the car, so the drift it causes
partly cancels: `rostest inekf_semantic_mapping wheel_odometry.test wheel_rate_hz:=0` prints the
error without the wheels).
Checks: the horizontal error at the end of the outage, the largest yaw error through it, and the
diagnostics' count of wheel speeds used.
"""
import math
import threading
import time
import unittest

import numpy as np
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry

from simulated_robot import fix_message, imu_and_fix_publishers, imu_message, truth, \
    wait_for_subscribers, yaw_error_deg

GPS_END_S, OUTAGE_S = 22.0, 15.0
BIAS_STEP_MPS2 = 0.4  # along base_link's x, from GPS_END_S on
WHEEL_SIGMA_MPS = 0.05
WHEEL_KEY = "wheel speeds used / rejected / stale / ignored / suspensions"


class WheelOdometryTest(unittest.TestCase):
    def test_wheels_hold_the_track_through_an_outage(self):
        rospy.init_node("wheel_odometry_test")
        wheel_rate_hz = rospy.get_param("~wheel_rate_hz", 20.0)
        imu_pub, fix_pub = imu_and_fix_publishers()
        wheel_pub = rospy.Publisher("/wheel_odom", Odometry, queue_size=50)
        lock = threading.Lock()
        odometry, diagnostics = [], {}

        def on_odometry(message):
            with lock:
                odometry.append(message)

        def on_diagnostics(message):
            for status in message.status:
                for item in status.values:
                    if item.key == WHEEL_KEY:
                        with lock:
                            diagnostics["wheels"] = item.value

        rospy.Subscriber("/inekf/odometry", Odometry, on_odometry, queue_size=1000)
        rospy.Subscriber("/diagnostics", DiagnosticArray, on_diagnostics, queue_size=20)
        wait_for_subscribers([imu_pub, fix_pub] + ([wheel_pub] if wheel_rate_hz > 0 else []))
        rng = np.random.default_rng(5)
        start = rospy.Time.now()
        truth_at = {}
        wheels_sent = 0
        wheel_every = int(round(100 / wheel_rate_hz)) if wheel_rate_hz > 0 else 0
        end_s = GPS_END_S + OUTAGE_S
        for k in range(int(end_s * 100) + 1):
            if rospy.is_shutdown():
                break
            t = 0.01 * k
            stamp = start + rospy.Duration(t)
            position, yaw, speed, _, yaw_rate, _ = truth(t)
            truth_at[stamp.to_nsec()] = (position, yaw)
            bias = (BIAS_STEP_MPS2 if t >= GPS_END_S else 0.0, 0.0, 0.0)
            imu_pub.publish(imu_message(stamp, t, bias))
            if k % 20 == 0 and t < GPS_END_S:
                fix_pub.publish(fix_message(stamp, t, rng))
            if wheel_every and k % wheel_every == 0:
                wheels = Odometry()
                wheels.header.stamp, wheels.header.frame_id = stamp, "odom"
                wheels.child_frame_id = "wheels_reversed"
                wheels.twist.twist.linear.x = -(speed + rng.normal(0.0, WHEEL_SIGMA_MPS))
                wheels.twist.twist.angular.z = yaw_rate
                wheels.twist.covariance[0] = WHEEL_SIGMA_MPS ** 2
                wheel_pub.publish(wheels)
                wheels_sent += 1
            time.sleep(max(0.0, (start + rospy.Duration(t + 0.01) - rospy.Time.now()).to_sec()))
        time.sleep(2.0)  # the last diagnostics
        with lock:
            poses = list(odometry)
            wheels = diagnostics.get("wheels")
        self.assertGreater(len(poses), 0.8 * end_s * 100, "odometry stopped")
        in_outage = [m for m in poses if (m.header.stamp - start).to_sec() >= GPS_END_S]
        self.assertGreater(len(in_outage), 0.8 * OUTAGE_S * 100, "no odometry through the outage")
        yaw_errors = []
        for message in in_outage:
            _, yaw = truth_at[message.header.stamp.to_nsec()]
            yaw_errors.append(yaw_error_deg(message.pose.pose.orientation, yaw))
        last = in_outage[-1]
        position, _ = truth_at[last.header.stamp.to_nsec()]
        p = last.pose.pose.position
        error_m = math.hypot(p.x - position[0], p.y - position[1])
        rospy.loginfo("wheel_odometry_test: wheel rate %.0f Hz, %d sent; diagnostics '%s'; after "
                      "%.0f s without fixes: horizontal error %.2f m, max yaw error %.2f deg",
                      wheel_rate_hz, wheels_sent, wheels, OUTAGE_S, error_m, max(yaw_errors))
        print("wheel_odometry_test: horizontal error %.2f m after the outage, max yaw error "
              "%.2f deg, wheel speeds %s of %d sent" % (error_m, max(yaw_errors), wheels,
                                                        wheels_sent))
        if wheel_rate_hz <= 0:
            return  # the figure without wheels, for the docs; nothing to check
        self.assertIsNotNone(wheels, "no '%s' in /diagnostics" % WHEEL_KEY)
        used = int(wheels.split("/")[0])
        # Those before the filter starts (at the first fix with IMU data) are not used.
        self.assertGreater(used, 0.8 * wheels_sent, wheels)
        self.assertLess(error_m, 4.0)
        self.assertLess(max(yaw_errors), 3.0)


if __name__ == "__main__":
    rostest.rosrun("inekf_semantic_mapping", "wheel_odometry_test", WheelOdometryTest)
