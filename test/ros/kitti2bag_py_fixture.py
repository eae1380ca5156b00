#!/usr/bin/python3
"""Test fixture: writes a KITTI raw drive into a bag the way the Python kitti2bag does
(tomas789/kitti2bag with pykitti, `kitti2bag -t DATE -r DRIVE raw_synced BASEDIR`), which cannot
be run here. Every convention of that tool that this package has to cope with:

- /tf: world -> base_link at every OXTS stamp, the OXTS pose (pykitti T_w_imu: devkit Mercator
  with the scale of the first fix, origin at the first pose, R = Rz(yaw) Ry(pitch) Rx(roll));
- /tf_static, not latched, re-published at every OXTS stamp: base_link -> imu_link =
  (-1.405, 0.32, 0.93) m, imu_link -> velo_link = inv(T_velo_imu), velo_link -> camera_* =
  inv(T_camN_velo) with pykitti's rectified camera frames (the baseline P_rect_N[0,3] / fx in
  the transform);
- /kitti/oxts/imu (imu_link): linear_acceleration af al au, angular_velocity wf wl wu (the
  levelled frame), orientation from roll pitch yaw, covariances zero;
- /kitti/oxts/gps/fix (imu_link): position_covariance_type 0, status STATUS_FIX, service 1,
  whatever posmode says; /kitti/oxts/gps/vel (imu_link): vf vl vu, wf wl wu;
- /kitti/velo/pointcloud (velo_link): fields x y z i, FLOAT32, no ring;
- /kitti/camera_color_left/{image_raw, camera_info} (camera_color_left): bgr8; camera_info K =
  K_02, D = D_02 (unrectified), R = R_rect_02, P = P_rect_02 (P[3] = fx * baseline), size
  S_rect_02;
- no /kitti/oxts/ground_truth;
- stamps from the timestamps.txt files read as local time (datetime.strftime("%s.%f")): the
  nanoseconds cut to microseconds and every topic shifted by the bag maker's UTC offset
  (--utc-offset-hours, default 2: a machine in UTC+2).

The image pixels come from a bag of this package's kitti2bag of the same drive (--images-from):
the Python tool's cv2.imread + cv_bridge bgr8 gives the same bytes, and no PNG decoder is
available to python3 here; headers and camera_info are this fixture's own.

  kitti2bag_py_fixture.py --drive DIR [--calib-dir DIR] --output FILE.bag
                          [--images-from OWN.bag] [--utc-offset-hours H]
"""
import argparse
import datetime
import math
import os
import sys

import numpy as np
import rosbag
import rospy
from geometry_msgs.msg import TransformStamped, TwistStamped
from sensor_msgs.msg import CameraInfo, Imu, NavSatFix, NavSatStatus, PointCloud2, PointField
from tf2_msgs.msg import TFMessage

BASE_LINK_TO_IMU = (-2.71 / 2.0 - 0.05, 0.32, 0.93)  # what kitti2bag hard-codes
CAMERAS = [(0, "camera_gray_left"), (1, "camera_gray_right"), (2, "camera_color_left"),
           (3, "camera_color_right")]
IMAGE_TOPIC = "/kitti/camera_color_left/image_raw"
CAMERA_INFO_TOPIC = "/kitti/camera_color_left/camera_info"


def read_calib_file(path):
    """pykitti.utils.read_calib_file: key: float values (non-numeric lines skipped)."""
    data = {}
    with open(path) as f:
        for line in f:
            if ":" not in line:
                continue
            key, value = line.split(":", 1)
            try:
                data[key] = np.array([float(x) for x in value.split()])
            except ValueError:
                pass
    return data


def transform_from_rot_trans(R, t):
    T = np.eye(4)
    T[:3, :3] = np.asarray(R).reshape(3, 3)
    T[:3, 3] = np.asarray(t).reshape(3)
    return T


def rotx(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def roty(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rotz(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def quaternion_from_matrix(M):
    """(x, y, z, w) of a rotation matrix (as tf.transformations.quaternion_from_matrix)."""
    R = np.asarray(M)[:3, :3]
    trace = np.trace(R)
    if trace > 0:
        s = 0.5 / math.sqrt(trace + 1.0)
        w, x, y, z = 0.25 / s, (R[2, 1] - R[1, 2]) * s, (R[0, 2] - R[2, 0]) * s, (R[1, 0] - R[0, 1]) * s
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        w, x, y, z = (R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        w, x, y, z = (R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s
    else:
        s = 2.0 * math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        w, x, y, z = (R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s
    return x, y, z, w


def quaternion_from_euler(roll, pitch, yaw):
    """tf.transformations.quaternion_from_euler(roll, pitch, yaw) (static xyz: Rz Ry Rx)."""
    return quaternion_from_matrix(rotz(yaw) @ roty(pitch) @ rotx(roll))


def read_timestamps(path, utc_offset_hours):
    """pykitti / kitti2bag: datetime.strptime(line[:-4], ...) (microseconds), then
    float(dt.strftime("%s.%f")) on the bag maker's machine: the naive time read as local time."""
    stamps = []
    with open(path) as f:
        for line in f:
            if len(line.strip()) == 0:
                continue
            dt = datetime.datetime.strptime(line.strip()[:26], "%Y-%m-%d %H:%M:%S.%f")
            utc = dt.replace(tzinfo=datetime.timezone.utc).timestamp()
            stamps.append(rospy.Time.from_sec(round(utc - 3600.0 * utc_offset_hours, 6)))
    return stamps


def read_oxts(drive):
    data_dir = os.path.join(drive, "oxts", "data")
    packets = []
    for name in sorted(os.listdir(data_dir)):
        with open(os.path.join(data_dir, name)) as f:
            values = [float(v) for v in f.read().split()]
        packets.append(dict(zip(
            "lat lon alt roll pitch yaw vn ve vf vl vu ax ay az af al au wx wy wz wf wl wu "
            "pos_accuracy vel_accuracy navstat numsats posmode velmode orimode".split(), values)))
    return packets


def oxts_poses(packets):
    """pykitti.utils.poses_from_oxts: T_w_imu of every packet."""
    er = 6378137.0
    scale = math.cos(packets[0]["lat"] * math.pi / 180.0)
    origin = None
    poses = []
    for p in packets:
        t = np.array([scale * p["lon"] * math.pi * er / 180.0,
                      scale * er * math.log(math.tan((90.0 + p["lat"]) * math.pi / 360.0)),
                      p["alt"]])
        R = rotz(p["yaw"]) @ roty(p["pitch"]) @ rotx(p["roll"])
        if origin is None:
            origin = t
        poses.append(transform_from_rot_trans(R, t - origin))
    return poses


def transform_message(parent, child, T, stamp):
    msg = TransformStamped()
    msg.header.frame_id = parent
    msg.header.stamp = stamp
    msg.child_frame_id = child
    msg.transform.translation.x, msg.transform.translation.y, msg.transform.translation.z = T[:3, 3]
    q = quaternion_from_matrix(T)
    msg.transform.rotation.x, msg.transform.rotation.y, msg.transform.rotation.z, \
        msg.transform.rotation.w = q
    return msg


def calibration(calib_dir):
    """pykitti's raw calibration: T_velo_imu and the rectified camera frames T_camN_velo."""
    imu_to_velo = read_calib_file(os.path.join(calib_dir, "calib_imu_to_velo.txt"))
    velo_to_cam = read_calib_file(os.path.join(calib_dir, "calib_velo_to_cam.txt"))
    cam_to_cam = read_calib_file(os.path.join(calib_dir, "calib_cam_to_cam.txt"))
    T_velo_imu = transform_from_rot_trans(imu_to_velo["R"], imu_to_velo["T"])
    T_cam0unrect_velo = transform_from_rot_trans(velo_to_cam["R"], velo_to_cam["T"])
    R_rect_00 = np.eye(4)
    R_rect_00[:3, :3] = cam_to_cam["R_rect_00"].reshape(3, 3)
    T_cam_velo = {}
    for index, _ in CAMERAS:
        P = cam_to_cam["P_rect_%02d" % index].reshape(3, 4)
        T = np.eye(4)
        T[0, 3] = P[0, 3] / P[0, 0]
        T_cam_velo[index] = T @ R_rect_00 @ T_cam0unrect_velo
    return T_velo_imu, T_cam_velo, cam_to_cam


def static_transforms(T_velo_imu, T_cam_velo):
    transforms = [("base_link", "imu_link", transform_from_rot_trans(np.eye(3), BASE_LINK_TO_IMU)),
                  ("imu_link", "velo_link", np.linalg.inv(T_velo_imu))]
    for index, frame in CAMERAS:
        transforms.append(("velo_link", frame, np.linalg.inv(T_cam_velo[index])))
    return transforms


def cloud_message(scan, stamp):
    msg = PointCloud2()
    msg.header.frame_id = "velo_link"
    msg.header.stamp = stamp
    msg.height = 1
    msg.width = scan.shape[0]
    msg.fields = [PointField("x", 0, PointField.FLOAT32, 1), PointField("y", 4, PointField.FLOAT32, 1),
                  PointField("z", 8, PointField.FLOAT32, 1), PointField("i", 12, PointField.FLOAT32, 1)]
    msg.is_bigendian = False
    msg.point_step = 16
    msg.row_step = 16 * scan.shape[0]
    msg.is_dense = False  # sensor_msgs.point_cloud2.create_cloud's
    msg.data = scan.astype(np.float32).tobytes()
    return msg


def camera_info_message(cam_to_cam, stamp):
    info = CameraInfo()
    info.header.frame_id = "camera_color_left"
    info.header.stamp = stamp
    info.width, info.height = (int(v) for v in cam_to_cam["S_rect_02"])
    info.distortion_model = "plumb_bob"
    info.K = cam_to_cam["K_02"].tolist()
    info.R = cam_to_cam["R_rect_02"].tolist()
    info.D = cam_to_cam["D_02"].tolist()
    info.P = cam_to_cam["P_rect_02"].tolist()
    return info


def write_bag(drive, calib_dir, output, images_from, utc_offset_hours):
    packets = read_oxts(drive)
    oxts_stamps = read_timestamps(os.path.join(drive, "oxts", "timestamps.txt"), utc_offset_hours)
    if len(packets) != len(oxts_stamps):
        raise RuntimeError("%s: %d OXTS files, %d timestamps" % (drive, len(packets), len(oxts_stamps)))
    T_velo_imu, T_cam_velo, cam_to_cam = calibration(calib_dir)
    statics = static_transforms(T_velo_imu, T_cam_velo)
    partial = output + ".partial"
    with rosbag.Bag(partial, "w") as bag:
        for stamp, packet, T_w_imu in zip(oxts_stamps, packets, oxts_poses(packets)):
            bag.write("/tf_static", TFMessage([transform_message(p, c, T, stamp) for p, c, T in statics]),
                      t=stamp)
            bag.write("/tf", TFMessage([transform_message("world", "base_link", T_w_imu, stamp)]), t=stamp)
            imu = Imu()
            imu.header.frame_id = "imu_link"
            imu.header.stamp = stamp
            q = quaternion_from_euler(packet["roll"], packet["pitch"], packet["yaw"])
            imu.orientation.x, imu.orientation.y, imu.orientation.z, imu.orientation.w = q
            imu.linear_acceleration.x = packet["af"]
            imu.linear_acceleration.y = packet["al"]
            imu.linear_acceleration.z = packet["au"]
            imu.angular_velocity.x = packet["wf"]
            imu.angular_velocity.y = packet["wl"]
            imu.angular_velocity.z = packet["wu"]
            bag.write("/kitti/oxts/imu", imu, t=stamp)
            fix = NavSatFix()
            fix.header.frame_id = "imu_link"
            fix.header.stamp = stamp
            fix.latitude, fix.longitude, fix.altitude = packet["lat"], packet["lon"], packet["alt"]
            fix.status.service = 1
            fix.status.status = NavSatStatus.STATUS_FIX
            fix.position_covariance_type = NavSatFix.COVARIANCE_TYPE_UNKNOWN
            bag.write("/kitti/oxts/gps/fix", fix, t=stamp)
            velocity = TwistStamped()
            velocity.header.frame_id = "imu_link"
            velocity.header.stamp = stamp
            velocity.twist.linear.x, velocity.twist.linear.y, velocity.twist.linear.z = \
                packet["vf"], packet["vl"], packet["vu"]
            velocity.twist.angular.x, velocity.twist.angular.y, velocity.twist.angular.z = \
                packet["wf"], packet["wl"], packet["wu"]
            bag.write("/kitti/oxts/gps/vel", velocity, t=stamp)

        velo_dir = os.path.join(drive, "velodyne_points")
        if os.path.isdir(velo_dir):
            velo_stamps = read_timestamps(os.path.join(velo_dir, "timestamps.txt"), utc_offset_hours)
            names = sorted(os.listdir(os.path.join(velo_dir, "data")))
            for stamp, name in zip(velo_stamps, names):
                scan = np.fromfile(os.path.join(velo_dir, "data", name), dtype=np.float32).reshape(-1, 4)
                bag.write("/kitti/velo/pointcloud", cloud_message(scan, stamp), t=stamp)

        image_dir = os.path.join(drive, "image_02")
        if os.path.isdir(image_dir) and images_from:
            image_stamps = read_timestamps(os.path.join(image_dir, "timestamps.txt"), utc_offset_hours)
            with rosbag.Bag(images_from) as own:
                images = [m for _, m, _ in own.read_messages(topics=[IMAGE_TOPIC])]
            if len(images) != len(image_stamps):
                raise RuntimeError("%s: %d images, %d image_02 timestamps" % (
                    images_from, len(images), len(image_stamps)))
            for stamp, image in zip(image_stamps, images):
                image.header.stamp = stamp
                image.header.frame_id = "camera_color_left"
                bag.write(IMAGE_TOPIC, image, t=stamp)
                bag.write(CAMERA_INFO_TOPIC, camera_info_message(cam_to_cam, stamp), t=stamp)
    os.replace(partial, output)


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--drive", required=True, help="<date>_drive_<nnnn>_sync folder")
    parser.add_argument("--calib-dir", help="folder with calib_*.txt (default: the drive's parent)")
    parser.add_argument("--output", required=True)
    parser.add_argument("--images-from", help="a bag of this package's kitti2bag of the drive")
    parser.add_argument("--utc-offset-hours", type=float, default=2.0)
    args = parser.parse_args(argv)
    write_bag(args.drive, args.calib_dir or os.path.dirname(os.path.abspath(args.drive)),
              args.output, args.images_from, args.utc_offset_hours)


if __name__ == "__main__":
    main(sys.argv[1:])
