// semantic_octomap_node: lidar scans, label images and tf -> the semantic map, its displays,
// grids and services (ros/semantic_octomap_node_core.h; the same core runs as the nodelet
// inekf_semantic_mapping/SemanticOctomapNodelet). Prints the timing report at exit.
#include <ros/ros.h>

#include <iostream>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/ros/semantic_octomap_node_core.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "semantic_octomap_node");
  // Held outside the try: when the last NodeHandle goes, roscpp shuts rosconsole down, and the
  // fatal message of a node that could not start (a bad parameter) would print nothing.
  ros::NodeHandle nh;
  ros::NodeHandle private_nh("~");
  try {
    inekf_semantic_mapping::ros_conversions::SemanticOctomapNodeCore node{nh, private_nh};
    ros::spin();
  } catch (const std::exception& e) {
    ROS_FATAL_STREAM("semantic_octomap_node: " << e.what());
    return 1;
  }
  std::cerr << inekf_semantic_mapping::TimingRegistry::instance().report();
  return 0;
}
