// The camera of semantic_octomap_node's label images: the raw KITTI calibration (~calib_dir)
// when the node has one, else camera_info P (a rectified image) with the static lidar -> camera
// transform from tf. Label images do not wait here: the session takes each one as it comes and
// looks its camera up when it needs it (SemanticMappingSession::setCameraLookup).
// ROS-facing (src/ros): only nodes include this header.
#pragma once

#include <sensor_msgs/CameraInfo.h>
#include <tf2_ros/buffer.h>

#include <optional>
#include <string>

#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

class LabelCamera {
 public:
  // file_camera: the camera from calibration files, at its own image size (then tf and
  // camera_info are not used); file_camera_source names them in errors.
  LabelCamera(const tf2_ros::Buffer& tf, std::optional<mapping::CameraModel> file_camera,
              std::string file_camera_source = "")
      : tf_(tf),
        file_camera_(std::move(file_camera)),
        file_camera_source_(std::move(file_camera_source)) {}

  void setCameraInfo(const sensor_msgs::CameraInfo& info) { camera_info_ = info; }
  // The frame of the clouds (the camera's pose is looked up against it).
  void setLidarFrame(const std::string& frame) { lidar_frame_ = frame; }

  // The camera of a width x height label image in `camera_frame` (empty: camera_info's frame);
  // nullopt while something is missing (said once in a while in the log). Throws
  // std::invalid_argument for an unusable camera_info (non-finite P, zero size), and for a label
  // image of another size than the calibration files' rectified one (another day's calibration:
  // every label would land off by the difference).
  std::optional<mapping::CameraModel> cameraFor(const std::string& camera_frame, int width,
                                                int height) const;
  // Makes this the session's camera lookup, and its label warnings log lines naming the topic
  // and stamp. This object must outlive the session's use of it.
  void serve(mapping::SemanticMappingSession* session) const;
  // Scans that come before the first label image are cut to the camera's view as soon as the
  // camera is known, like the labelled ones (a whole HDL-64 scan costs several times more).
  void setCameraViewOf(mapping::SemanticMappingSession& session) const;

 private:
  std::optional<mapping::CameraModel> fromInfo(const std::string& camera_frame) const;

  const tf2_ros::Buffer& tf_;
  std::optional<mapping::CameraModel> file_camera_;
  std::string file_camera_source_;
  std::optional<sensor_msgs::CameraInfo> camera_info_;
  std::string lidar_frame_;
};

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
