// A node's last log lines (what went into the map at shutdown, where it was saved). rosconsole
// prints nothing once ros::shutdown() has run, which is when a nodelet manager stopped with
// Ctrl-C unloads its nodelets: then the line goes to stderr in rosconsole's own layout.
#pragma once

#include <string>

namespace inekf_semantic_mapping {
namespace ros_conversions {

enum class ShutdownLogLevel { kInfo, kError };

// Through rosconsole while ROS runs, else straight to stderr.
void logAtShutdown(ShutdownLogLevel level, const std::string& text);

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
