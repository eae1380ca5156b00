// semantic_octomap_node: the ROS face of mapping::SemanticMappingSession (semantic_map_offline is
// the other). It converts messages and calls the session; the session owns the policy.
//
// Subscribes /kitti/velo/pointcloud, /segmentation/labels (mono8 Cityscapes labelIds, stamped
// like the camera image) and /kitti/camera_color_left/camera_info (or reads the raw calibration
// in ~calib_dir). Every scan updates the map; a label image adds class evidence to the scan of
// its stamp. Poses come from tf (map_frame -> cloud frame at the scan stamp) when the session
// inserts a scan: scans queue until their pose is there, nothing blocks the spinner.
// Publishes /semantic_map/markers, /semantic_map/labeled_cloud, /semantic_map/info
// (SemanticMapInfo), /semantic_map/projected_map and /semantic_map/drivable_map
// (nav_msgs/OccupancyGrid, mapping/grid_projection.h); services ~save_map, ~load_map, ~reset;
// ~map_file resumes from a saved map, ~autosave_path saves periodically and at shutdown.
// Parameters: config/semantic_mapping.yaml.
#include <ros/ros.h>
#include <std_srvs/Empty.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <array>
#include <deque>
#include <memory>
#include <optional>

#include "inekf_semantic_mapping/LoadMap.h"
#include "inekf_semantic_mapping/SaveMap.h"
#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"
#include "inekf_semantic_mapping/ros/mapping_conversions.h"
#include "inekf_semantic_mapping/ros/names.h"

namespace inekf_semantic_mapping {
namespace {

namespace conv = ros_conversions;

// The node's own keys (display, frames, calibration); the rest belong to the session.
struct NodeOptions {
  std::string map_frame = frames::kMap;
  double marker_rate_hz = 1.0;
  double max_display_cpu_fraction = 0.1;
  int marker_depth = 15;
  std::string calib_dir;
  int camera_index = 2;
  std::string map_file;       // loaded at start when set
  std::string autosave_path;  // saved every autosave_period and at shutdown when set
  double autosave_period_s = 30.0;
  double log_period_s = 10.0;
};

class SemanticOctomapNode {
 public:
  SemanticOctomapNode(ros::NodeHandle nh, ros::NodeHandle pnh) : nh_(nh), pnh_(pnh) {
    const YAML::Node parameters = conv::privateParametersAsYaml(pnh_);
    const std::string source = "ROS parameters of " + pnh_.getNamespace();
    common::YamlReader reader(source, parameters);
    reader.read("map_frame", &options_.map_frame);
    reader.read("marker_rate", &options_.marker_rate_hz);
    reader.read("max_display_cpu_fraction", &options_.max_display_cpu_fraction);
    reader.read("marker_depth", &options_.marker_depth);
    reader.read("calib_dir", &options_.calib_dir);
    reader.read("camera_index", &options_.camera_index);
    reader.read("map_file", &options_.map_file);
    reader.read("autosave_path", &options_.autosave_path);
    reader.read("autosave_period", &options_.autosave_period_s);
    reader.read("log_period", &options_.log_period_s);
    session_ = std::make_unique<mapping::SemanticMappingSession>(
        mapping::readSemanticMappingConfig(parameters, source));
    grid_config_ = mapping::readGridProjectionConfig(parameters, source);
    ground_trace_ = mapping::GroundTrace(grid_config_.sensor_height);
    // A drivable class the class set lacks is reported now, not at the first display (the map
    // is still empty: nothing is projected).
    try {
      mapping::projectGrids(session_->tree(), grid_config_, {});
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(source + ": " + e.what() + " (class_set " +
                                  session_->config().class_set + ")");
    }
    session_->setPoseLookup([this](double stamp, const std::string& frame) {
      return lookup(options_.map_frame, frame, ros::Time(stamp));
    });
    session_->setInsertedCallback([this](double stamp, const mapping::LabeledScan& scan) {
      map_changed_ = true;
      grids_changed_ = true;
      ground_trace_.addSensorOrigin(scan.sensor_origin_map.cast<double>());
      if (cloud_pub_.getNumSubscribers() == 0) return;
      cloud_pub_.publish(conv::labeledCloudMessage(scan, session_->classSet(), options_.map_frame,
                                                   ros::Time(stamp)));
    });
    if (!options_.map_file.empty()) {
      session_->load(options_.map_file);
      ROS_INFO_STREAM("semantic_octomap_node: resumed from "
                      << options_.map_file << " (" << session_->tree().size() << " nodes)");
    }
    if (!options_.calib_dir.empty()) {
      file_camera_ =
          kitti::readRawCalibration(options_.calib_dir).projection(options_.camera_index);
    }
    markers_pub_ = nh_.advertise<visualization_msgs::MarkerArray>(topics::kMapMarkers, 1, true);
    cloud_pub_ = nh_.advertise<sensor_msgs::PointCloud2>(topics::kLabeledCloud, 2);
    info_pub_ = nh_.advertise<SemanticMapInfo>(topics::kMapInfo, 1, true);
    projected_pub_ = nh_.advertise<nav_msgs::OccupancyGrid>(topics::kProjectedMap, 1, true);
    drivable_pub_ = nh_.advertise<nav_msgs::OccupancyGrid>(topics::kDrivableMap, 1, true);
    camera_info_sub_ =
        nh_.subscribe(topics::kCameraColorLeftInfo, 1, &SemanticOctomapNode::onCameraInfo, this);
    // Room for the scans that arrive while a label image's batch of waiting scans goes in, and
    // as much for the label images: when inserting falls behind (a loaded machine), a dropped
    // label image leaves its scan without classes, and a newer one releases that scan unlabelled
    // (e2e_synthetic on a busy machine with 5 here: 27 of 98 scans labelled, voxel accuracy 0.27).
    constexpr int kInputQueue = 30;
    cloud_sub_ = nh_.subscribe(topics::kVelodyne, kInputQueue, &SemanticOctomapNode::onCloud, this);
    labels_sub_ = nh_.subscribe(topics::kSegmentationLabels, kInputQueue,
                                &SemanticOctomapNode::onLabels, this);
    save_srv_ = pnh_.advertiseService("save_map", &SemanticOctomapNode::onSaveMap, this);
    reset_srv_ = pnh_.advertiseService("reset", &SemanticOctomapNode::onReset, this);
    load_srv_ = pnh_.advertiseService("load_map", &SemanticOctomapNode::onLoadMap, this);
    if (!options_.autosave_path.empty() && options_.autosave_period_s > 0) {
      autosave_timer_ = nh_.createWallTimer(ros::WallDuration(options_.autosave_period_s),
                                            [this](const ros::WallTimerEvent&) { autosave(); });
    }
    // Pending scans go in when their wait is over, also after the last message of a bag.
    clock_timer_ = nh_.createWallTimer(ros::WallDuration(0.1), &SemanticOctomapNode::onTick, this);
    if (options_.marker_rate_hz > 0) {
      display_timer_ = nh_.createWallTimer(ros::WallDuration(1.0 / options_.marker_rate_hz),
                                           &SemanticOctomapNode::publishDisplay, this);
    }
    log_timer_ = nh_.createWallTimer(ros::WallDuration(options_.log_period_s),
                                     &SemanticOctomapNode::logStatus, this);
    const mapping::SemanticMappingConfig& config = session_->config();
    ROS_INFO_STREAM("semantic_octomap_node: resolution "
                    << config.resolution_m << " m, max range " << config.max_range_m
                    << " m, classes " << config.class_set << ", label wait " << config.label_wait_s
                    << " s");
  }

  ~SemanticOctomapNode() { autosave(); }

 private:
  std::optional<Eigen::Isometry3d> lookup(const std::string& target, const std::string& source,
                                          const ros::Time& stamp) const {
    if (!tf_buffer_.canTransform(target, source, stamp)) return std::nullopt;
    return tf2::transformToEigen(tf_buffer_.lookupTransform(target, source, stamp));
  }

  void onCameraInfo(const sensor_msgs::CameraInfo& info) { camera_info_ = info; }

  // The camera of a label image: calibration files, or camera_info P (rectified image) with the
  // static velodyne -> camera transform from tf.
  std::optional<mapping::CameraModel> cameraFor(const sensor_msgs::Image& labels) {
    if (file_camera_) {
      return mapping::CameraModel{file_camera_->P_rect, file_camera_->R_rect,
                                  file_camera_->T_cam0_velo, static_cast<int>(labels.width),
                                  static_cast<int>(labels.height)};
    }
    if (!camera_info_ || velo_frame_.empty()) return std::nullopt;
    const std::string camera_frame =
        labels.header.frame_id.empty() ? camera_info_->header.frame_id : labels.header.frame_id;
    const auto T_camera_velo = lookup(camera_frame, velo_frame_, ros::Time(0));
    if (!T_camera_velo) return std::nullopt;
    return conv::cameraModelFromInfo(*camera_info_, *T_camera_velo);
  }

  // Scans that come before the first label image are cut to the camera's view as soon as the
  // camera is known, like the labelled ones (a whole HDL-64 scan costs several times more).
  void setCameraView() {
    if (file_camera_ && file_camera_->width > 0 && file_camera_->height > 0) {
      session_->setCameraView(mapping::CameraModel{file_camera_->P_rect, file_camera_->R_rect,
                                                   file_camera_->T_cam0_velo, file_camera_->width,
                                                   file_camera_->height});
      return;
    }
    if (!camera_info_) return;
    const auto T_camera_velo = lookup(camera_info_->header.frame_id, velo_frame_, ros::Time(0));
    if (!T_camera_velo) return;
    try {
      session_->setCameraView(conv::cameraModelFromInfo(*camera_info_, *T_camera_velo));
    } catch (const std::exception& e) {
      ROS_WARN_STREAM_THROTTLE(10, "semantic_octomap_node: " << topics::kCameraColorLeftInfo
                                                             << " unusable: " << e.what());
    }
  }

  void onCloud(const sensor_msgs::PointCloud2ConstPtr& cloud) {
    try {
      ScopedTimer timer("semantic_map/scan");
      detectClockJump();
      velo_frame_ = cloud->header.frame_id;
      if (!session_->hasCameraView()) setCameraView();
      session_->addScan(cloud->header.stamp.toSec(), cloud->header.frame_id,
                        conv::pointsFromCloud(*cloud));
      passWaitingLabels();
    } catch (const std::exception& e) {
      ROS_ERROR_STREAM_THROTTLE(5, "semantic_octomap_node: " << topics::kVelodyne << " at "
                                                             << cloud->header.stamp
                                                             << " ignored: " << e.what());
    }
  }

  void onLabels(const sensor_msgs::ImageConstPtr& labels) {
    try {
      conv::labelImageView(*labels);  // a malformed image is reported now, not when retried
    } catch (const std::exception& e) {
      ROS_ERROR_STREAM_THROTTLE(5, "semantic_octomap_node: " << topics::kSegmentationLabels
                                                             << " at " << labels->header.stamp
                                                             << " ignored: " << e.what());
      return;
    }
    // The camera needs the lidar frame (from the first cloud) and camera_info: label images that
    // come before them wait here.
    labels_waiting_.push_back(labels);
    if (labels_waiting_.size() > kMaxLabelsWaiting) labels_waiting_.pop_front();
    passWaitingLabels();
  }

  void passWaitingLabels() {
    while (!labels_waiting_.empty()) {
      const sensor_msgs::ImageConstPtr labels = labels_waiting_.front();
      const std::optional<mapping::CameraModel> camera = cameraFor(*labels);
      if (!camera) {
        ROS_WARN_THROTTLE(5,
                          "semantic_octomap_node: waiting for the camera (%s and tf %s -> "
                          "camera, or ~calib_dir) to use label images",
                          topics::kCameraColorLeftInfo, velo_frame_.c_str());
        return;
      }
      labels_waiting_.pop_front();
      try {
        ScopedTimer timer("semantic_map/labels");
        session_->addLabelImage(labels->header.stamp.toSec(), conv::labelImageView(*labels),
                                *camera);
      } catch (const std::exception& e) {
        ROS_ERROR_STREAM_THROTTLE(5, "semantic_octomap_node: " << topics::kSegmentationLabels
                                                               << " at " << labels->header.stamp
                                                               << " ignored: " << e.what());
      }
    }
  }

  void onTick(const ros::WallTimerEvent&) {
    try {
      detectClockJump();
      passWaitingLabels();
      session_->advanceTo(ros::Time::now().toSec());
    } catch (const std::exception& e) {
      ROS_ERROR_STREAM_THROTTLE(5, "semantic_octomap_node: inserting pending scans: " << e.what());
    }
  }

  // A bag loop shows as the clock jumping back: the pending scans go in with the poses tf still
  // has, then tf forgets the old timeline.
  void detectClockJump() {
    const ros::Time now = ros::Time::now();
    if (!last_clock_.isZero() && now + ros::Duration(1.0) < last_clock_) {
      ROS_WARN_STREAM("semantic_octomap_node: clock jumped back (" << last_clock_ << " -> " << now
                                                                   << "): clearing the tf buffer");
      session_->flush();
      tf_buffer_.clear();
    }
    last_clock_ = now;
  }

  void publishDisplay(const ros::WallTimerEvent&) {
    const mapping::MappingStatistics& s = session_->statistics();
    const std::array<std::size_t, 4> counts{s.scans_received, s.scans_without_pose,
                                            s.label_images_received, s.label_images_unmatched};
    // The grids have their own flag: a subscriber that comes after the markers went out still
    // gets them once.
    const bool want_grids = grids_changed_ && (projected_pub_.getNumSubscribers() > 0 ||
                                               drivable_pub_.getNumSubscribers() > 0);
    if (!map_changed_ && !want_grids && counts == published_counts_) return;
    if (markers_pub_.getNumSubscribers() == 0 && info_pub_.getNumSubscribers() == 0 &&
        !want_grids) {
      return;
    }
    // The display walks the whole map on the thread that inserts scans: stretch the period so
    // that it takes at most max_display_cpu_fraction of the time.
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
    if (do_markers) {
      session_->tree().updateInnerOccupancy();
      markers_pub_.publish(conv::occupiedVoxelMarkers(session_->tree(), options_.marker_depth,
                                                      options_.map_frame, now));
      map_changed_ = false;
    }
    if (do_grids) publishGrids(now);
    published_counts_ = counts;
    info_pub_.publish(conv::mapInfoMessage(*session_, options_.map_frame, now));
    last_display_start_ = start;
    last_display_cost_s_ = (ros::WallTime::now() - start).toSec();
  }

  void publishGrids(const ros::Time& now) {
    ScopedTimer stage("semantic_map/grids");
    try {
      const mapping::ProjectedGrids grids =
          mapping::projectGrids(session_->tree(), grid_config_, ground_trace_.samples());
      projected_pub_.publish(conv::occupancyGridMessage(grids.occupancy, options_.map_frame, now));
      drivable_pub_.publish(conv::occupancyGridMessage(grids.drivable, options_.map_frame, now));
      grids_changed_ = false;
    } catch (const std::exception& e) {
      ROS_ERROR_STREAM_THROTTLE(10, "semantic_octomap_node: " << topics::kProjectedMap << ", "
                                                              << topics::kDrivableMap
                                                              << " not published: " << e.what());
    }
  }

  bool onSaveMap(SaveMap::Request& request, SaveMap::Response& response) {
    try {
      const mapping::MapFormat format = mapping::parseMapFormat(request.format, request.path);
      response.voxel_count = session_->save(request.path, format);
      response.success = true;
      response.message = "wrote " + request.path + " (" + std::to_string(response.voxel_count) +
                         " occupied voxels, " +
                         std::to_string(session_->statistics().scans_inserted) + " scans)";
      ROS_INFO_STREAM("semantic_octomap_node: " << response.message);
    } catch (const std::exception& e) {
      response.success = false;
      response.voxel_count = 0;
      response.message = e.what();
      ROS_ERROR_STREAM("semantic_octomap_node: save_map failed: " << e.what());
    }
    return true;  // the failure is in the response, the node keeps running
  }

  bool onLoadMap(LoadMap::Request& request, LoadMap::Response& response) {
    try {
      session_->load(request.path);
      map_changed_ = true;
      grids_changed_ = true;
      ground_trace_.clear();  // the loaded map's path is not known: the plane ground_z
      response.success = true;
      response.nodes = session_->tree().size();
      response.message =
          "loaded " + request.path + " (" + std::to_string(response.nodes) + " nodes)";
      ROS_INFO_STREAM("semantic_octomap_node: " << response.message);
    } catch (const std::exception& e) {
      response.success = false;
      response.message = e.what();
      ROS_ERROR_STREAM(
          "semantic_octomap_node: load_map failed, the current map is kept: " << e.what());
    }
    return true;
  }

  // Atomic, so a crash during a save never leaves a broken file.
  void autosave() {
    if (options_.autosave_path.empty() || !session_ || session_->statistics().scans_inserted == 0) {
      return;
    }
    try {
      session_->save(options_.autosave_path, mapping::MapFormat::kSemanticOt);
    } catch (const std::exception& e) {
      ROS_ERROR_STREAM_THROTTLE(60, "semantic_octomap_node: autosave failed: " << e.what());
    }
  }

  bool onReset(std_srvs::Empty::Request&, std_srvs::Empty::Response&) {
    session_->reset();
    map_changed_ = true;
    grids_changed_ = true;
    ground_trace_.clear();
    ROS_INFO("semantic_octomap_node: map reset");
    return true;
  }

  void logStatus(const ros::WallTimerEvent&) {
    const mapping::MappingStatistics& s = session_->statistics();
    const auto stats = TimingRegistry::instance().snapshot();
    const auto insert = stats.find("semantic_map/insert");
    ROS_INFO(
        "semantic_octomap_node: %zu of %zu scans in the map (%zu with labels, %zu pending, "
        "%zu without pose), %zu of %zu label images used (%zu late), %zu nodes, insert %.1f ms",
        s.scans_inserted, s.scans_received, s.scans_with_labels, session_->pendingScans(),
        s.scans_without_pose, s.label_images_used, s.label_images_received, s.label_images_late,
        session_->tree().size(), insert == stats.end() ? 0.0 : 1e3 * insert->second.meanSeconds());
  }

  ros::NodeHandle nh_, pnh_;
  NodeOptions options_;
  tf2_ros::Buffer tf_buffer_;
  tf2_ros::TransformListener tf_listener_{tf_buffer_};
  std::unique_ptr<mapping::SemanticMappingSession> session_;
  std::optional<kitti::CameraProjection> file_camera_;
  std::optional<sensor_msgs::CameraInfo> camera_info_;
  std::string velo_frame_;
  static constexpr std::size_t kMaxLabelsWaiting = 5;
  std::deque<sensor_msgs::ImageConstPtr> labels_waiting_;
  std::array<std::size_t, 4> published_counts_{};
  ros::Subscriber camera_info_sub_, cloud_sub_, labels_sub_;
  ros::Publisher markers_pub_, cloud_pub_, info_pub_, projected_pub_, drivable_pub_;
  ros::ServiceServer save_srv_, reset_srv_, load_srv_;
  ros::WallTimer clock_timer_, display_timer_, log_timer_, autosave_timer_;
  ros::WallTime last_display_start_;
  double last_display_cost_s_ = 0.0;
  ros::Time last_clock_;
  bool map_changed_ = true;
  mapping::GridProjectionConfig grid_config_;
  mapping::GroundTrace ground_trace_{grid_config_.sensor_height};
  bool grids_changed_ = true;
  bool grids_turn_ = false;
};

}  // namespace
}  // namespace inekf_semantic_mapping

int main(int argc, char** argv) {
  ros::init(argc, argv, "semantic_octomap_node");
  try {
    inekf_semantic_mapping::SemanticOctomapNode node{ros::NodeHandle(), ros::NodeHandle("~")};
    ros::spin();
  } catch (const std::exception& e) {
    ROS_FATAL_STREAM("semantic_octomap_node: " << e.what());
    return 1;
  }
  std::cerr << inekf_semantic_mapping::TimingRegistry::instance().report();
  return 0;
}
