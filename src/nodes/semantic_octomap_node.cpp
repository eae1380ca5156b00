// semantic_octomap_node: fuses lidar scans and segmentation label images into a SemanticOcTree.
//
// Subscribes /kitti/velo/pointcloud and /segmentation/labels (mono8 labelIds, stamped like the
// camera image), paired by message_filters ApproximateTime (~sync_tolerance), and the camera
// calibration from /kitti/camera_color_left/camera_info + tf velo_link -> camera frame (or the
// raw calibration files in ~calib_dir). The pose map -> velo_link comes from tf at the scan
// stamp (waiting up to ~tf_timeout); a scan without a pose is skipped, never inserted with a
// wrong one. Publishes /semantic_map/markers, /semantic_map/labeled_cloud, /semantic_map/info;
// services ~save_map (SaveMap) and ~reset (std_srvs/Empty). The algorithms live in the mapping
// and projection libraries; this node converts messages and calls them.
#include <message_filters/subscriber.h>
#include <message_filters/sync_policies/approximate_time.h>
#include <message_filters/synchronizer.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/image_encodings.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <std_msgs/String.h>
#include <std_srvs/Empty.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>
#include <visualization_msgs/MarkerArray.h>

#include <cstring>
#include <map>
#include <memory>
#include <optional>
#include <sstream>

#include "inekf_semantic_mapping/SaveMap.h"
#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/mapping/map_io.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"
#include "inekf_semantic_mapping/perception/projection.h"
#include "inekf_semantic_mapping/ros/names.h"

namespace inekf_semantic_mapping {
namespace {

using mapping::ClassIndex;
using mapping::SemanticOcTree;
using mapping::SemanticOcTreeNode;

constexpr std::uint32_t kNoLabel = 0xFFFFFFFF;  // a point outside the image: no class evidence

struct NodeParameters {
  std::string map_frame = frames::kMap;
  double resolution_m = 0.2;
  double max_range_m = 50.0;
  double prob_hit = 0.7, prob_miss = 0.4, clamping_min = 0.12, clamping_max = 0.97;
  std::string class_set = "cityscapes";
  mapping::FusionModel fusion;
  double sync_tolerance_s = 0.05;
  int sync_queue_size = 30;
  double tf_timeout_s = 0.2;
  bool use_labels_without_image = false;
  bool insert_points_outside_image = false;
  double labels_timeout_s = 2.0;
  double marker_rate_hz = 1.0;
  double max_display_cpu_fraction = 0.1;
  int marker_depth = 15;
  std::string calib_dir;
  int camera_index = 2;
  int ray_casting_threads = 1;
  double grazing_ray_truncation_voxels = 1.0;
  double log_period_s = 10.0;
};

NodeParameters readParameters(const ros::NodeHandle& pnh) {
  NodeParameters p;
  pnh.param("map_frame", p.map_frame, p.map_frame);
  pnh.param("resolution", p.resolution_m, p.resolution_m);
  pnh.param("max_range", p.max_range_m, p.max_range_m);
  pnh.param("sensor_model/hit", p.prob_hit, p.prob_hit);
  pnh.param("sensor_model/miss", p.prob_miss, p.prob_miss);
  pnh.param("sensor_model/clamping_min", p.clamping_min, p.clamping_min);
  pnh.param("sensor_model/clamping_max", p.clamping_max, p.clamping_max);
  pnh.param("class_set", p.class_set, p.class_set);
  std::string rule = "bayes";
  pnh.param("fusion_rule", rule, rule);
  p.fusion.rule = mapping::parseFusionRule(rule);
  pnh.param("confusion_probability", p.fusion.correct_probability, p.fusion.correct_probability);
  pnh.param("dirichlet_prior", p.fusion.dirichlet_prior, p.fusion.dirichlet_prior);
  pnh.param("sync_tolerance", p.sync_tolerance_s, p.sync_tolerance_s);
  pnh.param("sync_queue_size", p.sync_queue_size, p.sync_queue_size);
  p.sync_queue_size = std::max(p.sync_queue_size, 1);
  pnh.param("tf_timeout", p.tf_timeout_s, p.tf_timeout_s);
  pnh.param("use_labels_without_image", p.use_labels_without_image, p.use_labels_without_image);
  pnh.param("labels_timeout", p.labels_timeout_s, p.labels_timeout_s);
  pnh.param("insert_points_outside_image", p.insert_points_outside_image,
            p.insert_points_outside_image);
  pnh.param("marker_rate", p.marker_rate_hz, p.marker_rate_hz);
  pnh.param("max_display_cpu_fraction", p.max_display_cpu_fraction, p.max_display_cpu_fraction);
  pnh.param("marker_depth", p.marker_depth, p.marker_depth);
  pnh.param("calib_dir", p.calib_dir, p.calib_dir);
  pnh.param("camera_index", p.camera_index, p.camera_index);
  pnh.param("ray_casting_threads", p.ray_casting_threads, p.ray_casting_threads);
  pnh.param("grazing_ray_truncation_voxels", p.grazing_ray_truncation_voxels,
            p.grazing_ray_truncation_voxels);
  if (!(p.grazing_ray_truncation_voxels >= 0.0)) {
    throw std::invalid_argument("~grazing_ray_truncation_voxels must be >= 0");
  }
  pnh.param("log_period", p.log_period_s, p.log_period_s);
  if (!(p.resolution_m > 0)) throw std::invalid_argument("~resolution must be > 0");
  if (!(p.fusion.correct_probability > 0 && p.fusion.correct_probability < 1)) {
    throw std::invalid_argument("~confusion_probability must be in (0, 1)");
  }
  if (p.class_set != "cityscapes" && p.class_set != "semantickitti") {
    throw std::invalid_argument("~class_set must be cityscapes or semantickitti, got '" +
                                p.class_set + "'");
  }
  return p;
}

class SemanticOctomapNode {
 public:
  SemanticOctomapNode(ros::NodeHandle nh, ros::NodeHandle pnh)
      : nh_(nh), pnh_(pnh), params_(readParameters(pnh)), tf_listener_(tf_buffer_) {
    resetTree();
    if (!params_.calib_dir.empty()) {
      // Raw calibration files: the projection needs neither camera_info nor the camera tf.
      const kitti::CameraProjection camera =
          kitti::readRawCalibration(params_.calib_dir).projection(params_.camera_index);
      file_camera_ = camera;
      ROS_INFO_STREAM("semantic_octomap_node: camera "
                      << params_.camera_index << " calibration from " << params_.calib_dir);
    }
    markers_pub_ = nh_.advertise<visualization_msgs::MarkerArray>(topics::kMapMarkers, 1, true);
    cloud_pub_ = nh_.advertise<sensor_msgs::PointCloud2>(topics::kLabeledCloud, 2);
    info_pub_ = nh_.advertise<std_msgs::String>(topics::kMapInfo, 1, true);
    camera_info_sub_ =
        nh_.subscribe(topics::kCameraColorLeftInfo, 1, &SemanticOctomapNode::onCameraInfo, this);
    // Labels arrive one segmentation latency after their scan: the synchronizer must hold
    // scans that long (sync_queue_size scans, 3 s at 10 Hz by default) or they never pair.
    cloud_sync_sub_.subscribe(nh_, topics::kVelodyne, 10);
    labels_sync_sub_.subscribe(nh_, topics::kSegmentationLabels, 10);
    sync_ = std::make_unique<Synchronizer>(SyncPolicy(params_.sync_queue_size), cloud_sync_sub_,
                                           labels_sync_sub_);
    sync_->setMaxIntervalDuration(ros::Duration(params_.sync_tolerance_s));
    sync_->registerCallback(&SemanticOctomapNode::onLabeledScan, this);
    labels_sub_ =
        nh_.subscribe(topics::kSegmentationLabels, 1, &SemanticOctomapNode::onLabelsSeen, this);
    if (params_.use_labels_without_image) {
      cloud_sub_ = nh_.subscribe(topics::kVelodyne, 2, &SemanticOctomapNode::onScanAlone, this);
    }
    save_srv_ = pnh_.advertiseService("save_map", &SemanticOctomapNode::onSaveMap, this);
    reset_srv_ = pnh_.advertiseService("reset", &SemanticOctomapNode::onReset, this);
    if (params_.marker_rate_hz > 0) {
      marker_timer_ = nh_.createWallTimer(ros::WallDuration(1.0 / params_.marker_rate_hz),
                                          &SemanticOctomapNode::publishMapDisplay, this);
    }
    log_timer_ = nh_.createWallTimer(ros::WallDuration(params_.log_period_s),
                                     &SemanticOctomapNode::logStatus, this);
    ROS_INFO_STREAM("semantic_octomap_node: resolution " << params_.resolution_m << " m, max range "
                                                         << params_.max_range_m << " m, classes "
                                                         << params_.class_set);
  }

 private:
  using SyncPolicy =
      message_filters::sync_policies::ApproximateTime<sensor_msgs::PointCloud2, sensor_msgs::Image>;
  using Synchronizer = message_filters::Synchronizer<SyncPolicy>;

  void resetTree() {
    tree_ = std::make_unique<SemanticOcTree>(params_.resolution_m,
                                             params_.class_set == "cityscapes"
                                                 ? mapping::ClassSet::cityscapes()
                                                 : mapping::ClassSet::semanticKitti(),
                                             params_.fusion);
    tree_->setProbHit(params_.prob_hit);
    tree_->setProbMiss(params_.prob_miss);
    tree_->setClampingThresMin(params_.clamping_min);
    tree_->setClampingThresMax(params_.clamping_max);
    tree_->setRayCastingThreads(params_.ray_casting_threads);
    tree_->setGrazingRayTruncation(params_.grazing_ray_truncation_voxels);
    scans_inserted_ = 0;
    map_changed_ = true;
  }

  void onCameraInfo(const sensor_msgs::CameraInfo& info) {
    Eigen::Matrix<double, 3, 4> P;
    for (int i = 0; i < 12; ++i) P(i / 4, i % 4) = info.P[i];
    if (!P.allFinite() || P(2, 2) == 0 || info.width == 0 || info.height == 0) {
      ROS_WARN_THROTTLE(10,
                        "semantic_octomap_node: ignoring camera_info with an invalid P or size");
      return;
    }
    camera_info_ = info;
  }

  void onLabelsSeen(const sensor_msgs::ImageConstPtr&) { last_labels_seen_ = ros::Time::now(); }

  // The projector for a label image: calibration files, or camera_info P (rectified image,
  // R = I) with the velodyne -> camera transform from tf (static).
  std::optional<perception::PointProjector> projectorFor(const std::string& velo_frame,
                                                         const sensor_msgs::Image& labels) {
    if (file_camera_) {
      return perception::PointProjector(file_camera_->P_rect, file_camera_->R_rect,
                                        file_camera_->T_cam0_velo, labels.width, labels.height);
    }
    if (!camera_info_) {
      ROS_WARN_THROTTLE(5, "semantic_octomap_node: no camera_info on %s yet: scan skipped",
                        topics::kCameraColorLeftInfo);
      return std::nullopt;
    }
    const std::string camera_frame =
        labels.header.frame_id.empty() ? camera_info_->header.frame_id : labels.header.frame_id;
    Eigen::Isometry3d T_camera_velo;
    try {
      T_camera_velo =
          tf2::transformToEigen(tf_buffer_.lookupTransform(camera_frame, velo_frame, ros::Time(0)));
    } catch (const tf2::TransformException& e) {
      ROS_WARN_THROTTLE(5, "semantic_octomap_node: no tf %s -> %s: %s; scan skipped",
                        velo_frame.c_str(), camera_frame.c_str(), e.what());
      return std::nullopt;
    }
    if (camera_info_->width != labels.width || camera_info_->height != labels.height) {
      ROS_WARN_THROTTLE(10, "semantic_octomap_node: label image %ux%u but camera_info %ux%u",
                        labels.width, labels.height, camera_info_->width, camera_info_->height);
    }
    Eigen::Matrix<double, 3, 4> P;
    for (int i = 0; i < 12; ++i) P(i / 4, i % 4) = camera_info_->P[i];
    return perception::PointProjector(P, Eigen::Matrix3d::Identity(), T_camera_velo, labels.width,
                                      labels.height);
  }

  // Pose of the cloud's frame in the map at the scan time; nullopt (and a warning) if unknown.
  std::optional<Eigen::Isometry3d> poseAt(const std_msgs::Header& header) {
    // A bag loop shows as the clock jumping back. Scan stamps are no guide: a labeled pair can
    // legitimately be older than the last lidar-only scan when segmentation lags.
    const ros::Time now = ros::Time::now();
    if (!last_clock_.isZero() && now + ros::Duration(1.0) < last_clock_) {
      ROS_WARN_STREAM("semantic_octomap_node: clock jumped back (" << last_clock_ << " -> " << now
                                                                   << "): clearing the tf buffer");
      tf_buffer_.clear();
    }
    last_clock_ = now;
    // Wait in wall time: under a paused or stopped /clock a sim-time timeout never expires and
    // would block this callback (and the services queued behind it) forever.
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(params_.tf_timeout_s);
    while (ros::ok() && ros::WallTime::now() < deadline &&
           !tf_buffer_.canTransform(params_.map_frame, header.frame_id, header.stamp)) {
      ros::WallDuration(0.005).sleep();
    }
    try {
      return tf2::transformToEigen(
          tf_buffer_.lookupTransform(params_.map_frame, header.frame_id, header.stamp));
    } catch (const tf2::TransformException& e) {
      ROS_WARN_THROTTLE(5, "semantic_octomap_node: no pose %s -> %s at %.3f: %s; scan skipped",
                        params_.map_frame.c_str(), header.frame_id.c_str(), header.stamp.toSec(),
                        e.what());
      return std::nullopt;
    }
  }

  static Eigen::Matrix3Xf cloudPoints(const sensor_msgs::PointCloud2& cloud) {
    Eigen::Matrix3Xf points(3, static_cast<Eigen::Index>(cloud.width * cloud.height));
    sensor_msgs::PointCloud2ConstIterator<float> x(cloud, "x"), y(cloud, "y"), z(cloud, "z");
    for (Eigen::Index i = 0; i < points.cols(); ++i, ++x, ++y, ++z) points.col(i) << *x, *y, *z;
    return points;
  }

  void onLabeledScan(const sensor_msgs::PointCloud2ConstPtr& cloud,
                     const sensor_msgs::ImageConstPtr& labels) {
    try {
      ScopedTimer timer("semantic_map/total");
      if (labels->encoding != sensor_msgs::image_encodings::MONO8 &&
          labels->encoding != sensor_msgs::image_encodings::TYPE_8UC1) {
        ROS_WARN_THROTTLE(10, "semantic_octomap_node: labels must be mono8, got '%s'",
                          labels->encoding.c_str());
        return;
      }
      if (labels->step < labels->width || labels->data.size() < labels->step * labels->height) {
        ROS_WARN_THROTTLE(10, "semantic_octomap_node: malformed label image (step/size)");
        return;
      }
      const std::optional<Eigen::Isometry3d> pose = poseAt(cloud->header);
      if (!pose) return;
      std::optional<perception::PointProjector> projector =
          projectorFor(cloud->header.frame_id, *labels);
      if (!projector) return;
      mapping::LabeledScan scan;
      Eigen::Matrix3Xf points_sensor;
      {
        ScopedTimer stage("semantic_map/convert");
        points_sensor = cloudPoints(*cloud);
      }
      {
        ScopedTimer stage("semantic_map/project_label");
        perception::ProjectedPoints projected;
        projector->project(points_sensor, &projected);
        perception::labelPointsFromImage(projected, labels->data.data(), labels->width,
                                         labels->height, labels->step, kNoLabel, &scan.label_ids);
      }
      if (!params_.insert_points_outside_image) {
        // Only what the camera saw: ~5x less ray casting, and no unlabeled voxels around the
        // car that would never get a class.
        Eigen::Index kept = 0;
        for (Eigen::Index i = 0; i < points_sensor.cols(); ++i) {
          if (scan.label_ids[i] == kNoLabel) continue;
          points_sensor.col(kept) = points_sensor.col(i);
          scan.label_ids[kept] = scan.label_ids[i];
          ++kept;
        }
        points_sensor.conservativeResize(3, kept);
        scan.label_ids.resize(static_cast<std::size_t>(kept));
      }
      insert(std::move(points_sensor), std::move(scan), *pose, cloud->header);
    } catch (const std::exception& e) {
      ROS_ERROR_STREAM_THROTTLE(5, "semantic_octomap_node: labeled scan at "
                                       << cloud->header.stamp << " failed: " << e.what());
    }
  }

  // Scans that no label image will come for: occupancy only (lidar-only runs).
  void onScanAlone(const sensor_msgs::PointCloud2ConstPtr& cloud) {
    if (!last_labels_seen_.isZero() &&
        (ros::Time::now() - last_labels_seen_).toSec() < params_.labels_timeout_s) {
      return;  // segmentation is running: the synchronized callback handles this scan
    }
    try {
      ScopedTimer timer("semantic_map/total_unlabeled");
      const std::optional<Eigen::Isometry3d> pose = poseAt(cloud->header);
      if (!pose) return;
      insert(cloudPoints(*cloud), mapping::LabeledScan(), *pose, cloud->header);
    } catch (const std::exception& e) {
      ROS_ERROR_STREAM_THROTTLE(
          5, "semantic_octomap_node: scan at " << cloud->header.stamp << " failed: " << e.what());
    }
  }

  void insert(Eigen::Matrix3Xf points_sensor, mapping::LabeledScan scan,
              const Eigen::Isometry3d& T_map_sensor, const std_msgs::Header& header) {
    {
      ScopedTimer stage("semantic_map/transform");
      const Eigen::Matrix3f rotation = T_map_sensor.linear().cast<float>();
      const Eigen::Vector3f translation = T_map_sensor.translation().cast<float>();
      scan.points_map = (rotation * points_sensor).colwise() + translation;
      scan.sensor_origin_map = translation;
      scan.unknown_label_id = kNoLabel;
    }
    {
      ScopedTimer stage("semantic_map/insert");
      tree_->insertLabeledScan(scan, params_.max_range_m);
    }
    ++scans_inserted_;
    map_changed_ = true;
    if (cloud_pub_.getNumSubscribers() > 0) {
      ScopedTimer stage("semantic_map/publish_cloud");
      publishLabeledCloud(scan, header.stamp);
    }
  }

  void publishLabeledCloud(const mapping::LabeledScan& scan, const ros::Time& stamp) {
    sensor_msgs::PointCloud2 out;
    out.header.stamp = stamp;
    out.header.frame_id = params_.map_frame;
    sensor_msgs::PointCloud2Modifier modifier(out);
    modifier.setPointCloud2Fields(
        5, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1, sensor_msgs::PointField::FLOAT32, "z",
        1, sensor_msgs::PointField::FLOAT32, "rgb", 1, sensor_msgs::PointField::FLOAT32, "label", 1,
        sensor_msgs::PointField::UINT32);
    const std::size_t n = static_cast<std::size_t>(scan.points_map.cols());
    modifier.resize(n);
    sensor_msgs::PointCloud2Iterator<float> x(out, "x"), y(out, "y"), z(out, "z"), rgb(out, "rgb");
    sensor_msgs::PointCloud2Iterator<std::uint32_t> label(out, "label");
    const mapping::ClassSet& classes = tree_->classSet();
    for (std::size_t i = 0; i < n; ++i, ++x, ++y, ++z, ++rgb, ++label) {
      *x = scan.points_map(0, i);
      *y = scan.points_map(1, i);
      *z = scan.points_map(2, i);
      const std::uint32_t id = scan.label_ids.empty() ? kNoLabel : scan.label_ids[i];
      const ClassIndex index = id == kNoLabel ? mapping::kNoClass : classes.indexOf(id);
      std::uint32_t packed = 0x808080;  // grey: no label
      if (index != mapping::kNoClass) {
        const auto& c = classes.info(index).rgb;
        packed = (std::uint32_t{c[0]} << 16) | (std::uint32_t{c[1]} << 8) | c[2];
      }
      std::memcpy(&*rgb, &packed, sizeof(float));
      *label = id;
    }
    cloud_pub_.publish(out);
  }

  void publishMapDisplay(const ros::WallTimerEvent&) {
    if (!map_changed_) return;
    // Nobody watching: build nothing. map_changed_ stays set, so a display that subscribes
    // later gets the map at the next tick.
    if (markers_pub_.getNumSubscribers() == 0 && info_pub_.getNumSubscribers() == 0) return;
    // The display walks the whole map, so its cost grows with the drive (0.25 s after 30 s of
    // an HDL-64) and it runs on the thread that inserts scans: stretch the period so that it
    // takes at most max_display_cpu_fraction of the time.
    const ros::WallTime start = ros::WallTime::now();
    if (params_.max_display_cpu_fraction > 0 && !last_display_start_.isZero() &&
        (start - last_display_start_).toSec() <
            last_display_cost_s_ / params_.max_display_cpu_fraction) {
      return;
    }
    map_changed_ = false;
    ScopedTimer stage("semantic_map/markers");
    publishMarkersAndInfo();
    last_display_start_ = start;
    last_display_cost_s_ = (ros::WallTime::now() - start).toSec();
  }

  void publishMarkersAndInfo() {
    tree_->updateInnerOccupancy();
    const unsigned int depth = static_cast<unsigned int>(std::clamp(params_.marker_depth, 1, 16));
    const double size = tree_->getNodeSize(depth);
    const mapping::ClassSet& classes = tree_->classSet();
    std::map<int, visualization_msgs::Marker> by_class;  // class index (-1: none) -> cube list
    std::map<int, std::size_t> finest_counts;
    for (auto it = tree_->begin_leafs(depth), end = tree_->end_leafs(); it != end; ++it) {
      if (!tree_->isNodeOccupied(*it)) continue;
      const ClassIndex index = it->mostLikelyClass();
      const int key = index == mapping::kNoClass ? -1 : index;
      visualization_msgs::Marker& marker = by_class[key];
      geometry_msgs::Point p;
      p.x = it.getX();
      p.y = it.getY();
      p.z = it.getZ();
      marker.points.push_back(p);
    }
    visualization_msgs::MarkerArray array;
    visualization_msgs::Marker clear;
    clear.action = visualization_msgs::Marker::DELETEALL;
    array.markers.push_back(clear);
    const ros::Time now = ros::Time::now();
    for (auto& [key, marker] : by_class) {
      marker.header.frame_id = params_.map_frame;
      marker.header.stamp = now;
      marker.ns = key < 0 ? "unlabeled" : classes.info(static_cast<ClassIndex>(key)).name;
      marker.id = key;
      marker.type = visualization_msgs::Marker::CUBE_LIST;
      marker.action = visualization_msgs::Marker::ADD;
      marker.pose.orientation.w = 1.0;
      marker.scale.x = marker.scale.y = marker.scale.z = size;
      marker.color.a = 1.0;
      if (key < 0) {
        marker.color.r = marker.color.g = marker.color.b = 0.5;
      } else {
        const auto& c = classes.info(static_cast<ClassIndex>(key)).rgb;
        marker.color.r = c[0] / 255.0;
        marker.color.g = c[1] / 255.0;
        marker.color.b = c[2] / 255.0;
      }
      array.markers.push_back(marker);
    }
    markers_pub_.publish(array);

    // Map size and per-class voxel counts (finest resolution), as JSON.
    std::map<std::string, std::size_t> class_voxels;
    std::size_t occupied = 0;
    const unsigned int max_depth = tree_->getTreeDepth();
    for (auto it = tree_->begin_leafs(), end = tree_->end_leafs(); it != end; ++it) {
      if (!tree_->isNodeOccupied(*it)) continue;
      const std::size_t cells = std::size_t{1} << (3 * (max_depth - it.getDepth()));
      occupied += cells;
      const ClassIndex index = it->mostLikelyClass();
      class_voxels[index == mapping::kNoClass ? "unlabeled" : classes.info(index).name] += cells;
    }
    std::ostringstream json;
    json << "{\"scans\": " << scans_inserted_ << ", \"nodes\": " << tree_->size()
         << ", \"occupied_voxels\": " << occupied << ", \"resolution\": " << params_.resolution_m
         << ", \"memory_bytes\": " << tree_->memoryUsage() << ", \"classes\": {";
    bool first = true;
    for (const auto& [name, count] : class_voxels) {
      json << (first ? "" : ", ") << "\"" << name << "\": " << count;
      first = false;
    }
    json << "}}";
    std_msgs::String info;
    info.data = json.str();
    info_pub_.publish(info);
  }

  bool onSaveMap(SaveMap::Request& request, SaveMap::Response& response) {
    try {
      ScopedTimer stage("semantic_map/save");
      const mapping::MapFormat format = mapping::parseMapFormat(request.format, request.path);
      response.voxel_count = mapping::saveMap(*tree_, request.path, format);
      response.success = true;
      response.message = "wrote " + request.path + " (" + std::to_string(response.voxel_count) +
                         " occupied voxels, " + std::to_string(scans_inserted_) + " scans)";
      ROS_INFO_STREAM("semantic_octomap_node: " << response.message);
    } catch (const std::exception& e) {
      response.success = false;
      response.voxel_count = 0;
      response.message = e.what();
      ROS_ERROR_STREAM("semantic_octomap_node: save_map failed: " << e.what());
    }
    return true;  // the failure is in the response, the node keeps running
  }

  bool onReset(std_srvs::Empty::Request&, std_srvs::Empty::Response&) {
    resetTree();
    ROS_INFO("semantic_octomap_node: map reset");
    return true;
  }

  void logStatus(const ros::WallTimerEvent&) {
    const auto stats = TimingRegistry::instance().snapshot();
    const auto it = stats.find("semantic_map/total");
    ROS_INFO("semantic_octomap_node: %zu scans, %zu nodes, %.1f MB, labeled scan mean %.1f ms",
             scans_inserted_, tree_->size(), tree_->memoryUsage() / 1e6,
             it == stats.end() ? 0.0 : 1e3 * it->second.meanSeconds());
  }

  ros::NodeHandle nh_, pnh_;
  NodeParameters params_;
  tf2_ros::Buffer tf_buffer_;
  tf2_ros::TransformListener tf_listener_;
  std::unique_ptr<SemanticOcTree> tree_;
  std::optional<kitti::CameraProjection> file_camera_;
  std::optional<sensor_msgs::CameraInfo> camera_info_;
  message_filters::Subscriber<sensor_msgs::PointCloud2> cloud_sync_sub_;
  message_filters::Subscriber<sensor_msgs::Image> labels_sync_sub_;
  std::unique_ptr<Synchronizer> sync_;
  ros::Subscriber camera_info_sub_, labels_sub_, cloud_sub_;
  ros::Publisher markers_pub_, cloud_pub_, info_pub_;
  ros::ServiceServer save_srv_, reset_srv_;
  ros::WallTimer marker_timer_, log_timer_;
  ros::WallTime last_display_start_;
  double last_display_cost_s_ = 0.0;
  ros::Time last_labels_seen_, last_clock_;
  std::size_t scans_inserted_ = 0;
  bool map_changed_ = true;
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
