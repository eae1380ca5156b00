#include "inekf_semantic_mapping/ros/label_input.h"

#include <ros/console.h>
#include <tf2_eigen/tf2_eigen.h>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/ros/mapping_conversions.h"
#include "inekf_semantic_mapping/ros/names.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

void LabelInput::push(const sensor_msgs::ImageConstPtr& labels) {
  labelImageView(*labels);
  waiting_.push_back(labels);
  if (waiting_.size() > kMaxWaiting) waiting_.pop_front();
}

void LabelInput::passTo(mapping::SemanticMappingSession& session) {
  while (!waiting_.empty()) {
    const sensor_msgs::ImageConstPtr labels = waiting_.front();
    try {
      const std::optional<mapping::CameraModel> camera = cameraFor(*labels);
      if (!camera) {
        ROS_WARN_THROTTLE(5,
                          "semantic_octomap_node: waiting for the camera (%s and tf %s -> "
                          "camera, or ~calib_dir) to use label images",
                          topics::kCameraColorLeftInfo, lidar_frame_.c_str());
        return;
      }
      waiting_.pop_front();
      ScopedTimer timer("semantic_map/labels");
      session.addLabelImage(labels->header.stamp.toSec(), labelImageView(*labels), *camera);
    } catch (const std::exception& e) {
      if (!waiting_.empty() && waiting_.front() == labels) waiting_.pop_front();
      ROS_ERROR_STREAM_THROTTLE(5, "semantic_octomap_node: " << topics::kSegmentationLabels
                                                             << " at " << labels->header.stamp
                                                             << " ignored: " << e.what());
    }
  }
}

void LabelInput::setCameraViewOf(mapping::SemanticMappingSession& session) const {
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

std::optional<mapping::CameraModel> LabelInput::cameraFor(const sensor_msgs::Image& labels) const {
  if (file_camera_) {
    mapping::CameraModel camera = *file_camera_;
    camera.width = static_cast<int>(labels.width);
    camera.height = static_cast<int>(labels.height);
    return camera;
  }
  if (!camera_info_) return std::nullopt;
  return fromInfo(labels.header.frame_id.empty() ? camera_info_->header.frame_id
                                                 : labels.header.frame_id);
}

std::optional<mapping::CameraModel> LabelInput::fromInfo(const std::string& camera_frame) const {
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
