#include "inekf_semantic_mapping/ros/map_display.h"

#include <ros/console.h>
#include <ros/single_subscriber_publisher.h>

#include <stdexcept>

#include "inekf_semantic_mapping/SemanticMapInfo.h"
#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/ros/mapping_conversions.h"
#include "inekf_semantic_mapping/ros/names.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

MapDisplay::MapDisplay(ros::NodeHandle& nh, mapping::SemanticMappingSession& session,
                       const MapDisplayOptions& options, const mapping::GridProjectionConfig& grids)
    : session_(session),
      options_(options),
      grid_config_(grids),
      ground_trace_(grids.sensor_height) {
  try {
    mapping::projectGrids(session_.tree(), grid_config_, {});
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string(e.what()) + " (class_set " +
                                mapping::mapClassSetName(session_.config().class_set) + ")");
  }
  // Latched (octomap_server's topics are), and a new subscriber to a map that changed since the
  // last message is sent the map as it is now: the latched one can be seconds old.
  markers_pub_ = nh.advertise<visualization_msgs::MarkerArray>(
      topics::kMapMarkers, 1,
      [this](const ros::SingleSubscriberPublisher& subscriber) {
        if (!map_changed_) return;
        session_.tree().updateInnerOccupancy();
        subscriber.publish(occupiedVoxelMarkers(session_.tree(), options_.marker_depth,
                                                options_.map_frame, ros::Time::now()));
      },
      ros::SubscriberStatusCallback(), ros::VoidConstPtr(), true);
  // Not latched: the info is published only while someone listens, so a latched one could be
  // stale (a `rostopic echo -n1` after a reset showed the old map). A new subscriber gets the
  // current figures at once instead.
  info_pub_ = nh.advertise<SemanticMapInfo>(
      topics::kMapInfo, 1, [this](const ros::SingleSubscriberPublisher& subscriber) {
        subscriber.publish(mapInfoMessage(session_, options_.map_frame, ros::Time::now()));
      });
  const auto currentGrid = [this](bool drivable) {
    return [this, drivable](const ros::SingleSubscriberPublisher& subscriber) {
      if (!grids_changed_) return;
      const std::optional<mapping::ProjectedGrids> grids = gridsNow();
      if (!grids) return;
      subscriber.publish(occupancyGridMessage(drivable ? grids->drivable : grids->occupancy,
                                              options_.map_frame, ros::Time::now()));
    };
  };
  projected_pub_ = nh.advertise<nav_msgs::OccupancyGrid>(
      topics::kProjectedMap, 1, currentGrid(false), ros::SubscriberStatusCallback(),
      ros::VoidConstPtr(), true);
  drivable_pub_ = nh.advertise<nav_msgs::OccupancyGrid>(topics::kDrivableMap, 1, currentGrid(true),
                                                        ros::SubscriberStatusCallback(),
                                                        ros::VoidConstPtr(), true);
}

void MapDisplay::scanInserted(const mapping::LabeledScan& scan) {
  map_changed_ = true;
  grids_changed_ = true;
  ground_trace_.addSensorOrigin(scan.sensor_origin_map.cast<double>());
}

void MapDisplay::classesChanged() {
  map_changed_ = true;
  grids_changed_ = true;
}

void MapDisplay::mapReplaced() {
  map_changed_ = true;
  grids_changed_ = true;  // until published (the grids' projection may fail)
  ground_trace_.clear();
  const ros::Time now = ros::Time::now();
  publishMarkers(now);
  publishGrids(now);
  info_pub_.publish(mapInfoMessage(session_, options_.map_frame, now));
}

void MapDisplay::update() {
  const mapping::MappingStatistics& s = session_.statistics();
  const std::array<std::size_t, 4> counts{s.scans_received, s.scans_without_pose,
                                          s.label_images_received, s.label_images_unmatched};
  const bool want_grids = grids_changed_ && (projected_pub_.getNumSubscribers() > 0 ||
                                             drivable_pub_.getNumSubscribers() > 0);
  if (!map_changed_ && !want_grids && counts == published_counts_) return;
  if (markers_pub_.getNumSubscribers() == 0 && info_pub_.getNumSubscribers() == 0 && !want_grids) {
    return;
  }
  // Stretch the period so that the display takes at most max_display_cpu_fraction of the time.
  const ros::WallTime start = ros::WallTime::now();
  if (options_.max_display_cpu_fraction > 0 && !last_display_start_.isZero() &&
      (start - last_display_start_).toSec() <
          last_display_cost_s_ / options_.max_display_cpu_fraction) {
    return;
  }
  ScopedTimer stage("semantic_map/markers");
  const ros::Time now = ros::Time::now();
  // Markers and grids take turns when both are due: one display call blocks the spinner (and
  // fills the label image queue) half as long.
  bool do_markers = map_changed_;
  bool do_grids = want_grids;
  if (do_markers && do_grids) {
    (grids_turn_ ? do_markers : do_grids) = false;
    grids_turn_ = !grids_turn_;
  }
  if (do_markers) publishMarkers(now);
  if (do_grids) publishGrids(now);
  published_counts_ = counts;
  info_pub_.publish(mapInfoMessage(session_, options_.map_frame, now));
  last_display_start_ = start;
  last_display_cost_s_ = (ros::WallTime::now() - start).toSec();
}

void MapDisplay::publishMarkers(const ros::Time& now) {
  session_.tree().updateInnerOccupancy();  // what the merged markers show
  markers_pub_.publish(
      occupiedVoxelMarkers(session_.tree(), options_.marker_depth, options_.map_frame, now));
  map_changed_ = false;
}

std::optional<mapping::ProjectedGrids> MapDisplay::gridsNow() {
  ScopedTimer stage("semantic_map/grids");
  try {
    return mapping::projectGrids(session_.tree(), grid_config_, ground_trace_.samples());
  } catch (const std::exception& e) {
    ROS_ERROR_STREAM_THROTTLE(10, "semantic_octomap_node: " << topics::kProjectedMap << ", "
                                                            << topics::kDrivableMap
                                                            << " not published: " << e.what());
    return std::nullopt;
  }
}

void MapDisplay::publishGrids(const ros::Time& now) {
  const std::optional<mapping::ProjectedGrids> grids = gridsNow();
  if (!grids) return;
  projected_pub_.publish(occupancyGridMessage(grids->occupancy, options_.map_frame, now));
  drivable_pub_.publish(occupancyGridMessage(grids->drivable, options_.map_frame, now));
  grids_changed_ = false;
}

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
