#include "inekf_semantic_mapping/evaluation/semantic_evaluation.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <limits>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <stdexcept>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/kitti/poses.h"
#include "inekf_semantic_mapping/mapping/map_io.h"
#include "inekf_semantic_mapping/mapping/offline_mapping.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"
#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "inekf_semantic_mapping/perception/semantickitti_to_cityscapes.h"

namespace inekf_semantic_mapping {
namespace evaluation {

using namespace perception;  // NOLINT: the labelling path is perception's, step by step

namespace {

namespace fs = std::filesystem;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

double ratio(std::uint64_t numerator, std::uint64_t denominator) {
  return denominator == 0 ? kNaN : static_cast<double>(numerator) / denominator;
}

// JSON has no NaN: null instead.
std::string jsonNumber(double value) {
  if (!std::isfinite(value)) return "null";
  std::ostringstream out;
  out << std::setprecision(6) << value;
  return out.str();
}

// A label image from a LabelImageSource, refused (naming the frame) unless it is one byte per
// pixel at the image's size: the map reads it by the image's pixel coordinates.
cv::Mat checkedLabelImage(cv::Mat labels, const cv::Mat& image, const std::string& sequence_dir,
                          const std::string& frame) {
  if (labels.type() != CV_8UC1 || labels.size() != image.size()) {
    throw std::runtime_error(sequence_dir + "/image_2/" + frame + ".png: its label image is " +
                             std::to_string(labels.cols) + "x" + std::to_string(labels.rows) +
                             " of type " + std::to_string(labels.type()) + ", not " +
                             std::to_string(image.cols) + "x" + std::to_string(image.rows) +
                             " CV_8UC1");
  }
  return labels;
}

}  // namespace

PointLabelScore::PointLabelScore() : confusion_(static_cast<std::size_t>(kRows) * kCols, 0) {}

void PointLabelScore::add(std::uint8_t truth, std::uint32_t predicted) {
  if (truth == kIgnoredLabel) return;
  ++confusion_[static_cast<std::size_t>(truth) * kCols + std::min<std::uint32_t>(predicted, 255)];
}

void PointLabelScore::merge(const PointLabelScore& other) {
  for (std::size_t i = 0; i < confusion_.size(); ++i) confusion_[i] += other.confusion_[i];
}

std::uint64_t PointLabelScore::scored() const {
  std::uint64_t total = 0;
  for (std::uint64_t count : confusion_) total += count;
  return total;
}

std::uint64_t PointLabelScore::labelled() const {
  std::uint64_t total = 0;
  for (int t = 0; t < kRows; ++t)
    for (int p = 1; p < kCols; ++p) total += at(t, p);
  return total;
}

std::uint64_t PointLabelScore::correct() const {
  std::uint64_t total = 0;
  for (int t = 1; t < kRows; ++t) total += at(t, t);
  return total;
}

double PointLabelScore::coverage() const { return ratio(labelled(), scored()); }
double PointLabelScore::accuracy() const { return ratio(correct(), labelled()); }

std::uint64_t PointLabelScore::truthCount(std::uint8_t label_id) const {
  std::uint64_t total = 0;
  for (int p = 1; p < kCols; ++p) total += at(label_id, p);
  return total;
}

std::uint64_t PointLabelScore::predictedCount(std::uint8_t label_id) const {
  std::uint64_t total = 0;
  for (int t = 0; t < kRows; ++t) total += at(t, label_id);
  return total;
}

std::uint64_t PointLabelScore::truePositives(std::uint8_t label_id) const {
  return label_id == 0 ? 0 : at(label_id, label_id);
}

std::uint64_t PointLabelScore::unlabelledCount(std::uint8_t label_id) const {
  return at(label_id, 0);
}

double PointLabelScore::iou(std::uint8_t label_id) const {
  const std::uint64_t tp = truePositives(label_id);
  const std::uint64_t uni = truthCount(label_id) + predictedCount(label_id) - tp;
  return ratio(tp, uni);
}

double PointLabelScore::meanIoU() const {
  double sum = 0.0;
  int classes = 0;
  for (std::uint8_t label : kScoredCityscapesLabels) {
    if (truthCount(label) == 0) continue;
    sum += iou(label);
    ++classes;
  }
  return classes == 0 ? kNaN : sum / classes;
}

double PointLabelScore::meanIoUWithMisses() const {
  double sum = 0.0;
  int classes = 0;
  for (std::uint8_t label : kScoredCityscapesLabels) {
    const std::uint64_t truth = truthCount(label) + unlabelledCount(label);
    const std::uint64_t predicted = predictedCount(label);
    if (truth + predicted == 0) continue;
    const std::uint64_t tp = truePositives(label);
    sum += static_cast<double>(tp) / static_cast<double>(truth + predicted - tp);
    ++classes;
  }
  return classes == 0 ? kNaN : sum / classes;
}

std::string PointLabelScore::toJson() const {
  std::ostringstream out;
  out << "{\"scored\":" << scored() << ",\"labelled\":" << labelled()
      << ",\"correct\":" << correct() << ",\"coverage\":" << jsonNumber(coverage())
      << ",\"accuracy\":" << jsonNumber(accuracy()) << ",\"miou\":" << jsonNumber(meanIoU())
      << ",\"miou_with_misses\":" << jsonNumber(meanIoUWithMisses()) << ",\"classes\":{";
  bool first = true;
  for (std::uint8_t label : kScoredCityscapesLabels) {
    if (truthCount(label) + predictedCount(label) + unlabelledCount(label) == 0) continue;
    out << (first ? "" : ",") << "\"" << cityscapes::labelName(label)
        << "\":{\"label_id\":" << static_cast<int>(label) << ",\"truth\":" << truthCount(label)
        << ",\"predicted\":" << predictedCount(label) << ",\"correct\":" << truePositives(label)
        << ",\"unlabelled\":" << unlabelledCount(label)
        << ",\"accuracy\":" << jsonNumber(ratio(truePositives(label), truthCount(label)))
        << ",\"iou\":" << jsonNumber(iou(label)) << "}";
    first = false;
  }
  out << "}}";
  return out.str();
}

std::vector<std::string> listSemanticKittiFrames(const std::string& sequence_dir,
                                                 std::vector<std::string>* incomplete) {
  const fs::path dir(sequence_dir);
  if (!fs::is_directory(dir / "velodyne"))
    throw std::runtime_error("not a SemanticKITTI sequence (no velodyne/): " + sequence_dir);
  std::vector<std::string> names, lacking;
  for (const auto& entry : fs::directory_iterator(dir / "velodyne")) {
    if (entry.path().extension() != ".bin") continue;
    const std::string name = entry.path().stem().string();
    // Frame numbers only (a stray copy "000001_copy.bin" stopped the run with "stoul" after the
    // whole labelling pass).
    if (name.empty() || name.find_first_not_of("0123456789") != std::string::npos) {
      throw std::runtime_error(entry.path().string() + ": not a frame (its name is not a number)");
    }
    const bool complete = fs::exists(dir / "labels" / (name + ".label")) &&
                          fs::exists(dir / "image_2" / (name + ".png"));
    (complete ? names : lacking).push_back(name);
  }
  if (names.empty())
    throw std::runtime_error("no frame with velodyne/, labels/ and image_2/ files in " +
                             sequence_dir);
  std::sort(names.begin(), names.end());
  if (incomplete) {
    std::sort(lacking.begin(), lacking.end());
    *incomplete = std::move(lacking);
  }
  return names;
}

SemanticKittiFrame readSemanticKittiFrame(const std::string& sequence_dir,
                                          const std::string& name) {
  const fs::path dir(sequence_dir);
  SemanticKittiFrame frame;
  frame.name = name;
  const std::string image_path = (dir / "image_2" / (name + ".png")).string();
  frame.image = cv::imread(image_path, cv::IMREAD_COLOR);
  if (frame.image.empty()) throw std::runtime_error("cannot read image " + image_path);
  frame.scan = kitti::readVelodyneBin((dir / "velodyne" / (name + ".bin")).string());
  const std::string label_path = (dir / "labels" / (name + ".label")).string();
  const std::vector<std::uint32_t> labels = kitti::readLabelFile(label_path);
  if (labels.size() != frame.scan.size())
    throw std::runtime_error(label_path + " has " + std::to_string(labels.size()) + " labels for " +
                             std::to_string(frame.scan.size()) + " points");
  frame.truth.resize(labels.size());
  for (std::size_t i = 0; i < labels.size(); ++i)
    frame.truth[i] = semanticKittiToCityscapes(kitti::semanticClass(labels[i]));
  return frame;
}

kitti::CameraProjection readSemanticKittiCamera(const std::string& sequence_dir, int width,
                                                int height) {
  return kitti::readObjectCalibration((fs::path(sequence_dir) / "calib.txt").string())
      .projection(2, width, height);
}

std::vector<std::uint32_t> labelScanPoints(const Segmentation& segmentation,
                                           const PointProjector& projector,
                                           const kitti::VelodyneScan& scan,
                                           const PointLabellingOptions& options,
                                           ProjectedPoints* projected) {
  if (segmentation.label_ids.cols != projector.width() ||
      segmentation.label_ids.rows != projector.height())
    throw std::invalid_argument(
        "labelScanPoints: the segmentation and the projector differ in size");
  const Eigen::Map<const Eigen::Matrix<float, 4, Eigen::Dynamic>> xyzi(
      scan.xyzi.data(), 4, static_cast<Eigen::Index>(scan.size()));
  {
    ScopedTimer timer("labelling/project");
    projector.project(xyzi.topRows<3>(), projected);
  }
  cv::Mat filtered;
  {
    ScopedTimer timer("labelling/filter_labels");
    filtered = filterLabels(segmentation, options.filter);
  }
  std::vector<std::uint32_t> labels;
  {
    ScopedTimer timer("labelling/label_points");
    labelPointsFromImage(*projected, filtered.ptr<std::uint8_t>(), filtered.cols, filtered.rows,
                         filtered.step, cityscapes::kUnlabeled, &labels);
  }
  if (options.reject_occluded) {
    ScopedTimer timer("labelling/reject_occluded");
    rejectOccludedPoints(*projected, projector.width(), projector.height(), options.occlusion,
                         cityscapes::kUnlabeled, &labels);
  }
  if (options.check_geometry) {
    ScopedTimer timer("labelling/label_geometry");
    CityscapesLidarChecks checks;
    checks.geometry = options.geometry;
    checks.high_terrain_is_vegetation = options.high_terrain_is_vegetation;
    checks.curbs = options.check_curbs;
    checks.curb = options.curbs;
    applyCityscapesLidarChecks(xyzi.topRows<3>(), checks, cityscapes::kUnlabeled, &labels);
  }
  return labels;
}

std::uint32_t mapLabelAt(const mapping::SemanticOcTree& tree, const Eigen::Vector3f& point_map) {
  const mapping::SemanticOcTreeNode* node =
      tree.search(point_map.x(), point_map.y(), point_map.z());
  if (!node || !tree.isNodeOccupied(node)) return cityscapes::kUnlabeled;
  return tree.mostLikelyLabel(*node, cityscapes::kUnlabeled);
}

SequenceMapScores scoreSequenceMaps(const std::string& sequence_dir, Segmenter* segmenter,
                                    int max_frames, const mapping::SemanticMappingConfig& config,
                                    int label_every, const FrameProgress& on_frame) {
  const LabelImageSource segment = [segmenter](const std::string&, const cv::Mat& image) {
    return filterLabels(segmenter->segment(image), segmenter->card().label_filter);
  };
  return scoreSequenceMaps(sequence_dir, segment, max_frames, config, label_every, on_frame);
}

SequenceMapScores scoreSequenceMaps(const std::string& sequence_dir,
                                    const LabelImageSource& label_image_of, int max_frames,
                                    const mapping::SemanticMappingConfig& config, int label_every,
                                    const FrameProgress& on_frame) {
  if (label_every < 1) throw std::invalid_argument("scoreSequenceMaps: label_every must be >= 1");
  std::vector<std::string> names = listSemanticKittiFrames(sequence_dir);
  if (max_frames > 0 && static_cast<int>(names.size()) > max_frames) names.resize(max_frames);
  const std::vector<Eigen::Isometry3d> poses = kitti::readKittiPoses(sequence_dir + "/poses.txt");
  mapping::SemanticMappingSession camera_map(config);
  mapping::SemanticMappingSession human_map(config);
  constexpr double kFramePeriod_s = 0.1;
  std::map<std::size_t, Eigen::Isometry3d> streamed_poses;  // by frame index (label_every > 1)
  camera_map.setPoseLookup(
      [&](double stamp, const std::string&) -> std::optional<Eigen::Isometry3d> {
        const auto it =
            streamed_poses.find(static_cast<std::size_t>(std::lround(stamp / kFramePeriod_s)));
        if (it == streamed_poses.end()) return std::nullopt;
        return it->second;
      });
  struct Kept {
    Eigen::Matrix3Xf points_in_view;
    std::vector<std::uint8_t> truth_in_view;
    Eigen::Isometry3d T_w_velo;
  };
  std::vector<Kept> kept;
  for (const std::string& name : names) {
    const SemanticKittiFrame frame = readSemanticKittiFrame(sequence_dir, name);
    const std::size_t index = std::stoul(name);
    if (index >= poses.size()) {
      throw std::runtime_error(sequence_dir + "/poses.txt: no pose for frame " + name);
    }
    const kitti::CameraProjection projection =
        readSemanticKittiCamera(sequence_dir, frame.image.cols, frame.image.rows);
    const Eigen::Isometry3d T_velo_cam0 = projection.T_cam0_velo.inverse();
    const Eigen::Isometry3d T_w_velo = T_velo_cam0 * poses[index] * projection.T_cam0_velo;
    const Eigen::Map<const Eigen::Matrix<float, 4, Eigen::Dynamic>> xyzi(
        frame.scan.xyzi.data(), 4, static_cast<Eigen::Index>(frame.scan.size()));
    const Eigen::Matrix3Xf points = xyzi.topRows<3>();

    const int width = frame.image.cols, height = frame.image.rows;
    const mapping::CameraModel camera{projection.P_rect, projection.R_rect, projection.T_cam0_velo,
                                      width, height};
    if (label_every == 1) {
      const cv::Mat labels =
          checkedLabelImage(label_image_of(name, frame.image), frame.image, sequence_dir, name);
      const mapping::LabelImageView view{labels.ptr<std::uint8_t>(), labels.cols, labels.rows,
                                         labels.step};
      camera_map.insertScan(points, T_w_velo, &view, &camera);
    } else {
      const double stamp = kFramePeriod_s * static_cast<double>(index);
      streamed_poses[index] = T_w_velo;
      camera_map.setCameraView(camera);
      if (kept.size() % static_cast<std::size_t>(label_every) == 0) {
        const cv::Mat labels =
            checkedLabelImage(label_image_of(name, frame.image), frame.image, sequence_dir, name);
        camera_map.addLabelImage(stamp,
                                 mapping::LabelImageView{labels.ptr<std::uint8_t>(), labels.cols,
                                                         labels.rows, labels.step},
                                 camera);
      }
      camera_map.addScan(stamp, "velo", points);
    }

    const PointProjector projector(projection.P_rect, projection.R_rect, projection.T_cam0_velo,
                                   width, height);
    ProjectedPoints projected;
    projector.project(points, &projected);
    Kept k;
    k.T_w_velo = T_w_velo;
    k.points_in_view.resize(3, static_cast<Eigen::Index>(projected.validCount()));
    std::vector<std::uint32_t> human;
    Eigen::Index n = 0;
    for (std::size_t i = 0; i < projected.size(); ++i) {
      if (!projected.valid[i]) continue;
      k.points_in_view.col(n++) = points.col(static_cast<Eigen::Index>(i));
      k.truth_in_view.push_back(frame.truth[i]);
      human.push_back(frame.truth[i]);
    }
    human_map.insertScanWithPointLabels(k.points_in_view, T_w_velo, human, kIgnoredLabel);
    kept.push_back(std::move(k));
    if (on_frame) on_frame(kept.size(), names.size());
  }
  if (label_every > 1) camera_map.flush();
  SequenceMapScores scores;
  // Lookups only from here on: each map held once (the tree), not beside its insertion grid.
  camera_map.treeReleasingGrid().updateInnerOccupancy();
  human_map.treeReleasingGrid().updateInnerOccupancy();
  scores.map_voxels = mapping::countOccupiedFinestVoxels(camera_map.tree());
  for (const Kept& k : kept) {
    const Eigen::Matrix3Xf points_map =
        (k.T_w_velo.linear().cast<float>() * k.points_in_view).colwise() +
        k.T_w_velo.translation().cast<float>();
    for (Eigen::Index i = 0; i < points_map.cols(); ++i) {
      const std::uint8_t truth = k.truth_in_view[static_cast<std::size_t>(i)];
      scores.camera.add(truth, mapLabelAt(camera_map.tree(), points_map.col(i)));
      scores.ceiling.add(truth, mapLabelAt(human_map.tree(), points_map.col(i)));
    }
  }
  return scores;
}

}  // namespace evaluation
}  // namespace inekf_semantic_mapping
