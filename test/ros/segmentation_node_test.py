#!/usr/bin/python3
"""rostest for segmentation_node: an image published on the camera topic comes back as a mono8
Cityscapes labelId image with the same header (stamp, frame_id) and size, and an rgb8 overlay;
rgb8, mono8, bgra8, mono16 and Bayer inputs work too; an encoding cv_bridge cannot make bgr8 of
is skipped, counted as a failed frame on /diagnostics, with the node staying up."""
import os
import sys
import threading
import unittest

import numpy as np
import rospy
import rostest
import yaml
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import Image

PKG = "inekf_semantic_mapping"
CAMERA_TOPIC = "/kitti/camera_color_left/image_raw"
LABELS_TOPIC = "/segmentation/labels"
OVERLAY_TOPIC = "/segmentation/overlay"
WIDTH, HEIGHT = 1242, 375


def make_image(encoding, stamp, frame_id, seed):
    rng = np.random.default_rng(seed)
    channels = {"bgr8": 3, "rgb8": 3, "mono8": 1, "16UC1": 2, "bgra8": 4, "mono16": 2,
                "bayer_rggb8": 1}[encoding]
    # A sky-like top, a road-like bottom, noise: a plausible image, not an all-black one.
    pixels = rng.integers(0, 60, size=(HEIGHT, WIDTH * channels), dtype=np.uint8)
    pixels[: HEIGHT // 2] += 150
    msg = Image()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.height, msg.width = HEIGHT, WIDTH
    msg.encoding = encoding
    msg.step = WIDTH * channels
    msg.data = pixels.tobytes()
    return msg


class SegmentationNodeTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("segmentation_node_test")
        cls.lock = threading.Lock()
        cls.labels = {}
        cls.overlays = {}
        rospy.Subscriber(LABELS_TOPIC, Image, cls.on_labels, queue_size=10)
        rospy.Subscriber(OVERLAY_TOPIC, Image, cls.on_overlay, queue_size=10)
        cls.publisher = rospy.Publisher(CAMERA_TOPIC, Image, queue_size=1)
        model = rospy.get_param("~model")
        card = rospy.get_param("~model_card", "") or os.path.splitext(model)[0] + ".yaml"
        if os.path.exists(card):
            with open(card) as f:
                cls.valid_ids = set(yaml.safe_load(f)["output_label_ids"])
        else:  # the built-in ENet card: unlabeled + the 19 trainId classes
            cls.valid_ids = {0, 7, 8, 11, 12, 13, 17, 19, 20, 21, 22, 23, 24, 25, 26, 27, 28, 31,
                             32, 33}
        deadline = rospy.Time.now() + rospy.Duration(30)
        while cls.publisher.get_num_connections() == 0 and rospy.Time.now() < deadline:
            rospy.sleep(0.1)

    @classmethod
    def on_labels(cls, msg):
        with cls.lock:
            cls.labels[msg.header.frame_id] = msg

    @classmethod
    def on_overlay(cls, msg):
        with cls.lock:
            cls.overlays[msg.header.frame_id] = msg

    def publish_until_answered(self, encoding, frame_id, seed, store=None, timeout_s=30.0):
        """Publishes (and republishes, in case the node was busy) until a reply with frame_id."""
        store = self.labels if store is None else store
        stamp = rospy.Time(1000 + seed, 250000000)
        msg = make_image(encoding, stamp, frame_id, seed)
        deadline = rospy.Time.now() + rospy.Duration(timeout_s)
        while rospy.Time.now() < deadline and not rospy.is_shutdown():
            self.publisher.publish(msg)
            for _ in range(20):
                with self.lock:
                    if frame_id in store:
                        return store[frame_id], stamp
                rospy.sleep(0.1)
        self.fail(f"no reply on the segmentation topics for a {encoding} image '{frame_id}'")

    def check_labels(self, reply, stamp, frame_id):
        self.assertEqual(reply.header.stamp, stamp)
        self.assertEqual(reply.header.frame_id, frame_id)
        self.assertEqual(reply.encoding, "mono8")
        self.assertEqual((reply.width, reply.height), (WIDTH, HEIGHT))
        ids = np.frombuffer(reply.data, dtype=np.uint8).reshape(HEIGHT, reply.step)[:, :WIDTH]
        unexpected = set(np.unique(ids).tolist()) - self.valid_ids
        self.assertFalse(unexpected, f"labelIds outside the model card: {sorted(unexpected)}")

    def test_1_bgr8_image_gives_labels_and_overlay_with_its_header(self):
        reply, stamp = self.publish_until_answered("bgr8", "cam_bgr", 1)
        self.check_labels(reply, stamp, "cam_bgr")
        overlay, _ = self.publish_until_answered("bgr8", "cam_bgr", 1, store=self.overlays)
        self.assertEqual(overlay.encoding, "rgb8")
        self.assertEqual((overlay.width, overlay.height), (WIDTH, HEIGHT))

    def test_2_rgb8_and_mono8_images_are_segmented(self):
        # bgra8, mono16 and Bayer (a driver's image_raw) were refused: only bgr8, rgb8, mono8 were
        # segmented.
        for encoding, seed in (("rgb8", 2), ("mono8", 3), ("bgra8", 6), ("mono16", 7),
                               ("bayer_rggb8", 8)):
            reply, stamp = self.publish_until_answered(encoding, "cam_" + encoding, seed)
            self.check_labels(reply, stamp, "cam_" + encoding)

    def test_3_unsupported_encoding_is_skipped_and_node_stays_up(self):
        failed = []

        def on_diagnostics(msg):
            for status in msg.status:
                for value in status.values:
                    if value.key == "failed frames in window" and int(value.value) > 0:
                        failed.append(status.message)

        diagnostics = rospy.Subscriber("/diagnostics", DiagnosticArray, on_diagnostics)
        self.addCleanup(diagnostics.unregister)
        bad = make_image("16UC1", rospy.Time(2000), "cam_bad", 4)
        # An empty rgb8 image passes cv_bridge's own checks and fails in OpenCV's conversion.
        empty = Image(encoding="rgb8", height=0, width=0, step=0, data=b"")
        empty.header.stamp, empty.header.frame_id = rospy.Time(2001), "cam_empty"
        for _ in range(3):
            self.publisher.publish(bad)
            self.publisher.publish(empty)
            rospy.sleep(0.2)
        rospy.sleep(1.0)
        with self.lock:
            self.assertNotIn("cam_bad", self.labels)
            self.assertNotIn("cam_empty", self.labels)
        # Counted as failed frames: the status said OK "segmenting" while every frame was dropped.
        deadline = rospy.Time.now() + rospy.Duration(5)
        while not failed and rospy.Time.now() < deadline:
            rospy.sleep(0.2)
        self.assertTrue(failed, "the refused frames are not on /diagnostics")
        self.assertIn(failed[-1], ("every frame failed", "some frames failed"))
        reply, stamp = self.publish_until_answered("bgr8", "cam_after_bad", 5)
        self.check_labels(reply, stamp, "cam_after_bad")

    def test_4_a_misspelt_parameter_stops_a_second_node_with_its_name(self):
        from strict_parameters import run_with_parameters
        code, output = run_with_parameters("segmentation_node", "misspelt_parameter_segmentation",
                                           {"model": rospy.get_param("~model"),
                                            "overlay_alhpa": 0.3})
        self.assertNotEqual(code, 0, output)
        self.assertIn("overlay_alhpa", output)
        self.assertIn("misspelt_parameter_segmentation", output)

    def test_5_a_subscription_that_cannot_be_made_stops_the_node_with_the_reason(self):
        # Found by review: the inference thread was already running, and the exception ended
        # the process in std::terminate (no message; in a nodelet manager, the manager too).
        from strict_parameters import run_with_parameters
        for name, parameters, expected in [
                ("bad_topic_segmentation", {"image_topic": "camera/image raw"},
                 "camera/image raw"),
                ("bad_transport_segmentation", {"image_transport": "no_such_transport"},
                 "no_such_transport")]:
            parameters["model"] = rospy.get_param("~model")
            code, output = run_with_parameters("segmentation_node", name, parameters)
            self.assertEqual(code, 1, output)
            self.assertIn(expected, output)
            self.assertNotIn("terminate called", output)


if __name__ == "__main__":
    rostest.rosrun(PKG, "segmentation_node_test", SegmentationNodeTest, sys.argv)
