// Scoring camera labels at lidar points against human point labels (SemanticKITTI), and the
// labelling path from a segmentation to per-point labels that the scores are taken on. ROS-free;
// used by the evaluate_semantics and evaluate_map tools and the real-data tests. A layer above
// perception and mapping (it builds maps to score them), so that neither depends on the other.
#pragma once

#include <cstdint>
#include <functional>
#include <opencv2/core/mat.hpp>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/kitti/calibration.h"
#include "inekf_semantic_mapping/kitti/velodyne.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"
#include "inekf_semantic_mapping/perception/label_geometry.h"
#include "inekf_semantic_mapping/perception/projection.h"
#include "inekf_semantic_mapping/perception/segmenter.h"

namespace inekf_semantic_mapping {
namespace evaluation {

// Confusion counts of camera labels (Cityscapes labelIds, 0 = no label) against true labels
// (Cityscapes labelIds of scored classes, kIgnoredLabel = not scored). A camera label of a class
// that is not scored (sky, wall...) counts as wrong.
class PointLabelScore {
 public:
  PointLabelScore();
  void add(std::uint8_t truth, std::uint32_t predicted);
  void merge(const PointLabelScore& other);

  std::uint64_t scored() const;    // points with a scored true label
  std::uint64_t labelled() const;  // of those, the ones with a camera label
  std::uint64_t correct() const;
  double coverage() const;  // labelled / scored
  double accuracy() const;  // correct / labelled (NaN when none)

  // Per class, over labelled points: points of that true class, points the camera gave that
  // class, both; and scored points of that true class left without a camera label.
  std::uint64_t truthCount(std::uint8_t label_id) const;
  std::uint64_t predictedCount(std::uint8_t label_id) const;
  std::uint64_t truePositives(std::uint8_t label_id) const;
  std::uint64_t unlabelledCount(std::uint8_t label_id) const;
  double iou(std::uint8_t label_id) const;  // NaN when the class is neither true nor predicted
  double meanIoU() const;                   // over the scored classes present in the truth
  // The benchmarks' convention (SemanticKITTI's api, Cityscapes' scripts): a true point left
  // without a label is a miss of its class, and a class predicted where the truth has none
  // counts with IoU 0. Over the scored classes true or predicted anywhere. Lower than meanIoU
  // wherever a filter leaves points unlabelled.
  double meanIoUWithMisses() const;
  // Points of true class `truth` the camera labelled `predicted` (0: no label).
  std::uint64_t count(std::uint8_t truth, std::uint8_t predicted) const {
    return at(truth, predicted);
  }

  // {"scored":..,"labelled":..,"coverage":..,"accuracy":..,"miou":..,"miou_with_misses":..,
  //  "classes":{name:{..}}}
  std::string toJson() const;

 private:
  static constexpr int kRows = 256;
  static constexpr int kCols = 256;
  std::uint64_t at(int truth, int predicted) const {
    return confusion_[static_cast<std::size_t>(truth) * kCols + predicted];
  }
  std::vector<std::uint64_t> confusion_;  // [truth][predicted]
};

// One SemanticKITTI frame with what scoring needs.
struct SemanticKittiFrame {
  std::string name;  // "000000"
  cv::Mat image;     // image_2, BGR
  kitti::VelodyneScan scan;
  std::vector<std::uint8_t> truth;  // per point: Cityscapes labelId or kIgnoredLabel
};

// The frames of a SemanticKITTI sequence folder that have velodyne/, labels/ and image_2/ files,
// sorted. When `incomplete` is given it receives, sorted, the scans in velodyne/ that lack their
// label or image file (what a caller tells its user it skipped). Throws std::runtime_error naming
// the folder when it has no complete frame.
std::vector<std::string> listSemanticKittiFrames(const std::string& sequence_dir,
                                                 std::vector<std::string>* incomplete = nullptr);

// Throws std::runtime_error / kitti::KittiFormatError naming the file that cannot be read, or
// when the label file does not have one label per point.
SemanticKittiFrame readSemanticKittiFrame(const std::string& sequence_dir, const std::string& name);

// image_2's projection from the sequence's calib.txt (P2, Tr).
kitti::CameraProjection readSemanticKittiCamera(const std::string& sequence_dir, int width,
                                                int height);

// The labelling path from a segmentation to point labels, as the mapping uses it.
struct PointLabellingOptions {
  perception::LabelFilterOptions filter;
  bool reject_occluded = true;
  perception::OcclusionOptions occlusion;
  // rejectGeometricallyInconsistentLabels with the Cityscapes kinds (and, with
  // high_terrain_is_vegetation, cityscapesHighFlatRelabels): the session's defaults.
  bool check_geometry = true;
  perception::LabelGeometryOptions geometry;
  bool high_terrain_is_vegetation = true;
  // ... and then road beyond a kerb is sidewalk (applyCityscapesLidarChecks; with
  // check_geometry only): the session's default.
  bool check_curbs = true;
  perception::CurbOptions curbs;
};

// Per point of the scan: the camera's labelId at its pixel after filterLabels, 0 for points
// outside the image, hidden from the camera (when reject_occluded), filtered or ruled out by the
// lidar geometry (when check_geometry). projected: filled with the scan's projection.
std::vector<std::uint32_t> labelScanPoints(const perception::Segmentation& segmentation,
                                           const perception::PointProjector& projector,
                                           const kitti::VelodyneScan& scan,
                                           const PointLabellingOptions& options,
                                           perception::ProjectedPoints* projected);

// The package's one map metric, "the map at the lidar points": each labelled lidar point (map
// frame) takes the most likely class of its voxel; cityscapes::kUnlabeled (the point is not
// covered) when there is no voxel, it is free, or it has no class evidence. Accuracy and IoU per
// class are over the covered points, mIoU over the scored classes present in the truth
// (PointLabelScore). scoreSequenceMaps (SemanticKITTI) and the evaluate_map tool (any drive with
// labelled scans: the synthetic drives of the demo and the e2e tests) score maps with it.
std::uint32_t mapLabelAt(const mapping::SemanticOcTree& tree, const Eigen::Vector3f& point_map);

// The map at the lidar points (the map mIoU): the sequence's scans go through a
// mapping::SemanticMappingSession with the poses of poses.txt (T_w_velo = inv(Tr) P Tr) twice,
// once with the camera's label images (the node's path: the card's label filter, the session's
// occlusion test) and once with the human labels of the points in the camera's view (the
// ceiling of the same map). Then every scored point in the camera's view takes the most likely
// class of its voxel (none: a free or classless voxel, counted as not covered). `config` is the
// mapping config of both maps (its defaults: the node's).
// label_every > 1: only every label_every-th frame is segmented, as by a segmentation slower than
// the lidar; the camera map's scans and label images then stream through the session's pairing
// as the node's do (stamps 0.1 s per frame), so that a scan without its own label image borrows
// a neighbour's (config.label_neighbour_s).
struct SequenceMapScores {
  PointLabelScore camera;   // map built from the camera labels
  PointLabelScore ceiling;  // map built from the human labels
  std::size_t map_voxels = 0;
};
// on_frame (optional) is called after each frame goes into both maps with the frames done and
// the frames in all (a tool's progress line).
using FrameProgress = std::function<void(std::size_t done, std::size_t total)>;
SequenceMapScores scoreSequenceMaps(const std::string& sequence_dir,
                                    perception::Segmenter* segmenter, int max_frames = -1,
                                    const mapping::SemanticMappingConfig& config = {},
                                    int label_every = 1, const FrameProgress& on_frame = {});

// Where the camera map's label images come from: a frame's name (as listSemanticKittiFrames
// gives it) and image_2 in, its label image out (CV_8UC1 Cityscapes labelIds, the image's size,
// the card's label filter applied). The Segmenter overload above segments each frame; a tool
// that has segmented the frames already (evaluate_semantics' label pass) hands its own back.
using LabelImageSource = std::function<cv::Mat(const std::string& frame, const cv::Mat& image)>;
SequenceMapScores scoreSequenceMaps(const std::string& sequence_dir,
                                    const LabelImageSource& label_image_of, int max_frames = -1,
                                    const mapping::SemanticMappingConfig& config = {},
                                    int label_every = 1, const FrameProgress& on_frame = {});

}  // namespace evaluation
}  // namespace inekf_semantic_mapping
