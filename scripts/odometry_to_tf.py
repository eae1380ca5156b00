#!/usr/bin/python3
"""Broadcasts an Odometry topic as the tf header.frame_id -> child_frame_id.

Used by the launch files with use_ground_truth_pose:=true: the OXTS ground truth
(/kitti/oxts/ground_truth) then provides map -> base_link for the semantic map, and inekf_node
runs with publish_tf false so that the frame has exactly one parent.
"""
import math

import rospy
import tf2_ros
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import Odometry


class OdometryToTf:
    def __init__(self):
        self.broadcaster = tf2_ros.TransformBroadcaster()
        self.child_frame_override = rospy.get_param("~child_frame", "")
        self.last_stamp = None
        rospy.Subscriber("odometry", Odometry, self.on_odometry, queue_size=50)

    def on_odometry(self, msg):
        p = msg.pose.pose.position
        q = msg.pose.pose.orientation
        if not all(math.isfinite(v) for v in (p.x, p.y, p.z, q.x, q.y, q.z, q.w)):
            rospy.logwarn_throttle(5.0, "odometry_to_tf: non-finite pose at %s, skipped",
                                   msg.header.stamp)
            return
        if self.last_stamp is not None and msg.header.stamp == self.last_stamp:
            return  # tf2 rejects a repeated stamp with a warning per message
        self.last_stamp = msg.header.stamp
        t = TransformStamped()
        t.header = msg.header
        t.child_frame_id = self.child_frame_override or msg.child_frame_id or "base_link"
        t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = p.x, p.y, p.z
        t.transform.rotation = q
        self.broadcaster.sendTransform(t)


if __name__ == "__main__":
    import sys
    if any(arg in ("-h", "--help") for arg in sys.argv[1:]):
        # Said without a ROS master (init_node waited for one, then failed in a traceback).
        print(__doc__ + "\nParameters: ~child_frame (default: the message's child_frame_id). "
              "Topics: odometry (in), tf (out).")
        sys.exit(0)
    rospy.init_node("odometry_to_tf")
    OdometryToTf()
    rospy.spin()
