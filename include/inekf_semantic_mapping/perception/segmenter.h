// Semantic segmentation of camera images with OpenCV's dnn module (CPU). ROS-free: the
// segmentation_node and the segment_image tool are thin faces over this class.
#pragma once

#include <memory>
#include <opencv2/core/mat.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/perception/model_card.h"

namespace inekf_semantic_mapping {
namespace perception {

// Thrown for unusable models (unknown format, output channels that do not match the card) and
// unusable images (empty, unsupported pixel type).
class SegmentationError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Segmentation {
  cv::Mat label_ids;   // CV_8UC1 Cityscapes labelIds, same size as the input image
  cv::Mat confidence;  // CV_32FC1 softmax probability of the chosen class, same size
};

class Segmenter {
 public:
  // Loads `.onnx` (readNetFromONNX) or Torch7 `.net`/`.t7` (readNetFromTorch) and checks with one
  // forward pass that the network's output channel count equals the card's.
  Segmenter(const std::string& model_path, const ModelCard& card, int num_threads = 2);
  ~Segmenter();
  Segmenter(Segmenter&&) noexcept;
  Segmenter& operator=(Segmenter&&) noexcept;

  // image: CV_8UC3 BGR, CV_8UC4 BGRA or CV_8UC1 gray, any size. Not thread-safe (one network).
  // camera_focal_px: the camera's focal length in image pixels (e.g. P_rect(0,0)), 0 when not
  // known; with the kTiles policy and a card that gives network_focal_px it sets the scale.
  Segmentation segment(const cv::Mat& image, double camera_focal_px = 0.0);

  // The factor kTiles scales an image of this size by (1 for the other policies).
  double tileScaleFor(const cv::Size& image_size, double camera_focal_px = 0.0) const;

  const ModelCard& card() const { return card_; }
  const std::string& modelPath() const { return model_path_; }

 private:
  struct Network;
  Segmentation segmentTiles(const cv::Mat& bgr, double camera_focal_px);
  // The probabilities of canvas(tile), and of its mirror image when the card's flip_average
  // says so, added into `sum` with the feathering weights (their outer product into `weight`).
  void accumulateProbabilities(const cv::Mat& canvas, const cv::Rect& tile,
                               const std::vector<float>& column_weight,
                               const std::vector<float>& row_weight, std::vector<cv::Mat>* sum,
                               cv::Mat* weight);
  // One network input and its mirror image, their probabilities averaged (flip_average on the
  // single-pass policies); valid: the image's region of network_image.
  Segmentation segmentMirrorAveraged(const cv::Mat& network_image, const cv::Rect& valid,
                                     const cv::Size& image_size);
  // Argmax and mean winning probability of per-channel probability sums over `weight`, in
  // `valid`, back to image_size.
  Segmentation labelsFromProbabilitySums(const std::vector<cv::Mat>& sum, const cv::Mat& weight,
                                         const cv::Rect& valid, const cv::Size& image_size) const;
  cv::Mat forward(const cv::Mat& network_image);  // 1 x C x h x w scores, checked
  // Throws unless the card names one of the model's outputs, or the model has only one.
  void checkOutputName();
  // Throws when a (first) output is probabilities rather than class scores.
  void checkOutputIsScores(const cv::Mat& output) const;
  bool skipsInArgmax(int channel) const;
  std::string model_path_;
  ModelCard card_;
  std::unique_ptr<Network> network_;
};

// Pixels whose class evidence is weak: the softmax probability of the chosen class is below
// min_confidence, or a pixel with another label lies within boundary_radius_px (square window),
// where the network's label edges and the lidar-camera calibration are least reliable.
// The labelIds with the weak pixels set to 0 (Cityscapes "unlabeled", which the semantic map
// treats as no class evidence). Boundaries are found on the unfiltered labels.
cv::Mat filterLabels(const Segmentation& segmentation, double min_confidence,
                     int boundary_radius_px);
inline cv::Mat filterLabels(const Segmentation& segmentation, const LabelFilterOptions& options) {
  return filterLabels(segmentation, options.min_confidence, options.boundary_radius_px);
}

// CV_8UC1 labelIds -> CV_8UC3 RGB colors from the Cityscapes palette.
cv::Mat colorizeLabelIds(const cv::Mat& label_ids);

// Blends the palette colors over a BGR image: RGB result, alpha = weight of the label colors.
cv::Mat overlayLabelIds(const cv::Mat& bgr_image, const cv::Mat& label_ids, double alpha);

// labelIds -> trainIds (255 for ignored classes), per pixel.
cv::Mat labelIdsToTrainIds(const cv::Mat& label_ids);

}  // namespace perception
}  // namespace inekf_semantic_mapping
