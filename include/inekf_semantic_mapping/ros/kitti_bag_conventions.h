// The two KITTI bag conventions kitti_bag.launch plays, and the conversions kitti_bag_adapter
// applies so that the nodes see one convention (this package's, see kitti_conversions.h).
//
//   ism           this package's kitti2bag: IMU body-frame ax..az / wx..wz, gps/vel (ve, vn, vu)
//                 in map, camera_info of the rectified camera with the baseline in the tf only,
//                 ground truth on /kitti/oxts/ground_truth, nothing on /tf.
//   kitti2bag_py  the Python kitti2bag (tomas789/kitti2bag, pykitti): /tf world -> base_link
//                 (the OXTS pose, pykitti T_w_imu), /tf_static base_link -> imu_link = (-1.405,
//                 0.32, 0.93) m re-published every frame, IMU af..au / wf..wu (levelled
//                 forward-left-up, gravity-aligned), gps/vel (vf, vl, vu) levelled, fixes with
//                 unknown covariance, camera_info K/D unrectified with P = P_rect (P[3] = fx * b
//                 while the tf already holds b), clouds x y z i without ring.
// ROS-facing (src/ros): only nodes and tests include this header.
#pragma once

#include <geometry_msgs/TransformStamped.h>
#include <geometry_msgs/TwistStamped.h>
#include <nav_msgs/Odometry.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Imu.h>

#include <Eigen/Geometry>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace inekf_semantic_mapping {
namespace ros_conversions {

enum class BagConvention { kIsm, kKitti2bagPy };

// "ism" | "kitti2bag_py" (what ~convention / bag_convention:= take besides "auto").
std::string bagConventionName(BagConvention convention);
// Throws std::invalid_argument naming the accepted values.
BagConvention bagConventionFromString(const std::string& name);

// What a bag holds, as far as the convention goes: each topic's message type and the
// parent -> child pairs seen on /tf and /tf_static.
struct BagContents {
  std::string path;  // for messages
  std::map<std::string, std::string> topic_types;
  std::set<std::pair<std::string, std::string>> dynamic_frames, static_frames;
};

// The start of a bag file: its topics and the tf frames of its first kTfMessagesToRead /tf and
// /tf_static messages (the frames of both conventions are all in the first frame's messages),
// and the first transform of each static pair (broadcast before the bag plays). Throws
// std::runtime_error naming the bag and the topic when a tf topic is not tf2_msgs/TFMessage.
struct BagStart {
  static constexpr int kTfMessagesToRead = 200;
  BagContents contents;
  std::vector<geometry_msgs::TransformStamped> first_static;
};
BagStart readBagStart(const std::string& path);

// The static transforms seen so far, by (parent, child). The Python kitti2bag re-publishes them
// with every frame: add() returns only those that are new or changed (to be sent again).
class StaticTransformSet {
 public:
  std::vector<geometry_msgs::TransformStamped> add(
      const std::vector<geometry_msgs::TransformStamped>& transforms);
  const geometry_msgs::TransformStamped* find(const std::string& parent,
                                              const std::string& child) const;

 private:
  std::map<std::pair<std::string, std::string>, geometry_msgs::TransformStamped> transforms_;
};

// The convention of a bag: kitti2bag_py when /tf carries world -> base_link, ism when /tf_static
// carries base_link -> imu_link and nothing on /tf has base_link as child. Throws
// std::runtime_error naming the bag, the topic and what was expected when the bag fits neither
// (no IMU or fix topic of the right type, no frames that tell).
BagConvention detectBagConvention(const BagContents& bag);

// The same checks for a convention chosen by the user: throws std::runtime_error when the bag
// does not fit it (e.g. bag_convention:=ism on a bag with world -> base_link on /tf, whose
// base_link would get two parents).
void checkBagConvention(const BagContents& bag, BagConvention convention);

// R_level_body: the body (imu_link) axes in the OXTS levelled frame (x forward along the heading,
// parallel to the ground, z up), i.e. the orientation with its yaw taken out:
// Rz(-yaw) * R_map_body, where yaw = atan2(R(1,0), R(0,0)) (REP-103 ZYX).
Eigen::Matrix3d levelledFromBody(const Eigen::Matrix3d& R_map_body);

// An Imu message of the kitti2bag_py convention (vectors levelled) in this package's (vectors in
// the body frame: R_level_body^T v, with the message's own roll and pitch). nullopt when the
// message has no usable orientation (covariance[0] == -1, not finite, not unit).
std::optional<sensor_msgs::Imu> imuLevelledToBody(const sensor_msgs::Imu& message);

// gps/vel of the kitti2bag_py convention (vf, vl, vu: levelled) in map axes (ve, vn, vu) with
// frame_id map, as this package's bags carry it: Rz(yaw) v with the yaw of R_map_body.
geometry_msgs::TwistStamped velocityLevelledToMap(const geometry_msgs::TwistStamped& message,
                                                  const Eigen::Matrix3d& R_map_body,
                                                  const std::string& map_frame);

// camera_info of the kitti2bag_py convention as the rectified camera it describes, with the
// baseline counted once (in the tf): K = P(0:3, 0:3), D = 0 (the image is rectified), R = I,
// P = [K | 0]. Throws std::invalid_argument when P is not a finite projection (P(2,2) == 0).
sensor_msgs::CameraInfo rectifiedCameraInfo(const sensor_msgs::CameraInfo& info);

// Ground truth of base_link from the bag's world -> base_link (which holds the OXTS unit's
// pose, pykitti's T_w_imu): T_map_base = T_world_oxts * T_imu_base, where T_imu_base is the
// inverse of the bag's static base_link -> imu_link. world is taken as map: both are the devkit
// Mercator frame at the first OXTS pose (inekf_node's map origin is the first fix, and every fix
// of such a bag is STATUS_FIX). Twist left zero (unknown).
nav_msgs::Odometry groundTruthOfBase(const geometry_msgs::TransformStamped& world_oxts,
                                     const Eigen::Isometry3d& T_imu_base,
                                     const std::string& map_frame, const std::string& base_frame);

Eigen::Isometry3d toIsometry(const geometry_msgs::Transform& transform);

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
