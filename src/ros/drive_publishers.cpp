#include "inekf_semantic_mapping/ros/drive_publishers.h"

#include <ros/console.h>
#include <rosgraph_msgs/Clock.h>

#include <filesystem>
#include <vector>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/ros/names.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

KittiPlayerOptions readKittiPlayerOptions(common::YamlReader* reader) {
  KittiPlayerOptions options;
  reader->read("drive_dir", &options.drive_dir);
  reader->read("calib_dir", &options.calib_dir);
  // Named, it must be there: a mistyped folder played the drive without its camera, warned once.
  if (!options.calib_dir.empty() && !std::filesystem::is_directory(options.calib_dir)) {
    reader->fail("calib_dir", "'" + options.calib_dir +
                                  "' is not a folder (empty: the drive's "
                                  "parent folder)");
  }
  reader->read("rate", &options.rate);
  reader->read("start_offset_s", &options.timeline.start_offset_s);
  reader->read("duration_s", &options.timeline.duration_s);
  reader->read("loop", &options.loop);
  reader->read("publish_clock", &options.publish_clock);
  reader->read("exit_when_done", &options.exit_when_done);
  reader->read("paused", &options.paused);
  // An hour is beyond any start-up; far more overflows ros::WallDuration.
  reader->readInRange("wait_for_subscribers_s", &options.wait_for_subscribers_s, 0.0, 3600.0);
  reader->read("wait_for_cloud_subscriber", &options.wait_for_cloud_subscriber);
  reader->read("publish_velodyne", &options.timeline.velodyne);
  reader->read("publish_camera", &options.timeline.cameras[2]);
  kitti::GpsDegradationOptions& gps = options.gps;
  reader->read("gps_sigma_horizontal_m", &gps.sigma_horizontal_m);
  reader->read("gps_sigma_vertical_m", &gps.sigma_vertical_m);
  reader->read("gps_every_n_frames", &gps.every_n_frames);
  int seed = 0;
  reader->read("gps_seed", &seed);
  // kitti2bag --seed takes no negative seed: -1 here would be a seed it cannot give.
  if (seed < 0) reader->fail("gps_seed", "must be >= 0, got " + std::to_string(seed));
  gps.seed = static_cast<std::uint64_t>(seed);
  std::vector<std::string> outages;  // ["START:DURATION", ...] seconds since the first frame
  reader->read("gps_outages", &outages);
  try {
    for (const std::string& outage : outages) {
      gps.outages_s.push_back(kitti::GpsDegradationOptions::parseOutage(outage));
    }
    gps.validate();
  } catch (const std::invalid_argument& error) {
    reader->fail("gps_*", error.what());
  }
  reader->rejectUnknown();
  if (options.drive_dir.empty()) reader->fail("drive_dir", "is required (a <date>_drive_<n>_sync)");
  if (!(options.rate > 0)) reader->fail("rate", "must be > 0");
  return options;
}

DrivePublishers::DrivePublishers(ros::NodeHandle& nh, DriveMessageFactory* factory,
                                 const kitti::TimelineOptions& timeline, bool publish_clock)
    : factory_(factory), publish_clock_(publish_clock) {
  const kitti::RawDrive& drive = factory->drive();
  imu_ = nh.advertise<sensor_msgs::Imu>(topics::kImu, 200);
  fix_ = nh.advertise<sensor_msgs::NavSatFix>(topics::kGpsFix, 50);
  velocity_ = nh.advertise<geometry_msgs::TwistStamped>(topics::kGpsVelocity, 50);
  ground_truth_ = nh.advertise<nav_msgs::Odometry>(topics::kGroundTruthOdometry, 50);
  if (drive.hasVelodyne() && timeline.velodyne) {
    velodyne_ = nh.advertise<sensor_msgs::PointCloud2>(topics::kVelodyne, 5);
  }
  if (timeline.cameras[2] && drive.hasCamera(2)) {
    image_ = nh.advertise<sensor_msgs::Image>(topics::kCameraColorLeftImage, 5);
    camera_info_ = nh.advertise<sensor_msgs::CameraInfo>(topics::kCameraColorLeftInfo, 5);
  }
  if (publish_clock_) clock_ = nh.advertise<rosgraph_msgs::Clock>("/clock", 100);
}

std::vector<DrivePublishers::TopicConnections> DrivePublishers::sensorTopicConnections() const {
  std::vector<TopicConnections> connections;
  for (const ros::Publisher* publisher : {&imu_, &fix_, &velocity_, &velodyne_, &image_}) {
    if (*publisher) {
      connections.push_back({publisher->getTopic(), publisher->getNumSubscribers(),
                             publisher == &imu_ || publisher == &fix_, publisher == &velodyne_});
    }
  }
  return connections;
}

bool DrivePublishers::publish(const kitti::TimelineEvent& event) {
  if (publish_clock_) {
    rosgraph_msgs::Clock clock;
    clock.clock = toRosTime(event.stamp_ns);
    clock_.publish(clock);
  }
  try {
    switch (event.sensor) {
      case kitti::DriveSensor::kOxts: {
        ScopedTimer timer("kitti_player/oxts");
        const OxtsMessages messages = factory_->oxtsMessages(event.frame);
        imu_.publish(messages.imu);
        if (messages.gps_fix) fix_.publish(*messages.gps_fix);
        velocity_.publish(messages.gps_velocity);
        ground_truth_.publish(messages.ground_truth);
        break;
      }
      case kitti::DriveSensor::kVelodyne: {
        ScopedTimer timer("kitti_player/velodyne");
        velodyne_.publish(factory_->velodyneMessage(event.frame));
        break;
      }
      case kitti::DriveSensor::kCamera2: {
        ScopedTimer timer("kitti_player/camera");
        const auto [image, info] = factory_->cameraMessages(2, event.frame);
        image_.publish(image);
        camera_info_.publish(info);
        break;
      }
      default:
        break;
    }
    ++published_;
    return true;
  } catch (const std::exception& error) {
    ++skipped_;
    ROS_ERROR_STREAM("kitti_player: skipping frame " << event.frame << ": " << error.what());
    return false;
  }
}

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
