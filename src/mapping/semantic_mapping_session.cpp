#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "inekf_semantic_mapping/perception/label_geometry.h"
#include "inekf_semantic_mapping/perception/projection.h"

namespace inekf_semantic_mapping {
namespace mapping {
SemanticMappingSession::SemanticMappingSession(const SemanticMappingConfig& config)
    : config_(config),
      pairing_(PairingOptions{config_.label_stamp_tolerance_s, config_.label_wait_s,
                              config_.pose_wait_s},
               &statistics_) {
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
  auto tree = std::make_unique<SemanticOcTree>(config_.resolution_m, classSetOf(config_.class_set),
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
  if (!origin_refusal_.empty()) throw std::invalid_argument(origin_refusal_);
  ++statistics_.scans_received;
  if (pairing_.wentBack(stamp)) {  // a bag loop: what is pending goes in, the clock restarts
    flush();
    pairing_.restartClock();
    recent_labels_.clear();
  }
  pairing_.addScan(PendingScan{stamp, frame, std::move(points_sensor), nullptr, std::nullopt});
  return insertReadyScans(pairing_.now());
}

namespace {

void checkLabelView(const LabelImageView& labels) {
  if (!labels.data || labels.width <= 0 || labels.height <= 0 ||
      labels.step < static_cast<std::size_t>(labels.width)) {
    throw std::invalid_argument("label image: malformed (null data, size or row step)");
  }
}

void checkCameraFits(const CameraModel& camera, const LabelImageView& labels) {
  if (camera.width != labels.width || camera.height != labels.height) {
    throw std::invalid_argument("label image is " + std::to_string(labels.width) + "x" +
                                std::to_string(labels.height) + " but the camera is " +
                                std::to_string(camera.width) + "x" + std::to_string(camera.height));
  }
}

}  // namespace

void SemanticMappingSession::checkLabelImage(double stamp, const LabelImageView& labels,
                                             const CameraModel* camera) {
  try {
    if (!std::isfinite(stamp)) throw std::invalid_argument("addLabelImage: stamp is not finite");
    checkLabelView(labels);
    if (camera) checkCameraFits(*camera, labels);
  } catch (const std::invalid_argument&) {
    ++statistics_.label_images_refused;
    throw;
  }
}

std::size_t SemanticMappingSession::addLabelImage(double stamp, const LabelImageView& labels,
                                                  const CameraModel& camera) {
  checkLabelImage(stamp, labels, &camera);
  std::shared_ptr<PendingLabels> copy = PendingLabels::copyOf(stamp, labels);
  copy->camera = camera;
  return addLabels(std::move(copy));
}

std::size_t SemanticMappingSession::addLabelImage(double stamp, const LabelImageView& labels,
                                                  const std::string& camera_frame) {
  checkLabelImage(stamp, labels, nullptr);
  // Known now: checked now, so that a label image that does not fit its camera is reported as it
  // comes.
  std::optional<CameraModel> camera;
  if (camera_lookup_) {
    try {
      camera = camera_lookup_(camera_frame, labels.width, labels.height);
    } catch (const std::invalid_argument&) {
      ++statistics_.label_images_refused;  // its camera refuses it
      throw;
    }
  }
  if (camera) checkLabelImage(stamp, labels, &*camera);
  std::shared_ptr<PendingLabels> copy = PendingLabels::copyOf(stamp, labels);
  copy->camera_frame = camera_frame;
  copy->camera = std::move(camera);
  return addLabels(std::move(copy));
}

void SemanticMappingSession::noteUnknownLabelIds(const LabelImageView& labels) {
  std::array<bool, 256> seen{};
  for (int row = 0; row < labels.height; ++row) {
    const std::uint8_t* pixel = labels.data + static_cast<std::size_t>(row) * labels.step;
    for (int col = 0; col < labels.width; ++col) seen[pixel[col]] = true;
  }
  for (int id = 1; id < 256; ++id) {  // 0: unlabelled in every set
    if (seen[static_cast<std::size_t>(id)] && classSet().indexOf(id) == kNoClass) {
      ++statistics_.label_images_with_unknown_ids;
      statistics_.last_unknown_label_id = static_cast<std::uint32_t>(id);
      return;
    }
  }
}

std::size_t SemanticMappingSession::addLabels(std::shared_ptr<PendingLabels> labels) {
  ++statistics_.label_images_received;
  noteUnknownLabelIds(labels->view);
  const std::optional<CameraModel> camera = labels->camera;
  const std::shared_ptr<PendingLabels> shared = labels;  // the same pixels, for the neighbours
  const ScanLabelPairing::LabelsPlace place = pairing_.addLabels(
      std::move(labels),
      [this](PendingLabels& l, InsertedScan& scan) { return applyLateLabels(l, scan); });
  // The camera view of the scans without labels follows the label images of the present.
  if (camera && place != ScanLabelPairing::LabelsPlace::kUnmatched) last_camera_ = camera;
  // Also one whose own scan is gone (or never came): its neighbours may still be in the window.
  if (config_.label_neighbour_s > 0.0) lendToNeighbours(shared);
  return insertReadyScans(pairing_.now());
}

std::size_t SemanticMappingSession::advanceTo(double now) {
  const std::size_t inserted = insertReadyScans(now);
  // The poses of the scans that wait for their label images, while tf has them (tf clears its
  // buffer when the clock goes back: at a bag loop those scans were dropped without a pose).
  // Here, on the clock's ticks, not at every scan or label image: a few lookups a tick.
  if (pose_lookup_) {
    looking_up_ahead_ = true;
    pairing_.forEachWaitingForLabels([this](PendingScan& scan) {
      if (scan.pose) return;
      try {
        scan.pose = pose_lookup_(scan.stamp, scan.frame);
      } catch (const std::exception&) {
        // Said when the scan is inserted (insertOrReject): the lookup is tried again there.
      }
    });
    looking_up_ahead_ = false;
  }
  return inserted;
}

std::size_t SemanticMappingSession::insertReadyScans(double now) {
  const std::size_t rejected = statistics_.scans_rejected;
  const std::size_t taken = pairing_.insertReady(
      now, [this](PendingScan& scan) { return insertOrReject(scan, /*may_wait=*/true); });
  return taken - (statistics_.scans_rejected - rejected);
}

std::size_t SemanticMappingSession::flush() {
  const std::size_t rejected = statistics_.scans_rejected;
  const std::size_t taken = pairing_.flush(
      [this](PendingScan& scan) { return insertOrReject(scan, /*may_wait=*/false); });
  return taken - (statistics_.scans_rejected - rejected);
}

std::size_t SemanticMappingSession::insertWithoutWaiting() {
  const std::size_t rejected = statistics_.scans_rejected;
  const std::size_t taken = pairing_.insertWithoutWaiting(
      [this](PendingScan& scan) { return insertOrReject(scan, /*may_wait=*/false); });
  return taken - (statistics_.scans_rejected - rejected);
}

bool SemanticMappingSession::insertOrReject(PendingScan& scan, bool may_wait) {
  try {
    return insertWhenReady(scan, may_wait);
  } catch (const std::exception& e) {
    // Left in the queue it would fail again at every call and hold back every scan behind it
    // (after a bag loop, every new one too): the map would stop growing for good.
    ++statistics_.scans_rejected;
    if (scan_warning_) scan_warning_(scan.stamp, e.what());
    return true;
  }
}

bool SemanticMappingSession::resolveCamera(PendingLabels& labels, bool* unusable) {
  *unusable = false;
  if (labels.camera) return true;
  if (!camera_lookup_) return false;
  try {
    labels.camera = camera_lookup_(labels.camera_frame, labels.view.width, labels.view.height);
    if (labels.camera) checkCameraFits(*labels.camera, labels.view);
  } catch (const std::exception& e) {
    labels.camera.reset();
    *unusable = true;
    if (label_warning_) label_warning_(labels.stamp, e.what());
  }
  return labels.camera.has_value();
}

bool SemanticMappingSession::insertWhenReady(PendingScan& scan, bool may_wait) {
  if (!scan.pose && pose_lookup_) scan.pose = pose_lookup_(scan.stamp, scan.frame);
  if (!scan.pose) return false;
  const Eigen::Isometry3d pose = *scan.pose;
  if (scan.labels) {
    bool unusable = false;
    if (!resolveCamera(*scan.labels, &unusable)) {
      // Waits for its camera as for its pose, then goes in without its classes.
      const double waited = pairing_.now() - scan.stamp;
      if (may_wait && !unusable && waited <= config_.label_wait_s + config_.pose_wait_s) {
        return false;
      }
      if (!unusable && label_warning_) {
        label_warning_(scan.labels->stamp,
                       "its camera is still unknown (camera_info and the "
                       "lidar -> camera transform): the scan goes in "
                       "without its classes");
      }
      ++statistics_.label_images_without_camera;
      scan.labels.reset();
    }
  }
  insertPending(scan, pose);
  return true;
}

void SemanticMappingSession::insertPending(const PendingScan& scan, const Eigen::Isometry3d& pose) {
  if (scan.labels) {
    insertScan(scan.points_sensor, pose, &scan.labels->view, &*scan.labels->camera);
    ++statistics_.label_images_used;
  } else {
    insertScan(scan.points_sensor, pose);
    InsertedScan inserted{scan.stamp, last_scan_.points_map, pose, scan.frame};
    if (config_.label_neighbour_s > 0.0) borrowFromNeighbours(&inserted);
    pairing_.keepForLateLabels(std::move(inserted));
  }
  if (inserted_callback_) inserted_callback_(scan.stamp, last_scan_, MapUpdate::kScanInserted);
}

bool SemanticMappingSession::applyLateLabels(PendingLabels& labels, InsertedScan& scan) {
  bool unusable = false;
  if (!resolveCamera(labels, &unusable)) return false;  // it waits, or ends unmatched
  LabeledScan labeled;
  {
    ScopedTimer timer("semantic_map/late_labels");
    labeled = addImageEvidence(labels, scan.T_map_sensor, std::move(scan.points_map));
  }
  ++statistics_.label_images_used;
  ++statistics_.label_images_late;
  ++statistics_.scans_with_labels;
  last_scan_ = std::move(labeled);
  if (inserted_callback_) inserted_callback_(scan.stamp, last_scan_, MapUpdate::kLateLabels);
  return true;
}

void SemanticMappingSession::lendToNeighbours(const std::shared_ptr<PendingLabels>& labels) {
  bool unusable = false;
  if (!resolveCamera(*labels, &unusable)) return;
  const double stamp = labels->stamp;
  for (InsertedScan& scan : pairing_.scansWithoutLabels()) {
    const double gap = std::abs(scan.stamp - stamp);
    if (scan.has_neighbour_labels || gap <= config_.label_stamp_tolerance_s ||
        gap > config_.label_neighbour_s) {
      continue;
    }
    scan.has_neighbour_labels = applyNeighbourLabels(*labels, &scan);
  }
  recent_labels_.push_back(labels);
  // Scans come in stamp order: older label images than one window behind this one, or more
  // than a few, will lend to no scan still to come.
  while (recent_labels_.size() > 4 ||
         (!recent_labels_.empty() &&
          recent_labels_.front()->stamp < stamp - 2.0 * config_.label_neighbour_s - 1.0)) {
    recent_labels_.pop_front();
  }
}

void SemanticMappingSession::borrowFromNeighbours(InsertedScan* scan) {
  const PendingLabels* nearest = nullptr;
  double nearest_gap = config_.label_neighbour_s;
  for (const std::shared_ptr<PendingLabels>& labels : recent_labels_) {
    const double gap = std::abs(labels->stamp - scan->stamp);
    if (gap > config_.label_stamp_tolerance_s && gap <= nearest_gap) {
      nearest = labels.get();
      nearest_gap = gap;
    }
  }
  if (nearest) scan->has_neighbour_labels = applyNeighbourLabels(*nearest, scan);
}

bool SemanticMappingSession::applyNeighbourLabels(const PendingLabels& labels, InsertedScan* scan) {
  if (!labels.camera || !pose_lookup_ || scan->points_map.cols() == 0) return false;
  const std::optional<Eigen::Isometry3d> pose = pose_lookup_(labels.stamp, scan->frame);
  if (!pose) return false;
  ScopedTimer timer("semantic_map/neighbour_labels");
  addImageEvidence(labels, *pose, scan->points_map);
  ++statistics_.scans_with_neighbour_labels;
  return true;
}

LabeledScan SemanticMappingSession::addImageEvidence(const PendingLabels& labels,
                                                     const Eigen::Isometry3d& T_map_sensor,
                                                     Eigen::Matrix3Xf points_map) {
  const Eigen::Isometry3d T_sensor_map = T_map_sensor.inverse();
  const Eigen::Matrix3Xf points_sensor =
      (T_sensor_map.linear().cast<float>() * points_map).colwise() +
      T_sensor_map.translation().cast<float>();
  std::vector<std::uint8_t> in_image;
  LabeledScan labeled;
  labeled.label_ids = labelPointsFromCamera(points_sensor, labels.view, *labels.camera, &in_image);
  labeled.points_map = std::move(points_map);
  labeled.sensor_origin_map = T_map_sensor.translation().cast<float>();
  labeled.unknown_label_id = kNoLabel;
  statistics_.points_with_class +=
      grid_ ? gridForInsertion().addClassEvidence(labeled, tree_->classSet())
            : tree_->addClassEvidence(labeled);
  return labeled;
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
  // Maps are saved with the resolution's every digit; earlier ones with 6 significant digits,
  // which a relative tolerance of 1e-5 still takes (then the configured value holds).
  if (std::abs(loaded->getResolution() - config_.resolution_m) > 1e-5 * config_.resolution_m) {
    std::ostringstream why;
    why.precision(10);
    why << path << ": map resolution " << loaded->getResolution()
        << " m differs from the configured " << config_.resolution_m << " m";
    throw MapIoError(why.str());
  }
  if (loaded->getResolution() != config_.resolution_m) loaded->setResolution(config_.resolution_m);
  // The class indices the map stores stand for its own table's label ids, and the labels to come
  // are in the configured set's: the configured set must be where the map's table begins (the
  // map may have added ids it met since, never reordered). A SemanticKITTI map loaded into a
  // Cityscapes session would have turned each new camera label into another class.
  const ClassSet expected = classSetOf(config_.class_set);
  const ClassSet& found = loaded->classSet();
  bool same_ids = found.size() >= expected.size();
  for (int i = 0; same_ids && i < expected.size(); ++i) {
    same_ids = found.info(i).label_id == expected.info(i).label_id;
  }
  if (!same_ids) {
    throw MapIoError(path + ": the map's classes (" + std::to_string(found.size()) +
                     ", the first '" + (found.size() > 0 ? found.info(0).name : "none") +
                     "') are not the configured class set " + mapClassSetName(config_.class_set) +
                     " (" + std::to_string(expected.size()) + " classes)");
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
  map_from_file_ = true;
  origin_refusal_.clear();
  statistics_ = MappingStatistics();
}

std::string SemanticMappingSession::agreeOnGeodeticOrigin(const GeodeticOrigin& localization) {
  const std::optional<GeodeticOrigin>& map = tree_->geodeticOrigin();
  if (!map) {
    // Built here (in the localization's frame): it takes the origin. Loaded without one: where
    // it lies is not known, and no origin is made up for it.
    if (!map_from_file_) tree_->setGeodeticOrigin(localization);
    return "";
  }
  // The localization's origin in the map's own frame (the same projection as inekf_node's map).
  const Eigen::Vector3d offset =
      kitti::MercatorProjection(map->lat_deg, map->lon_deg, map->alt_m)
          .toMap(localization.lat_deg, localization.lon_deg, localization.alt_m);
  if (offset.norm() <= config_.resolution_m) {
    origin_refusal_.clear();
    return "";
  }
  std::ostringstream why;
  why.precision(10);
  why << "the map was saved with its frame at lat " << map->lat_deg << ", lon " << map->lon_deg
      << ", alt " << map->alt_m << "; the localization's map frame is ";
  why.precision(3);
  why << offset.norm() << " m away (east " << offset.x() << ", north " << offset.y() << ", up "
      << offset.z() << "): its scans would be mapped a second time, shifted. ";
  why.precision(10);
  why << "Start the localization at the map's origin (origin_lat:=" << map->lat_deg
      << " origin_lon:=" << map->lon_deg << " origin_alt:=" << map->alt_m
      << "), or reset or replace the map";
  origin_refusal_ = why.str();
  pairing_.clear();  // the scans waiting would take their poses in the other frame
  return origin_refusal_;
}

void SemanticMappingSession::reset() {
  tree_ = makeTree();
  map_from_file_ = false;
  origin_refusal_.clear();
  grid_ = makeGrid();
  grid_released_ = false;
  pairing_.clear();
  recent_labels_.clear();
  statistics_ = MappingStatistics();
  last_scan_ = LabeledScan();
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
