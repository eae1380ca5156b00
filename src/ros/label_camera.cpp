#include "inekf_semantic_mapping/ros/label_camera.h"

#include <ros/console.h>
#include <tf2_eigen/tf2_eigen.h>

#include <stdexcept>
#include <string>

#include "inekf_semantic_mapping/ros/mapping_conversions.h"
#include "inekf_semantic_mapping/ros/names.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

std::optional<mapping::CameraModel> LabelCamera::cameraFor(const std::string& camera_frame,
                                                           int width, int height) const {
  if (file_camera_) {
    mapping::CameraModel camera = *file_camera_;
    if (camera.width > 0 && camera.height > 0 &&
        (camera.width != width || camera.height != height)) {
      throw std::invalid_argument(
          "label image is " + std::to_string(width) + "x" + std::to_string(height) +
          ", the rectified size (S_rect) of " + file_camera_source_ + " says " +
          std::to_string(camera.width) + "x" + std::to_string(camera.height) +
          ": the calibration of another recording day or camera? (~calib_dir)");
    }
    camera.width = width;  // a calibration without S_rect: the images' own size
    camera.height = height;
    return camera;
  }
  std::optional<mapping::CameraModel> camera;
  if (camera_info_) {
    camera = fromInfo(camera_frame.empty() ? camera_info_->header.frame_id : camera_frame);
  }
  if (!camera) {
    ROS_WARN_THROTTLE(5,
                      "semantic_octomap_node: waiting for the camera (%s and tf %s -> camera, or "
                      "~calib_dir) to use label images",
                      topics::kCameraColorLeftInfo,
                      lidar_frame_.empty() ? "<lidar frame>" : lidar_frame_.c_str());
  }
  return camera;
}

void LabelCamera::serve(mapping::SemanticMappingSession* session) const {
  session->setCameraLookup([this](const std::string& frame, int width, int height) {
    return cameraFor(frame, width, height);
  });
  session->setLabelWarningCallback([](double stamp, const std::string& why) {
    ROS_ERROR_STREAM_THROTTLE(5, "semantic_octomap_node: " << topics::kSegmentationLabels << " at "
                                                           << ros::Time(stamp)
                                                           << " not used: " << why);
  });
}

void LabelCamera::setCameraViewOf(mapping::SemanticMappingSession& session) const {
  try {
    std::optional<mapping::CameraModel> view;
    if (file_camera_) {
      if (file_camera_->width > 0 && file_camera_->height > 0) view = file_camera_;
    } else if (camera_info_) {
      view = fromInfo(camera_info_->header.frame_id);
    }
    if (view) session.setCameraView(*view);
  } catch (const std::exception& e) {
    ROS_WARN_STREAM_THROTTLE(
        10, "semantic_octomap_node: " << topics::kCameraColorLeftInfo << " unusable: " << e.what());
  }
}

std::optional<mapping::CameraModel> LabelCamera::fromInfo(const std::string& camera_frame) const {
  // The lidar -> camera transform is static: the latest one is the one.
  if (lidar_frame_.empty() || !tf_.canTransform(camera_frame, lidar_frame_, ros::Time(0))) {
    return std::nullopt;
  }
  const Eigen::Isometry3d T_camera_lidar =
      tf2::transformToEigen(tf_.lookupTransform(camera_frame, lidar_frame_, ros::Time(0)));
  return cameraModelFromInfo(*camera_info_, T_camera_lidar);
}

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
