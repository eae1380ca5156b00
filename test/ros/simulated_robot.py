"""The simulated robot of the live rostests (own_robot_test.py, wheel_odometry_test.py): its path
and the messages of its IMU and GPS.

A car stands REST_S, speeds up at ACCEL_MPS2 to SPEED_MPS and drives a circle of RADIUS_M. Its IMU
(frame imu_turned) is mounted turned 90 deg about base_link's z axis and gives no orientation; its
GPS is of an antenna ANTENNA_IN_BASE from base_link (frame gps_antenna). The .test files publish
the static tf.
"""
import math
import time

import numpy as np
import rospy
from sensor_msgs.msg import Imu, NavSatFix, NavSatStatus

LAT0, LON0, ALT0 = 48.0, 11.0, 500.0
EARTH_RADIUS_M = 6378137.0
RADIUS_M, SPEED_MPS, ACCEL_MPS2, REST_S = 40.0, 8.0, 2.0, 2.0
YAW0 = math.radians(30.0)
GRAVITY = 9.81
BASE_FROM_IMU = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # yaw 90 deg
ANTENNA_IN_BASE = np.array([1.0, 0.0, 1.5])
LIDAR_HEIGHT_M = 1.8
WALL_RADIUS_M = 55.0  # around the circle's centre


def rotation_z(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def truth(t):
    """base_link's position (map, east-north-up from the start), yaw, speed, acceleration along
    the path and yaw rate at t seconds."""
    if t < REST_S:
        along, speed, accel = 0.0, 0.0, 0.0
    else:
        ta, t_full = t - REST_S, SPEED_MPS / ACCEL_MPS2
        if ta < t_full:
            along, speed, accel = 0.5 * ACCEL_MPS2 * ta * ta, ACCEL_MPS2 * ta, ACCEL_MPS2
        else:
            along = 0.5 * ACCEL_MPS2 * t_full ** 2 + SPEED_MPS * (ta - t_full)
            speed, accel = SPEED_MPS, 0.0
    yaw = YAW0 + along / RADIUS_M
    centre = np.array([-RADIUS_M * math.sin(YAW0), RADIUS_M * math.cos(YAW0), 0.0])
    position = centre + RADIUS_M * np.array([math.sin(yaw), -math.cos(yaw), 0.0])
    return position, yaw, speed, accel, speed / RADIUS_M, centre


def geodetic(p):
    lat = LAT0 + math.degrees(p[1] / EARTH_RADIUS_M)
    lon = LON0 + math.degrees(p[0] / (EARTH_RADIUS_M * math.cos(math.radians(LAT0))))
    return lat, lon, ALT0 + p[2]


def imu_and_fix_publishers():
    """The publishers of the robot's IMU (/imu/data) and GPS (/gps/fix)."""
    return (rospy.Publisher("/imu/data", Imu, queue_size=200),
            rospy.Publisher("/gps/fix", NavSatFix, queue_size=20))


def wait_for_subscribers(publishers, timeout_s=30.0):
    """Until each publisher has a subscriber (a message sent before is lost), and 1 s more."""
    deadline = time.time() + timeout_s
    while any(p.get_num_connections() == 0 for p in publishers) and time.time() < deadline:
        time.sleep(0.1)
    time.sleep(1.0)


def imu_message(stamp, t, force_bias_in_base=(0.0, 0.0, 0.0)):
    """The IMU's sample at t (frame imu_turned, no orientation), its specific force offset by a
    bias stated in base_link's axes."""
    _, _, speed, accel, yaw_rate, _ = truth(t)
    imu = Imu()
    imu.header.stamp, imu.header.frame_id = stamp, "imu_turned"
    gyro = BASE_FROM_IMU.T.dot([0.0, 0.0, yaw_rate])
    force = BASE_FROM_IMU.T.dot(np.add([accel, speed * yaw_rate, GRAVITY], force_bias_in_base))
    imu.angular_velocity.x, imu.angular_velocity.y, imu.angular_velocity.z = gyro
    imu.linear_acceleration.x, imu.linear_acceleration.y, imu.linear_acceleration.z = force
    imu.orientation_covariance[0] = -1.0  # sensor_msgs: no orientation
    return imu


def fix_message(stamp, t, rng, sigma_h_m=0.3):
    """The antenna's fix at t (frame gps_antenna), horizontal noise sigma_h_m, its covariance
    stated."""
    position, yaw = truth(t)[:2]
    antenna = position + rotation_z(yaw).dot(ANTENNA_IN_BASE)
    antenna[:2] += rng.normal(0.0, sigma_h_m, 2)
    fix = NavSatFix()
    fix.header.stamp, fix.header.frame_id = stamp, "gps_antenna"
    fix.status.status, fix.status.service = NavSatStatus.STATUS_FIX, NavSatStatus.SERVICE_GPS
    fix.latitude, fix.longitude, fix.altitude = geodetic(antenna)
    fix.position_covariance = [sigma_h_m ** 2, 0, 0, 0, sigma_h_m ** 2, 0, 0, 0, 0.25]
    fix.position_covariance_type = NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
    return fix


def yaw_of(quaternion):
    q = quaternion
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y ** 2 + q.z ** 2))


def yaw_error_deg(quaternion, yaw):
    return abs(math.degrees(math.remainder(yaw_of(quaternion) - yaw, 2 * math.pi)))
