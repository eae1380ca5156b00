// The one way every node reads its private parameters: all of ~ as a YAML map, through the strict
// common::YamlReader that also reads the config files, so a misspelt or unknown parameter, or one
// of the wrong type, stops the node with a message naming the parameter and the node (e.g.
// "ROS parameters of /inekf_node: key 'filtr' is not a known key") instead of being ignored.
// ROS-facing (src/ros): only nodes include this header.
#pragma once

#include <ros/node_handle.h>
#include <yaml-cpp/yaml.h>

#include <string>

#include "inekf_semantic_mapping/common/yaml_reader.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

// All parameters in a node's private namespace as a YAML map (ints, doubles, bools, strings,
// lists and nested maps as they are on the parameter server). The first call routes the readers'
// warnings (common::setConfigWarningHandler) to ROS_WARN.
YAML::Node privateParametersAsYaml(const ros::NodeHandle& private_nh);

// "ROS parameters of /node_name": the source every message names; with "(loaded from FILE)"
// when ~loaded_from says which YAML file the launch loaded into the namespace (rosparam load
// leaves the node no other way to know it).
std::string parameterSource(const ros::NodeHandle& private_nh);

// A reader of the node's private parameters. The node reads each key it knows, then calls
// rejectUnknown() before it advertises or subscribes anything.
common::YamlReader privateParameterReader(const ros::NodeHandle& private_nh);

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
