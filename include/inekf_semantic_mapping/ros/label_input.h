// semantic_octomap_node's label images on their way into the session. Their camera is the raw
// KITTI calibration (~calib_dir) when the node has one, else camera_info P (a rectified image)
// with the static lidar -> camera transform from tf; label images that come before the camera is
// known (the first cloud names the lidar frame) wait here, the newest few of them.
// ROS-facing (src/ros): only nodes include this header.
#pragma once

#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <tf2_ros/buffer.h>

#include <cstddef>
#include <deque>
#include <optional>
#include <string>

#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

class LabelInput {
 public:
  // file_camera: the camera from calibration files, at its own image size (then tf and
  // camera_info are not used).
  LabelInput(const tf2_ros::Buffer& tf, std::optional<mapping::CameraModel> file_camera)
      : tf_(tf), file_camera_(std::move(file_camera)) {}

  void setCameraInfo(const sensor_msgs::CameraInfo& info) { camera_info_ = info; }
  // The frame of the clouds (the camera's pose is looked up against it).
  void setLidarFrame(const std::string& frame) { lidar_frame_ = frame; }

  // Checks the image now (a malformed one is reported when it comes, not when retried) and
  // queues it; throws std::invalid_argument naming the field that is wrong.
  void push(const sensor_msgs::ImageConstPtr& labels);
  // Passes the waiting label images whose camera is known to the session (errors are logged,
  // naming the topic and stamp; that image is dropped, the rest go on).
  void passTo(mapping::SemanticMappingSession& session);
  // Scans that come before the first label image are cut to the camera's view as soon as the
  // camera is known, like the labelled ones (a whole HDL-64 scan costs several times more).
  void setCameraViewOf(mapping::SemanticMappingSession& session) const;

  // The camera of a label image, sized to it (the image's frame_id, else camera_info's, names
  // the camera frame); nullopt while something is missing. Throws std::invalid_argument for an
  // unusable camera_info (non-finite P, zero size).
  std::optional<mapping::CameraModel> cameraFor(const sensor_msgs::Image& labels) const;

 private:
  std::optional<mapping::CameraModel> fromInfo(const std::string& camera_frame) const;

  static constexpr std::size_t kMaxWaiting = 5;
  const tf2_ros::Buffer& tf_;
  std::optional<mapping::CameraModel> file_camera_;
  std::optional<sensor_msgs::CameraInfo> camera_info_;
  std::string lidar_frame_;
  std::deque<sensor_msgs::ImageConstPtr> waiting_;
};

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
