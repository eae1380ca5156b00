// segmentation_node: camera image -> segmentation/labels and segmentation/overlay
// (ros/segmentation_node_core.h; the same core runs as the nodelet
// inekf_semantic_mapping/SegmentationNodelet).
#include <ros/ros.h>

#include "inekf_semantic_mapping/ros/segmentation_node_core.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "segmentation_node");
  // Held outside the try: when the last NodeHandle goes, roscpp shuts rosconsole down, and the
  // fatal message of a node that could not start would print nothing.
  ros::NodeHandle nh;
  ros::NodeHandle pnh("~");
  try {
    inekf_semantic_mapping::ros_conversions::SegmentationNodeCore node(nh, pnh);
    ros::spin();
  } catch (const std::exception& e) {
    // Without a usable model there is nothing to do: say why, once, and exit.
    ROS_FATAL_STREAM("segmentation_node: " << e.what());
    return 1;
  }
  return 0;
}
