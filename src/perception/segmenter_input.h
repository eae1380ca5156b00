// Segmenter's input preparation, private to src/perception: the image as 8-bit BGR, its tone
// (gamma) and colour statistics brought to the network's, and the network input made from it by
// the card's resize policy (the kTiles policy cuts its own inputs in segmentTiles).
// training/preprocess.py mirrors these steps in numpy for the networks' training images.
#pragma once

#include <opencv2/core.hpp>

#include "inekf_semantic_mapping/perception/model_card.h"

namespace inekf_semantic_mapping {
namespace perception {
namespace detail {

// The image as 8-bit BGR, whatever of the supported pixel types it came in; throws
// SegmentationError for the others.
cv::Mat toBgr(const cv::Mat& image);

// v' = 255 (v / 255)^gamma per channel.
cv::Mat applyGamma(const cv::Mat& bgr, double gamma);

// Maps each channel affinely so its mean and standard deviation over the image become the
// card's color_mean / color_std (given in the network's channel order).
cv::Mat standardizeColors(const cv::Mat& bgr, const ModelCard& card);

// The network input made from an image, and where the image lies in it.
struct PreparedInput {
  cv::Mat network_image;  // BGR, what blobFromImage receives
  cv::Rect valid_region;  // the image's pixels inside network_image (output is cropped to it)
};

// The network input for the card's kResize, kLetterbox or kPadToMultiple policy.
PreparedInput prepareInput(const cv::Mat& bgr, const ModelCard& card);

}  // namespace detail
}  // namespace perception
}  // namespace inekf_semantic_mapping
