// semantic_octomap_node's services on its map, in its private namespace: ~save_map (SaveMap:
// .ot / .ply by format or extension, .bt refused), ~load_map (LoadMap: the current map is kept when
// the file is refused), ~reset (std_srvs/Empty); and the autosave to autosave_path: every
// autosave_period_s, and once more when the node finishes (finalAutosave). Every save is atomic, so
// a crash never leaves a broken file; a failure is reported in the response and the node keeps
// running. ROS-facing (src/ros): only nodes include this header.
#pragma once

#include <ros/node_handle.h>
#include <ros/service_server.h>
#include <ros/wall_timer.h>
#include <std_srvs/Empty.h>

#include <functional>
#include <string>

#include "inekf_semantic_mapping/LoadMap.h"
#include "inekf_semantic_mapping/SaveMap.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"
#include "inekf_semantic_mapping/ros/map_display.h"
#include "inekf_semantic_mapping/ros/mapping_diagnostics.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

class MapServices {
 public:
  // autosave_path empty or autosave_period_s <= 0: no periodic autosave (an empty path: none).
  MapServices(ros::NodeHandle& nh, ros::NodeHandle& private_nh,
              mapping::SemanticMappingSession& session, MapDisplay& display,
              std::string autosave_path, double autosave_period_s);

  // Saves to autosave_path when it is set and the map has scans; errors are logged.
  void autosave();
  // The save when the node finishes: as autosave, and says where the map went.
  void finalAutosave();
  // Called after ~load_map replaced the map or ~reset emptied it.
  void setMapReplacedCallback(std::function<void()> callback) {
    map_replaced_ = std::move(callback);
  }
  // The last ~save_map and autosave (for /diagnostics).
  const SaveRecord& lastSave() const { return last_save_; }
  const SaveRecord& lastAutosave() const { return last_autosave_; }

 private:
  // Saves to autosave_path and records it in last_autosave_; false (error recorded) on failure.
  bool saveToAutosavePath();
  bool onSave(SaveMap::Request& request, SaveMap::Response& response);
  bool onLoad(LoadMap::Request& request, LoadMap::Response& response);
  bool onReset(std_srvs::Empty::Request&, std_srvs::Empty::Response&);

  mapping::SemanticMappingSession& session_;
  MapDisplay& display_;
  std::string autosave_path_;
  ros::ServiceServer save_srv_, load_srv_, reset_srv_;
  ros::WallTimer autosave_timer_;
  SaveRecord last_save_, last_autosave_;
  std::function<void()> map_replaced_;
};

// The node's periodic log line: scans in the map, with labels, pending, without pose; label
// images used and late; the map's size (SemanticMappingSession::mapSizeText: no grid -> tree sync,
// so a node nobody watches holds the map once, in the grid); mean insertion time.
std::string mappingStatusLine(const mapping::SemanticMappingSession& session);

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
