// What segmentation_node does, in a class that a node's main and a nodelet both hold: camera
// image -> labels (mono8 Cityscapes labelIds, after the model card's label filter) and overlay
// (rgb8), both with the input image's header, on a worker thread fed through a one-slot
// LatestFrameBuffer (stale frames are dropped and counted instead of queueing latency).
//
// Parameters (private, config/segmentation.yaml): model, model_card ("" = the model's default
// card), image_topic, publish_overlay, overlay_alpha, num_threads, rate_log_period_s,
// diagnostics.latency_warn_s. Any other private parameter, or one of the wrong type, throws
// naming it (ros/node_parameters.h). /diagnostics: model, input size, frame rate, latency,
// dropped stale and failed frames. The label images go out as shared pointers, so a map nodelet
// in the same manager receives them without a copy.
// ROS-facing (src/ros): only nodes and nodelets include this header.
#pragma once

#include <ros/node_handle.h>

#include <memory>

namespace inekf_semantic_mapping {
namespace ros_conversions {

class SegmentationNodeCore {
 public:
  // Throws (std::exception) on a bad parameter or a model that does not load.
  SegmentationNodeCore(ros::NodeHandle nh, ros::NodeHandle private_nh);
  ~SegmentationNodeCore();  // stops the worker thread
  SegmentationNodeCore(const SegmentationNodeCore&) = delete;
  SegmentationNodeCore& operator=(const SegmentationNodeCore&) = delete;

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
