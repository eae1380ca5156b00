// inekf_node: the ROS face of the estimation library's Localizer (the same streaming front end as
// inekf_offline). Subscribes the IMU and the GPS fix (kitti_player / kitti2bag topics by default,
// remappable), converts fixes to the map frame (KITTI devkit Mercator at the first fix), and
// publishes nav_msgs/Odometry, nav_msgs/Path, tf map -> base_link and FilterStatus.
//
// Parameters (private):
//   config_file (string, default $(find inekf_semantic_mapping)/config/inekf.yaml)
//   filter | filter_type (string, left | right | ekf; overrides the config file)
//   init_orientation_from_imu (bool, default: the config file's init_orientation_from_reference)
//   origin_lat, origin_lon, origin_alt (double; all three or none: the map origin, else the first
//     usable fix)
//   default_fix_sigma_horizontal_m (1.5), default_fix_sigma_vertical_m (3.0): for fixes without
//     covariance;  min_fix_sigma_m (0.3): floor of the fix sigmas
//   publish_tf (true), map_frame (map), base_frame (base_link)
//   max_path_length (5000 poses), path_publish_period_s (1.0)
//   time_jump_back_s (1.0): a stamp or a /clock this much earlier than the last one resets
#include <geometry_msgs/TransformStamped.h>
#include <geometry_msgs/TwistStamped.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <ros/package.h>
#include <ros/ros.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/NavSatFix.h>
#include <tf2_ros/transform_broadcaster.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>

#include "inekf_semantic_mapping/FilterStatus.h"
#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/estimation/lazy_start.h"
#include "inekf_semantic_mapping/estimation/localizer.h"
#include "inekf_semantic_mapping/kitti/mercator.h"
#include "inekf_semantic_mapping/ros/localization_conversions.h"
#include "inekf_semantic_mapping/ros/names.h"

namespace inekf_semantic_mapping {
namespace {

using estimation::Localizer;
using estimation::LocalizerConfig;

std::string describeFilter(estimation::FilterType type) {
  switch (type) {
    case estimation::FilterType::kLeftInvariant:
      return "left_inekf";
    case estimation::FilterType::kRightInvariant:
      return "right_inekf";
    case estimation::FilterType::kQuaternionEskf:
      return "quaternion_eskf";
  }
  return "unknown";
}

class InekfNode {
 public:
  InekfNode(ros::NodeHandle& nh, ros::NodeHandle& private_nh) {
    loadParameters(private_nh);
    localizer_ = std::make_unique<Localizer>(config_);
    estimation::LazyStart::Config start_config;
    start_config.use_reference = config_.init_orientation_from_reference;
    lazy_start_ = std::make_unique<estimation::LazyStart>(start_config);

    odometry_publisher_ = nh.advertise<nav_msgs::Odometry>(topics::kOdometry, 50);
    path_publisher_ = nh.advertise<nav_msgs::Path>(topics::kPath, 1, /*latch=*/true);
    status_publisher_ = nh.advertise<FilterStatus>(topics::kFilterStatus, 10);
    imu_subscriber_ = nh.subscribe(topics::kImu, 400, &InekfNode::onImu, this,
                                   ros::TransportHints().tcpNoDelay());
    fix_subscriber_ = nh.subscribe(topics::kGpsFix, 50, &InekfNode::onFix, this);
    velocity_subscriber_ = nh.subscribe(topics::kGpsVelocity, 10, &InekfNode::onVelocity, this);
    path_.header.frame_id = map_frame_;
    ROS_INFO_STREAM("inekf_node: " << describeFilter(config_.filter_type) << " filter, config "
                                   << config_file_ << ", waiting for IMU on "
                                   << imu_subscriber_.getTopic() << " and GPS on "
                                   << fix_subscriber_.getTopic());
  }

  ~InekfNode() { ROS_INFO_STREAM("inekf_node timing:\n" << TimingRegistry::instance().report()); }

 private:
  void loadParameters(ros::NodeHandle& private_nh) {
    const std::string default_config =
        ros::package::getPath("inekf_semantic_mapping") + "/config/inekf.yaml";
    // An explicitly given config file must load (a bad one is fatal at start-up: nothing
    // sensible to run with, and fromYamlFile names the file and the key); without the parameter
    // a missing default file means the built-in defaults.
    if (private_nh.getParam("config_file", config_file_)) {
      config_ = LocalizerConfig::fromYamlFile(config_file_);
    } else if (std::ifstream(default_config).good()) {
      config_file_ = default_config;
      config_ = LocalizerConfig::fromYamlFile(config_file_);
    } else {
      config_file_ = "(built-in defaults)";
      ROS_WARN_STREAM("inekf_node: " << default_config
                                     << " not found, using the built-in filter defaults");
    }

    std::string filter_name;
    if (private_nh.getParam("filter_type", filter_name) ||
        private_nh.getParam("filter", filter_name)) {
      config_.filter_type = estimation::filterTypeFromString(filter_name);
    }
    private_nh.param("init_orientation_from_imu", config_.init_orientation_from_reference,
                     config_.init_orientation_from_reference);

    double lat = 0.0, lon = 0.0, alt = 0.0;
    const int origin_parts = private_nh.getParam("origin_lat", lat) +
                             private_nh.getParam("origin_lon", lon) +
                             private_nh.getParam("origin_alt", alt);
    if (origin_parts == 3) {
      projection_.emplace(lat, lon, alt);
    } else if (origin_parts != 0) {
      throw std::invalid_argument(
          "inekf_node: set all three of ~origin_lat, ~origin_lon, ~origin_alt or none");
    }

    private_nh.param("default_fix_sigma_horizontal_m", default_fix_sigma_horizontal_m_, 1.5);
    private_nh.param("default_fix_sigma_vertical_m", default_fix_sigma_vertical_m_, 3.0);
    private_nh.param("min_fix_sigma_m", min_fix_sigma_m_, 0.3);
    private_nh.param("publish_tf", publish_tf_, true);
    private_nh.param<std::string>("map_frame", map_frame_, frames::kMap);
    private_nh.param<std::string>("base_frame", base_frame_, frames::kBaseLink);
    private_nh.param("max_path_length", max_path_length_, 5000);
    private_nh.param("path_publish_period_s", path_publish_period_s_, 1.0);
    private_nh.param("time_jump_back_s", time_jump_back_s_, 1.0);
    max_path_length_ = std::max(max_path_length_, 1);
  }

  // A bag loop or a restarted player shows as a stamp (or /clock) clearly earlier than the last
  // one: the old state is meaningless in the new time line, so start over.
  void resetOnTimeJumpBack(const ros::Time& stamp, const char* source) {
    const ros::Time now = ros::Time::now();
    const ros::Duration tolerance(time_jump_back_s_);
    const bool stamp_back = !last_stamp_.isZero() && stamp + tolerance < last_stamp_;
    const bool clock_back = !last_clock_.isZero() && !now.isZero() && now + tolerance < last_clock_;
    if (stamp_back || clock_back) {
      ROS_WARN_STREAM(std::fixed << std::setprecision(3) << "inekf_node: time jumped back ("
                                 << (stamp_back ? "stamp" : "/clock") << " of " << source << " "
                                 << stamp.toSec() << " s, last " << last_stamp_.toSec()
                                 << " s): resetting the filter and the path (bag loop?)");
      localizer_->reset();
      lazy_start_->reset();
      path_.poses.clear();
      path_publisher_.publish(path_);
      last_path_publish_ = ros::Time();
      last_stamp_ = ros::Time();
      ++resets_;
    }
    last_stamp_ = std::max(last_stamp_, stamp);
    if (clock_back || now > last_clock_) last_clock_ = now;
  }

  // Callbacks never let an exception out: log it with context and keep running.
  void onImu(const sensor_msgs::Imu::ConstPtr& message) {
    try {
      handleImu(*message);
    } catch (const std::exception& error) {
      ROS_ERROR_STREAM_THROTTLE(5.0, "inekf_node: IMU message at " << message->header.stamp
                                                                   << " failed: " << error.what());
    }
  }

  void onFix(const sensor_msgs::NavSatFix::ConstPtr& message) {
    try {
      handleFix(*message);
    } catch (const std::exception& error) {
      ROS_ERROR_STREAM_THROTTLE(
          5.0, "inekf_node: GPS fix at " << message->header.stamp << " failed: " << error.what());
    }
  }

  void handleImu(const sensor_msgs::Imu& imu_message) {
    const sensor_msgs::Imu* message = &imu_message;
    ScopedTimer timer("inekf_node/imu");
    resetOnTimeJumpBack(message->header.stamp, "IMU");
    const std::optional<estimation::ImuSample> sample =
        ros_conversions::imuSampleFromMessage(*message);
    if (!sample) {
      ++imu_invalid_;
      ROS_WARN_THROTTLE(5.0, "inekf_node: IMU message with non-finite values ignored (%ld so far)",
                        imu_invalid_);
      return;
    }
    latest_angular_velocity_ = sample->angular_velocity;
    if (!localizer_->initialized()) {
      if (const auto orientation = ros_conversions::imuOrientation(*message)) {
        lazy_start_->offerOrientation(*orientation);
      }
    }
    const Localizer::ImuStatus status = localizer_->addImu(*sample);
    if (status == Localizer::ImuStatus::kNotInitialized) {
      tryStart(message->header.stamp);
      if (!localizer_->initialized()) return;
      // Started at the pending fix's stamp: a later sample carries the state on to its own.
      if (sample->stamp_s > localizer_->state().stamp_s + 1e-6) localizer_->addImu(*sample);
      if (std::abs(sample->stamp_s - localizer_->state().stamp_s) < 1e-6) {
        publishState(message->header.stamp);
      }
      return;
    }
    switch (status) {
      case Localizer::ImuStatus::kDroppedOutOfOrder:
      case Localizer::ImuStatus::kDroppedDuplicate:
        ROS_WARN_THROTTLE(
            5.0, "inekf_node: IMU sample at %.6f s dropped (%s; %ld dropped so far)",
            sample->stamp_s,
            status == Localizer::ImuStatus::kDroppedDuplicate ? "duplicate stamp" : "out of order",
            static_cast<long>(localizer_->statistics().imu_dropped));
        return;
      case Localizer::ImuStatus::kGap:
        ROS_WARN_THROTTLE(5.0, "inekf_node: IMU gap before %.3f s bridged with inflated noise",
                          sample->stamp_s);
        break;
      case Localizer::ImuStatus::kNotInitialized:
        return;
      case Localizer::ImuStatus::kUsed:
        break;
    }
    // The message's own stamp, not ros::Time(state.stamp_s): a double loses the nanoseconds,
    // and consumers match our poses to their data by exact stamp.
    publishState(message->header.stamp);
  }

  void onVelocity(const geometry_msgs::TwistStamped::ConstPtr& message) {
    if (localizer_->initialized()) return;  // only the start uses it
    if (const auto velocity = ros_conversions::gpsVelocity(*message)) {
      lazy_start_->offerVelocity(velocity->stamp_s, velocity->velocity, velocity->in_body_frame);
    }
    try {
      tryStart(message->header.stamp);
    } catch (const std::exception& error) {
      ROS_ERROR_STREAM_THROTTLE(5.0, "inekf_node: start at the GPS velocity at "
                                         << message->header.stamp << " failed: " << error.what());
    }
  }

  void handleFix(const sensor_msgs::NavSatFix& fix_message) {
    const sensor_msgs::NavSatFix* message = &fix_message;
    ScopedTimer timer("inekf_node/gps");
    resetOnTimeJumpBack(message->header.stamp, "GPS fix");
    if (!ros_conversions::isUsableFix(*message)) {
      ++fixes_ignored_;  // STATUS_NO_FIX (KITTI posmode <= 0) or NaN: never used
      return;
    }
    if (!projection_) {
      projection_.emplace(message->latitude, message->longitude, message->altitude);
      ROS_INFO("inekf_node: map origin at the first usable fix: lat %.8f lon %.8f alt %.3f",
               message->latitude, message->longitude, message->altitude);
    }
    estimation::PositionFix fix;
    fix.stamp_s = message->header.stamp.toSec();
    fix.position_map = projection_->toMap(message->latitude, message->longitude, message->altitude);
    fix.covariance_map = ros_conversions::fixCovarianceMap(
        *message, min_fix_sigma_m_, default_fix_sigma_horizontal_m_, default_fix_sigma_vertical_m_);

    if (!localizer_->initialized()) {
      // The newest fix waits (briefly) for its instant's IMU orientation and GPS velocity.
      lazy_start_->offerFix(fix);
      tryStart(message->header.stamp);
      publishStatus(message->header.stamp);
      return;
    }
    const estimation::CorrectionResult result = localizer_->addPositionFix(fix);
    last_mahalanobis_squared_ = result.mahalanobis_squared;
    if (!result.accepted) {
      ROS_WARN_THROTTLE(5.0, "inekf_node: GPS fix at %.3f s rejected: %s (d^2 = %.1f)", fix.stamp_s,
                        result.reason.c_str(), result.mahalanobis_squared);
    }
    publishStatus(message->header.stamp);
  }

  // Starts the filter when the LazyStart says so (see estimation/lazy_start.h). Called on every
  // fix, IMU and velocity message while not started; `now` is that message's stamp.
  void tryStart(const ros::Time& now) {
    if (localizer_->initialized()) return;
    const std::optional<estimation::LazyStart::Start> start =
        lazy_start_->poll(now.toSec(), velocity_subscriber_.getNumPublishers() > 0);
    if (!start) return;
    if (start->orientation) {
      localizer_->setInitialReference(*start->orientation, start->velocity_map);
    }
    const estimation::PositionFix& fix = start->fix;
    const estimation::CorrectionResult result = localizer_->addPositionFix(fix);
    last_mahalanobis_squared_ = result.mahalanobis_squared;
    if (!localizer_->initialized()) {
      ROS_INFO_STREAM("inekf_node: GPS fix at " << std::fixed << std::setprecision(3) << fix.stamp_s
                                                << " s not used: " << result.reason);
      return;
    }
    const estimation::NavState& state = localizer_->state();
    const double yaw_deg = std::atan2(state.rotation(1, 0), state.rotation(0, 0)) * 180.0 / M_PI;
    std::ostringstream how;
    how << std::fixed << std::setprecision(1);
    if (start->orientation) {
      how << "orientation from the IMU message";
    } else {
      how << "levelled from gravity, yaw unknown (sigma " << config_.unknown_yaw_sigma_deg
          << " deg)";
    }
    if (start->velocity_map) {
      how << ", velocity from the GPS velocity";
    } else {
      how << ", no GPS velocity: speed unknown (sigma "
          << config_.unknown_velocity_sigma_horizontal_mps << " m/s)";
    }
    ROS_INFO_STREAM(std::fixed << std::setprecision(3) << "inekf_node: initialized "
                               << describeFilter(config_.filter_type) << " at t=" << state.stamp_s
                               << " s, position " << state.position_map.transpose() << " m, yaw "
                               << yaw_deg << " deg (" << how.str() << ")");
  }

  void publishState(const ros::Time& stamp) {
    const estimation::NavState& state = localizer_->state();
    const estimation::PoseCovariance pose_covariance = localizer_->filter().poseCovariance();
    if (!ros_conversions::isFinite(state, pose_covariance)) {
      // The filter guards against this; if it ever happens, never publish it: start over.
      ROS_ERROR_THROTTLE(5.0, "inekf_node: non-finite state at %.3f s: resetting the filter",
                         state.stamp_s);
      localizer_->reset();
      lazy_start_->reset();
      ++resets_;
      return;
    }
    nav_msgs::Odometry odometry;
    odometry.header.stamp = stamp;
    odometry.header.frame_id = map_frame_;
    odometry.child_frame_id = base_frame_;
    ros_conversions::fillOdometry(state, pose_covariance, latest_angular_velocity_, &odometry);
    odometry_publisher_.publish(odometry);

    if (publish_tf_) {
      geometry_msgs::TransformStamped transform;
      transform.header = odometry.header;
      transform.child_frame_id = base_frame_;
      transform.transform.translation.x = odometry.pose.pose.position.x;
      transform.transform.translation.y = odometry.pose.pose.position.y;
      transform.transform.translation.z = odometry.pose.pose.position.z;
      transform.transform.rotation = odometry.pose.pose.orientation;
      tf_broadcaster_.sendTransform(transform);
    }

    geometry_msgs::PoseStamped pose;
    pose.header = odometry.header;
    pose.pose = odometry.pose.pose;
    path_.poses.push_back(pose);
    // Trim in chunks so a long drive does not pay an O(n) erase on every sample.
    const std::size_t limit = static_cast<std::size_t>(max_path_length_);
    if (path_.poses.size() > limit + limit / 10) {
      path_.poses.erase(path_.poses.begin(), path_.poses.end() - limit);
    }
    if (last_path_publish_.isZero() ||
        (stamp - last_path_publish_).toSec() >= path_publish_period_s_ ||
        stamp < last_path_publish_) {
      path_.header.stamp = stamp;
      path_publisher_.publish(path_);
      last_path_publish_ = stamp;
    }
    publishStatus(stamp);

    const double position_sigma = std::sqrt(pose_covariance.topLeftCorner<3, 3>().trace());
    const auto statistics = localizer_->statistics();
    // Stage timings go out with the periodic status line (not only at shutdown), so a slow
    // filter shows while it runs.
    const auto timings = TimingRegistry::instance().snapshot();
    const auto mean_ms = [&timings](const char* stage) {
      const auto it = timings.find(stage);
      return it == timings.end() ? 0.0 : 1e3 * it->second.meanSeconds();
    };
    ROS_INFO_THROTTLE(
        10.0,
        "inekf_node: t=%.2f s position (%.1f, %.1f, %.1f) m, sigma %.2f m; IMU "
        "%ld used / %ld dropped / %ld gaps; GPS %ld used (%ld late) / %ld rejected / %ld "
        "ignored; %d resets; mean IMU callback %.3f ms, GPS callback %.3f ms",
        state.stamp_s, state.position_map.x(), state.position_map.y(), state.position_map.z(),
        position_sigma, static_cast<long>(statistics.imu_used),
        static_cast<long>(statistics.imu_dropped), static_cast<long>(statistics.imu_gaps),
        static_cast<long>(statistics.gps_used), static_cast<long>(statistics.gps_applied_late),
        static_cast<long>(statistics.gps_rejected), fixes_ignored_, resets_,
        mean_ms("inekf_node/imu"), mean_ms("inekf_node/gps"));
  }

  void publishStatus(const ros::Time& stamp) {
    const auto statistics = localizer_->statistics();
    FilterStatus status;
    status.header.stamp = stamp;
    status.header.frame_id = base_frame_;
    status.filter_type = describeFilter(config_.filter_type);
    if (localizer_->initialized()) {
      const estimation::NavState& state = localizer_->state();
      status.gyro_bias.x = state.gyro_bias.x();
      status.gyro_bias.y = state.gyro_bias.y();
      status.gyro_bias.z = state.gyro_bias.z();
      status.accel_bias.x = state.accel_bias.x();
      status.accel_bias.y = state.accel_bias.y();
      status.accel_bias.z = state.accel_bias.z();
    }
    status.last_innovation_mahalanobis = std::isfinite(last_mahalanobis_squared_)
                                             ? std::sqrt(std::max(0.0, last_mahalanobis_squared_))
                                             : 0.0;
    status.gps_fixes_used = static_cast<uint32_t>(statistics.gps_used);
    status.gps_fixes_rejected = static_cast<uint32_t>(statistics.gps_rejected + fixes_ignored_);
    status.imu_samples = static_cast<uint32_t>(statistics.imu_used);
    status.imu_samples_dropped = static_cast<uint32_t>(statistics.imu_dropped + imu_invalid_);
    status_publisher_.publish(status);
  }

  // Configuration.
  std::string config_file_;
  LocalizerConfig config_;
  double default_fix_sigma_horizontal_m_ = 1.5;
  double default_fix_sigma_vertical_m_ = 3.0;
  double min_fix_sigma_m_ = 0.3;
  bool publish_tf_ = true;
  std::string map_frame_, base_frame_;
  int max_path_length_ = 5000;
  double path_publish_period_s_ = 1.0;
  double time_jump_back_s_ = 1.0;

  // State.
  std::unique_ptr<Localizer> localizer_;
  std::optional<kitti::MercatorProjection> projection_;
  std::unique_ptr<estimation::LazyStart> lazy_start_;
  Eigen::Vector3d latest_angular_velocity_ = Eigen::Vector3d::Zero();
  double last_mahalanobis_squared_ = 0.0;
  ros::Time last_stamp_, last_clock_, last_path_publish_;
  nav_msgs::Path path_;
  long imu_invalid_ = 0;
  long fixes_ignored_ = 0;
  int resets_ = 0;

  // ROS.
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
