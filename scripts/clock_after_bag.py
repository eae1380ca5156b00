#!/usr/bin/python3
"""Keeps /clock running after a bag ends: continues from the last /clock value at wall rate.

Why: with use_sim_time, a node that waits for tf with a timeout (tf2 lookupTransform(..., timeout))
waits on ROS time; when `rosbag play` ends, /clock stops and such a wait never returns, which
blocks that node's callbacks (services included). A live system's time keeps going; this
script gives the replayed one the same property so that the map can still be saved.
Started by scripts/demo.sh after the bag finished; stops on Ctrl-C.
"""
import time

import rospy
from rosgraph_msgs.msg import Clock


def main():
    rospy.init_node("clock_after_bag", disable_signals=False)
    start_ros = rospy.get_param("~start", 0.0)
    if start_ros <= 0:
        raise SystemExit("clock_after_bag: ~start (the last /clock value, seconds) is required")
    publisher = rospy.Publisher("/clock", Clock, queue_size=1)
    wall_start = time.time()
    while not rospy.is_shutdown():
        now = start_ros + (time.time() - wall_start)
        publisher.publish(Clock(clock=rospy.Time.from_sec(now)))
        time.sleep(0.02)


if __name__ == "__main__":
    main()
