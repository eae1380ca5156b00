// kitti_player: publishes a KITTI raw drive (OXTS IMU/GPS, ground truth, velodyne, color
// camera, /tf_static) at `~rate` times real time, paced by WALL time so that it can itself
// publish /clock (`~publish_clock`) without depending on it. See config/kitti_player.yaml; any
// other private parameter, or one of the wrong type, stops the player naming it.
#include <ros/ros.h>
#include <rosgraph_msgs/Clock.h>
#include <std_srvs/SetBool.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/static_transform_broadcaster.h>

#include <atomic>
#include <mutex>
#include <sstream>
#include <thread>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/kitti/drive_timeline.h"
#include "inekf_semantic_mapping/ros/kitti_conversions.h"
#include "inekf_semantic_mapping/ros/names.h"
#include "inekf_semantic_mapping/ros/node_parameters.h"

namespace inekf_semantic_mapping {
namespace {

namespace conv = ros_conversions;
using kitti::DriveSensor;

kitti::GpsDegradationOptions readGpsOptions(common::YamlReader* reader) {
  kitti::GpsDegradationOptions options;
  reader->read("gps_sigma_horizontal_m", &options.sigma_horizontal_m);
  reader->read("gps_sigma_vertical_m", &options.sigma_vertical_m);
  reader->read("gps_every_n_frames", &options.every_n_frames);
  int seed = 0;
  reader->read("gps_seed", &seed);
  options.seed = static_cast<std::uint64_t>(seed);
  std::vector<std::string> outages;
  reader->read("gps_outages", &outages);  // ["START:DURATION", ...] seconds since first frame
  for (const std::string& outage : outages) {
    options.outages_s.push_back(kitti::GpsDegradationOptions::parseOutage(outage));
  }
  options.validate();
  return options;
}

// How long the player stays up after the last message when ~exit_when_done is set.
constexpr double kExitFlushSeconds = 1.0;

class KittiPlayer {
 public:
  KittiPlayer(ros::NodeHandle& nh, ros::NodeHandle& pnh) : pnh_(pnh) {
    common::YamlReader parameters = conv::privateParameterReader(pnh);
    std::string drive_dir, calib_dir;
    bool paused = false;
    parameters.read("drive_dir", &drive_dir);
    parameters.read("calib_dir", &calib_dir);
    parameters.read("rate", &rate_);
    parameters.read("start_offset_s", &timeline_options_.start_offset_s);
    parameters.read("duration_s", &timeline_options_.duration_s);
    parameters.read("loop", &loop_);
    parameters.read("publish_clock", &publish_clock_);
    parameters.read("exit_when_done", &exit_when_done_);
    parameters.read("paused", &paused);
    parameters.read("publish_velodyne", &timeline_options_.velodyne);
    parameters.read("publish_camera", &timeline_options_.cameras[2]);
    const kitti::GpsDegradationOptions gps = readGpsOptions(&parameters);
    parameters.rejectUnknown();
    if (drive_dir.empty()) parameters.fail("drive_dir", "is required (a <date>_drive_<n>_sync)");
    if (!(rate_ > 0)) parameters.fail("rate", "must be > 0");
    paused_ = paused;

    drive_ = std::make_unique<kitti::RawDrive>(drive_dir, calib_dir);
    factory_ = std::make_unique<conv::DriveMessageFactory>(*drive_, gps);
    const auto missing = drive_->missingParts();
    if (!missing.empty()) {
      std::ostringstream text;
      for (const auto& part : missing) text << " " << part;
      ROS_WARN_STREAM("kitti_player: " << drive_->driveDir() << " has no" << text.str()
                                       << ": those topics will not be published");
    }
    if (drive_->hasCamera(2) && !drive_->hasCalibration()) {
      ROS_WARN("kitti_player: image_02 present but no calibration: camera not published");
      timeline_options_.cameras[2] = false;
    }
    timeline_ = kitti::buildDriveTimeline(*drive_, timeline_options_);
    if (timeline_.empty()) throw std::invalid_argument("nothing to play in the chosen window");
    conv::checkTimelineFitsRosTime(drive_dir, timeline_.front().stamp_ns,
                                   timeline_.back().stamp_ns);

    imu_pub_ = nh.advertise<sensor_msgs::Imu>(topics::kImu, 200);
    fix_pub_ = nh.advertise<sensor_msgs::NavSatFix>(topics::kGpsFix, 50);
    velocity_pub_ = nh.advertise<geometry_msgs::TwistStamped>(topics::kGpsVelocity, 50);
    ground_truth_pub_ = nh.advertise<nav_msgs::Odometry>(topics::kGroundTruthOdometry, 50);
    if (drive_->hasVelodyne() && timeline_options_.velodyne) {
      velodyne_pub_ = nh.advertise<sensor_msgs::PointCloud2>(topics::kVelodyne, 5);
    }
    if (timeline_options_.cameras[2] && drive_->hasCamera(2)) {
      image_pub_ = nh.advertise<sensor_msgs::Image>(topics::kCameraColorLeftImage, 5);
      camera_info_pub_ = nh.advertise<sensor_msgs::CameraInfo>(topics::kCameraColorLeftInfo, 5);
    }
    if (publish_clock_) clock_pub_ = nh.advertise<rosgraph_msgs::Clock>("/clock", 100);
    pause_service_ = pnh.advertiseService("pause", &KittiPlayer::onPause, this);
    step_service_ = pnh.advertiseService("step", &KittiPlayer::onStep, this);
    ROS_INFO("kitti_player: %s, %zu events over %.1f s at rate %.2f%s%s", drive_dir.c_str(),
             timeline_.size(), spanSeconds(), rate_, loop_ ? ", looping" : "",
             paused_ ? ", PAUSED (call ~pause false or ~step)" : "");
  }

  void run() {
    static_broadcaster_.sendTransform(
        factory_->staticTransformMessages(conv::toRosTime(timeline_.front().stamp_ns)));
    do {
      factory_->restart();
      if (!playOnce()) return;
      if (loop_) ROS_INFO("kitti_player: end of drive, looping");
    } while (loop_ && ros::ok());
    ROS_INFO("kitti_player: finished (%zu events)", published_events_);
    if (!exit_when_done_) {
      ros::waitForShutdown();
      return;
    }
    // roscpp writes to subscribers from its own threads and has no flush: exiting right after
    // the last publish lost the final frame's messages on a loaded machine. Linger briefly.
    ros::WallDuration(kExitFlushSeconds).sleep();
  }

 private:
  double spanSeconds() const {
    return kitti::secondsBetween(timeline_.front().stamp_ns, timeline_.back().stamp_ns);
  }

  bool onPause(std_srvs::SetBool::Request& request, std_srvs::SetBool::Response& response) {
    paused_ = request.data;
    response.success = true;
    response.message = request.data ? "paused" : "playing";
    return true;
  }

  bool onStep(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response) {
    if (!paused_) {
      response.success = false;
      response.message = "not paused: call ~pause with data=true first";
      return true;
    }
    ++pending_steps_;
    response.success = true;
    response.message = "stepping one OXTS frame";
    return true;
  }

  // Plays the timeline once; false when ROS shut down.
  bool playOnce() {
    ros::WallTime wall_anchor = ros::WallTime::now();
    std::int64_t data_anchor_ns = timeline_.front().stamp_ns;
    bool stepping = false;  // publishing the events of one ~step
    for (const kitti::TimelineEvent& event : timeline_) {
      for (;;) {
        if (!ros::ok()) return false;
        if (paused_ && !stepping) {
          if (pending_steps_ > 0) {
            --pending_steps_;
            stepping = true;
            break;
          }
          ros::WallDuration(0.01).sleep();
          // Resume from here without a burst to catch up the paused time.
          wall_anchor = ros::WallTime::now();
          data_anchor_ns = event.stamp_ns;
          continue;
        }
        if (stepping) break;
        const ros::WallTime due =
            wall_anchor +
            ros::WallDuration(kitti::secondsBetween(data_anchor_ns, event.stamp_ns) / rate_);
        const ros::WallTime now = ros::WallTime::now();
        if (now >= due) break;
        ros::WallDuration(std::min((due - now).toSec(), 0.01)).sleep();
      }
      publish(event);
      if (stepping && event.sensor == DriveSensor::kOxts) stepping = false;
      ROS_INFO_THROTTLE(5.0, "kitti_player: %.1f / %.1f s, %zu events published",
                        kitti::secondsBetween(timeline_.front().stamp_ns, event.stamp_ns),
                        spanSeconds(), published_events_);
    }
    return true;
  }

  void publish(const kitti::TimelineEvent& event) {
    const ros::Time stamp = conv::toRosTime(event.stamp_ns);
    if (publish_clock_) {
      rosgraph_msgs::Clock clock;
      clock.clock = stamp;
      clock_pub_.publish(clock);
    }
    try {
      switch (event.sensor) {
        case DriveSensor::kOxts: {
          ScopedTimer timer("kitti_player/oxts");
          const conv::OxtsMessages messages = factory_->oxtsMessages(event.frame);
          imu_pub_.publish(messages.imu);
          if (messages.gps_fix) fix_pub_.publish(*messages.gps_fix);
          velocity_pub_.publish(messages.gps_velocity);
          ground_truth_pub_.publish(messages.ground_truth);
          break;
        }
        case DriveSensor::kVelodyne: {
          ScopedTimer timer("kitti_player/velodyne");
          velodyne_pub_.publish(factory_->velodyneMessage(event.frame));
          break;
        }
        case DriveSensor::kCamera2: {
          ScopedTimer timer("kitti_player/camera");
          const auto [image, info] = factory_->cameraMessages(2, event.frame);
          image_pub_.publish(image);
          camera_info_pub_.publish(info);
          break;
        }
        default:
          break;
      }
      ++published_events_;
    } catch (const std::exception& error) {
      // One bad file must not stop the replay: report it and go on with the next frame.
      ROS_ERROR_STREAM("kitti_player: skipping frame " << event.frame << ": " << error.what());
    }
  }

  ros::NodeHandle pnh_;
  double rate_ = 1.0;
  bool loop_ = false, publish_clock_ = false, exit_when_done_ = false;
  std::atomic<bool> paused_{false};
  std::atomic<int> pending_steps_{0};
  kitti::TimelineOptions timeline_options_;
  std::unique_ptr<kitti::RawDrive> drive_;
  std::unique_ptr<conv::DriveMessageFactory> factory_;
  std::vector<kitti::TimelineEvent> timeline_;
  std::size_t published_events_ = 0;
  ros::Publisher imu_pub_, fix_pub_, velocity_pub_, ground_truth_pub_, velodyne_pub_, image_pub_,
      camera_info_pub_, clock_pub_;
  ros::ServiceServer pause_service_, step_service_;
  tf2_ros::StaticTransformBroadcaster static_broadcaster_;
};

}  // namespace
}  // namespace inekf_semantic_mapping

int main(int argc, char** argv) {
  ros::init(argc, argv, "kitti_player");
  // Held outside the try: when the last NodeHandle goes, roscpp shuts rosconsole down, and the
  // fatal message of a player that could not start would print nothing.
  ros::NodeHandle nh, pnh("~");
  // Services are served on their own thread while the main thread paces the replay.
  ros::AsyncSpinner spinner(1);
  spinner.start();
  try {
    inekf_semantic_mapping::KittiPlayer player(nh, pnh);
    player.run();
  } catch (const std::exception& error) {
    ROS_FATAL_STREAM("kitti_player: " << error.what());
    return 1;
  }
  std::fputs(inekf_semantic_mapping::TimingRegistry::instance().report().c_str(), stderr);
  return 0;
}
