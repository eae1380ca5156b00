// What kitti_player publishes for each event of a drive's timeline (ros/kitti_conversions.h makes
// the messages), and its private parameters. ROS-facing (src/ros): only nodes include this header.
#pragma once

#include <ros/node_handle.h>
#include <ros/publisher.h>

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/kitti/drive_timeline.h"
#include "inekf_semantic_mapping/kitti/gps_degradation.h"
#include "inekf_semantic_mapping/ros/kitti_conversions.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

struct KittiPlayerOptions {
  std::string drive_dir;  // required
  std::string calib_dir;  // "": the drive's parent
  double rate = 1.0;
  bool loop = false, publish_clock = false, exit_when_done = false, paused = false;
  // Before playing (unless paused): wait up to this long for the subscribers (KittiPlayer),
  // the velodyne cloud's too when wait_for_cloud_subscriber.
  double wait_for_subscribers_s = 10.0;
  bool wait_for_cloud_subscriber = false;
  kitti::TimelineOptions timeline;  // start_offset_s, duration_s, publish_velodyne / _camera
  kitti::GpsDegradationOptions gps;
};

// config/kitti_player.yaml's keys, the player's whole parameter set; throws common::ConfigError
// naming the parameter (an unknown one, a missing drive_dir, rate <= 0, a bad GPS option).
KittiPlayerOptions readKittiPlayerOptions(common::YamlReader* reader);

class DrivePublishers {
 public:
  // Advertises the OXTS topics, and the velodyne and camera ones when `timeline` plays them and
  // the drive has them; /clock when publish_clock.
  DrivePublishers(ros::NodeHandle& nh, DriveMessageFactory* factory,
                  const kitti::TimelineOptions& timeline, bool publish_clock);

  // The messages of one event (and /clock at its stamp). A frame whose file cannot be read is
  // reported and skipped: one bad file must not stop the replay. True when it was published.
  bool publish(const kitti::TimelineEvent& event);

  // A sensor topic it publishes (IMU, GPS fix and velocity, velodyne, camera image), with the
  // number of subscribers connected to it. essential: the IMU and the GPS fix, which a filter
  // needs from the drive's first message on; cloud: the velodyne's.
  struct TopicConnections {
    std::string topic;
    std::uint32_t connected = 0;
    bool essential = false;
    bool cloud = false;
  };
  std::vector<TopicConnections> sensorTopicConnections() const;

  std::size_t published() const { return published_; }
  std::size_t skipped() const { return skipped_; }

 private:
  DriveMessageFactory* factory_;
  bool publish_clock_ = false;
  std::size_t published_ = 0, skipped_ = 0;
  ros::Publisher imu_, fix_, velocity_, ground_truth_, velodyne_, image_, camera_info_, clock_;
};

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
