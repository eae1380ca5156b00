// The map node's work, shared by semantic_octomap_node and the map nodelet
// (see ros/semantic_octomap_node_core.h).
#include "inekf_semantic_mapping/ros/semantic_octomap_node_core.h"

#include <ros/ros.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <cmath>
#include <filesystem>
#include <iomanip>
#include <memory>
#include <optional>
#include <sstream>
#include <string>

#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/ros/label_camera.h"
#include "inekf_semantic_mapping/ros/map_display.h"
#include "inekf_semantic_mapping/ros/map_services.h"
#include "inekf_semantic_mapping/ros/mapping_conversions.h"
#include "inekf_semantic_mapping/ros/mapping_diagnostics.h"
#include "inekf_semantic_mapping/ros/names.h"
#include "inekf_semantic_mapping/ros/node_parameters.h"
#include "inekf_semantic_mapping/ros/shutdown_log.h"

namespace inekf_semantic_mapping {
namespace ros_conversions {
namespace {

// A scan this far from the clock is not late or early: the clock is another time than the data's
// (a working pipeline's scans arrive within seconds of their stamps).
constexpr double kClockMismatchWarnS = 60.0;
// Wall seconds without the clock moving after which scans stop waiting for their label images:
// at the end of a bag (or while it is paused) data time stands still and would hold the last
// second of scans out of the map, and out of a save_map, until shutdown.
constexpr double kClockStoppedInsertS = 2.0;

// The node's own keys (display, frames, calibration); the rest belong to the session.
struct NodeOptions {
  MapDisplayOptions display{frames::kMap};
  double marker_rate_hz = 1.0;
  std::string calib_dir;
  int camera_index = 2;
  std::string map_file;  // loaded at start when set
  // Where the localization says its map frame lies on the Earth (lat, lon, alt under it):
  // inekf_node's. Saved with the map; a resumed map saved under another origin takes no scans.
  std::string map_origin_param = "inekf_node/map_origin_in_use";
  std::string autosave_path;  // saved every autosave_period and at shutdown when set
  double autosave_period_s = 30.0;
  double log_period_s = 10.0;
  MappingDiagnosticsOptions diagnostics;
};

}  // namespace

class SemanticOctomapNodeCore::Impl {
 public:
  Impl(ros::NodeHandle nh, ros::NodeHandle pnh) : nh_(nh), pnh_(pnh) {
    const YAML::Node parameters = privateParametersAsYaml(pnh_);
    const std::string source = parameterSource(pnh_);
    common::YamlReader reader(source, parameters);
    // The node's own keys, renamed ones under their old names too (the session's reader only
    // lets them through), each checked as the session's keys are.
    reader.renamed("marker_rate", "marker_rate_hz");
    reader.renamed("autosave_period", "autosave_period_s");
    reader.renamed("log_period", "log_period_s");
    reader.read("map_frame", &options_.display.map_frame);
    reader.readInRange("marker_rate_hz", &options_.marker_rate_hz, 0.0, 1000.0);  // 0: off
    reader.readInRange("max_display_cpu_fraction", &options_.display.max_display_cpu_fraction, 0.0,
                       1.0);
    reader.readInRange("marker_depth", &options_.display.marker_depth, 1, 16);
    reader.read("calib_dir", &options_.calib_dir);
    reader.readInRange("camera_index", &options_.camera_index, 0, 3);
    reader.read("map_file", &options_.map_file);
    reader.read("map_origin_param", &options_.map_origin_param);
    reader.read("autosave_path", &options_.autosave_path);
    if (!options_.autosave_path.empty()) {
      // Checked now: a mistyped folder was found at the end, when the whole map was lost.
      options_.autosave_path = std::filesystem::absolute(options_.autosave_path).string();
      try {
        common::checkOutputPath(options_.autosave_path);
      } catch (const std::exception& e) {
        reader.fail("autosave_path", e.what());
      }
    }
    reader.read("autosave_period_s", &options_.autosave_period_s);  // <= 0: at shutdown only
    reader.readInRange("log_period_s", &options_.log_period_s, 0.0, 1e6, true);
    const YAML::Node& all = parameters;  // const: operator[] must not add the key
    common::YamlReader diagnostics_reader(source + ", diagnostics", all["diagnostics"]);
    readMappingDiagnosticsOptions(&diagnostics_reader, &options_.diagnostics);
    diagnostics_reader.rejectUnknown();
    monitor_ = std::make_unique<MappingMonitor>(options_.diagnostics);
    session_ = std::make_unique<mapping::SemanticMappingSession>(
        mapping::readSemanticMappingConfig(parameters, source));
    display_ = std::make_unique<MapDisplay>(nh_, *session_, options_.display,
                                            mapping::readGridProjectionConfig(parameters, source));
    session_->setPoseLookup([this](double stamp, const std::string& frame) {
      const std::string& map = options_.display.map_frame;
      std::optional<Eigen::Isometry3d> pose;
      std::string why;
      if (tf_buffer_.canTransform(map, frame, ros::Time(stamp), &why)) {
        pose = tf2::transformToEigen(tf_buffer_.lookupTransform(map, frame, ros::Time(stamp)));
      } else if (!session_->lookingUpAhead()) {
        last_pose_error_ = map + " -> " + frame + " at " + std::to_string(stamp) + ": " + why;
      }
      return pose;
    });
    session_->setScanWarningCallback([this](double stamp, const std::string& why) {
      ROS_ERROR_STREAM_THROTTLE(5, "semantic_octomap_node: " << cloudTopic() << " at "
                                                             << ros::Time(stamp)
                                                             << " not mapped: " << why);
    });
    session_->setInsertedCallback([this](double stamp, const mapping::LabeledScan& scan,
                                         mapping::SemanticMappingSession::MapUpdate update) {
      if (update == mapping::SemanticMappingSession::MapUpdate::kScanInserted) {
        monitor_->noteInserted(stamp, wallNow());
        display_->scanInserted(scan);
      } else {
        display_->classesChanged();  // the same voxels, new class evidence: no ground sample
      }
      // Not after ROS has shut down (the scans flushed at shutdown): the publisher is invalid.
      if (!cloud_pub_ || cloud_pub_.getNumSubscribers() == 0) return;
      cloud_pub_.publish(labeledCloudMessage(scan, session_->classSet(), options_.display.map_frame,
                                             ros::Time(stamp)));
    });
    if (!options_.map_file.empty()) {
      session_->load(options_.map_file);
      ROS_INFO_STREAM("semantic_octomap_node: resumed from "
                      << options_.map_file << " (" << session_->tree().size() << " nodes)");
    }
    std::optional<mapping::CameraModel> file_camera;
    std::string file_camera_source;
    if (!options_.calib_dir.empty()) {
      const kitti::CameraProjection c =
          kitti::readRawCalibration(options_.calib_dir).projection(options_.camera_index);
      file_camera = mapping::CameraModel{c.P_rect, c.R_rect, c.T_cam0_velo, c.width, c.height};
      file_camera_source = options_.calib_dir + "/calib_cam_to_cam.txt (camera " +
                           std::to_string(options_.camera_index) + ")";
    }
    label_camera_ = std::make_unique<LabelCamera>(tf_buffer_, file_camera, file_camera_source);
    label_camera_->serve(session_.get());
    cloud_pub_ = nh_.advertise<sensor_msgs::PointCloud2>(topics::kLabeledCloud, 2);
    camera_info_sub_ = nh_.subscribe(topics::kCameraColorLeftInfo, 1, &LabelCamera::setCameraInfo,
                                     label_camera_.get());
    // Room for what arrives while a batch of waiting scans goes in: on a loaded machine a dropped
    // label image leaves its scan without classes (with 5 here most scans of e2e_synthetic were).
    constexpr int kInputQueue = 30;
    cloud_sub_ = nh_.subscribe(topics::kVelodyne, kInputQueue, &Impl::onCloud, this);
    labels_sub_ = nh_.subscribe(topics::kSegmentationLabels, kInputQueue, &Impl::onLabels, this);
    services_ = std::make_unique<MapServices>(nh_, pnh_, *session_, *display_,
                                              options_.autosave_path, options_.autosave_period_s);
    services_->setMapReplacedCallback([this] {
      origin_decided_ = false;  // the new map's origin (or none) is checked at the next scan
      last_origin_query_ = ros::WallTime();
    });
    // Pending scans go in when their wait is over, also after the last message of a bag.
    clock_timer_ = nh_.createWallTimer(ros::WallDuration(0.1), &Impl::onTick, this);
    if (options_.marker_rate_hz > 0) {
      display_timer_ =
          nh_.createWallTimer(ros::WallDuration(1.0 / options_.marker_rate_hz),
                              [this](const ros::WallTimerEvent&) { display_->update(); });
    }
    log_timer_ = nh_.createWallTimer(ros::WallDuration(options_.log_period_s), [this](auto&) {
      ROS_INFO_STREAM("semantic_octomap_node: " << mappingStatusLine(*session_));
    });
    diagnostics_ = std::make_unique<NodeDiagnostics>(nh_, pnh_);
    diagnostics_->add("map", [this](auto& status) {
      monitor_->fillMap(*session_, services_->lastSave(), services_->lastAutosave(), wallNow(),
                        &status);
    });
    diagnostics_->add("labels", [this](auto& status) {
      const bool expected =
          labels_sub_.getNumPublishers() > 0 || session_->statistics().label_images_received > 0;
      monitor_->fillLabels(*session_, expected, wallNow(), &status);
    });
    const mapping::SemanticMappingConfig& c = session_->config();
    ROS_INFO_STREAM("semantic_octomap_node: resolution "
                    << c.resolution_m << " m, max range " << c.max_range_m << " m, classes "
                    << mapping::mapClassSetName(c.class_set) << ", label wait " << c.label_wait_s
                    << " s");
  }

  ~Impl() { finish(); }

  // Once: the scans still waiting for their label image go into the map with what has arrived,
  // then the final autosave. At the end of a bag the clock stops and they would wait forever:
  // without this the saved map missed up to label_wait_s of the last scans.
  void finish() {
    if (finished_) return;
    finished_ = true;
    try {
      const std::size_t pending = session_->pendingScans();
      if (pending > 0) {
        const std::size_t without_pose = session_->statistics().scans_without_pose;
        const std::size_t inserted = session_->flush();
        const std::size_t no_pose = session_->statistics().scans_without_pose - without_pose;
        logAtShutdown(ShutdownLogLevel::kInfo,
                      "semantic_octomap_node: finishing: " + std::to_string(inserted) + " of " +
                          std::to_string(pending) + " waiting scans put in the map" +
                          (no_pose > 0 ? " (" + std::to_string(no_pose) +
                                             " without a pose in tf: none was published for "
                                             "their stamps)"
                                       : ""));
      }
    } catch (const std::exception& e) {
      logAtShutdown(
          ShutdownLogLevel::kError,
          std::string("semantic_octomap_node: finishing: the waiting scans are lost: ") + e.what());
    }
    services_->finalAutosave();
  }

 private:
  // The cloud topic as resolved (remapped, in a namespace): the name a user looks for.
  std::string cloudTopic() const {
    return cloud_sub_ ? cloud_sub_.getTopic() : std::string(topics::kVelodyne);
  }

  void onCloud(const sensor_msgs::PointCloud2ConstPtr& cloud) {
    try {
      ScopedTimer timer("semantic_map/scan");
      detectClockJump();
      warnIfOffTheClock(cloud->header.stamp);
      monitor_->noteScan(cloud->header.stamp.toSec(), wallNow());
      // A leading slash ("/velo_link"): every scan was dropped "without a pose".
      const std::string frame = frames::tfFrameId(cloud->header.frame_id);
      if (frame.empty()) throw std::invalid_argument("no frame_id: its pose in tf needs one");
      label_camera_->setLidarFrame(frame);
      if (!session_->hasCameraView()) label_camera_->setCameraViewOf(*session_);
      checkGeodeticOrigin();
      session_->addScan(cloud->header.stamp.toSec(), frame, pointsFromCloud(*cloud));
    } catch (const std::exception& e) {
      monitor_->noteScanRefused(wallNow(), e.what());
      ROS_ERROR_STREAM_THROTTLE(5, "semantic_octomap_node: " << cloudTopic() << " at "
                                                             << cloud->header.stamp
                                                             << " ignored: " << e.what());
    }
  }

  // Once the localization has published its map origin: the map takes it, or (a resumed map
  // saved under another one) refuses scans until it is reset or replaced.
  void checkGeodeticOrigin() {
    if (origin_decided_ || options_.map_origin_param.empty()) return;
    // Asked of the master (a cached value lagged a change made just before a ~load_map) until it
    // is there: at each scan for a map that has an origin to check (the scans waiting meanwhile
    // would go in under the other one), else at most once a second.
    const ros::WallTime now = ros::WallTime::now();
    if (!session_->geodeticOrigin() && !last_origin_query_.isZero() &&
        (now - last_origin_query_).toSec() < 1.0) {
      return;
    }
    last_origin_query_ = now;
    mapping::GeodeticOrigin origin;
    const std::string& param = options_.map_origin_param;
    if (!(nh_.getParam(param + "/lat", origin.lat_deg) &&
          nh_.getParam(param + "/lon", origin.lon_deg) &&
          nh_.getParam(param + "/alt", origin.alt_m))) {
      return;  // not yet (or another localization): the map keeps what it has
    }
    origin_decided_ = true;
    const std::string refusal = session_->agreeOnGeodeticOrigin(origin);
    if (!refusal.empty()) {
      ROS_ERROR_STREAM("semantic_octomap_node: scans are not mapped: " << refusal << " (" << param
                                                                       << ")");
    } else if (session_->geodeticOrigin()) {
      const mapping::GeodeticOrigin& in_map = *session_->geodeticOrigin();
      ROS_INFO_STREAM(std::setprecision(10)
                      << "semantic_octomap_node: map frame at lat " << in_map.lat_deg << ", lon "
                      << in_map.lon_deg << ", alt " << in_map.alt_m << " (" << param
                      << "), saved with the map");
    }
  }

  void onLabels(const sensor_msgs::ImageConstPtr& labels) {
    monitor_->noteLabelImage(wallNow());
    try {
      ScopedTimer timer("semantic_map/labels");
      mapping::LabelImageView view;
      try {
        view = labelImageView(*labels);
      } catch (const std::exception&) {
        session_->noteLabelImageRefused();  // counted: it came, and the map could not read it
        throw;
      }
      // Checked as it comes (a malformed image is reported now, naming the field); the session
      // keeps it until its scan and its camera are there.
      session_->addLabelImage(labels->header.stamp.toSec(), view, labels->header.frame_id);
    } catch (const std::exception& e) {
      ROS_ERROR_STREAM_THROTTLE(5, "semantic_octomap_node: " << topics::kSegmentationLabels
                                                             << " at " << labels->header.stamp
                                                             << " ignored: " << e.what());
    }
  }

  void onTick(const ros::WallTimerEvent&) {
    try {
      detectClockJump();
      const ros::Time now = ros::Time::now();
      session_->advanceTo(now.toSec());
      insertIfClockStopped(now);
      warnOfDroppedInputs();
    } catch (const std::exception& e) {
      ROS_ERROR_STREAM_THROTTLE(5, "semantic_octomap_node: inserting pending scans: " << e.what());
    }
  }

  // Scans dropped without a pose, and label images that matched no scan, were only counted (a
  // number in the 10 s status line): said with what tf or the stamps gave, every 10 s at most.
  void warnOfDroppedInputs() {
    const double wall_s = wallNow();
    if (wall_s - dropped_warned_wall_s_ < 10.0) return;
    const mapping::MappingStatistics& s = session_->statistics();
    // Each count is said, with what `say` writes, when it has grown since it was last said.
    const auto warnIfGrew = [&](std::size_t count, std::size_t* said, auto say) {
      if (count <= *said) return;
      std::ostringstream text;
      say(text, count - *said);
      ROS_WARN_STREAM("semantic_octomap_node: " << text.str());
      *said = count;
      dropped_warned_wall_s_ = wall_s;
    };
    warnIfGrew(s.scans_without_pose, &scans_without_pose_warned_,
               [&](std::ostream& out, std::size_t more) {
                 out << more << " scans on " << cloudTopic() << " dropped without a pose ("
                     << s.scans_without_pose << " of " << s.scans_received
                     << " so far); the last tf lookup that failed: " << last_pose_error_;
               });
    if (mostLabelImagesUnmatched(s)) {
      warnIfGrew(s.label_images_unmatched, &label_images_unmatched_warned_,
                 [&](std::ostream& out, std::size_t) {
                   out << s.label_images_unmatched << " of " << s.label_images_received
                       << " label images on " << topics::kSegmentationLabels
                       << " matched no scan: each needs a scan within label_stamp_tolerance_s ("
                       << session_->config().label_stamp_tolerance_s
                       << " s) of its stamp (label images keep their camera image's stamp)";
                 });
    }
    warnIfGrew(s.label_images_with_unknown_ids, &unknown_ids_warned_,
               [&](std::ostream& out, std::size_t) {
                 out << s.label_images_with_unknown_ids << " of " << s.label_images_received
                     << " label images on " << topics::kSegmentationLabels
                     << " hold ids the map's class set ("
                     << mapping::mapClassSetName(session_->config().class_set)
                     << ") does not know, e.g. " << s.last_unknown_label_id
                     << ": those pixels give no class evidence (labels of another id scheme? "
                        "~class_set)";
               });
  }

  void insertIfClockStopped(const ros::Time& now) {
    const double wall_s = wallNow();
    if (now != clock_at_last_move_) {
      clock_at_last_move_ = now;
      clock_moved_wall_s_ = wall_s;
      return;
    }
    if (wall_s - clock_moved_wall_s_ < kClockStoppedInsertS || session_->pendingScans() == 0) {
      return;
    }
    const std::size_t waiting = session_->pendingScans();
    const std::size_t inserted = session_->insertWithoutWaiting();
    if (inserted == 0) return;  // they wait for their pose (the map diagnostics say so)
    if (now.isZero()) {
      // Scans come and the clock never started: said for what it is (it read "the clock has
      // stood at 0 for 1796613641 s (the bag ended or is paused)", ten times a second).
      ROS_WARN_STREAM_THROTTLE(
          10,
          "semantic_octomap_node: use_sim_time is true and no /clock has come while scans "
          "do (a bag played without --clock?): scans go in without waiting for their label "
          "images ("
              << inserted << " of " << waiting << " now)");
      return;
    }
    ROS_INFO_STREAM_THROTTLE(10, "semantic_octomap_node: the clock has stood at "
                                     << now << " for " << std::fixed << std::setprecision(1)
                                     << wall_s - clock_moved_wall_s_
                                     << " s (the bag ended or is paused): " << inserted << " of "
                                     << waiting
                                     << " waiting scans put in the map without waiting longer "
                                        "for their label images (one that still comes is added "
                                        "to its scan)");
  }

  // Scans are matched to tf and label images as the clock passes them: a clock that is not the
  // data's time drops every scan as "without pose" and nothing said why. A bag recorded from a
  // replay and played with --clock gives its record time, years after the stamps.
  void warnIfOffTheClock(const ros::Time& stamp) {
    const ros::Time now = ros::Time::now();
    if (now.isZero()) return;  // sim time before the first /clock
    const double offset_s = (now - stamp).toSec();
    if (std::abs(offset_s) < kClockMismatchWarnS) return;
    ROS_WARN_STREAM_THROTTLE(
        10, "semantic_octomap_node: " << cloudTopic() << " stamped " << stamp << " is "
                                      << std::fixed << std::setprecision(1) << std::abs(offset_s)
                                      << " s " << (offset_s > 0 ? "behind" : "ahead of")
                                      << " the clock (" << now
                                      << "): the clock is not the data's time (a bag played with "
                                         "--clock gives its record time: a bag recorded from a "
                                         "replay is years after its stamps; kitti2bag writes a "
                                         "drive's bag at its own time). Its scans cannot be "
                                         "matched to tf and are dropped");
  }

  // A bag loop shows as the clock jumping back: the pending scans go in with the poses tf still
  // has, then tf forgets the old timeline.
  void detectClockJump() {
    const ros::Time now = ros::Time::now();
    if (!last_clock_.isZero() && now + ros::Duration(1.0) < last_clock_) {
      ROS_WARN_STREAM("semantic_octomap_node: clock jumped back ("
                      << last_clock_ << " -> " << now
                      << "): the scans waiting go in with the poses they have");
      // tf's listener clears its buffer itself at the jump. Clearing it again here, later (this
      // node may be busy), wiped the new timeline's first transforms: under load a quarter of a
      // looping bag's scans were dropped without a pose.
      session_->flush();
    }
    last_clock_ = now;
  }

  ros::NodeHandle nh_, pnh_;
  std::string last_pose_error_;  // the last tf lookup that failed, for the warning
  std::size_t scans_without_pose_warned_ = 0, label_images_unmatched_warned_ = 0;
  std::size_t unknown_ids_warned_ = 0;
  double dropped_warned_wall_s_ = -1e9;
  ros::Time clock_at_last_move_;
  double clock_moved_wall_s_ = 0.0;
  NodeOptions options_;
  tf2_ros::Buffer tf_buffer_;
  tf2_ros::TransformListener tf_listener_{tf_buffer_, nh_};  // nh_: the node's tf remapping
  std::unique_ptr<MappingMonitor> monitor_;  // before the session: its callback notes
  std::unique_ptr<mapping::SemanticMappingSession> session_;
  std::unique_ptr<MapDisplay> display_;
  std::unique_ptr<LabelCamera> label_camera_;
  ros::Subscriber camera_info_sub_, cloud_sub_, labels_sub_;
  ros::Publisher cloud_pub_;
  std::unique_ptr<MapServices> services_;
  bool origin_decided_ = false;
  ros::WallTime last_origin_query_;
  std::unique_ptr<NodeDiagnostics> diagnostics_;
  ros::WallTimer clock_timer_, display_timer_, log_timer_;
  ros::Time last_clock_;
  bool finished_ = false;
};

SemanticOctomapNodeCore::SemanticOctomapNodeCore(ros::NodeHandle nh, ros::NodeHandle private_nh)
    : impl_(std::make_unique<Impl>(nh, private_nh)) {}

SemanticOctomapNodeCore::~SemanticOctomapNodeCore() = default;

void SemanticOctomapNodeCore::finish() { impl_->finish(); }

}  // namespace ros_conversions
}  // namespace inekf_semantic_mapping
