#include "inekf_semantic_mapping/ros/kitti_bag_conventions.h"

#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_msgs/TFMessage.h>

#include <cmath>
#include <sstream>
#include <stdexcept>

#include "inekf_semantic_mapping/ros/localization_conversions.h"
#include "inekf_semantic_mapping/ros/names.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

namespace {

constexpr char kWorld[] = "world";  // the parent of base_link on the Python kitti2bag's /tf

const char kBothConventions[] =
    "expected a bag of this package's kitti2bag (/tf_static base_link -> imu_link, nothing on "
    "/tf) or of the Python kitti2bag, tomas789/kitti2bag (/tf world -> base_link)";

Eigen::Vector3d toEigen(const geometry_msgs::Vector3& v) { return {v.x, v.y, v.z}; }

bool sameTransform(const geometry_msgs::Transform& a, const geometry_msgs::Transform& b) {
  return a.translation.x == b.translation.x && a.translation.y == b.translation.y &&
         a.translation.z == b.translation.z && a.rotation.x == b.rotation.x &&
         a.rotation.y == b.rotation.y && a.rotation.z == b.rotation.z &&
         a.rotation.w == b.rotation.w;
}

geometry_msgs::Vector3 toVector3(const Eigen::Vector3d& v) {
  geometry_msgs::Vector3 out;
  out.x = v.x();
  out.y = v.y();
  out.z = v.z();
  return out;
}

Eigen::Matrix3d yawOnly(const Eigen::Matrix3d& R_map_body) {
  return Eigen::AngleAxisd(std::atan2(R_map_body(1, 0), R_map_body(0, 0)), Eigen::Vector3d::UnitZ())
      .toRotationMatrix();
}

void requireTopic(const BagContents& bag, const std::string& topic, const std::string& type) {
  const auto found = bag.topic_types.find(topic);
  if (found == bag.topic_types.end()) {
    throw std::runtime_error("bag " + bag.path + ": no topic " + topic + " (" + type + "); " +
                             kBothConventions);
  }
  if (found->second != type) {
    throw std::runtime_error("bag " + bag.path + ": topic " + topic + " is " + found->second +
                             ", expected " + type);
  }
}

// The /tf pairs whose child is base_link (a second parent next to inekf_node's map).
std::set<std::pair<std::string, std::string>> dynamicParentsOfBase(const BagContents& bag) {
  std::set<std::pair<std::string, std::string>> out;
  for (const auto& pair : bag.dynamic_frames) {
    if (pair.second == frames::kBaseLink) out.insert(pair);
  }
  return out;
}

std::string describe(const std::set<std::pair<std::string, std::string>>& pairs) {
  std::ostringstream out;
  const char* separator = "";
  for (const auto& [parent, child] : pairs) {
    out << separator << parent << " -> " << child;
    separator = ", ";
  }
  return pairs.empty() ? "nothing" : out.str();
}

}  // namespace

std::string bagConventionName(BagConvention convention) {
  return convention == BagConvention::kIsm ? "ism" : "kitti2bag_py";
}

BagConvention bagConventionFromString(const std::string& name) {
  if (name == "ism") return BagConvention::kIsm;
  if (name == "kitti2bag_py") return BagConvention::kKitti2bagPy;
  throw std::invalid_argument("bag convention '" + name +
                              "': expected auto, ism (this package's kitti2bag) or kitti2bag_py "
                              "(tomas789/kitti2bag)");
}

BagConvention detectBagConvention(const BagContents& bag) {
  requireTopic(bag, bag_topics::kImu, "sensor_msgs/Imu");
  requireTopic(bag, bag_topics::kGpsFix, "sensor_msgs/NavSatFix");
  const auto parents = dynamicParentsOfBase(bag);
  if (parents.count({kWorld, frames::kBaseLink})) return BagConvention::kKitti2bagPy;
  if (!parents.empty()) {
    throw std::runtime_error("bag " + bag.path + ": /tf carries " + describe(parents) +
                             " (base_link would have a second parent next to inekf_node's map); " +
                             kBothConventions);
  }
  if (bag.static_frames.count({frames::kBaseLink, frames::kImu})) return BagConvention::kIsm;
  throw std::runtime_error("bag " + bag.path +
                           ": /tf_static has no base_link -> imu_link and /tf " +
                           "no world -> base_link (/tf_static: " + describe(bag.static_frames) +
                           "); " + kBothConventions);
}

void checkBagConvention(const BagContents& bag, BagConvention convention) {
  requireTopic(bag, bag_topics::kImu, "sensor_msgs/Imu");
  requireTopic(bag, bag_topics::kGpsFix, "sensor_msgs/NavSatFix");
  const auto parents = dynamicParentsOfBase(bag);
  if (convention == BagConvention::kIsm && !parents.empty()) {
    throw std::runtime_error("bag " + bag.path + " played as bag_convention ism, but its /tf " +
                             "carries " + describe(parents) +
                             " (base_link would have two parents): use bag_convention:=auto or "
                             "kitti2bag_py");
  }
  if (convention == BagConvention::kKitti2bagPy && !parents.count({kWorld, frames::kBaseLink})) {
    throw std::runtime_error("bag " + bag.path + " played as bag_convention kitti2bag_py, but " +
                             "its /tf has no world -> base_link (the OXTS pose; /tf has " +
                             describe(bag.dynamic_frames) + "): use bag_convention:=auto or ism");
  }
}

Eigen::Matrix3d levelledFromBody(const Eigen::Matrix3d& R_map_body) {
  return yawOnly(R_map_body).transpose() * R_map_body;
}

std::optional<sensor_msgs::Imu> imuLevelledToBody(const sensor_msgs::Imu& message) {
  const std::optional<Eigen::Matrix3d> R_map_body = imuOrientation(message);
  if (!R_map_body) return std::nullopt;
  const Eigen::Matrix3d R_body_level = levelledFromBody(*R_map_body).transpose();
  sensor_msgs::Imu out = message;
  out.linear_acceleration = toVector3(R_body_level * toEigen(message.linear_acceleration));
  out.angular_velocity = toVector3(R_body_level * toEigen(message.angular_velocity));
  // A diagonal covariance with equal entries (or unknown/zero) is unchanged by the rotation;
  // otherwise rotate it too.
  for (auto* covariance : {&out.linear_acceleration_covariance, &out.angular_velocity_covariance}) {
    if ((*covariance)[0] == -1.0) continue;
    Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> C(covariance->data());
    const Eigen::Matrix3d rotated = R_body_level * C * R_body_level.transpose();
    C = rotated;
  }
  return out;
}

geometry_msgs::TwistStamped velocityLevelledToMap(const geometry_msgs::TwistStamped& message,
                                                  const Eigen::Matrix3d& R_map_body,
                                                  const std::string& map_frame) {
  geometry_msgs::TwistStamped out = message;
  out.header.frame_id = map_frame;
  const Eigen::Matrix3d R_map_level = yawOnly(R_map_body);
  out.twist.linear = toVector3(R_map_level * toEigen(message.twist.linear));
  out.twist.angular = toVector3(R_map_level * toEigen(message.twist.angular));
  return out;
}

sensor_msgs::CameraInfo rectifiedCameraInfo(const sensor_msgs::CameraInfo& info) {
  bool finite = true;
  for (double p : info.P) finite = finite && std::isfinite(p);
  if (!finite || info.P[10] == 0.0) {
    throw std::invalid_argument("camera_info of " + info.header.frame_id +
                                ": P is not a finite projection matrix");
  }
  sensor_msgs::CameraInfo out = info;
  for (int row = 0; row < 3; ++row) {
    for (int col = 0; col < 3; ++col) out.K[3 * row + col] = info.P[4 * row + col];
    out.P[4 * row + 3] = 0.0;  // the baseline: already in the tf to this camera frame
  }
  out.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  out.D.assign(5, 0.0);
  out.distortion_model = "plumb_bob";
  return out;
}

Eigen::Isometry3d toIsometry(const geometry_msgs::Transform& transform) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(transform.rotation.w, transform.rotation.x, transform.rotation.y,
                                  transform.rotation.z)
                   .normalized()
                   .toRotationMatrix();
  T.translation() = toEigen(transform.translation);
  return T;
}

nav_msgs::Odometry groundTruthOfBase(const geometry_msgs::TransformStamped& world_oxts,
                                     const Eigen::Isometry3d& T_imu_base,
                                     const std::string& map_frame, const std::string& base_frame) {
  const Eigen::Isometry3d T_map_base = toIsometry(world_oxts.transform) * T_imu_base;
  nav_msgs::Odometry odometry;
  odometry.header.stamp = world_oxts.header.stamp;
  odometry.header.frame_id = map_frame;
  odometry.child_frame_id = base_frame;
  odometry.pose.pose = tf2::toMsg(T_map_base);
  return odometry;
}

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
    if (++read > BagStart::kTfMessagesToRead) break;
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

std::vector<geometry_msgs::TransformStamped> StaticTransformSet::add(
    const std::vector<geometry_msgs::TransformStamped>& transforms) {
  std::vector<geometry_msgs::TransformStamped> changed;
  for (const geometry_msgs::TransformStamped& transform : transforms) {
    const std::pair<std::string, std::string> key{transform.header.frame_id,
                                                  transform.child_frame_id};
    const auto found = transforms_.find(key);
    if (found != transforms_.end() && sameTransform(found->second.transform, transform.transform)) {
      continue;
    }
    transforms_[key] = transform;
    changed.push_back(transform);
  }
  return changed;
}

const geometry_msgs::TransformStamped* StaticTransformSet::find(const std::string& parent,
                                                                const std::string& child) const {
  const auto found = transforms_.find({parent, child});
  return found == transforms_.end() ? nullptr : &found->second;
}

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
