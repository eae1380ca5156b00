#include "inekf_semantic_mapping/ros/node_parameters.h"

#include <ros/console.h>
#include <xmlrpcpp/XmlRpcValue.h>

#include <mutex>

namespace inekf_semantic_mapping {
namespace ros_conversions {
namespace {

YAML::Node toYaml(const XmlRpc::XmlRpcValue& value) {
  // XmlRpcValue's conversions are non-const.
  XmlRpc::XmlRpcValue& v = const_cast<XmlRpc::XmlRpcValue&>(value);
  switch (v.getType()) {
    case XmlRpc::XmlRpcValue::TypeBoolean:
      return YAML::Node(static_cast<bool>(v));
    case XmlRpc::XmlRpcValue::TypeInt:
      return YAML::Node(static_cast<int>(v));
    case XmlRpc::XmlRpcValue::TypeDouble:
      return YAML::Node(static_cast<double>(v));
    case XmlRpc::XmlRpcValue::TypeString:
      return YAML::Node(static_cast<std::string>(v));
    case XmlRpc::XmlRpcValue::TypeArray: {
      YAML::Node list(YAML::NodeType::Sequence);
      for (int i = 0; i < v.size(); ++i) list.push_back(toYaml(v[i]));
      return list;
    }
    case XmlRpc::XmlRpcValue::TypeStruct: {
      YAML::Node map(YAML::NodeType::Map);
      for (auto it = v.begin(); it != v.end(); ++it) map[it->first] = toYaml(it->second);
      return map;
    }
    default:
      return YAML::Node(v.toXml());
  }
}

}  // namespace

YAML::Node privateParametersAsYaml(const ros::NodeHandle& private_nh) {
  // The readers' warnings (a deprecated parameter name) go to rosconsole, where a node's other
  // messages are. Once per process: nodelets share one manager.
  static std::once_flag route_warnings;
  std::call_once(route_warnings, [] {
    common::setConfigWarningHandler([](const std::string& message) { ROS_WARN_STREAM(message); });
  });
  XmlRpc::XmlRpcValue all;
  if (!private_nh.getParam(private_nh.getNamespace(), all)) return YAML::Node(YAML::NodeType::Map);
  return toYaml(all);
}

std::string parameterSource(const ros::NodeHandle& private_nh) {
  std::string file;
  if (private_nh.getParam("loaded_from", file) && !file.empty()) {
    return "ROS parameters of " + private_nh.getNamespace() + " (loaded from " + file + ")";
  }
  return "ROS parameters of " + private_nh.getNamespace();
}

common::YamlReader privateParameterReader(const ros::NodeHandle& private_nh) {
  common::YamlReader reader(parameterSource(private_nh), privateParametersAsYaml(private_nh));
  reader.allow("diagnostic_period");  // diagnostic_updater's own (ros/diagnostics.h)
  reader.allow("loaded_from");        // the launch's YAML file, named in every message
  return reader;
}

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
