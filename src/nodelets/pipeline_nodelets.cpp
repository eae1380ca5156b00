// The segmentation and map nodes as nodelets (nodelet_plugins.xml): in one manager the label
// images pass from segmentation to the map as shared pointers, without serialisation or a copy.
// The nodelets hold the same cores as the node executables (ros/*_node_core.h) and read the same
// private parameters; name them segmentation_node and semantic_octomap_node (as
// launch/include/pipeline.launch does) and their services and statuses keep the nodes' names.
#include <nodelet/nodelet.h>
#include <ros/ros.h>

#include <memory>
#include <pluginlib/class_list_macros.hpp>

#include "inekf_semantic_mapping/ros/segmentation_node_core.h"
#include "inekf_semantic_mapping/ros/semantic_octomap_node_core.h"

namespace inekf_semantic_mapping {

// A core that cannot start (a bad parameter, a model that does not load) is reported and the
// nodelet stays empty; rethrowing would take the whole manager down with it.
template <typename Core>
class CoreNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    try {
      core_ = std::make_unique<Core>(getNodeHandle(), getPrivateNodeHandle());
    } catch (const std::exception& e) {
      NODELET_FATAL_STREAM(getName() << ": " << e.what() << " (the nodelet does nothing)");
    }
  }
  std::unique_ptr<Core> core_;
};

class SegmentationNodelet : public CoreNodelet<ros_conversions::SegmentationNodeCore> {};
class SemanticOctomapNodelet : public CoreNodelet<ros_conversions::SemanticOctomapNodeCore> {};

}  // namespace inekf_semantic_mapping

PLUGINLIB_EXPORT_CLASS(inekf_semantic_mapping::SegmentationNodelet, nodelet::Nodelet)
PLUGINLIB_EXPORT_CLASS(inekf_semantic_mapping::SemanticOctomapNodelet, nodelet::Nodelet)
