// kitti_bag_adapter: lets kitti_bag.launch play a KITTI bag of either convention unchanged
// (ros/kitti_bag_conventions.h): this package's kitti2bag ("ism") or the Python kitti2bag
// (tomas789/kitti2bag, "kitti2bag_py"). The bag plays with /tf, /tf_static, the IMU, gps/vel and
// camera_info remapped under /kitti_bag/; this node reads the bag file first (the convention, or
// an error naming the bag, the topic and what was expected), then republishes them: tf_static
// latched and only when a transform changes; /tf, less kitti2bag_py's world -> base_link (the
// OXTS pose), which becomes the ground-truth odometry instead of a second parent of base_link;
// for kitti2bag_py the levelled IMU vectors in the body frame, the levelled velocity in map axes
// with the heading of its own instant (ros/levelled_velocity_pairing.h), the rectified camera.
// Parameters (private): bag (required), convention (auto | ism | kitti2bag_py; auto); any other
// stops the node naming it. /diagnostics: convention, play rate, forwarded and dropped messages.
#include <geometry_msgs/TwistStamped.h>
#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Imu.h>
#include <tf2_msgs/TFMessage.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <tf2_ros/transform_broadcaster.h>

#include <string>
#include <vector>

#include "inekf_semantic_mapping/ros/diagnostics.h"
#include "inekf_semantic_mapping/ros/kitti_bag_conventions.h"
#include "inekf_semantic_mapping/ros/levelled_velocity_pairing.h"
#include "inekf_semantic_mapping/ros/localization_conversions.h"
#include "inekf_semantic_mapping/ros/names.h"
#include "inekf_semantic_mapping/ros/node_parameters.h"

namespace inekf_semantic_mapping {
namespace {

namespace conv = ros_conversions;
using conv::BagConvention;

// The remapped inputs (kitti_bag.launch remaps rosbag play's topics here).
constexpr const char* kRawTf = topics::kBagTf;
constexpr const char* kRawTfStatic = topics::kBagTfStatic;
constexpr const char* kRawImu = topics::kBagImu;
constexpr const char* kRawGpsVelocity = topics::kBagGpsVelocity;
constexpr const char* kRawCameraInfo = topics::kBagCameraInfo;

class KittiBagAdapter {
 public:
  KittiBagAdapter(ros::NodeHandle& nh, ros::NodeHandle& private_nh) : diagnostics_(nh, private_nh) {
    common::YamlReader parameters = conv::privateParameterReader(private_nh);
    std::string bag_path, convention = "auto";
    parameters.read("bag", &bag_path);
    parameters.read("convention", &convention);
    parameters.rejectUnknown();
    if (bag_path.empty()) parameters.fail("bag", "is not set (the bag kitti_bag.launch plays)");
    const conv::BagStart start = conv::readBagStart(bag_path);
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
    diagnostics_.add("bag adapter", [this, bag_path](auto& status) {
      playback_.fill(conv::wallNow(), 0.0, &status);
      status.add("bag convention", conv::bagConventionName(convention_));
      status.add("bag", bag_path);
    });
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

  // Sends the static transforms again only when one is new or changed.
  void addStatic(const std::vector<geometry_msgs::TransformStamped>& transforms) {
    const std::vector<geometry_msgs::TransformStamped> changed = static_.add(transforms);
    if (changed.empty()) return;
    if (const auto* base_imu = static_.find(frames::kBaseLink, frames::kImu)) {
      T_imu_base_ = conv::toIsometry(base_imu->transform).inverse();
    }
    static_broadcaster_.sendTransform(changed);
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
    playback_.noteData(message.header.stamp.toSec(), conv::wallNow(), "published imu");
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
      playback_.count("dropped imu", conv::wallNow());
      return;
    }
    imu_publisher_.publish(*body);
    publishVelocities(
        pairing_.addOrientation(message.header.stamp, *conv::imuOrientation(message)));
  }

  void onVelocity(const geometry_msgs::TwistStamped& message) {
    if (!levelled()) {
      velocity_publisher_.publish(message);
      return;
    }
    const std::size_t dropped_before = pairing_.dropped();
    publishVelocities(pairing_.addVelocity(message));
    if (pairing_.dropped() > dropped_before) {
      playback_.count("dropped velocity", conv::wallNow(), pairing_.dropped() - dropped_before);
      ROS_WARN_STREAM_THROTTLE(5.0, "kitti_bag_adapter: no IMU orientation on "
                                        << kRawImu << " up to the stamp of " << kRawGpsVelocity
                                        << " at " << pairing_.lastDroppedStamp()
                                        << ": dropped (its levelled velocity needs the heading)");
    }
  }

  void publishVelocities(const std::vector<geometry_msgs::TwistStamped>& velocities) {
    for (const geometry_msgs::TwistStamped& velocity : velocities) {
      velocity_publisher_.publish(velocity);
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
      playback_.count("dropped camera_info", conv::wallNow());
    }
  }

  BagConvention convention_ = BagConvention::kIsm;
  Eigen::Isometry3d T_imu_base_ = Eigen::Isometry3d::Identity();
  conv::StaticTransformSet static_;
  conv::LevelledVelocityPairing pairing_{frames::kMap};
  ros::Publisher imu_publisher_, velocity_publisher_, camera_info_publisher_,
      ground_truth_publisher_;
  std::vector<ros::Subscriber> subscribers_;
  tf2_ros::TransformBroadcaster broadcaster_;
  tf2_ros::StaticTransformBroadcaster static_broadcaster_;
  conv::PlaybackMonitor playback_{10.0, {"dropped imu", "dropped velocity", "dropped camera_info"}};
  conv::NodeDiagnostics diagnostics_;
};

}  // namespace
}  // namespace inekf_semantic_mapping

int main(int argc, char** argv) {
  ros::init(argc, argv, "kitti_bag_adapter");
  // Held outside the try: when the last NodeHandle goes, roscpp shuts rosconsole down, and the
  // fatal message of a node that could not start would print nothing.
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
