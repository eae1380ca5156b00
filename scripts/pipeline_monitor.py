#!/usr/bin/python3
"""Watches the running pipeline and writes what the demo, the benchmark and the tests measure.

Records, without deserializing the big messages (AnyMsg: only the header is read from the raw
bytes), for each watched topic: count, header stamps and wall-clock arrival times; and the
estimated and ground-truth trajectories (TUM files). On shutdown (Ctrl-C, roslaunch stop, or
~duration elapsed with no data) it writes OUT_DIR/monitor.json and OUT_DIR/{estimate,truth}_tum.txt.

  scripts/pipeline_monitor.py _output_dir:=output/demo [_idle_timeout:=5]

The JSON holds per topic: messages, first/last stamp, mean rate over sim and over wall time, for
the map cloud the wall-clock latency from the scan's arrival to the map update with the same
stamp, and the map node's latest /semantic_map/info (SemanticMapInfo) as "map_info".
"""
import json
import math
import os
import struct
import threading
import time

import rospy
from nav_msgs.msg import Odometry

from inekf_semantic_mapping.msg import SemanticMapInfo

SCAN_TOPIC = "/kitti/velo/pointcloud"
IMAGE_TOPIC = "/kitti/camera_color_left/image_raw"
WATCHED_TOPICS = [
    "/kitti/oxts/imu", "/kitti/oxts/gps/fix", SCAN_TOPIC, IMAGE_TOPIC,
    "/segmentation/labels", "/segmentation/overlay", "/semantic_map/labeled_cloud",
    "/semantic_map/markers", "/inekf/status",
]
MAP_INFO_TOPIC = "/semantic_map/info"
MAP_INFO_FIELDS = ("scans_received", "scans_inserted", "scans_with_labels", "scans_without_pose",
                   "label_images_received", "label_images_used", "resolution", "nodes",
                   "occupied_voxels", "memory_bytes")
# Subscribed with their type (a rospy process has one subscription type per topic), and logged
# like the raw ones.
ODOMETRY_TOPICS = ["/inekf/odometry", "/kitti/oxts/ground_truth"]
# Topics whose first field is a std_msgs/Header (the others are only counted).
STAMPED_TOPICS = {t for t in WATCHED_TOPICS if t != "/semantic_map/markers"}


def header_stamp_from_raw(buff):
    """The header stamp (seconds) of a serialized stamped message: seq u32, secs u32, nsecs u32."""
    if len(buff) < 12:
        return None
    _, secs, nsecs = struct.unpack_from("<III", buff, 0)
    return secs + 1e-9 * nsecs


class TopicLog:
    def __init__(self):
        self.stamps = []        # header stamps (s)
        self.arrivals = []      # wall-clock arrival (s)
        self.count = 0


class PipelineMonitor:
    def __init__(self, topics=WATCHED_TOPICS):
        self.lock = threading.Lock()
        self.logs = {t: TopicLog() for t in list(topics) + ODOMETRY_TOPICS + [MAP_INFO_TOPIC]}
        self.map_info = None  # the latest SemanticMapInfo
        self.estimate = []
        self.truth = []
        self.last_message_wall = None
        self.clock_jumps_back = 0
        self.last_clock = None
        for topic in topics:
            rospy.Subscriber(topic, rospy.AnyMsg, self.on_raw, callback_args=topic,
                             queue_size=200, buff_size=2 ** 25, tcp_nodelay=True)
        rospy.Subscriber(ODOMETRY_TOPICS[0], Odometry, self.on_odometry, callback_args=self.estimate,
                         queue_size=200)
        rospy.Subscriber(ODOMETRY_TOPICS[1], Odometry, self.on_odometry, callback_args=self.truth,
                         queue_size=200)
        rospy.Subscriber(MAP_INFO_TOPIC, SemanticMapInfo, self.on_map_info, queue_size=10)

    def on_raw(self, msg, topic):
        now = time.time()
        stamp = header_stamp_from_raw(msg._buff) if topic in STAMPED_TOPICS else None
        with self.lock:
            log = self.logs[topic]
            log.count += 1
            log.arrivals.append(now)
            if stamp is not None:
                log.stamps.append(stamp)
            self.last_message_wall = now

    def on_map_info(self, msg):
        now = time.time()
        with self.lock:
            log = self.logs[MAP_INFO_TOPIC]
            log.count += 1
            log.arrivals.append(now)
            self.map_info = msg

    def latest_map_info(self):
        """The latest SemanticMapInfo as a dict (class_voxels: {class name: voxels}), or None."""
        with self.lock:
            msg = self.map_info
        if msg is None:
            return None
        info = {f: getattr(msg, f) for f in MAP_INFO_FIELDS}
        info["class_voxels"] = dict(zip(msg.class_names, (int(n) for n in msg.class_voxels)))
        return info

    def on_odometry(self, msg, store):
        now = time.time()
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        topic = ODOMETRY_TOPICS[0] if store is self.estimate else ODOMETRY_TOPICS[1]
        with self.lock:
            stamp = msg.header.stamp.to_sec()
            log = self.logs[topic]
            log.count += 1
            log.arrivals.append(now)
            log.stamps.append(stamp)
            self.last_message_wall = now
            if store is self.estimate and store and stamp < store[-1][0] - 1.0:
                self.clock_jumps_back += 1
            store.append((stamp, p.x, p.y, p.z, q.x, q.y, q.z, q.w))

    def summary(self):
        with self.lock:
            result = {"topics": {}, "estimate_poses": len(self.estimate),
                      "truth_poses": len(self.truth), "estimate_time_jumps_back": self.clock_jumps_back}
            for topic, log in self.logs.items():
                entry = {"messages": log.count}
                if len(log.stamps) >= 2:
                    span = log.stamps[-1] - log.stamps[0]
                    entry.update(first_stamp=log.stamps[0], last_stamp=log.stamps[-1],
                                 rate_hz=(len(log.stamps) - 1) / span if span > 0 else None)
                # Over wall time: what a slow stage (segmentation) really delivers, whatever the
                # playback rate and however sparse the stamps of what it kept.
                if len(log.arrivals) >= 2:
                    wall_span = log.arrivals[-1] - log.arrivals[0]
                    entry["wall_rate_hz"] = (len(log.arrivals) - 1) / wall_span if wall_span > 0 else None
                result["topics"][topic] = entry
            result["scan_to_map_latency_s"] = self._latency(SCAN_TOPIC, "/semantic_map/labeled_cloud")
            result["image_to_labels_latency_s"] = self._latency(IMAGE_TOPIC, "/segmentation/labels")
        result["map_info"] = self.latest_map_info()
        return result

    def _latency(self, source, sink):
        """Wall time from a message's arrival on `source` to the arrival of `sink` with its stamp."""
        arrival_by_stamp = {round(s, 6): a for s, a in zip(self.logs[source].stamps,
                                                           self.logs[source].arrivals)}
        delays = []
        for s, a in zip(self.logs[sink].stamps, self.logs[sink].arrivals):
            start = arrival_by_stamp.get(round(s, 6))
            if start is not None and a >= start:
                delays.append(a - start)
        if not delays:
            return None
        delays.sort()
        return {"matched": len(delays), "mean": sum(delays) / len(delays),
                "p50": delays[len(delays) // 2], "p95": delays[min(len(delays) - 1, int(0.95 * len(delays)))],
                "max": delays[-1]}

    def write(self, output_dir):
        os.makedirs(output_dir, exist_ok=True)
        summary = self.summary()
        write_atomic(os.path.join(output_dir, "monitor.json"), json.dumps(summary, indent=2))
        with self.lock:
            for name, poses in (("estimate_tum.txt", self.estimate), ("truth_tum.txt", self.truth)):
                text = "".join("%.9f %.6f %.6f %.6f %.9f %.9f %.9f %.9f\n" % p
                               for p in poses if all(math.isfinite(v) for v in p))
                write_atomic(os.path.join(output_dir, name), text)
        return summary


def write_atomic(path, text):
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        f.write(text)
    os.replace(tmp, path)


def main():
    rospy.init_node("pipeline_monitor")
    output_dir = rospy.get_param("~output_dir", "output/monitor")
    idle_timeout = rospy.get_param("~idle_timeout", 0.0)  # 0: run until shut down
    monitor = PipelineMonitor()
    rospy.on_shutdown(lambda: monitor.write(output_dir))
    while not rospy.is_shutdown():
        time.sleep(0.5)
        last = monitor.last_message_wall
        if idle_timeout > 0 and last is not None and time.time() - last > idle_timeout:
            rospy.loginfo("pipeline_monitor: no data for %.1f s, writing %s", idle_timeout, output_dir)
            rospy.signal_shutdown("idle")
    monitor.write(output_dir)


if __name__ == "__main__":
    main()
