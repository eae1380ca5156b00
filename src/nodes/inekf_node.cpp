// inekf_node: the ROS face of estimation::LocalizationSession (the same session inekf_offline
// drives: start, map origin, fix policy, time-jump reset and statistics live there). Subscribes
// the IMU, the GPS fix and the GPS velocity (kitti_player / kitti2bag topics by default,
// remappable), and publishes nav_msgs/Odometry, nav_msgs/Path, tf map -> base_link and
// FilterStatus. Poses: the start's at the first used fix's stamp, then one per IMU sample.
//
// Parameters (private):
//   config_file (string, default $(find inekf_semantic_mapping)/config/inekf.yaml)
//   filter | filter_type (string, left | right | ekf; overrides the config file)
//   init_orientation_from_imu (bool; overrides init_orientation_from_reference)
//   origin_lat, origin_lon, origin_alt (double; all three or none: the map origin, else the first
//     usable fix)
//   default_fix_sigma_horizontal_m, default_fix_sigma_vertical_m, time_jump_back_s (override the
//     config's session.*); min_fix_sigma_m (overrides gps.min_sigma_m, the one fix floor)
//   publish_tf (true), map_frame (map), base_frame (base_link)
//   imu_frame (string, default: the IMU messages' frame_id): the filter estimates this frame's
//     pose; odometry and tf are of base_frame, through the static base_frame -> imu_frame of tf
//     (identity, with one warning, while tf has none: a bag whose IMU is the body)
//   max_path_length (5000 poses), path_publish_period_s (1.0)
#include <geometry_msgs/TwistStamped.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <ros/package.h>
#include <ros/ros.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/NavSatFix.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <functional>
#include <optional>
#include <string>

#include "inekf_semantic_mapping/FilterStatus.h"
#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/estimation/localization_session.h"
#include "inekf_semantic_mapping/ros/kitti_bag_conventions.h"
#include "inekf_semantic_mapping/ros/localization_conversions.h"
#include "inekf_semantic_mapping/ros/names.h"

namespace inekf_semantic_mapping {
namespace {

using estimation::LocalizationSession;

class InekfNode {
 public:
  InekfNode(ros::NodeHandle& nh, ros::NodeHandle& private_nh)
      : session_(ros_conversions::sessionConfigFromParameters(
            private_nh, ros::package::getPath("inekf_semantic_mapping") + "/config/inekf.yaml",
            &config_file_)) {
    private_nh.param("publish_tf", publish_tf_, true);
    private_nh.param<std::string>("map_frame", path_.header.frame_id, frames::kMap);
    private_nh.param<std::string>("base_frame", base_frame_, frames::kBaseLink);
    private_nh.param<std::string>("imu_frame", imu_frame_, "");
    private_nh.param("max_path_length", max_path_length_, 5000);
    private_nh.param("path_publish_period_s", path_publish_period_s_, 1.0);
    max_path_length_ = std::max(max_path_length_, 1);
    odometry_publisher_ = nh.advertise<nav_msgs::Odometry>(topics::kOdometry, 50);
    path_publisher_ = nh.advertise<nav_msgs::Path>(topics::kPath, 1, /*latch=*/true);
    status_publisher_ = nh.advertise<FilterStatus>(topics::kFilterStatus, 10);
    imu_subscriber_ = nh.subscribe(topics::kImu, 400, &InekfNode::onImu, this,
                                   ros::TransportHints().tcpNoDelay());
    fix_subscriber_ = nh.subscribe(topics::kGpsFix, 50, &InekfNode::onFix, this);
    velocity_subscriber_ = nh.subscribe(topics::kGpsVelocity, 10, &InekfNode::onVelocity, this);
    ROS_INFO_STREAM("inekf_node: " << filterStatus().filter_type << " filter, config "
                                   << config_file_ << ", waiting for IMU on "
                                   << imu_subscriber_.getTopic() << " and GPS on "
                                   << fix_subscriber_.getTopic());
  }

  ~InekfNode() { ROS_INFO_STREAM("inekf_node timing:\n" << TimingRegistry::instance().report()); }

 private:
  // Runs one event through the session (`stage` in the timing report); a callback never lets an
  // exception out.
  void handle(const char* stage, const ros::Time& stamp,
              const std::function<LocalizationSession::Update()>& event) {
    try {
      ScopedTimer timer(stage);
      session_.setGpsVelocityExpected(velocity_subscriber_.getNumPublishers() > 0);
      const ros::Time now = ros::Time::now();
      if (!now.isZero()) report(session_.addClock(now.toSec()));
      const LocalizationSession::Update update = event();
      report(update);
      // The start's pose at the first fix's stamp, whichever message completed the start: a scan
      // between it and the next IMU sample has a pose (issue 13: before, the first pose came with
      // the next IMU sample, 0.1 s later on KITTI, and such scans stayed out of the map).
      if (update.start_estimate) {
        publishState(startStamp(update.start_estimate->state.stamp_s), update.start_estimate->state,
                     update.start_estimate->pose_covariance);
      }
      if (update.new_estimate) publishState(stamp, session_.state(), session_.poseCovariance());
      if (update.new_estimate || update.correction || update.started) publishStatus(stamp);
    } catch (const std::exception& error) {
      ROS_ERROR_STREAM_THROTTLE(
          5.0, "inekf_node: " << stage << " message at " << stamp << " failed: " << error.what());
    }
  }

  void report(const LocalizationSession::Update& update) {
    if (update.reset) {
      ROS_WARN_STREAM("inekf_node: " << update.note << ": filter and path reset (bag loop?)");
      path_.poses.clear();
      path_publisher_.publish(path_);
      last_path_publish_ = ros::Time();
    } else if (update.started) {
      ROS_INFO_STREAM("inekf_node: " << filterStatus().filter_type << " " << update.note);
    } else if (!update.note.empty()) {
      ROS_WARN_STREAM_THROTTLE(5.0, "inekf_node: " << update.note);
    }
  }

  void onImu(const sensor_msgs::Imu::ConstPtr& message) {
    if (imu_frame_.empty() && !message->header.frame_id.empty()) {
      imu_frame_ = message->header.frame_id;
    }
    handle("inekf_node/imu", message->header.stamp,
           [&] { return session_.addImu(ros_conversions::imuEvent(*message)); });
  }

  void onFix(const sensor_msgs::NavSatFix::ConstPtr& message) {
    if (!logged_unknown_fix_covariance_ && ros_conversions::isUsableFix(*message) &&
        !ros_conversions::fixCovarianceEnu(*message)) {
      // E.g. the Python kitti2bag writes position_covariance_type 0 on every fix.
      logged_unknown_fix_covariance_ = true;
      ROS_INFO_STREAM("inekf_node: fixes on "
                      << fix_subscriber_.getTopic() << " without a usable covariance (type "
                      << int(message->position_covariance_type)
                      << "): using the configured sigmas, horizontal "
                      << session_.config().default_fix_sigma_horizontal_m << " m, vertical "
                      << session_.config().default_fix_sigma_vertical_m
                      << " m (session.default_fix_sigma_*)");
    }
    recent_fix_stamps_.push_back(message->header.stamp);
    while (recent_fix_stamps_.size() > kRecentFixStamps) recent_fix_stamps_.pop_front();
    handle("inekf_node/gps", message->header.stamp,
           [&] { return session_.addFix(ros_conversions::fixEvent(*message)); });
  }

  void onVelocity(const geometry_msgs::TwistStamped::ConstPtr& message) {
    const auto velocity = ros_conversions::gpsVelocity(*message);
    if (!velocity) return;
    handle("inekf_node/gps_velocity", message->header.stamp,
           [&] { return session_.addGpsVelocity(*velocity); });
  }

  // The start fix's own message stamp (the start is at a fix's stamp): exact, as every other
  // estimate's. ros::Time(stamp_s) only if that fix is not among the recent ones.
  ros::Time startStamp(double stamp_s) const {
    for (const ros::Time& fix_stamp : recent_fix_stamps_) {
      if (std::abs(fix_stamp.toSec() - stamp_s) < estimation::Localizer::kDuplicateStampS) {
        return fix_stamp;
      }
    }
    return ros::Time(stamp_s);
  }

  // Stamped with the message's own stamp, not ros::Time(state.stamp_s): a double loses the
  // nanoseconds, and consumers match our poses to their data by exact stamp.
  void publishState(const ros::Time& stamp, const estimation::NavState& state,
                    const estimation::PoseCovariance& pose_covariance) {
    nav_msgs::Odometry odometry;
    odometry.header.stamp = stamp;
    odometry.header.frame_id = path_.header.frame_id;
    odometry.child_frame_id = base_frame_;
    ros_conversions::fillOdometry(state, pose_covariance, session_.latestAngularVelocity(),
                                  &odometry);
    if (const auto T_base_imu = baseFromImu()) {
      odometry = ros_conversions::odometryOfBase(odometry, *T_base_imu, base_frame_);
    }
    odometry_publisher_.publish(odometry);
    if (publish_tf_) tf_broadcaster_.sendTransform(ros_conversions::transformOfOdometry(odometry));
    ros_conversions::appendToPath(odometry, static_cast<std::size_t>(max_path_length_), &path_);
    if (last_path_publish_.isZero() || stamp < last_path_publish_ ||
        (stamp - last_path_publish_).toSec() >= path_publish_period_s_) {
      path_.header.stamp = stamp;
      path_publisher_.publish(path_);
      last_path_publish_ = stamp;
    }
    ROS_INFO_STREAM_THROTTLE(10.0, "inekf_node: " << session_.summary());
  }

  // The static base_frame -> imu_frame from tf; nullopt (the IMU pose is published as the base
  // pose) when the IMU is the base or tf has no such transform (warned once). Looked up on
  // every estimate: it is cheap, and a transform that arrives late is picked up.
  std::optional<Eigen::Isometry3d> baseFromImu() {
    if (imu_frame_.empty() || imu_frame_ == base_frame_) return std::nullopt;
    try {
      const geometry_msgs::TransformStamped T =
          tf_buffer_.lookupTransform(base_frame_, imu_frame_, ros::Time(0));
      if (!found_base_imu_) {
        found_base_imu_ = true;
        ROS_INFO_STREAM("inekf_node: the filter estimates " << imu_frame_ << "; publishing "
                                                            << base_frame_ << " through tf "
                                                            << base_frame_ << " -> " << imu_frame_);
      }
      return ros_conversions::toIsometry(T.transform);
    } catch (const tf2::TransformException& error) {
      if (!warned_no_base_imu_) {
        warned_no_base_imu_ = true;
        ROS_WARN_STREAM("inekf_node: no tf " << base_frame_ << " -> " << imu_frame_ << " yet ("
                                             << error.what() << "): publishing the pose of "
                                             << imu_frame_ << " as " << base_frame_
                                             << " until it comes");
      }
      return std::nullopt;
    }
  }

  FilterStatus filterStatus() const { return ros_conversions::filterStatus(session_); }

  void publishStatus(const ros::Time& stamp) {
    FilterStatus status = filterStatus();
    status.header.stamp = stamp;
    status.header.frame_id = base_frame_;
    status_publisher_.publish(status);
  }

  static constexpr std::size_t kRecentFixStamps = 20;
  std::deque<ros::Time> recent_fix_stamps_;  // of the latest fixes received (startStamp)
  std::string config_file_;
  LocalizationSession session_;
  bool publish_tf_ = true;
  int max_path_length_ = 5000;
  double path_publish_period_s_ = 1.0;
  std::string base_frame_, imu_frame_;
  bool found_base_imu_ = false, warned_no_base_imu_ = false, logged_unknown_fix_covariance_ = false;
  tf2_ros::Buffer tf_buffer_;
  tf2_ros::TransformListener tf_listener_{tf_buffer_};
  ros::Time last_path_publish_;
  nav_msgs::Path path_;
  ros::Publisher odometry_publisher_, path_publisher_, status_publisher_;
  ros::Subscriber imu_subscriber_, fix_subscriber_, velocity_subscriber_;
  tf2_ros::TransformBroadcaster tf_broadcaster_;
};

}  // namespace
}  // namespace inekf_semantic_mapping

int main(int argc, char** argv) {
  ros::init(argc, argv, "inekf_node");
  ros::NodeHandle nh;
  ros::NodeHandle private_nh("~");
  try {
    inekf_semantic_mapping::InekfNode node(nh, private_nh);
    ros::spin();
  } catch (const std::exception& error) {
    ROS_FATAL_STREAM("inekf_node: " << error.what());
    return 1;
  }
  return 0;
}
