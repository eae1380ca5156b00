// What semantic_octomap_node does, in a class that a node's main and a nodelet both hold: the ROS
// face of mapping::SemanticMappingSession (semantic_map_offline is the other). It converts
// messages and calls the session; the session owns the policy.
//
// Subscribes kitti/velo/pointcloud, segmentation/labels (mono8 Cityscapes labelIds, stamped like
// the camera image) and kitti/camera_color_left/camera_info (or reads the raw calibration in
// ~calib_dir). Every scan updates the map; a label image adds class evidence to the scan of its
// stamp. Poses come from tf (map_frame -> cloud frame at the scan stamp) when the session inserts
// a scan: scans queue until their pose is there, nothing blocks the spinner. Publishes
// semantic_map/{markers, labeled_cloud, info, projected_map, drivable_map}; services ~save_map,
// ~load_map, ~reset; ~map_file resumes from a saved map, ~autosave_path saves every
// ~autosave_period_s and at finish(). Parameters: config/semantic_mapping.yaml.
// /diagnostics: "map" and "labels" statuses at 1 Hz (ros/mapping_diagnostics.h).
// ROS-facing (src/ros): only nodes and nodelets include this header.
#pragma once

#include <ros/node_handle.h>

#include <memory>

namespace inekf_semantic_mapping {
namespace ros_conversions {

class SemanticOctomapNodeCore {
 public:
  // Throws (std::exception) on a bad parameter, calibration or map file.
  SemanticOctomapNodeCore(ros::NodeHandle nh, ros::NodeHandle private_nh);
  ~SemanticOctomapNodeCore();  // finish() unless it was called

  // The end of the run: the scans still waiting for their label image go into the map (with the
  // labels that came), then the final autosave (~autosave_path). Call it while ROS still runs
  // (after ros::shutdown() roscpp logs nothing); later calls do nothing.
  void finish();
  SemanticOctomapNodeCore(const SemanticOctomapNodeCore&) = delete;
  SemanticOctomapNodeCore& operator=(const SemanticOctomapNodeCore&) = delete;

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
