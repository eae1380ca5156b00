// inekf_node's work (see ros/inekf_node_core.h).
#include "inekf_semantic_mapping/ros/inekf_node_core.h"

#include <geometry_msgs/TwistStamped.h>
#include <nav_msgs/Odometry.h>
#include <ros/package.h>
#include <ros/ros.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/NavSatFix.h>
#include <std_srvs/Trigger.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <set>
#include <string>

#include "inekf_semantic_mapping/FilterStatus.h"
#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/estimation/localization_session.h"
#include "inekf_semantic_mapping/ros/diagnostics.h"
#include "inekf_semantic_mapping/ros/localization_conversions.h"
#include "inekf_semantic_mapping/ros/localization_diagnostics.h"
#include "inekf_semantic_mapping/ros/names.h"
#include "inekf_semantic_mapping/ros/node_parameters.h"
#include "inekf_semantic_mapping/ros/odometry_output.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {
namespace {

using estimation::LocalizationSession;

// Every private parameter, read (and checked) before anything is advertised.
struct InekfNodeParameters {
  std::string config_file;
  estimation::LocalizationSessionConfig session;
  OdometryOutputOptions output;
  LocalizationDiagnosticsOptions diagnostics;
};

InekfNodeParameters readParameters(const ros::NodeHandle& private_nh) {
  common::YamlReader reader = privateParameterReader(private_nh);
  InekfNodeParameters parameters;
  parameters.session = sessionConfigFromParameters(
      &reader, ros::package::getPath("inekf_semantic_mapping") + "/config/inekf.yaml",
      &parameters.config_file);
  parameters.output = readOdometryOutputOptions(&reader);
  if (std::filesystem::is_regular_file(parameters.config_file)) {
    // The config file's node-only section (LocalizationSessionConfig leaves it alone).
    common::YamlReader file(parameters.config_file + " (section node)",
                            common::loadYamlFile(parameters.config_file)["node"]);
    readLocalizationDiagnosticsOptions(&file, "diagnostics.", &parameters.diagnostics);
    file.rejectUnknown();
  }
  readLocalizationDiagnosticsOptions(&reader, "diagnostics.", &parameters.diagnostics);
  reader.rejectUnknown();
  return parameters;
}

}  // namespace

class InekfNodeCore::Impl {
 public:
  Impl(ros::NodeHandle& nh, ros::NodeHandle& private_nh, const InekfNodeParameters& parameters)
      : config_file_(parameters.config_file),
        session_(parameters.session),
        output_(nh, parameters.output),
        monitor_(parameters.diagnostics),
        diagnostics_(nh, private_nh),
        private_nh_(private_nh) {
    diagnostics_.add("localization",
                     [this](auto& status) { monitor_.fill(session_, wallNow(), &status); });
    status_publisher_ = nh.advertise<FilterStatus>(topics::kFilterStatus, 10);
    imu_subscriber_ =
        nh.subscribe(topics::kImu, 400, &Impl::onImu, this, ros::TransportHints().tcpNoDelay());
    fix_subscriber_ = nh.subscribe(topics::kGpsFix, 50, &Impl::onFix, this);
    velocity_subscriber_ = nh.subscribe(topics::kGpsVelocity, 10, &Impl::onVelocity, this);
    wheel_subscriber_ = nh.subscribe(topics::kWheelOdometry, 100, &Impl::onWheelOdometry, this,
                                     ros::TransportHints().tcpNoDelay());
    reset_service_ = private_nh.advertiseService("reset", &Impl::onReset, this);
    ROS_INFO_STREAM("inekf_node: " << filterStatus().filter_type << " filter, config "
                                   << config_file_ << ", waiting for IMU on "
                                   << imu_subscriber_.getTopic() << " and GPS on "
                                   << fix_subscriber_.getTopic());
  }

  ~Impl() { ROS_INFO_STREAM("inekf_node timing:\n" << TimingRegistry::instance().report()); }

 private:
  // Runs one event through the session (`stage` in the timing report); a callback never lets an
  // exception out.
  void handle(const char* stage, const ros::Time& stamp,
              const std::function<LocalizationSession::Update()>& event) {
    try {
      ScopedTimer timer(stage);
      session_.setGpsVelocityExpected(velocity_subscriber_.getNumPublishers() > 0);
      const LocalizationSession::Update update = event();
      report(update);
      keepOriginForARestart();
      // The start's pose at the first fix's stamp, whichever message completed the start: a scan
      // between it and the next IMU sample has a pose (otherwise the first pose would come with
      // the next IMU sample, 0.1 s later on KITTI, and such scans would stay out of the map).
      if (const auto& start = update.start_estimate) {
        output_.publish(exactStamp(recent_fix_stamps_, start->state.stamp_s), *start,
                        session_.latestAngularVelocity());
      }
      // IMU samples held back as the first of a time jump, used once it was confirmed.
      for (const LocalizationSession::Estimate& held : update.held_estimates) {
        output_.publish(exactStamp(recent_imu_stamps_, held.state.stamp_s), held,
                        session_.latestAngularVelocity());
      }
      if (update.new_estimate) publishState(stamp);
      if (update.new_estimate || update.correction || update.started ||
          !update.held_estimates.empty()) {
        publishStatus(stamp);
      }
    } catch (const std::exception& error) {
      ROS_ERROR_STREAM_THROTTLE(
          5.0, "inekf_node: " << stage << " message at " << stamp << " failed: " << error.what());
    }
  }

  // The map origin on the parameter server (~map_origin_in_use): a restarted node (respawn, a
  // crash) takes it again (session.resume_origin_max_m). Its own first fix moved the map frame by
  // metres under the map and rviz, with no word.
  void keepOriginForARestart() {
    if (origin_kept_ || !session_.projection()) return;
    const kitti::MercatorProjection& origin = *session_.projection();
    private_nh_.setParam("map_origin_in_use/lat", origin.lat0Deg());
    private_nh_.setParam("map_origin_in_use/lon", origin.lon0Deg());
    private_nh_.setParam("map_origin_in_use/alt", origin.alt0M());
    origin_kept_ = true;
  }

  // ~reset (std_srvs/Trigger): the filter starts over at the next fix, in the same map frame.
  // Served on the callbacks' own thread (ros::spin), so it never runs inside a message's update.
  bool onReset(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response) {
    report(session_.restart("~reset called"));
    response.success = true;
    response.message =
        "filter and path reset: the filter starts again at the next fix, in the same map frame";
    return true;
  }

  void report(const LocalizationSession::Update& update) {
    if (update.reset) {
      ROS_WARN_STREAM("inekf_node: " << update.note << ": filter and path reset");
      output_.clearPath();
    } else if (update.started) {
      ROS_INFO_STREAM("inekf_node: " << filterStatus().filter_type << " " << update.note);
    } else if (update.heading_event) {
      // Each alignment, recovery or re-open of the heading: once, never throttled away.
      ROS_WARN_STREAM("inekf_node: " << update.note);
    } else if (!update.note.empty()) {
      ROS_WARN_STREAM_THROTTLE(5.0, "inekf_node: " << update.note);
    }
  }

  // The IMU's mounting from tf, once: the land-vehicle constraint and the heading monitor take
  // base_link's x axis as the car's forward one (an IMU turned 90 deg about z held the heading
  // 90 deg off before).
  void takeImuMounting() {
    const std::optional<Eigen::Matrix3d> base_from_imu = output_.imuMounting();
    if (!base_from_imu) return;  // tf has none yet: the next IMU message asks again
    mounting_taken_ = true;
    if (!session_.setImuMounting(*base_from_imu)) {
      ROS_ERROR_STREAM("inekf_node: the tf " << output_.baseFrame() << " -> IMU frame is not a "
                                             << "rotation: the IMU's x axis is taken as forward");
      return;
    }
    if (!base_from_imu->isIdentity(1e-6)) {
      const Eigen::Vector3d forward = base_from_imu->transpose().col(0);
      char axis[96];
      std::snprintf(axis, sizeof(axis), "(%.2f, %.2f, %.2f)", forward.x() + 0.0, forward.y() + 0.0,
                    forward.z() + 0.0);
      ROS_INFO_STREAM("inekf_node: the IMU is mounted turned in "
                      << output_.baseFrame() << " (tf): the car's forward axis is " << axis
                      << " in the IMU's axes, for the land-vehicle constraint and the heading "
                         "monitor");
    }
  }

  void onImu(const sensor_msgs::Imu::ConstPtr& message) {
    output_.noteImuFrame(message->header.frame_id);
    if (!mounting_taken_) takeImuMounting();
    if (velocity_before_imu_) {
      useVelocity(*velocity_before_imu_);
      velocity_before_imu_.reset();
    }
    remember(message->header.stamp, kRecentImuStamps, &recent_imu_stamps_);
    handle("inekf_node/imu", message->header.stamp,
           [&] { return session_.addImu(imuEvent(*message)); });
    monitor_.noteImu(message->header.stamp.toSec(), wallNow(), session_);
  }

  void onFix(const sensor_msgs::NavSatFix::ConstPtr& message) {
    if (!logged_unknown_fix_covariance_ && isUsableFix(*message) && !fixCovarianceEnu(*message)) {
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
    remember(message->header.stamp, kRecentFixStamps, &recent_fix_stamps_);
    estimation::GeodeticFixEvent event = fixEvent(*message);
    event.antenna_in_imu = antennaInImu(message->header.frame_id);
    handle("inekf_node/gps", message->header.stamp, [&] { return session_.addFix(event); });
    monitor_.noteFix(message->header.stamp.toSec(), wallNow(), session_);
  }

  // The antenna's lever arm from tf (the fix's frame in the IMU's), once per frame name: 1.5 m
  // ignored was 1.5 m of position error and a 2 deg heading bias, without a word.
  Eigen::Vector3d antennaInImu(const std::string& fix_frame) {
    const auto known = antenna_by_frame_.find(fix_frame);
    if (known != antenna_by_frame_.end()) return known->second;
    const std::optional<Eigen::Isometry3d> fix_in_imu = output_.frameInImu(fix_frame);
    const std::optional<Eigen::Vector3d> antenna =
        fix_in_imu ? std::optional<Eigen::Vector3d>(fix_in_imu->translation()) : std::nullopt;
    if (!antenna) {
      // Before the first IMU message the IMU's frame is not known: nothing to say yet.
      if (!output_.imuFrame().empty() && warned_no_antenna_frame_.insert(fix_frame).second) {
        ROS_WARN_STREAM("inekf_node: no tf from the IMU's frame to the fixes' frame '"
                        << fix_frame << "' (" << fix_subscriber_.getTopic()
                        << ") yet: the fixes are taken as of the IMU until it comes");
      }
      return Eigen::Vector3d::Zero();
    }
    antenna_by_frame_[fix_frame] = *antenna;
    if (!antenna->isZero(1e-3)) {
      char lever[96];
      std::snprintf(lever, sizeof(lever), "(%.2f, %.2f, %.2f)", antenna->x(), antenna->y(),
                    antenna->z());
      ROS_INFO_STREAM("inekf_node: the GPS antenna ('" << fix_frame << "') sits at " << lever
                                                       << " m in the IMU's frame (tf): its lever "
                                                          "arm is in the position update");
    }
    return *antenna;
  }

  // The GPS velocity (for the start): frame_id the map frame: east-north-up; the IMU's frame or
  // none: the IMU's axes; another frame on the robot: turned into the IMU's axes through tf (a
  // velocity in base_link's axes with the IMU mounted turned was taken in the IMU's, 4 m off).
  void onVelocity(const geometry_msgs::TwistStamped::ConstPtr& message) {
    const std::string frame = frames::tfFrameId(message->header.frame_id);
    if (output_.imuFrame().empty() && !frame.empty() && frame != output_.mapFrame()) {
      // The IMU's frame is not known before its first message: used right after it comes.
      velocity_before_imu_ = message;
      return;
    }
    useVelocity(*message);
  }

  void useVelocity(const geometry_msgs::TwistStamped& message) {
    std::optional<estimation::GpsVelocityEvent> velocity = gpsVelocity(message);
    if (!velocity) return;
    const std::string frame = frames::tfFrameId(message.header.frame_id);
    velocity->in_body_frame = frame != output_.mapFrame();
    if (velocity->in_body_frame) {
      const std::optional<Eigen::Isometry3d> frame_in_imu = output_.frameInImu(frame);
      if (!frame_in_imu) {
        ROS_WARN_STREAM_THROTTLE(10.0, "inekf_node: no tf from the IMU's frame to '"
                                           << frame << "', the frame of the GPS velocity on "
                                           << velocity_subscriber_.getTopic()
                                           << ": not used (frame_id " << output_.mapFrame()
                                           << " for east-north-up)");
        return;
      }
      velocity->velocity = frame_in_imu->rotation() * velocity->velocity;
    }
    handle("inekf_node/gps_velocity", message.header.stamp,
           [&] { return session_.addGpsVelocity(*velocity); });
  }

  // Wheel odometry: the speed along base_link's x axis (the twist is in the child frame; another
  // child frame than base_link is turned into base_link's axes through tf).
  void onWheelOdometry(const nav_msgs::Odometry::ConstPtr& message) {
    if (!wheel_logged_) {
      wheel_logged_ = true;
      ROS_INFO_STREAM(
          "inekf_node: wheel odometry on "
          << wheel_subscriber_.getTopic() << " (child frame '" << message->child_frame_id
          << "'): its forward speed goes into the filter (wheel_speed in " << config_file_ << ")");
    }
    const std::optional<Eigen::Matrix3d> base_from_child =
        wheelFrameInBase(message->child_frame_id);
    if (!base_from_child) return;
    const std::optional<estimation::WheelSpeedEvent> speed = wheelSpeed(*message, *base_from_child);
    if (!speed) {
      ROS_WARN_STREAM_THROTTLE(10.0, "inekf_node: wheel odometry on "
                                         << wheel_subscriber_.getTopic() << " at "
                                         << message->header.stamp
                                         << " has a non-finite linear velocity: not used");
      return;
    }
    handle("inekf_node/wheel_speed", message->header.stamp,
           [&] { return session_.addWheelSpeed(*speed); });
  }

  // The child frame's axes in base_link's: identity for base_link itself or no frame; else
  // base_link -> IMU (the mounting) times IMU -> child, from tf. nullopt (warned) while tf lacks
  // it or before the IMU's frame is known.
  std::optional<Eigen::Matrix3d> wheelFrameInBase(const std::string& child_frame_id) {
    const std::string frame = frames::tfFrameId(child_frame_id);
    if (frame.empty() || frame == output_.baseFrame()) return Eigen::Matrix3d::Identity();
    // Before the first IMU message its frame is not known (the filter has not started either);
    // IMU messages without a frame_id leave it unknown for good.
    if (output_.imuFrame().empty()) {
      if (session_.started()) {
        ROS_WARN_STREAM_THROTTLE(10.0,
                                 "inekf_node: the IMU messages name no frame_id, so the "
                                 "wheel odometry's child frame '"
                                     << frame << "' (" << wheel_subscriber_.getTopic()
                                     << ") cannot be turned into base_link's axes: not "
                                        "used (give it child_frame_id "
                                     << output_.baseFrame() << ")");
      }
      return std::nullopt;
    }
    const std::optional<Eigen::Matrix3d> base_from_imu = output_.imuMounting();
    const std::optional<Eigen::Isometry3d> child_in_imu = output_.frameInImu(frame);
    if (!base_from_imu || !child_in_imu) {
      ROS_WARN_STREAM_THROTTLE(10.0, "inekf_node: no tf from "
                                         << output_.baseFrame() << " to '" << frame
                                         << "', the child frame of the wheel odometry on "
                                         << wheel_subscriber_.getTopic() << " (yet): not used");
      return std::nullopt;
    }
    return *base_from_imu * child_in_imu->rotation();
  }

  static void remember(const ros::Time& stamp, std::size_t keep, std::deque<ros::Time>* recent) {
    recent->push_back(stamp);
    while (recent->size() > keep) recent->pop_front();
  }

  // The own message stamp of an estimate made at another message than the current one (the
  // start at its fix, an IMU sample held for a time jump): exact, as every other estimate's (a
  // double loses the nanoseconds). ros::Time(stamp_s) only if it is not among the recent ones.
  static ros::Time exactStamp(const std::deque<ros::Time>& recent, double stamp_s) {
    for (const ros::Time& stamp : recent) {
      if (std::abs(stamp.toSec() - stamp_s) < estimation::Localizer::kDuplicateStampS) {
        return stamp;
      }
    }
    return ros::Time(stamp_s);
  }

  // Stamped with the message's own stamp, not ros::Time(state.stamp_s): a double loses the
  // nanoseconds, and consumers match our poses to their data by exact stamp.
  void publishState(const ros::Time& stamp) {
    output_.publish(stamp, session_.estimate(), session_.latestAngularVelocity());
    ROS_INFO_STREAM_THROTTLE(10.0, "inekf_node: " << session_.summary());
  }

  FilterStatus filterStatus() const { return ros_conversions::filterStatus(session_); }

  void publishStatus(const ros::Time& stamp) {
    FilterStatus status = filterStatus();
    status.header.stamp = stamp;
    status.header.frame_id = output_.baseFrame();
    status_publisher_.publish(status);
  }

  std::string config_file_;
  LocalizationSession session_;
  OdometryOutput output_;
  bool logged_unknown_fix_covariance_ = false;
  // The start fix is among the last few fixes; a held IMU sample goes through up to
  // time_jump_back_s (1 s) of data later: 5 s at 100 Hz.
  static constexpr std::size_t kRecentFixStamps = 40, kRecentImuStamps = 500;
  std::deque<ros::Time> recent_fix_stamps_;  // of the latest fixes received
  std::deque<ros::Time> recent_imu_stamps_;  // of the latest IMU samples received
  ros::Publisher status_publisher_;
  ros::Subscriber imu_subscriber_, fix_subscriber_, velocity_subscriber_, wheel_subscriber_;
  ros::ServiceServer reset_service_;
  bool wheel_logged_ = false;
  LocalizationMonitor monitor_;
  NodeDiagnostics diagnostics_;
  ros::NodeHandle private_nh_;
  bool origin_kept_ = false;
  bool mounting_taken_ = false;
  geometry_msgs::TwistStamped::ConstPtr velocity_before_imu_;  // used at the first IMU message
  std::map<std::string, Eigen::Vector3d> antenna_by_frame_;    // fix frame -> lever arm (IMU frame)
  std::set<std::string> warned_no_antenna_frame_;
};

InekfNodeCore::InekfNodeCore(ros::NodeHandle nh, ros::NodeHandle private_nh)
    : impl_(std::make_unique<Impl>(nh, private_nh, readParameters(private_nh))) {}

InekfNodeCore::~InekfNodeCore() = default;

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
