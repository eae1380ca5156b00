// kitti_bag_adapter: lets kitti_bag.launch play a KITTI bag of either convention unchanged
// (ros/kitti_bag_conventions.h): this package's kitti2bag ("ism") or the Python kitti2bag
// (tomas789/kitti2bag, "kitti2bag_py"). kitti_bag.launch plays the bag with /tf, /tf_static,
// the IMU, gps/vel and camera_info remapped under /kitti_bag/; this node reads the bag file
// first (its topics and tf frames: the convention, or a clear error when it fits neither), then
// republishes them in this package's convention:
//   /kitti_bag/tf_static -> tf static (latched; sent again only when a transform changes, and
//       already before the bag plays: the bag's first static transforms are read from the file)
//   /kitti_bag/tf        -> /tf, except kitti2bag_py's world -> base_link (the OXTS pose), which
//       becomes /kitti/oxts/ground_truth (nav_msgs/Odometry of base_link in map): never a second
//       parent of base_link next to inekf_node's map
//   /kitti_bag/oxts/imu  -> /kitti/oxts/imu (kitti2bag_py: levelled vectors into the body frame)
//   /kitti_bag/oxts/gps/vel -> /kitti/oxts/gps/vel (kitti2bag_py: levelled (vf, vl, vu) -> map
//       with the heading of the IMU message of the same stamp: a velocity that arrives before
//       that message (a separate connection) waits for it, no longer; dropped only while no IMU
//       message comes at all, beyond 50 waiting)
//   /kitti_bag/camera_color_left/camera_info -> /kitti/camera_color_left/camera_info
//       (kitti2bag_py: the rectified camera, baseline once)
//
// Parameters (private): bag (string, required), convention (auto | ism | kitti2bag_py, auto);
// any other, or one of the wrong type, stops the node naming it.
// Exits with an error naming the bag, the topic and what was expected when the bag fits neither.
#include <geometry_msgs/TwistStamped.h>
#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Imu.h>
#include <tf2_msgs/TFMessage.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <tf2_ros/transform_broadcaster.h>

#include <cmath>
#include <deque>
#include <limits>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "inekf_semantic_mapping/ros/kitti_bag_conventions.h"
#include "inekf_semantic_mapping/ros/localization_conversions.h"
#include "inekf_semantic_mapping/ros/names.h"
#include "inekf_semantic_mapping/ros/node_parameters.h"

namespace inekf_semantic_mapping {
namespace {

namespace conv = ros_conversions;
using conv::BagConvention;

// The remapped inputs (kitti_bag.launch remaps rosbag play's topics here).
constexpr char kRawTf[] = "/kitti_bag/tf";
constexpr char kRawTfStatic[] = "/kitti_bag/tf_static";
constexpr char kRawImu[] = "/kitti_bag/oxts/imu";
constexpr char kRawGpsVelocity[] = "/kitti_bag/oxts/gps/vel";
constexpr char kRawCameraInfo[] = "/kitti_bag/camera_color_left/camera_info";
// How many /tf + /tf_static messages of the bag file are read to learn its frames (the frames
// of both conventions are all in the first frame's messages).
constexpr int kTfMessagesToRead = 200;

struct BagStart {
  conv::BagContents contents;
  std::vector<geometry_msgs::TransformStamped> first_static;  // the first of each pair
};

BagStart readBagStart(const std::string& path) {
  BagStart start;
  start.contents.path = path;
  rosbag::Bag bag(path, rosbag::bagmode::Read);
  rosbag::View all(bag);
  for (const rosbag::ConnectionInfo* connection : all.getConnections()) {
    start.contents.topic_types[connection->topic] = connection->datatype;
  }
  rosbag::View tf(bag, rosbag::TopicQuery(std::vector<std::string>{"/tf", "/tf_static"}));
  int read = 0;
  for (const rosbag::MessageInstance& instance : tf) {
    if (++read > kTfMessagesToRead) break;
    const auto message = instance.instantiate<tf2_msgs::TFMessage>();
    if (!message) {
      throw std::runtime_error("bag " + path + ": topic " + instance.getTopic() + " is " +
                               instance.getDataType() + ", expected tf2_msgs/TFMessage");
    }
    const bool is_static = instance.getTopic() == "/tf_static";
    for (const geometry_msgs::TransformStamped& transform : message->transforms) {
      const std::pair<std::string, std::string> pair{transform.header.frame_id,
                                                     transform.child_frame_id};
      if (is_static) {
        if (start.contents.static_frames.insert(pair).second) {
          start.first_static.push_back(transform);
        }
      } else {
        start.contents.dynamic_frames.insert(pair);
      }
    }
  }
  return start;
}

bool sameTransform(const geometry_msgs::Transform& a, const geometry_msgs::Transform& b) {
  return a.translation.x == b.translation.x && a.translation.y == b.translation.y &&
         a.translation.z == b.translation.z && a.rotation.x == b.rotation.x &&
         a.rotation.y == b.rotation.y && a.rotation.z == b.rotation.z &&
         a.rotation.w == b.rotation.w;
}

class KittiBagAdapter {
 public:
  KittiBagAdapter(ros::NodeHandle& nh, ros::NodeHandle& private_nh) {
    common::YamlReader parameters = conv::privateParameterReader(private_nh);
    std::string bag_path, convention = "auto";
    parameters.read("bag", &bag_path);
    parameters.read("convention", &convention);
    parameters.rejectUnknown();
    if (bag_path.empty()) parameters.fail("bag", "is not set (the bag kitti_bag.launch plays)");
    const BagStart start = readBagStart(bag_path);
    if (convention == "auto") {
      convention_ = conv::detectBagConvention(start.contents);
    } else {
      convention_ = conv::bagConventionFromString(convention);
      conv::checkBagConvention(start.contents, convention_);
    }
    ROS_INFO_STREAM("kitti_bag_adapter: " << bag_path << ": convention "
                                          << conv::bagConventionName(convention_)
                                          << (convention == "auto" ? " (detected)" : " (chosen)"));
    addStatic(start.first_static);

    imu_publisher_ = nh.advertise<sensor_msgs::Imu>(topics::kImu, 400);
    velocity_publisher_ = nh.advertise<geometry_msgs::TwistStamped>(topics::kGpsVelocity, 50);
    camera_info_publisher_ = nh.advertise<sensor_msgs::CameraInfo>(topics::kCameraColorLeftInfo, 5);
    if (convention_ == BagConvention::kKitti2bagPy) {
      ground_truth_publisher_ = nh.advertise<nav_msgs::Odometry>(topics::kGroundTruthOdometry, 50);
    }
    const auto hints = ros::TransportHints().tcpNoDelay();
    subscribers_.push_back(
        nh.subscribe(kRawTfStatic, 50, &KittiBagAdapter::onTfStatic, this, hints));
    subscribers_.push_back(nh.subscribe(kRawTf, 200, &KittiBagAdapter::onTf, this, hints));
    subscribers_.push_back(nh.subscribe(kRawImu, 400, &KittiBagAdapter::onImu, this, hints));
    subscribers_.push_back(
        nh.subscribe(kRawGpsVelocity, 50, &KittiBagAdapter::onVelocity, this, hints));
    subscribers_.push_back(nh.subscribe(kRawCameraInfo, 5, &KittiBagAdapter::onCameraInfo, this));
  }

 private:
  bool levelled() const { return convention_ == BagConvention::kKitti2bagPy; }

  // Sends the static transforms again only when one is new or changed: the Python kitti2bag
  // re-publishes them with every frame.
  void addStatic(const std::vector<geometry_msgs::TransformStamped>& transforms) {
    std::vector<geometry_msgs::TransformStamped> changed;
    for (const geometry_msgs::TransformStamped& transform : transforms) {
      const std::pair<std::string, std::string> key{transform.header.frame_id,
                                                    transform.child_frame_id};
      const auto found = static_.find(key);
      if (found != static_.end() && sameTransform(found->second.transform, transform.transform)) {
        continue;
      }
      static_[key] = transform;
      changed.push_back(transform);
      if (key == std::pair<std::string, std::string>{frames::kBaseLink, frames::kImu}) {
        T_imu_base_ = conv::toIsometry(transform.transform).inverse();
      }
    }
    if (!changed.empty()) static_broadcaster_.sendTransform(changed);
  }

  void onTfStatic(const tf2_msgs::TFMessage& message) { addStatic(message.transforms); }

  void onTf(const tf2_msgs::TFMessage& message) {
    std::vector<geometry_msgs::TransformStamped> forward;
    for (const geometry_msgs::TransformStamped& transform : message.transforms) {
      if (levelled() && transform.child_frame_id == frames::kBaseLink) {
        ground_truth_publisher_.publish(
            conv::groundTruthOfBase(transform, T_imu_base_, frames::kMap, frames::kBaseLink));
      } else {
        forward.push_back(transform);
      }
    }
    if (!forward.empty()) broadcaster_.sendTransform(forward);
  }

  void onImu(const sensor_msgs::Imu& message) {
    if (!levelled()) {
      imu_publisher_.publish(message);
      return;
    }
    const std::optional<sensor_msgs::Imu> body = conv::imuLevelledToBody(message);
    if (!body) {
      ROS_WARN_STREAM_THROTTLE(5.0, "kitti_bag_adapter: " << kRawImu << " message at "
                                                          << message.header.stamp
                                                          << " has no usable orientation: its "
                                                             "levelled vectors cannot be turned "
                                                             "into the body frame, dropped");
      return;
    }
    if (!orientations_.empty() && message.header.stamp < orientations_.back().first) {
      // The bag looped (or the player restarted): the old orientations are of another time, and
      // velocities waiting from before the jump will never be reached.
      orientations_.clear();
      while (!pending_velocities_.empty() && pending_velocities_.front().header.stamp >
                                                 message.header.stamp + ros::Duration(kLoopJumpS)) {
        pending_velocities_.pop_front();
      }
    }
    orientations_.emplace_back(message.header.stamp, *conv::imuOrientation(message));
    while (orientations_.size() > 200) orientations_.pop_front();
    imu_publisher_.publish(*body);
    releaseVelocities();
  }

  void onVelocity(const geometry_msgs::TwistStamped& message) {
    if (!levelled()) {
      velocity_publisher_.publish(message);
      return;
    }
    // Its levelled vector needs the heading of its instant (the bag writes IMU and gps/vel with
    // equal stamps), which travels on the IMU's connection: rosbag play's messages of one
    // instant can arrive in either order. Dropping a velocity that came first (as before) could
    // lose the first frame's, and inekf_node's start waits for it: the start came a frame later.
    if (!pending_velocities_.empty() &&
        message.header.stamp < pending_velocities_.back().header.stamp) {
      pending_velocities_.clear();  // the bag looped: those wait for an IMU of another time
    }
    pending_velocities_.push_back(message);
    releaseVelocities();
    while (pending_velocities_.size() > kMaxPendingVelocities) {
      ROS_WARN_STREAM_THROTTLE(5.0, "kitti_bag_adapter: no IMU orientation on "
                                        << kRawImu << " up to the stamp of " << kRawGpsVelocity
                                        << " at " << pending_velocities_.front().header.stamp
                                        << ": dropped (its levelled velocity needs the heading)");
      pending_velocities_.pop_front();
    }
  }

  // Publishes the waiting velocities the IMU has reached (an orientation at or after their
  // stamp), each with the orientation nearest to its stamp (the same stamp on KITTI).
  void releaseVelocities() {
    while (!pending_velocities_.empty() && !orientations_.empty() &&
           pending_velocities_.front().header.stamp <= orientations_.back().first) {
      const geometry_msgs::TwistStamped& velocity = pending_velocities_.front();
      const Eigen::Matrix3d* R_map_body = &orientations_.back().second;
      double nearest_s = std::numeric_limits<double>::infinity();
      for (const auto& [stamp, rotation] : orientations_) {
        const double gap_s = std::abs((stamp - velocity.header.stamp).toSec());
        if (gap_s < nearest_s) {
          nearest_s = gap_s;
          R_map_body = &rotation;
        }
      }
      velocity_publisher_.publish(conv::velocityLevelledToMap(velocity, *R_map_body, frames::kMap));
      pending_velocities_.pop_front();
    }
  }

  void onCameraInfo(const sensor_msgs::CameraInfo& message) {
    if (!levelled()) {
      camera_info_publisher_.publish(message);
      return;
    }
    try {
      camera_info_publisher_.publish(conv::rectifiedCameraInfo(message));
    } catch (const std::exception& error) {
      ROS_WARN_STREAM_THROTTLE(
          5.0, "kitti_bag_adapter: " << kRawCameraInfo << ": " << error.what() << ", dropped");
    }
  }

  BagConvention convention_ = BagConvention::kIsm;
  Eigen::Isometry3d T_imu_base_ = Eigen::Isometry3d::Identity();
  std::map<std::pair<std::string, std::string>, geometry_msgs::TransformStamped> static_;
  std::deque<std::pair<ros::Time, Eigen::Matrix3d>> orientations_;
  // Levelled velocities waiting for the IMU orientation of their stamp (releaseVelocities).
  static constexpr std::size_t kMaxPendingVelocities = 50;
  static constexpr double kLoopJumpS = 1.0;  // waiting velocities this much newer: another loop
  std::deque<geometry_msgs::TwistStamped> pending_velocities_;
  ros::Publisher imu_publisher_, velocity_publisher_, camera_info_publisher_,
      ground_truth_publisher_;
  std::vector<ros::Subscriber> subscribers_;
  tf2_ros::TransformBroadcaster broadcaster_;
  tf2_ros::StaticTransformBroadcaster static_broadcaster_;
};

}  // namespace
}  // namespace inekf_semantic_mapping

int main(int argc, char** argv) {
  ros::init(argc, argv, "kitti_bag_adapter");
  ros::NodeHandle nh;
  ros::NodeHandle private_nh("~");
  try {
    inekf_semantic_mapping::KittiBagAdapter adapter(nh, private_nh);
    ros::spin();
  } catch (const std::exception& error) {
    ROS_FATAL_STREAM("kitti_bag_adapter: " << error.what());
    return 1;
  }
  return 0;
}
