// inekf_node: IMU + GPS -> odometry, path, tf map -> base_link and FilterStatus
// (ros/inekf_node_core.h lists its topics and parameters; estimation::LocalizationSession is
// the filter's policy, shared with inekf_offline).
#include <ros/ros.h>

#include "inekf_semantic_mapping/ros/inekf_node_core.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "inekf_node");
  // Held outside the try: when the last NodeHandle goes, roscpp shuts rosconsole down, and the
  // fatal message of a node that could not start (a bad parameter) would print nothing.
  ros::NodeHandle nh;
  ros::NodeHandle private_nh("~");
  try {
    inekf_semantic_mapping::ros_conversions::InekfNodeCore node(nh, private_nh);
    ros::spin();
  } catch (const std::exception& error) {
    ROS_FATAL_STREAM("inekf_node: " << error.what());
    return 1;
  }
  return 0;
}
