#include "inekf_semantic_mapping/ros/shutdown_log.h"

#include <ros/console.h>
#include <ros/init.h>
#include <ros/time.h>

#include <cstdio>

namespace inekf_semantic_mapping {
namespace ros_conversions {

void logAtShutdown(ShutdownLogLevel level, const std::string& text) {
  if (ros::isStarted()) {
    if (level == ShutdownLogLevel::kError) {
      ROS_ERROR_STREAM(text);
    } else {
      ROS_INFO_STREAM(text);
    }
    return;
  }
  // rosconsole's default layout: "[ INFO] [wall time]: message".
  std::fprintf(stderr, "[%s] [%.9f]: %s\n", level == ShutdownLogLevel::kError ? "ERROR" : " INFO",
               ros::WallTime::now().toSec(), text.c_str());
  std::fflush(stderr);
}

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
