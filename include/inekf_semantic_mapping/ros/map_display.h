// What semantic_octomap_node shows of its map, all latched in the map frame: the occupied-voxel
// markers (/semantic_map/markers), SemanticMapInfo (/semantic_map/info) and octomap_server's 2D
// grids (/semantic_map/projected_map, /semantic_map/drivable_map; mapping/grid_projection.h).
// Each runs only when something changed and someone subscribes, and the whole display stays
// within a CPU budget: it walks the map on the thread that inserts scans. A latched message is
// the last one published, so the map's replacement (reset, load) is published at once whoever
// listens, and a new subscriber to a map that changed since is sent the map as it is.
// ROS-facing (src/ros): only nodes include this header.
#pragma once

#include <ros/node_handle.h>
#include <ros/publisher.h>
#include <ros/time.h>
#include <ros/wall_timer.h>

#include <array>
#include <cstddef>
#include <optional>
#include <string>

#include "inekf_semantic_mapping/mapping/grid_projection.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

struct MapDisplayOptions {
  std::string map_frame;
  int marker_depth = 15;                  // octree depth the markers merge voxels to
  double max_display_cpu_fraction = 0.1;  // the period stretches to keep within this share
};

class MapDisplay {
 public:
  // Advertises the topics on nh. Throws std::invalid_argument when the grid configuration names
  // a drivable class the session's class set lacks (reported at start, not at the first
  // display).
  MapDisplay(ros::NodeHandle& nh, mapping::SemanticMappingSession& session,
             const MapDisplayOptions& options, const mapping::GridProjectionConfig& grids);

  // A scan went in: the display is due, its lidar origin traces the ground for the grids.
  void scanInserted(const mapping::LabeledScan& scan);
  // Class evidence was added to voxels already in (a late label image): the display is due.
  void classesChanged();
  // The map was replaced (load, reset): its path is unknown, the grids use the plane ground_z.
  // Published at once: a later subscriber's latched map would be the old one.
  void mapReplaced();
  // Publishes what is due (the node's display timer).
  void update();

 private:
  void publishMarkers(const ros::Time& now);
  void publishGrids(const ros::Time& now);
  // The grids as they are now; nullopt (said) if the projection fails.
  std::optional<mapping::ProjectedGrids> gridsNow();

  mapping::SemanticMappingSession& session_;
  MapDisplayOptions options_;
  mapping::GridProjectionConfig grid_config_;
  mapping::GroundTrace ground_trace_;
  ros::Publisher markers_pub_, info_pub_, projected_pub_, drivable_pub_;
  bool map_changed_ = true;
  // The grids have their own flag: a subscriber that comes after the markers went out still
  // gets them once.
  bool grids_changed_ = true;
  bool grids_turn_ = false;
  std::array<std::size_t, 4> published_counts_{};
  ros::WallTime last_display_start_;
  double last_display_cost_s_ = 0.0;
};

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
