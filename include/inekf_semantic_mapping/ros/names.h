// One place for every topic and frame name (cartographer_ros style). Topic names follow
// kitti2bag so that bags made by kitti2bag play into these nodes unchanged. Plain constants:
// no ROS header is needed to use them.
#pragma once

namespace inekf_semantic_mapping {
namespace topics {
// Sensors (kitti_player / kitti2bag).
constexpr char kImu[] = "/kitti/oxts/imu";
constexpr char kGpsFix[] = "/kitti/oxts/gps/fix";
constexpr char kGpsVelocity[] = "/kitti/oxts/gps/vel";
constexpr char kGroundTruthOdometry[] = "/kitti/oxts/ground_truth";  // evaluation only
constexpr char kVelodyne[] = "/kitti/velo/pointcloud";
constexpr char kCameraColorLeftImage[] = "/kitti/camera_color_left/image_raw";
constexpr char kCameraColorLeftInfo[] = "/kitti/camera_color_left/camera_info";
// Localization (inekf_node).
constexpr char kOdometry[] = "/inekf/odometry";
constexpr char kPath[] = "/inekf/path";
constexpr char kFilterStatus[] = "/inekf/status";
// Segmentation (segmentation_node).
constexpr char kSegmentationLabels[] = "/segmentation/labels";    // mono8 Cityscapes labelIds
constexpr char kSegmentationOverlay[] = "/segmentation/overlay";  // rgb8
// Semantic map (semantic_octomap_node).
constexpr char kMapMarkers[] = "/semantic_map/markers";
constexpr char kLabeledCloud[] = "/semantic_map/labeled_cloud";
constexpr char kMapInfo[] = "/semantic_map/info";
// nav_msgs/OccupancyGrid: octomap_server's projected_map, and the drivable surface.
constexpr char kProjectedMap[] = "/semantic_map/projected_map";
constexpr char kDrivableMap[] = "/semantic_map/drivable_map";
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
}  // namespace frames
}  // namespace inekf_semantic_mapping
