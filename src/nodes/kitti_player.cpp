// kitti_player: publishes a KITTI raw drive (OXTS IMU/GPS, ground truth, velodyne, color
// camera, /tf_static) at `~rate` times real time, paced by WALL time so that it can itself
// publish /clock (`~publish_clock`) without depending on it. See config/kitti_player.yaml; any
// other private parameter, or one of the wrong type, stops the player naming it. /diagnostics:
// the play rate against the requested one, events published, frames skipped (unreadable files).
#include <ros/master.h>
#include <ros/ros.h>
#include <std_srvs/SetBool.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/static_transform_broadcaster.h>

#include <algorithm>
#include <atomic>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/kitti/drive_timeline.h"
#include "inekf_semantic_mapping/ros/diagnostics.h"
#include "inekf_semantic_mapping/ros/drive_publishers.h"
#include "inekf_semantic_mapping/ros/kitti_conversions.h"
#include "inekf_semantic_mapping/ros/names.h"
#include "inekf_semantic_mapping/ros/node_parameters.h"

namespace inekf_semantic_mapping {
namespace {

namespace conv = ros_conversions;
using kitti::DriveSensor;

// How long the player stays up after the last message when ~exit_when_done is set.
constexpr double kExitFlushSeconds = 1.0;
// Wall seconds between the end of a loop and the clock jumping back to its start.
constexpr double kLoopGapSeconds = 0.2;

class KittiPlayer {
 public:
  KittiPlayer(ros::NodeHandle& nh, ros::NodeHandle& pnh) : pnh_(pnh) {
    common::YamlReader parameters = conv::privateParameterReader(pnh);
    options_ = conv::readKittiPlayerOptions(&parameters);
    paused_ = options_.paused;
    drive_ = std::make_unique<kitti::RawDrive>(options_.drive_dir, options_.calib_dir);
    factory_ = std::make_unique<conv::DriveMessageFactory>(*drive_, options_.gps);
    const auto missing = drive_->missingParts();
    if (!missing.empty()) {
      std::ostringstream text;
      for (const auto& part : missing) text << " " << part;
      ROS_WARN_STREAM("kitti_player: " << drive_->driveDir() << " has no" << text.str()
                                       << ": those topics will not be published");
    }
    for (const std::string& warning : drive_->frameWarnings()) {
      ROS_WARN_STREAM("kitti_player: " << warning);
    }
    for (const std::string& step : drive_->stampWarnings()) {
      ROS_WARN_STREAM("kitti_player: " << step << " (published in stamp order)");
    }
    drive_->requireCalibrationFor(options_.timeline.velodyne, options_.timeline.cameras[2],
                                  "~calib_dir", "~publish_velodyne / ~publish_camera false");
    // The first image against the calibration's rectified size, before anything plays: another
    // day's calibration refused every image, one error a frame, and the drive played on without
    // its camera (kitti2bag and semantic_map_offline stop at once).
    if (options_.timeline.cameras[2] && drive_->hasCamera(2)) factory_->checkCameraImageSize(2);
    timeline_ = kitti::buildDriveTimeline(*drive_, options_.timeline);
    if (timeline_.empty()) throw std::invalid_argument("nothing to play in the chosen window");
    conv::checkTimelineFitsRosTime(options_.drive_dir, timeline_.front().stamp_ns,
                                   timeline_.back().stamp_ns);
    publishers_ = std::make_unique<conv::DrivePublishers>(nh, factory_.get(), options_.timeline,
                                                          options_.publish_clock);
    pause_service_ = pnh.advertiseService("pause", &KittiPlayer::onPause, this);
    step_service_ = pnh.advertiseService("step", &KittiPlayer::onStep, this);
    diagnostics_ = std::make_unique<conv::NodeDiagnostics>(nh, pnh);
    diagnostics_->add("player", [this](auto& status) {
      playback_.fill(conv::wallNow(), paused_ ? 0.0 : options_.rate, &status);
      if (paused_) status.summary(diagnostic_msgs::DiagnosticStatus::OK, "paused");
      status.add("drive", options_.drive_dir);
      status.add("paused", paused_ ? "yes" : "no");
    });
    ROS_INFO("kitti_player: %s, %zu events over %.1f s at rate %.2f%s%s",
             options_.drive_dir.c_str(), timeline_.size(), spanSeconds(), options_.rate,
             options_.loop ? ", looping" : "",
             paused_ ? ", PAUSED (call ~pause false or ~step)" : "");
    if (!factory_->oxtsFrames().empty()) {
      // inekf_node's map is at its own first fix (a later one with a start offset, a noisy one
      // with degraded GPS): the truth and the estimate sat 20-50 m apart in rviz, unexplained.
      const kitti::OxtsRecord& first = factory_->oxtsFrames().front().record;
      ROS_INFO(
          "kitti_player: %s is in the map frame at the drive's first OXTS fix (lat %.9f, "
          "lon %.9f, alt %.3f); inekf_node's map is at its own first fix unless "
          "origin_lat/lon/alt are these",
          topics::kGroundTruthOdometry, first.lat, first.lon, first.alt);
    }
  }

  void run() {
    static_broadcaster_.sendTransform(
        factory_->staticTransformMessages(conv::toRosTime(timeline_.front().stamp_ns)));
    warnOfOtherClocks();
    if (!paused_ && options_.wait_for_subscribers_s > 0) waitForSubscribers();
    do {
      factory_->restart();
      if (!playOnce()) return;
      if (options_.loop) {
        ROS_INFO("kitti_player: end of drive, looping");
        // The last frame's messages leave before the clock jumps back: sent in the same
        // millisecond, tf listeners took them for the new loop's (TF_REPEATED_DATA each loop).
        ros::WallDuration(kLoopGapSeconds).sleep();
      }
    } while (options_.loop && ros::ok());
    ROS_INFO("kitti_player: finished (%zu events)", publishers_->published());
    if (!options_.exit_when_done) {
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

  // The master's publishers (kind 0) or subscribers (kind 1) per topic; empty where the master
  // cannot be asked.
  static std::map<std::string, std::vector<std::string>> registeredNodes(int kind) {
    std::map<std::string, std::vector<std::string>> nodes;
    XmlRpc::XmlRpcValue request, response, payload;
    request[0] = ros::this_node::getName();
    if (!ros::master::execute("getSystemState", request, response, payload, false)) return nodes;
    XmlRpc::XmlRpcValue& topics = payload[kind];
    for (int i = 0; i < topics.size(); ++i) {
      std::vector<std::string>& names = nodes[static_cast<std::string>(topics[i][0])];
      for (int j = 0; j < topics[i][1].size(); ++j) {
        names.push_back(static_cast<std::string>(topics[i][1][j]));
      }
    }
    return nodes;
  }

  // Subscribers registered with the master per topic (0 where the master cannot be asked).
  static std::map<std::string, std::size_t> registeredSubscribers() {
    std::map<std::string, std::size_t> counts;
    for (const auto& [topic, names] : registeredNodes(1)) counts[topic] = names.size();
    return counts;
  }

  // Two players (or a player and `rosbag play --clock`) on one master publish two clocks: time
  // jumps back and forth and every node clears its tf buffer, with no word of why.
  void warnOfOtherClocks() const {
    if (!options_.publish_clock) return;
    std::string others;
    const std::map<std::string, std::vector<std::string>> publishers = registeredNodes(0);
    const auto clock = publishers.find(ros::names::resolve("/clock"));
    if (clock == publishers.end()) return;
    for (const std::string& node : clock->second) {
      if (node != ros::this_node::getName()) others += (others.empty() ? "" : ", ") + node;
    }
    if (!others.empty()) {
      ROS_WARN_STREAM("kitti_player: "
                      << clock->first << " is also published by " << others
                      << ": one master has one clock, two make time jump back and forth (run "
                         "one drive per master, or give this player publish_clock false)");
    }
  }

  // A message published before its subscriber has connected is lost: the drive's first fix, and
  // the filter's start with it, or the first scans of the map. Waits until the IMU and the GPS
  // fix have a subscriber each (the velodyne cloud too with ~wait_for_cloud_subscriber: a map
  // nodelet registers only once the manager has loaded the nodelets before it, the segmentation
  // network's load) and every subscriber the master lists on a sensor topic is connected, for at
  // most ~wait_for_subscribers_s (wall time).
  void waitForSubscribers() {
    const ros::WallTime deadline =
        ros::WallTime::now() + ros::WallDuration(options_.wait_for_subscribers_s);
    std::string missing;
    while (ros::ok()) {
      const std::map<std::string, std::size_t> registered = registeredSubscribers();
      missing.clear();
      for (const auto& publisher : publishers_->sensorTopicConnections()) {
        const auto it = registered.find(publisher.topic);
        const bool needed =
            publisher.essential || (publisher.cloud && options_.wait_for_cloud_subscriber);
        const std::size_t wanted =
            std::max<std::size_t>(needed ? 1 : 0, it == registered.end() ? 0 : it->second);
        if (publisher.connected < wanted)
          missing += (missing.empty() ? "" : ", ") + publisher.topic;
      }
      if (missing.empty()) return;
      if (ros::WallTime::now() >= deadline) break;
      ROS_INFO_ONCE(
          "kitti_player: waiting up to %.1f s (~wait_for_subscribers_s) for the "
          "subscribers of %s",
          options_.wait_for_subscribers_s, missing.c_str());
      ros::WallDuration(0.05).sleep();
    }
    if (!missing.empty()) {
      ROS_WARN(
          "kitti_player: no subscriber connected on %s after %.1f s "
          "(~wait_for_subscribers_s): playing anyway",
          missing.c_str(), options_.wait_for_subscribers_s);
    }
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
            wall_anchor + ros::WallDuration(kitti::secondsBetween(data_anchor_ns, event.stamp_ns) /
                                            options_.rate);
        const ros::WallTime now = ros::WallTime::now();
        if (now >= due) break;
        ros::WallDuration(std::min((due - now).toSec(), 0.01)).sleep();
      }
      const bool published = publishers_->publish(event);
      playback_.noteData(kitti::secondsBetween(0, event.stamp_ns), conv::wallNow(),
                         published ? "published events" : "dropped frames (unreadable)");
      if (stepping && event.sensor == DriveSensor::kOxts) stepping = false;
      ROS_INFO_THROTTLE(5.0, "kitti_player: %.1f / %.1f s, %zu events published",
                        kitti::secondsBetween(timeline_.front().stamp_ns, event.stamp_ns),
                        spanSeconds(), publishers_->published());
    }
    return true;
  }

  ros::NodeHandle pnh_;
  conv::KittiPlayerOptions options_;
  std::atomic<bool> paused_{false};
  std::atomic<int> pending_steps_{0};
  std::unique_ptr<kitti::RawDrive> drive_;
  std::unique_ptr<conv::DriveMessageFactory> factory_;
  std::vector<kitti::TimelineEvent> timeline_;
  std::unique_ptr<conv::DrivePublishers> publishers_;
  ros::ServiceServer pause_service_, step_service_;
  conv::PlaybackMonitor playback_{10.0, {"published events", "dropped frames (unreadable)"}};
  std::unique_ptr<conv::NodeDiagnostics> diagnostics_;
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
