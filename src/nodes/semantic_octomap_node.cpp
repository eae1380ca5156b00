// semantic_octomap_node: lidar scans, label images and tf -> the semantic map, its displays,
// grids and services (ros/semantic_octomap_node_core.h; the same core runs as the nodelet
// inekf_semantic_mapping/SemanticOctomapNodelet). Prints the timing report at exit.
//
// Ctrl-C (and roslaunch stopping it) is SIGINT: caught here so that the node finishes (the scans
// still waiting go into the map, the final autosave) while ROS still runs and its log lines still
// print; roscpp's own handler would shut ROS down first.
#include <ros/callback_queue.h>
#include <ros/ros.h>

#include <csignal>
#include <iostream>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/ros/semantic_octomap_node_core.h"

namespace {
volatile std::sig_atomic_t g_interrupted = 0;
void onSigint(int) { g_interrupted = 1; }
}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "semantic_octomap_node", ros::init_options::NoSigintHandler);
  std::signal(SIGINT, onSigint);
  // Held outside the try: when the last NodeHandle goes, roscpp shuts rosconsole down, and the
  // fatal message of a node that could not start (a bad parameter) would print nothing.
  ros::NodeHandle nh;
  ros::NodeHandle private_nh("~");
  try {
    inekf_semantic_mapping::ros_conversions::SemanticOctomapNodeCore node{nh, private_nh};
    // ros::spin() with a stop on SIGINT; ros::ok() turns false on a shutdown request over
    // XML-RPC (rosnode kill), after which finish() still saves and, rosconsole being down,
    // says so on stderr (logAtShutdown).
    while (ros::ok() && !g_interrupted) {
      ros::getGlobalCallbackQueue()->callAvailable(ros::WallDuration(0.1));
    }
    node.finish();
  } catch (const std::exception& e) {
    ROS_FATAL_STREAM("semantic_octomap_node: " << e.what());
    return 1;
  }
  std::cerr << inekf_semantic_mapping::TimingRegistry::instance().report();
  return 0;
}
