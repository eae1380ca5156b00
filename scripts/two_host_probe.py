#!/usr/bin/python3
"""Measuring helper of scripts/two_host_demo.sh (segmentation on a second host, in two network
namespaces). Three modes:

  two_host_probe.py count TOPIC OUT.json [--png]
      Counts the messages on TOPIC and their serialized bytes until SIGINT, then writes OUT.json.
      --png: also PNG-encodes every message (a mono8/rgb8/bgr8 sensor_msgs/Image) and sums the
      encoded sizes: what a PNG (lossless) transport would send instead.
  two_host_probe.py info OUT.json [TIMEOUT_S]
      Waits for /semantic_map/info (SemanticMapInfo; a new subscriber gets it at once) and writes its counts to OUT.json.
  two_host_probe.py subscribed TIMEOUT_S TOPIC=NODE...
      Waits until every NODE subscribes to its TOPIC (one master query a poll, no CLI tools in a
      pipeline); exit 0, or 1 with the master's subscriber lists when TIMEOUT_S passes.
  two_host_probe.py encodings BAG TOPIC OUT.json [SAMPLES]
      Offline: the raw size of the bag's images on TOPIC and, for SAMPLES of them spread over
      the bag, their size as JPEG (quality 80, compressed_image_transport's default) and as PNG
      (level 3, lossless).
"""
import json
import signal
import sys
import time


def _image_array(msg):
    import numpy as np
    channels = {"mono8": 1, "8UC1": 1, "rgb8": 3, "bgr8": 3, "8UC3": 3}.get(msg.encoding)
    if channels is None:
        return None
    data = np.frombuffer(msg.data, dtype=np.uint8)
    rows = data.reshape(msg.height, msg.step)[:, : msg.width * channels]
    image = rows.reshape(msg.height, msg.width, channels) if channels == 3 else rows
    if msg.encoding == "rgb8":
        image = image[:, :, ::-1]  # OpenCV encoders take BGR
    return np.ascontiguousarray(image)


def count(topic, out_path, png):
    import cv2
    import rospy
    from sensor_msgs.msg import Image
    stats = {"topic": topic, "messages": 0, "bytes": 0, "png_bytes": 0, "png_messages": 0,
             "width": 0, "height": 0, "encoding": "", "first_wall": None, "last_wall": None}

    def callback(raw):
        now = time.time()
        stats["messages"] += 1
        stats["bytes"] += len(raw._buff)
        stats["first_wall"] = stats["first_wall"] or now
        stats["last_wall"] = now
        if png:
            msg = Image()
            msg.deserialize(raw._buff)
            stats.update(width=msg.width, height=msg.height, encoding=msg.encoding)
            image = _image_array(msg)
            if image is not None:
                ok, encoded = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, 3])
                if ok:
                    stats["png_bytes"] += len(encoded)
                    stats["png_messages"] += 1

    rospy.init_node("two_host_count", anonymous=True)
    # Stopped with SIGINT/SIGTERM by the script: write the counts then (even where the signal
    # was ignored at start, as in a script's background job).
    for number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(number, lambda *_: rospy.signal_shutdown("stopped"))
    rospy.Subscriber(topic, rospy.AnyMsg, callback, queue_size=100, buff_size=1 << 24)
    rospy.spin()
    with open(out_path, "w") as f:
        json.dump(stats, f, indent=1)


def info(out_path, timeout_s):
    import rospy
    from inekf_semantic_mapping.msg import SemanticMapInfo
    rospy.init_node("two_host_info", anonymous=True)
    msg = rospy.wait_for_message("/semantic_map/info", SemanticMapInfo, timeout=timeout_s)
    fields = {name: getattr(msg, name) for name in msg.__slots__ if name not in ("header",)}
    fields["class_names"] = list(fields["class_names"])
    fields["class_voxels"] = [int(v) for v in fields["class_voxels"]]
    with open(out_path, "w") as f:
        json.dump(fields, f, indent=1)


def encodings(bag_path, topic, out_path, samples):
    import cv2
    import rosbag
    with rosbag.Bag(bag_path) as bag:
        total = bag.get_message_count(topic)
        step = max(1, total // samples)
        result = {"topic": topic, "messages": total, "raw_bytes": 0, "sampled": 0,
                  "sampled_raw_bytes": 0, "sampled_jpeg80_bytes": 0, "sampled_png3_bytes": 0}
        for index, (_, msg, _) in enumerate(bag.read_messages(topics=[topic])):
            result["raw_bytes"] += len(msg.data)
            result.update(width=msg.width, height=msg.height, encoding=msg.encoding)
            if index % step or result["sampled"] >= samples:
                continue
            image = _image_array(msg)
            if image is None:
                continue
            result["sampled"] += 1
            result["sampled_raw_bytes"] += len(msg.data)
            result["sampled_jpeg80_bytes"] += len(cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 80])[1])
            result["sampled_png3_bytes"] += len(cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, 3])[1])
    with open(out_path, "w") as f:
        json.dump(result, f, indent=1)


def subscribed(timeout_s, pairs):
    import rosgraph
    master = rosgraph.Master("/two_host_wait")
    wanted = [pair.split("=", 1) for pair in pairs]
    deadline = time.time() + timeout_s
    state = None
    while time.time() < deadline:
        try:
            subscribers = dict(master.getSystemState()[1])
            state = {topic: subscribers.get(topic, []) for topic, _ in wanted}
            if all(node in state[topic] for topic, node in wanted):
                return 0
        except Exception as error:  # the master not up yet: try again
            state = {"master": str(error)}
        time.sleep(0.25)
    sys.stderr.write("[two_host] not subscribed within %.0f s: wanted %s, master has %s\n" %
                     (timeout_s, wanted, state))
    return 1


def main(argv):
    if len(argv) >= 4 and argv[1] == "count":
        count(argv[2], argv[3], "--png" in argv[4:])
    elif len(argv) >= 3 and argv[1] == "info":
        info(argv[2], float(argv[3]) if len(argv) > 3 else 30.0)
    elif len(argv) >= 4 and argv[1] == "subscribed":
        return subscribed(float(argv[2]), argv[3:])
    elif len(argv) >= 5 and argv[1] == "encodings":
        encodings(argv[2], argv[3], argv[4], int(argv[5]) if len(argv) > 5 else 20)
    else:
        sys.stderr.write(__doc__)
        return 2
    return 0


if __name__ == "__main__":
    # rospy strips its remapping arguments (name:=value) itself; none are used here.
    sys.exit(main([a for a in sys.argv if ":=" not in a]))
