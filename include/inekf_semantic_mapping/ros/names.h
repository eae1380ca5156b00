// One place for every topic and frame name (cartographer_ros style). Plain constants: no ROS
// header is needed to use them.
//
// The nodes use RELATIVE topic names, resolved in the node's namespace: in the root namespace
// "kitti/oxts/imu" is kitti2bag's /kitti/oxts/imu, so bags made by kitti2bag play into the nodes
// unchanged, and a pipeline started in a namespace (<group ns="car_a">) reads and writes only
// /car_a/... (with /tf remapped to tf: docs/ros_interfaces.md, "Names"). Bags carry kitti2bag's
// absolute names (bag_topics), the nodes' defaults are the same names without the leading slash.
#pragma once

#include <string>

namespace inekf_semantic_mapping {
namespace bag_topics {
// The topics of a KITTI bag (this package's kitti2bag and the Python kitti2bag).
constexpr char kImu[] = "/kitti/oxts/imu";
constexpr char kGpsFix[] = "/kitti/oxts/gps/fix";
constexpr char kGpsVelocity[] = "/kitti/oxts/gps/vel";
constexpr char kGroundTruthOdometry[] = "/kitti/oxts/ground_truth";  // evaluation only
constexpr char kVelodyne[] = "/kitti/velo/pointcloud";
constexpr char kCameraColorLeftImage[] = "/kitti/camera_color_left/image_raw";
constexpr char kCameraColorLeftInfo[] = "/kitti/camera_color_left/camera_info";
}  // namespace bag_topics

namespace topics {
// Sensors (kitti_player, kitti_bag_adapter / a bag): the bag's names, relative.
constexpr const char* kImu = &bag_topics::kImu[1];
constexpr const char* kGpsFix = &bag_topics::kGpsFix[1];
constexpr const char* kGpsVelocity = &bag_topics::kGpsVelocity[1];
constexpr const char* kGroundTruthOdometry = &bag_topics::kGroundTruthOdometry[1];
constexpr const char* kVelodyne = &bag_topics::kVelodyne[1];
constexpr const char* kCameraColorLeftImage = &bag_topics::kCameraColorLeftImage[1];
constexpr const char* kCameraColorLeftInfo = &bag_topics::kCameraColorLeftInfo[1];
// Wheel odometry into inekf_node (nav_msgs/Odometry; none in a KITTI bag): remap to yours.
constexpr char kWheelOdometry[] = "wheel_odom";
// Localization (inekf_node).
constexpr char kOdometry[] = "inekf/odometry";
constexpr char kPath[] = "inekf/path";
constexpr char kFilterStatus[] = "inekf/status";
// Segmentation (segmentation_node).
constexpr char kSegmentationLabels[] = "segmentation/labels";    // mono8 Cityscapes labelIds
constexpr char kSegmentationOverlay[] = "segmentation/overlay";  // rgb8
// Semantic map (semantic_octomap_node).
constexpr char kMapMarkers[] = "semantic_map/markers";
constexpr char kLabeledCloud[] = "semantic_map/labeled_cloud";
constexpr char kMapInfo[] = "semantic_map/info";
// nav_msgs/OccupancyGrid: octomap_server's projected_map, and the drivable surface.
constexpr char kProjectedMap[] = "semantic_map/projected_map";
constexpr char kDrivableMap[] = "semantic_map/drivable_map";
// kitti_bag.launch plays a bag's tf, IMU, gps/vel and camera_info here; kitti_bag_adapter
// republishes them in this package's convention.
constexpr char kBagTf[] = "kitti_bag/tf";
constexpr char kBagTfStatic[] = "kitti_bag/tf_static";
constexpr char kBagImu[] = "kitti_bag/oxts/imu";
constexpr char kBagGpsVelocity[] = "kitti_bag/oxts/gps/vel";
constexpr char kBagCameraInfo[] = "kitti_bag/camera_color_left/camera_info";
}  // namespace topics

namespace frames {
// REP-105: map is the KITTI devkit Mercator frame at the first fix (x east, y north, z up).
constexpr char kMap[] = "map";
// REP-103 body frame. In this package's bags it coincides with the OXTS unit (imu_link); the
// Python kitti2bag puts imu_link 1.7 m away: inekf_node goes through tf base_link -> imu_link.
constexpr char kBaseLink[] = "base_link";
constexpr char kImu[] = "imu_link";
constexpr char kVelodyne[] = "velo_link";
constexpr char kCameraGrayLeft[] = "camera_gray_left";
constexpr char kCameraGrayRight[] = "camera_gray_right";
constexpr char kCameraColorLeft[] = "camera_color_left";
constexpr char kCameraColorRight[] = "camera_color_right";

// A message's frame_id as tf2 names it: tf2 refuses a leading slash (older drivers' "/velo_link",
// "/gps"), and every lookup of such a frame failed.
inline std::string tfFrameId(const std::string& frame_id) {
  return !frame_id.empty() && frame_id.front() == '/' ? frame_id.substr(1) : frame_id;
}
}  // namespace frames
}  // namespace inekf_semantic_mapping
