// SemanticMappingSession: the whole semantic-mapping pipeline of one run, ROS-free. The
// semantic_octomap_node and semantic_map_offline are two faces of it (cartographer's
// Node / offline_node split): they convert their inputs and call it, and it owns the policy —
// tree construction from one config, pairing scans with label images by stamp, projection and
// the label rules, the map-frame transform, statistics, save, load and reset.
//
// Occupancy comes from every scan; class evidence from a label image when one exists for the
// scan's stamp. A scan waits (in data time) at most label_wait_s for its label image, so a
// segmentation slower than the lidar delays class evidence but never drops a scan; the pairing
// rules are ScanLabelPairing's (scan_label_pairing.h).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "inekf_semantic_mapping/mapping/camera_model.h"
#include "inekf_semantic_mapping/mapping/hashed_voxel_grid.h"
#include "inekf_semantic_mapping/mapping/map_io.h"
#include "inekf_semantic_mapping/mapping/scan_label_pairing.h"
#include "inekf_semantic_mapping/mapping/semantic_classes.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_config.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"

namespace inekf_semantic_mapping {
namespace mapping {

struct MappingStatistics {
  std::size_t scans_received = 0;
  std::size_t scans_inserted = 0;
  std::size_t scans_with_labels = 0;
  std::size_t scans_without_pose = 0;  // dropped after pose_wait_s
  std::size_t scans_rejected = 0;      // the map could not take them (a pose beyond the map's
                                       // extent or not finite): dropped and reported
  std::size_t label_images_received = 0;
  std::size_t label_images_refused = 0;  // malformed, of another encoding, or not fitting their
                                         // camera: never reached the map (not in received)
  std::size_t label_images_used = 0;
  std::size_t label_images_late = 0;              // of the used ones: came after their scan went in
                                                  // (class evidence only)
  std::size_t label_images_unmatched = 0;         // no scan within the tolerance while it was kept
  std::size_t label_images_without_camera = 0;    // their camera never became known or was
                                                  // unusable: their scans went in without classes
  std::size_t scans_with_neighbour_labels = 0;    // without a label image of their own, the
                                                  // evidence of one within label_neighbour_s
  std::size_t label_images_with_unknown_ids = 0;  // holding ids the class set does not know
                                                  // (another id scheme, an "ignore" 255): those
                                                  // pixels give no class evidence
  std::uint32_t last_unknown_label_id = 0;        // one of them, for the message
  std::size_t points_inserted = 0;
  std::size_t points_with_class = 0;  // points that added class evidence
};

class SemanticMappingSession {
 public:
  // Pose of the scan's sensor frame in the map at `stamp`, or nullopt while it is unknown.
  using PoseLookup =
      std::function<std::optional<Eigen::Isometry3d>(double stamp, const std::string& frame)>;

  explicit SemanticMappingSession(const SemanticMappingConfig& config);

  const SemanticMappingConfig& config() const { return config_; }

  // --- Streaming (the node): scans and label images in any order; poses looked up when a scan
  // is inserted. Each call inserts what is ready and returns the number of scans inserted.
  void setPoseLookup(PoseLookup lookup) { pose_lookup_ = std::move(lookup); }
  // True while the lookup is asked ahead, for a scan that still waits for its label image: a
  // failure then is no drop (the node does not name it as the reason of one).
  bool lookingUpAhead() const { return looking_up_ahead_; }
  // Called after each streamed scan went in (kScanInserted), with its stamp and the scan as
  // inserted (map frame), and again when a label image that came after its scan went in adds
  // class evidence to it (kLateLabels: the scan's stamp, points and sensor origin, the new labels;
  // no occupancy update, so not a second insertion).
  enum class MapUpdate { kScanInserted, kLateLabels };
  using InsertedCallback =
      std::function<void(double stamp, const LabeledScan& scan, MapUpdate update)>;
  void setInsertedCallback(InsertedCallback callback) { inserted_callback_ = std::move(callback); }
  std::size_t addScan(double stamp, const std::string& frame, Eigen::Matrix3Xf points_sensor);
  // The image is copied. Throws std::invalid_argument for a view that does not fit `camera`.
  std::size_t addLabelImage(double stamp, const LabelImageView& labels, const CameraModel& camera);
  // The camera of a label image (camera_frame may be empty: the lookup's default camera), sized
  // to width x height; nullopt while it is unknown (the node: camera_info or the lidar -> camera
  // transform has not come yet). May throw std::exception for a camera that is unusable.
  using CameraLookup = std::function<std::optional<CameraModel>(const std::string& camera_frame,
                                                                int width, int height)>;
  void setCameraLookup(CameraLookup lookup) { camera_lookup_ = std::move(lookup); }
  // A label image whose camera is looked up (setCameraLookup) when it is needed: now if it is
  // known, else when its scan goes in; its scan waits for it as for its pose, then goes in without
  // labels. Throws std::invalid_argument for a malformed view or a known camera it does not fit.
  std::size_t addLabelImage(double stamp, const LabelImageView& labels,
                            const std::string& camera_frame);
  // A label image refused before it reached the session (the node: an encoding it cannot read).
  void noteLabelImageRefused() { ++statistics_.label_images_refused; }
  // Told why a label image gave no class evidence after it was accepted (its camera), with its
  // stamp; the node logs it.
  using LabelWarning = std::function<void(double stamp, const std::string& why)>;
  void setLabelWarningCallback(LabelWarning callback) { label_warning_ = std::move(callback); }
  // Told why a streamed scan could not go into the map (it is dropped, the scans behind it go
  // on), with its stamp; the node logs it.
  using ScanWarning = std::function<void(double stamp, const std::string& why)>;
  void setScanWarningCallback(ScanWarning callback) { scan_warning_ = std::move(callback); }
  // Data time has reached `now` (the clock, when no scan arrives): inserts scans whose wait is
  // over.
  std::size_t advanceTo(double now);
  // Inserts every pending scan (with the labels that have arrived) whose pose is known, e.g. at
  // the end of a run or before the node clears its tf buffer; the others are dropped.
  std::size_t flush();
  // Inserts every pending scan whose pose is known now, with the labels that have arrived,
  // without waiting longer for the rest: for a clock that has stopped (a bag ended or paused),
  // when data time will not end the wait. Scans without a pose wait on; label images stay
  // (one that comes later still reaches its scan as late labels).
  std::size_t insertWithoutWaiting();
  std::size_t pendingScans() const { return pairing_.pendingScans(); }
  std::optional<double> oldestPendingStamp() const { return pairing_.oldestPendingStamp(); }
  // The camera whose view scans without a label image are cut to (with
  // insert_points_outside_image false) before the first label image brings its own; without it
  // such scans go in whole (lidar-only runs).
  void setCameraView(const CameraModel& camera) { last_camera_ = camera; }
  bool hasCameraView() const { return last_camera_.has_value(); }

  // --- Direct insertion (offline tools): a scan with its pose and, optionally, its label image
  // or per-point label ids (points.cols() of them; `ignored_label` adds no class evidence).
  void insertScan(const Eigen::Matrix3Xf& points_sensor, const Eigen::Isometry3d& T_map_sensor,
                  const LabelImageView* labels = nullptr, const CameraModel* camera = nullptr);
  void insertScanWithPointLabels(const Eigen::Matrix3Xf& points_sensor,
                                 const Eigen::Isometry3d& T_map_sensor,
                                 const std::vector<std::uint32_t>& label_ids,
                                 std::uint32_t ignored_label);

  // The last scan that went in (map frame, label per point: kNoLabel for none), e.g. for the
  // node's labeled cloud; empty before the first.
  const LabeledScan& lastInsertedScan() const { return last_scan_; }
  static constexpr std::uint32_t kNoLabel = 0xFFFFFFFF;

  // The map. With insertion: hashed_grid the grid's changes are written into the tree first (a
  // cost proportional to what changed since the last call): the tree's leaves belong to the grid,
  // so change the map through the session, not through the tree. Grid and tree then both hold
  // the map (the node: its display asks for the tree again and again).
  SemanticOcTree& tree() {
    syncTree();
    return *tree_;
  }
  const SemanticOcTree& tree() const {
    syncTree();
    return *tree_;
  }
  // The map as tree() gives it, with the hashed grid's memory handed over to the tree block by
  // block (HashedVoxelGrid::moveTo): one copy of the map in memory instead of two, for the end of
  // a run (save, evaluation). The next insertion rebuilds the grid from the tree
  // (HashedVoxelGrid::loadFrom: the same voxels), so the map means the same either way.
  SemanticOcTree& treeReleasingGrid();
  // The map's class set (no sync: cheap per scan).
  const ClassSet& classSet() const { return tree_->classSet(); }
  // The hashed grid (insertion: hashed_grid), else null; empty while released (above).
  const HashedVoxelGrid* grid() const { return grid_.get(); }
  bool gridReleased() const { return grid_released_; }
  // Bytes of the map structures the session holds (tree and grid, as they are now).
  std::size_t mapMemoryUsage() const;
  // "N nodes" (octree) or "N blocks" (hashed grid): the map's size without a sync, for progress.
  std::string mapSizeText() const;
  const MappingStatistics& statistics() const { return statistics_; }

  // Atomic save (map_io); returns the number of occupied leaves written.
  std::size_t save(const std::string& path, MapFormat format);
  // Replaces the map with a saved one (its resolution must equal the config's); the statistics
  // restart. Throws MapIoError; the current map is kept on failure.
  void load(const std::string& path);
  // An empty map, no pending scans, statistics from zero.
  void reset();

  // The map frame's place on the Earth, saved with the map (none: unknown).
  const std::optional<GeodeticOrigin>& geodeticOrigin() const { return tree_->geodeticOrigin(); }
  // The localization's map origin, for the map to agree with. A map built here takes it; a map
  // saved under another origin (more than a voxel away) returns why its scans must not go in
  // (each would be written a second time, shifted by the difference), drops the scans waiting,
  // and addScan refuses with that reason until load() or reset(); a map loaded without one stays
  // unknown. Empty when they agree.
  std::string agreeOnGeodeticOrigin(const GeodeticOrigin& localization);

 private:
  // Throws std::invalid_argument for a label image that cannot be used (stamp, view, or the
  // camera when given), counting it as refused.
  void checkLabelImage(double stamp, const LabelImageView& labels, const CameraModel* camera);
  std::unique_ptr<SemanticOcTree> makeTree() const;
  std::unique_ptr<HashedVoxelGrid> makeGrid() const;
  void syncTree() const;
  // Insertion into a released grid: rebuilds it from the tree first.
  HashedVoxelGrid& gridForInsertion();
  // Class evidence per label id (kNoLabel for ids that carry none: unknown or "ignored" ids).
  std::uint32_t evidenceLabel(std::uint32_t label_id) const;

  // The stages of one insertion.
  std::vector<std::uint32_t> labelPointsFromCamera(const Eigen::Matrix3Xf& points_sensor,
                                                   const LabelImageView& labels,
                                                   const CameraModel& camera,
                                                   std::vector<std::uint8_t>* in_image) const;
  std::vector<std::uint8_t> pointsInCameraView(const Eigen::Matrix3Xf& points_sensor,
                                               const CameraModel& camera) const;
  void keepPointsInImage(const std::vector<std::uint8_t>& in_image, Eigen::Matrix3Xf* points,
                         std::vector<std::uint32_t>* labels) const;
  void insertIntoTree(const Eigen::Matrix3Xf& points_sensor, const Eigen::Isometry3d& T_map_sensor,
                      std::vector<std::uint32_t> labels);

  // Streaming: the pairing's scans go in through these.
  std::size_t addLabels(std::shared_ptr<PendingLabels> labels);
  void noteUnknownLabelIds(const LabelImageView& labels);
  std::size_t insertReadyScans(double now);
  // insertWhenReady, with a scan the map cannot take dropped and reported (true: off the queue).
  bool insertOrReject(PendingScan& scan, bool may_wait);
  // Inserts a ready scan if its pose is known: false if not, or if its labels' camera is not
  // known yet and `may_wait` (else it goes in without them).
  bool insertWhenReady(PendingScan& scan, bool may_wait);
  void insertPending(const PendingScan& scan, const Eigen::Isometry3d& pose);
  // Class evidence from a label image whose scan already went in; false if its camera is unknown.
  bool applyLateLabels(PendingLabels& labels, InsertedScan& scan);
  // A label image with its camera lends its class evidence to the scans without one of their own
  // within label_neighbour_s, and is kept a while for those still to come.
  void lendToNeighbours(const std::shared_ptr<PendingLabels>& labels);
  // A scan that just went in without labels borrows from the nearest kept label image.
  void borrowFromNeighbours(InsertedScan* scan);
  // Class evidence of `labels` for `scan`'s map points seen from the sensor's pose at the label
  // image's stamp; false when that pose is unknown.
  bool applyNeighbourLabels(const PendingLabels& labels, InsertedScan* scan);
  // Class evidence (no occupancy update) of a label image with its camera at `points_map`, seen
  // from the sensor at T_map_sensor (its pose at the image's stamp); returns the labelled points.
  LabeledScan addImageEvidence(const PendingLabels& labels, const Eigen::Isometry3d& T_map_sensor,
                               Eigen::Matrix3Xf points_map);
  // Looks up the camera of `labels` if it is not known: false while it is not (or never will be:
  // `*unusable` set, the warning sent).
  bool resolveCamera(PendingLabels& labels, bool* unusable);

  SemanticMappingConfig config_;
  std::unique_ptr<SemanticOcTree> tree_;
  std::unique_ptr<HashedVoxelGrid> grid_;  // insertion: hashed_grid
  // The grid is empty and the tree holds the map (treeReleasingGrid, load).
  bool grid_released_ = false;
  std::vector<std::uint8_t> ignored_label_;  // per label id < 256: 1 = no class evidence
  MappingStatistics statistics_;
  LabeledScan last_scan_;
  PoseLookup pose_lookup_;
  bool looking_up_ahead_ = false;
  CameraLookup camera_lookup_;
  LabelWarning label_warning_;
  ScanWarning scan_warning_;
  InsertedCallback inserted_callback_;
  bool map_from_file_ = false;  // load() since the start or the last reset()
  std::string origin_refusal_;  // agreeOnGeodeticOrigin's reason, until load() or reset()
  ScanLabelPairing pairing_;
  std::optional<CameraModel> last_camera_;
  // The latest label images with a known camera, newest last (label_neighbour_s).
  std::deque<std::shared_ptr<PendingLabels>> recent_labels_;
};

}  // namespace mapping
}  // namespace inekf_semantic_mapping
