// Segmenter's input preparation (segmenter_input.h).
#include "segmenter_input.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/perception/segmenter.h"

namespace inekf_semantic_mapping {
namespace perception {
namespace detail {
namespace {

int roundUpToMultiple(int value, int multiple) {
  return (value + multiple - 1) / multiple * multiple;
}

}  // namespace

cv::Mat toBgr(const cv::Mat& image) {
  if (image.empty()) throw SegmentationError("segment(): empty image");
  if (image.depth() != CV_8U)
    throw SegmentationError("segment(): unsupported pixel depth " + std::to_string(image.depth()) +
                            " (need 8-bit gray, BGR or BGRA)");
  cv::Mat bgr;
  switch (image.channels()) {
    case 1:
      cv::cvtColor(image, bgr, cv::COLOR_GRAY2BGR);
      return bgr;
    case 3:
      return image;
    case 4:
      cv::cvtColor(image, bgr, cv::COLOR_BGRA2BGR);
      return bgr;
    default:
      throw SegmentationError("segment(): unsupported channel count " +
                              std::to_string(image.channels()) + " (need 1, 3 or 4)");
  }
}

PreparedInput prepareInput(const cv::Mat& bgr, const ModelCard& card) {
  PreparedInput prepared;
  switch (card.resize_policy) {
    case ResizePolicy::kResize:
      cv::resize(bgr, prepared.network_image, cv::Size(card.input_width, card.input_height), 0, 0,
                 cv::INTER_LINEAR);
      prepared.valid_region = cv::Rect(0, 0, card.input_width, card.input_height);
      break;
    case ResizePolicy::kLetterbox: {
      const double scale = std::min(static_cast<double>(card.input_width) / bgr.cols,
                                    static_cast<double>(card.input_height) / bgr.rows);
      const int width =
          std::clamp(static_cast<int>(std::lround(bgr.cols * scale)), 1, card.input_width);
      const int height =
          std::clamp(static_cast<int>(std::lround(bgr.rows * scale)), 1, card.input_height);
      const int left = (card.input_width - width) / 2;
      const int top = (card.input_height - height) / 2;
      cv::Mat resized;
      cv::resize(bgr, resized, cv::Size(width, height), 0, 0, cv::INTER_LINEAR);
      // Pad with the mean color so the padding normalizes to zero.
      const cv::Scalar mean_bgr = card.swap_rb
                                      ? cv::Scalar(card.mean[2], card.mean[1], card.mean[0])
                                      : cv::Scalar(card.mean[0], card.mean[1], card.mean[2]);
      cv::copyMakeBorder(resized, prepared.network_image, top, card.input_height - height - top,
                         left, card.input_width - width - left, cv::BORDER_CONSTANT, mean_bgr);
      prepared.valid_region = cv::Rect(left, top, width, height);
      break;
    }
    case ResizePolicy::kTiles:  // handled by segmentTiles()
    case ResizePolicy::kPadToMultiple: {
      cv::Mat resized = bgr;
      cv::Size target = bgr.size();
      if (card.input_width > 0 && card.input_height > 0) {
        target = cv::Size(card.input_width, card.input_height);
      } else if (card.resize_factor != 1.0) {
        target =
            cv::Size(std::max(1, static_cast<int>(std::lround(bgr.cols * card.resize_factor))),
                     std::max(1, static_cast<int>(std::lround(bgr.rows * card.resize_factor))));
      }
      // INTER_AREA: what scripts/train_unet.py uses to make its training images.
      if (target != bgr.size()) cv::resize(bgr, resized, target, 0, 0, cv::INTER_AREA);
      const int padded_width = roundUpToMultiple(resized.cols, card.pad_multiple);
      const int padded_height = roundUpToMultiple(resized.rows, card.pad_multiple);
      // Reflect (not zero) padding: the network has seen no black borders in training.
      const int border = std::max(padded_width - resized.cols, padded_height - resized.rows);
      if (border >= std::min(resized.cols, resized.rows)) {
        cv::copyMakeBorder(resized, prepared.network_image, 0, padded_height - resized.rows, 0,
                           padded_width - resized.cols, cv::BORDER_REPLICATE);
      } else {
        cv::copyMakeBorder(resized, prepared.network_image, 0, padded_height - resized.rows, 0,
                           padded_width - resized.cols, cv::BORDER_REFLECT_101);
      }
      prepared.valid_region = cv::Rect(0, 0, resized.cols, resized.rows);
      break;
    }
  }
  return prepared;
}

// By a lookup table: 256 values, whatever the image's size.
cv::Mat applyGamma(const cv::Mat& bgr, double gamma) {
  cv::Mat table(1, 256, CV_8U);
  for (int v = 0; v < 256; ++v) {
    table.at<std::uint8_t>(v) = cv::saturate_cast<std::uint8_t>(255.0 * std::pow(v / 255.0, gamma));
  }
  cv::Mat out;
  cv::LUT(bgr, table, out);
  return out;
}

cv::Mat standardizeColors(const cv::Mat& bgr, const ModelCard& card) {
  cv::Scalar image_mean, image_std;
  cv::meanStdDev(bgr, image_mean, image_std);
  std::vector<cv::Mat> channels;
  cv::split(bgr, channels);
  for (int c = 0; c < 3; ++c) {
    // BGR channel c is network channel 2 - c when the network takes RGB.
    const int network_channel = card.swap_rb ? 2 - c : c;
    const double gain = card.color_std[network_channel] / std::max(image_std[c], 1.0);
    const double offset = card.color_mean[network_channel] - gain * image_mean[c];
    channels[c].convertTo(channels[c], CV_8U, gain, offset);  // saturates at 0 and 255
  }
  cv::Mat standardized;
  cv::merge(channels, standardized);
  return standardized;
}

}  // namespace detail
}  // namespace perception
}  // namespace inekf_semantic_mapping
