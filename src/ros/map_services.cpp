#include "inekf_semantic_mapping/ros/map_services.h"

#include <ros/console.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <string>
#include <utility>

#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/mapping/map_io.h"
#include "inekf_semantic_mapping/ros/shutdown_log.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {

MapServices::MapServices(ros::NodeHandle& nh, ros::NodeHandle& private_nh,
                         mapping::SemanticMappingSession& session, MapDisplay& display,
                         std::string autosave_path, double autosave_period_s)
    : session_(session), display_(display), autosave_path_(std::move(autosave_path)) {
  save_srv_ = private_nh.advertiseService("save_map", &MapServices::onSave, this);
  load_srv_ = private_nh.advertiseService("load_map", &MapServices::onLoad, this);
  reset_srv_ = private_nh.advertiseService("reset", &MapServices::onReset, this);
  if (!autosave_path_.empty() && autosave_period_s > 0) {
    autosave_timer_ = nh.createWallTimer(ros::WallDuration(autosave_period_s),
                                         [this](const ros::WallTimerEvent&) { autosave(); });
  }
}

bool MapServices::saveToAutosavePath() {
  last_autosave_ = SaveRecord{autosave_path_, wallNow(), true, ""};
  try {
    session_.save(autosave_path_, mapping::MapFormat::kSemanticOt);
  } catch (const std::exception& e) {
    last_autosave_.ok = false;
    last_autosave_.error = e.what();
  }
  return last_autosave_.ok;
}

void MapServices::autosave() {
  if (autosave_path_.empty() || session_.statistics().scans_inserted == 0) return;
  if (!saveToAutosavePath()) {
    ROS_ERROR_STREAM_THROTTLE(60,
                              "semantic_octomap_node: autosave failed: " << last_autosave_.error);
  }
}

void MapServices::finalAutosave() {
  if (autosave_path_.empty()) return;
  const std::size_t scans = session_.statistics().scans_inserted;
  if (scans == 0) {  // a resumed map unchanged, or none at all
    logAtShutdown(ShutdownLogLevel::kInfo,
                  "semantic_octomap_node: no scan went into the map: nothing to autosave");
    return;
  }
  if (saveToAutosavePath()) {
    logAtShutdown(ShutdownLogLevel::kInfo, "semantic_octomap_node: map saved to " + autosave_path_ +
                                               " (" + std::to_string(scans) + " scans)");
    return;
  }
  // The folder went away, or the disk filled, while mapping: the map is not lost with it.
  const std::string name =
      "semantic_map_autosave_" + std::to_string(static_cast<long>(::getpid())) + ".ot";
  std::string fallback = "/tmp/" + name;
  std::string fallback_result;
  try {
    std::error_code no_tmpdir;  // a TMPDIR that does not exist: /tmp
    const std::filesystem::path tmp = std::filesystem::temp_directory_path(no_tmpdir);
    if (!no_tmpdir) fallback = (tmp / name).string();
    session_.save(fallback, mapping::MapFormat::kSemanticOt);
    fallback_result = "saved to " + fallback + " instead";
  } catch (const std::exception& e) {
    fallback_result = "and to " + fallback + ": " + e.what() + ": the map is lost";
  }
  logAtShutdown(ShutdownLogLevel::kError, "semantic_octomap_node: the final autosave to " +
                                              autosave_path_ + " failed: " + last_autosave_.error +
                                              "; " + fallback_result);
}

bool MapServices::onSave(SaveMap::Request& request, SaveMap::Response& response) {
  last_save_ = SaveRecord{request.path, wallNow(), true, ""};
  try {
    const mapping::MapFormat format = mapping::parseMapFormat(request.format, request.path);
    // A relative path is the node's working directory's ($ROS_HOME under roslaunch, where no one
    // looks): said in full. A folder is refused before the map is written out.
    const std::string path =
        request.path.empty() ? request.path : std::filesystem::absolute(request.path).string();
    common::checkOutputPath(path);
    last_save_.path = path;
    response.voxel_count = session_.save(path, format);
    response.success = true;
    response.message = "wrote " + path + " (" + std::to_string(response.voxel_count) +
                       " occupied voxels, " + std::to_string(session_.statistics().scans_inserted) +
                       " scans)";
    ROS_INFO_STREAM("semantic_octomap_node: " << response.message);
  } catch (const std::exception& e) {
    response.success = false;
    response.voxel_count = 0;
    response.message = e.what();
    last_save_.ok = false;
    last_save_.error = e.what();
    ROS_ERROR_STREAM("semantic_octomap_node: save_map failed: " << e.what());
  }
  return true;  // the failure is in the response, the node keeps running
}

bool MapServices::onLoad(LoadMap::Request& request, LoadMap::Response& response) {
  try {
    session_.load(request.path);
    display_.mapReplaced();
    if (map_replaced_) map_replaced_();
    response.success = true;
    response.nodes = session_.tree().size();
    response.message = "loaded " + request.path + " (" + std::to_string(response.nodes) + " nodes)";
    ROS_INFO_STREAM("semantic_octomap_node: " << response.message);
  } catch (const std::exception& e) {
    response.success = false;
    response.message = e.what();
    ROS_ERROR_STREAM(
        "semantic_octomap_node: load_map failed, the current map is kept: " << e.what());
  }
  return true;
}

bool MapServices::onReset(std_srvs::Empty::Request&, std_srvs::Empty::Response&) {
  session_.reset();
  display_.mapReplaced();
  if (map_replaced_) map_replaced_();
  ROS_INFO("semantic_octomap_node: map reset");
  return true;
}

std::string mappingStatusLine(const mapping::SemanticMappingSession& session) {
  const mapping::MappingStatistics& s = session.statistics();
  const auto stats = TimingRegistry::instance().snapshot();
  const auto insert = stats.find("semantic_map/insert");
  char line[400];
  std::snprintf(line, sizeof(line),
                "%zu of %zu scans in the map (%zu with labels, %zu pending, %zu without pose, "
                "%zu rejected), %zu of %zu label images used (%zu late), map %s, insert %.1f ms",
                s.scans_inserted, s.scans_received, s.scans_with_labels, session.pendingScans(),
                s.scans_without_pose, s.scans_rejected, s.label_images_used,
                s.label_images_received, s.label_images_late, session.mapSizeText().c_str(),
                insert == stats.end() ? 0.0 : 1e3 * insert->second.meanSeconds());
  return line;
}

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
