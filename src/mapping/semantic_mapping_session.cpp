#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "inekf_semantic_mapping/perception/label_geometry.h"
#include "inekf_semantic_mapping/perception/projection.h"

namespace inekf_semantic_mapping {
namespace mapping {
namespace {

// Label images are kept this long past the newest scan for a scan that may still come (s).
constexpr double kLabelKeepMargin_s = 1.0;
// ... and at most this long past the clock (data time, s) when no newer scan comes at all (lidar
// stopped): it bounds the memory of the label images waiting, not the lag of the scan queue.
constexpr double kLabelKeepMax_s = 30.0;
// Scans that went in without labels are kept this long (data time) for a late label image.
constexpr double kLateLabelWindow_s = 10.0;
// A stamp this much older than the newest one means the clock went back (a bag loop).
constexpr double kTimeJump_s = 1.0;

// The item of `items` (scans or label images) whose stamp is nearest to `stamp`, within
// `tolerance`, among those `eligible` accepts; items.end() if none.
template <typename Items, typename Eligible>
auto nearestInTime(Items& items, double stamp, double tolerance, Eligible eligible) {
  auto best = items.end();
  for (auto it = items.begin(); it != items.end(); ++it) {
    const double gap = std::abs(it->stamp - stamp);
    if (eligible(*it) && gap <= tolerance &&
        (best == items.end() || gap < std::abs(best->stamp - stamp))) {
      best = it;
    }
  }
  return best;
}
constexpr auto kAny = [](const auto&) { return true; };

}  // namespace

SemanticMappingSession::SemanticMappingSession(const SemanticMappingConfig& config)
    : config_(config) {
  config_.validate();
  tree_ = makeTree();
  grid_ = makeGrid();
  // Cityscapes ids without a trainId (unlabeled, ego vehicle, ...) are what a network says when
  // it has nothing to say: they carry no class evidence. So does SemanticKITTI's unlabeled (0).
  ignored_label_.assign(256, 0);
  for (int id = 0; id < 256; ++id) {
    if (config_.class_set == MapClassSet::kCityscapes) {
      ignored_label_[id] = cityscapes::labelIdToTrainId(static_cast<std::uint8_t>(id)) == 255;
    } else {
      ignored_label_[id] = id == 0;
    }
  }
}

std::unique_ptr<SemanticOcTree> SemanticMappingSession::makeTree() const {
  auto tree = std::make_unique<SemanticOcTree>(config_.resolution_m,
                                               config_.class_set == MapClassSet::kCityscapes
                                                   ? ClassSet::cityscapes()
                                                   : ClassSet::semanticKitti(),
                                               config_.fusion);
  tree->setOccupancyModel(config_.occupancy);
  tree->setRayCastingThreads(config_.ray_casting_threads);
  tree->setGrazingRayTruncation(config_.grazing_ray_truncation_voxels);
  return tree;
}

std::unique_ptr<HashedVoxelGrid> SemanticMappingSession::makeGrid() const {
  if (config_.insertion != InsertionStructure::kHashedGrid) return nullptr;
  HashedVoxelGridOptions options;
  options.resolution_m = config_.resolution_m;
  options.occupancy = config_.occupancy;
  options.occupancy_threshold = tree_->getOccupancyThres();
  options.grazing_truncation_voxels = config_.grazing_ray_truncation_voxels;
  options.early_termination_voxels = config_.early_ray_termination_voxels;
  return std::make_unique<HashedVoxelGrid>(options);
}

void SemanticMappingSession::syncTree() const {
  if (grid_ && grid_->dirty()) {
    ScopedTimer timer("semantic_map/grid_to_tree");
    grid_->syncTo(tree_.get());
  }
}

SemanticOcTree& SemanticMappingSession::treeReleasingGrid() {
  if (grid_ && !grid_released_) {
    ScopedTimer timer("semantic_map/grid_to_tree");
    grid_->moveTo(tree_.get());
    grid_released_ = true;
  }
  return *tree_;
}

HashedVoxelGrid& SemanticMappingSession::gridForInsertion() {
  if (grid_released_) {
    ScopedTimer timer("semantic_map/tree_to_grid");
    grid_->loadFrom(*tree_);
    grid_released_ = false;
  }
  return *grid_;
}

std::size_t SemanticMappingSession::mapMemoryUsage() const {
  return tree_->memoryUsage() + (grid_ ? grid_->memoryUsage() : 0);
}

std::string SemanticMappingSession::mapSizeText() const {
  return grid_ && !grid_released_ ? std::to_string(grid_->blockCount()) + " blocks"
                                  : std::to_string(tree_->size()) + " nodes";
}

std::uint32_t SemanticMappingSession::evidenceLabel(std::uint32_t label_id) const {
  if (label_id < ignored_label_.size() && ignored_label_[label_id]) return kNoLabel;
  return label_id;
}

// ---------------------------------------------------------------------------------------------
// Insertion stages

std::vector<std::uint32_t> SemanticMappingSession::labelPointsFromCamera(
    const Eigen::Matrix3Xf& points_sensor, const LabelImageView& labels, const CameraModel& camera,
    std::vector<std::uint8_t>* in_image) const {
  ScopedTimer timer("semantic_map/project_label");
  const perception::PointProjector projector(camera.P, camera.R_rect, camera.T_camera_sensor,
                                             labels.width, labels.height);
  perception::ProjectedPoints projected;
  projector.project(points_sensor, &projected);
  std::vector<std::uint32_t> label_ids;
  perception::labelPointsFromImage(projected, labels.data, labels.width, labels.height, labels.step,
                                   kNoLabel, &label_ids);
  if (config_.reject_occluded_points) {
    perception::rejectOccludedPoints(projected, labels.width, labels.height,
                                     perception::OcclusionOptions(), kNoLabel, &label_ids);
  }
  if (config_.label_geometry_check && config_.class_set == MapClassSet::kCityscapes) {
    ScopedTimer geometry_timer("semantic_map/label_geometry");
    perception::CityscapesLidarChecks checks;
    checks.geometry.max_flat_height_m =
        static_cast<float>(config_.label_geometry_max_flat_height_m);
    checks.geometry.min_raised_height_m =
        static_cast<float>(config_.label_geometry_min_raised_height_m);
    checks.high_terrain_is_vegetation = config_.label_geometry_high_terrain_is_vegetation;
    checks.curbs = config_.label_geometry_curbs;
    perception::applyCityscapesLidarChecks(points_sensor, checks, kNoLabel, &label_ids);
  }
  for (std::uint32_t& id : label_ids) {
    if (id != kNoLabel) id = evidenceLabel(id);
  }
  *in_image = std::move(projected.valid);
  return label_ids;
}

std::vector<std::uint8_t> SemanticMappingSession::pointsInCameraView(
    const Eigen::Matrix3Xf& points_sensor, const CameraModel& camera) const {
  const perception::PointProjector projector(camera.P, camera.R_rect, camera.T_camera_sensor,
                                             camera.width, camera.height);
  perception::ProjectedPoints projected;
  projector.project(points_sensor, &projected);
  return std::move(projected.valid);
}

void SemanticMappingSession::keepPointsInImage(const std::vector<std::uint8_t>& in_image,
                                               Eigen::Matrix3Xf* points,
                                               std::vector<std::uint32_t>* labels) const {
  Eigen::Index kept = 0;
  for (Eigen::Index i = 0; i < points->cols(); ++i) {
    if (!in_image[static_cast<std::size_t>(i)]) continue;
    points->col(kept) = points->col(i);
    if (!labels->empty()) (*labels)[kept] = (*labels)[i];
    ++kept;
  }
  points->conservativeResize(3, kept);
  if (!labels->empty()) labels->resize(static_cast<std::size_t>(kept));
}

void SemanticMappingSession::insertIntoTree(const Eigen::Matrix3Xf& points_sensor,
                                            const Eigen::Isometry3d& T_map_sensor,
                                            std::vector<std::uint32_t> labels) {
  if (!T_map_sensor.matrix().allFinite()) {
    throw std::invalid_argument("scan pose is not finite");
  }
  {
    ScopedTimer timer("semantic_map/transform");
    const Eigen::Matrix3f rotation = T_map_sensor.linear().cast<float>();
    const Eigen::Vector3f translation = T_map_sensor.translation().cast<float>();
    last_scan_.points_map = (rotation * points_sensor).colwise() + translation;
    last_scan_.sensor_origin_map = translation;
    last_scan_.label_ids = std::move(labels);
    last_scan_.unknown_label_id = kNoLabel;
  }
  std::size_t with_class = 0;
  {
    ScopedTimer timer("semantic_map/insert");
    with_class = grid_ ? gridForInsertion().insertLabeledScan(last_scan_, config_.max_range_m,
                                                              tree_->classSet())
                       : tree_->insertLabeledScan(last_scan_, config_.max_range_m);
  }
  ++statistics_.scans_inserted;
  statistics_.points_inserted += static_cast<std::size_t>(points_sensor.cols());
  statistics_.points_with_class += with_class;
}

void SemanticMappingSession::insertScan(const Eigen::Matrix3Xf& points_sensor,
                                        const Eigen::Isometry3d& T_map_sensor,
                                        const LabelImageView* labels, const CameraModel* camera) {
  if (labels && !camera) throw std::invalid_argument("insertScan: a label image needs a camera");
  if (labels && (!labels->data || labels->width <= 0 || labels->height <= 0 ||
                 labels->step < static_cast<std::size_t>(labels->width))) {
    throw std::invalid_argument("insertScan: malformed label image view");
  }
  Eigen::Matrix3Xf points = points_sensor;
  std::vector<std::uint32_t> label_ids;
  std::vector<std::uint8_t> in_image;
  if (labels) {
    label_ids = labelPointsFromCamera(points, *labels, *camera, &in_image);
    last_camera_ = *camera;
  } else if (last_camera_ && !config_.insert_points_outside_image) {
    // Without labels the scan still covers what the camera sees, so labelled and unlabelled
    // scans build one consistent map.
    in_image = pointsInCameraView(points, *last_camera_);
  }
  if (!in_image.empty() && !config_.insert_points_outside_image) {
    keepPointsInImage(in_image, &points, &label_ids);
  }
  insertIntoTree(points, T_map_sensor, std::move(label_ids));
  if (labels) ++statistics_.scans_with_labels;
}

void SemanticMappingSession::insertScanWithPointLabels(const Eigen::Matrix3Xf& points_sensor,
                                                       const Eigen::Isometry3d& T_map_sensor,
                                                       const std::vector<std::uint32_t>& label_ids,
                                                       std::uint32_t ignored_label) {
  if (label_ids.size() != static_cast<std::size_t>(points_sensor.cols())) {
    throw std::invalid_argument("insertScanWithPointLabels: " + std::to_string(label_ids.size()) +
                                " labels for " + std::to_string(points_sensor.cols()) + " points");
  }
  std::vector<std::uint32_t> labels(label_ids.size());
  for (std::size_t i = 0; i < labels.size(); ++i) {
    const std::uint32_t id = label_ids[i];
    if (id == ignored_label) {
      labels[i] = kNoLabel;
      continue;
    }
    // Ids the class set does not know get their own class (grey for display).
    tree_->mutableClassSet().addLabel(id);
    labels[i] = id;
  }
  insertIntoTree(points_sensor, T_map_sensor, std::move(labels));
  ++statistics_.scans_with_labels;
}

// ---------------------------------------------------------------------------------------------
// Streaming

std::size_t SemanticMappingSession::addScan(double stamp, const std::string& frame,
                                            Eigen::Matrix3Xf points_sensor) {
  if (!std::isfinite(stamp)) throw std::invalid_argument("addScan: stamp is not finite");
  ++statistics_.scans_received;
  // Against the newest scan, not the clock: a scan that sat in a busy subscriber queue is older
  // than the clock by the queue's lag, and that is no bag loop.
  if (stamp + kTimeJump_s < newest_scan_stamp_) restartClock();
  PendingScan scan{stamp, frame, std::move(points_sensor), nullptr};
  // A label image that came first (segmentation can beat the pose or the cloud's transport).
  const auto best = nearestInTime(pending_labels_, stamp, config_.label_stamp_tolerance_s, kAny);
  if (best != pending_labels_.end()) {
    scan.labels = std::make_shared<const PendingLabels>(std::move(*best));
    pending_labels_.erase(best);
  }
  pending_scans_.push_back(std::move(scan));
  newest_stamp_ = std::max(newest_stamp_, stamp);
  newest_scan_stamp_ = std::max(newest_scan_stamp_, stamp);
  first_stamp_ = std::min(first_stamp_, stamp);
  return insertReadyScans(newest_stamp_);
}

std::size_t SemanticMappingSession::addLabelImage(double stamp, const LabelImageView& labels,
                                                  const CameraModel& camera) {
  if (!std::isfinite(stamp)) throw std::invalid_argument("addLabelImage: stamp is not finite");
  if (!labels.data || labels.width <= 0 || labels.height <= 0 ||
      labels.step < static_cast<std::size_t>(labels.width)) {
    throw std::invalid_argument("label image: malformed (null data, size or row step)");
  }
  if (camera.width != labels.width || camera.height != labels.height) {
    throw std::invalid_argument("label image is " + std::to_string(labels.width) + "x" +
                                std::to_string(labels.height) + " but the camera is " +
                                std::to_string(camera.width) + "x" + std::to_string(camera.height));
  }
  ++statistics_.label_images_received;
  // Its scan, in this order: still pending (waiting for labels or its pose), already in the map
  // without labels (the labels add class evidence), or not here yet. The scans' own stamps decide
  // the last case, not the clock: under load the scan queue can lag the clock by more than
  // label_wait, and the scan still comes.
  auto pending = nearestInTime(pending_scans_, stamp, config_.label_stamp_tolerance_s,
                               [](const PendingScan& scan) { return !scan.labels; });
  const bool scan_may_come = stamp + config_.label_stamp_tolerance_s >= newest_scan_stamp_;
  if (pending == pending_scans_.end() && !scan_may_come) {
    if (!applyLateLabels(stamp, labels, camera)) ++statistics_.label_images_unmatched;
    return insertReadyScans(newest_stamp_);
  }
  auto copy = std::make_shared<PendingLabels>();
  copy->stamp = stamp;
  copy->camera = camera;
  const std::size_t row = static_cast<std::size_t>(labels.width);
  copy->pixels.resize(row * static_cast<std::size_t>(labels.height));
  for (int r = 0; r < labels.height; ++r) {
    std::copy_n(labels.data + static_cast<std::size_t>(r) * labels.step, row,
                copy->pixels.data() + static_cast<std::size_t>(r) * row);
  }
  copy->view = LabelImageView{copy->pixels.data(), labels.width, labels.height, row};
  last_camera_ = camera;
  newest_label_stamp_ = std::max(newest_label_stamp_, stamp);
  newest_stamp_ = std::max(newest_stamp_, stamp);
  first_stamp_ = std::min(first_stamp_, stamp);
  last_label_arrival_ = newest_stamp_;

  if (pending != pending_scans_.end()) {
    pending->labels = std::move(copy);
  } else if (!applyLateLabels(stamp, copy->view, copy->camera)) {
    pending_labels_.push_back(std::move(*copy));
  }
  return insertReadyScans(newest_stamp_);
}

std::size_t SemanticMappingSession::advanceTo(double now) {
  if (std::isfinite(now)) newest_stamp_ = std::max(newest_stamp_, now);
  return insertReadyScans(newest_stamp_);
}

bool SemanticMappingSession::labelsMayStillCome(const PendingScan& scan, double now) const {
  if (scan.labels) return false;
  // Segmentation publishes in stamp order: once a newer label image is here, none will come
  // for this scan.
  if (newest_label_stamp_ > scan.stamp + config_.label_stamp_tolerance_s) return false;
  // No label image has arrived for a whole wait (data time of its arrival, not its stamp: a
  // label image comes one segmentation latency after its stamp), and the run is older than that:
  // segmentation is not running (lidar-only runs). At the start, scans wait for the first one.
  if (last_label_arrival_ < now - config_.label_wait_s &&
      first_stamp_ < now - config_.label_wait_s) {
    return false;
  }
  return now - scan.stamp <= config_.label_wait_s;
}

void SemanticMappingSession::insertPending(const PendingScan& scan, const Eigen::Isometry3d& pose) {
  if (scan.labels) {
    insertScan(scan.points_sensor, pose, &scan.labels->view, &scan.labels->camera);
    ++statistics_.label_images_used;
  } else {
    insertScan(scan.points_sensor, pose);
    unlabelled_scans_.push_back({scan.stamp, last_scan_.points_map, pose});
    while (!unlabelled_scans_.empty() &&
           unlabelled_scans_.front().stamp < scan.stamp - kLateLabelWindow_s) {
      unlabelled_scans_.pop_front();
    }
  }
  if (inserted_callback_) inserted_callback_(scan.stamp, last_scan_);
}

bool SemanticMappingSession::applyLateLabels(double stamp, const LabelImageView& labels,
                                             const CameraModel& camera) {
  const auto best = nearestInTime(unlabelled_scans_, stamp, config_.label_stamp_tolerance_s, kAny);
  if (best == unlabelled_scans_.end()) return false;
  const Eigen::Isometry3d T_sensor_map = best->T_map_sensor.inverse();
  const Eigen::Matrix3Xf points_sensor =
      (T_sensor_map.linear().cast<float>() * best->points_map).colwise() +
      T_sensor_map.translation().cast<float>();
  std::vector<std::uint8_t> in_image;
  LabeledScan scan;
  scan.label_ids = labelPointsFromCamera(points_sensor, labels, camera, &in_image);
  scan.points_map = std::move(best->points_map);
  scan.unknown_label_id = kNoLabel;
  unlabelled_scans_.erase(best);
  {
    ScopedTimer timer("semantic_map/late_labels");
    statistics_.points_with_class +=
        grid_ ? gridForInsertion().addClassEvidence(scan, tree_->classSet())
              : tree_->addClassEvidence(scan);
  }
  ++statistics_.label_images_used;
  ++statistics_.label_images_late;
  ++statistics_.scans_with_labels;
  last_scan_ = std::move(scan);
  if (inserted_callback_) inserted_callback_(stamp, last_scan_);
  return true;
}

std::size_t SemanticMappingSession::insertReadyScans(double now) {
  std::size_t inserted = 0;
  for (auto it = pending_scans_.begin(); it != pending_scans_.end();) {
    if (labelsMayStillCome(*it, now)) {
      ++it;
      continue;
    }
    std::optional<Eigen::Isometry3d> pose;
    if (pose_lookup_) pose = pose_lookup_(it->stamp, it->frame);
    if (!pose) {
      if (now - it->stamp > config_.label_wait_s + config_.pose_wait_s) {
        ++statistics_.scans_without_pose;
        it = pending_scans_.erase(it);
      } else {
        ++it;
      }
      continue;
    }
    insertPending(*it, *pose);
    ++inserted;
    it = pending_scans_.erase(it);
  }
  // Label images no scan will claim any more: newer scans have come (scans arrive in stamp
  // order), or none has for a long time.
  for (auto it = pending_labels_.begin(); it != pending_labels_.end();) {
    if (it->stamp + kLabelKeepMargin_s < newest_scan_stamp_ || it->stamp + kLabelKeepMax_s < now) {
      ++statistics_.label_images_unmatched;
      it = pending_labels_.erase(it);
    } else {
      ++it;
    }
  }
  return inserted;
}

void SemanticMappingSession::restartClock() {
  flush();
  unlabelled_scans_.clear();
  newest_stamp_ = newest_scan_stamp_ = newest_label_stamp_ = last_label_arrival_ = -1e300;
  first_stamp_ = 1e300;
}

std::size_t SemanticMappingSession::flush() {
  std::size_t inserted = 0;
  for (auto it = pending_scans_.begin(); it != pending_scans_.end();) {
    std::optional<Eigen::Isometry3d> pose;
    if (pose_lookup_) pose = pose_lookup_(it->stamp, it->frame);
    if (pose) {
      insertPending(*it, *pose);
      ++inserted;
    } else {
      ++statistics_.scans_without_pose;
    }
    it = pending_scans_.erase(it);
  }
  statistics_.label_images_unmatched += pending_labels_.size();
  pending_labels_.clear();
  return inserted;
}

// ---------------------------------------------------------------------------------------------
// Map files

std::size_t SemanticMappingSession::save(const std::string& path, MapFormat format) {
  syncTree();
  ScopedTimer timer("semantic_map/save");
  return saveMap(*tree_, path, format);
}

void SemanticMappingSession::load(const std::string& path) {
  std::unique_ptr<SemanticOcTree> loaded = loadSemanticOcTree(path);
  if (std::abs(loaded->getResolution() - config_.resolution_m) > 1e-9) {
    throw MapIoError(path + ": map resolution " + std::to_string(loaded->getResolution()) +
                     " m differs from the configured " + std::to_string(config_.resolution_m) +
                     " m");
  }
  loaded->setOccupancyModel(config_.occupancy);
  loaded->setRayCastingThreads(config_.ray_casting_threads);
  loaded->setGrazingRayTruncation(config_.grazing_ray_truncation_voxels);
  loaded->setFusionModel(config_.fusion);
  // The grid follows at the first insertion (gridForInsertion): a loaded map that is only shown
  // or saved is held once.
  if (grid_) {
    grid_ = makeGrid();
    grid_released_ = true;
  }
  tree_ = std::move(loaded);
  statistics_ = MappingStatistics();
}

void SemanticMappingSession::reset() {
  tree_ = makeTree();
  grid_ = makeGrid();
  grid_released_ = false;
  pending_scans_.clear();
  pending_labels_.clear();
  unlabelled_scans_.clear();
  statistics_ = MappingStatistics();
  last_scan_ = LabeledScan();
  newest_stamp_ = newest_scan_stamp_ = newest_label_stamp_ = last_label_arrival_ = -1e300;
  first_stamp_ = 1e300;
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
