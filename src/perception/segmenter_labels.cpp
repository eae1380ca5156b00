// The label-image functions of segmenter.h: the label filter, palette colours, overlays and
// trainIds.
#include <cstdint>
#include <opencv2/imgproc.hpp>

#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "inekf_semantic_mapping/perception/segmenter.h"
#include "segmenter_input.h"

namespace inekf_semantic_mapping {
namespace perception {

cv::Mat colorizeLabelIds(const cv::Mat& label_ids) {
  CV_Assert(label_ids.type() == CV_8UC1);
  cv::Mat lut(1, 256, CV_8UC3, cv::Scalar(0, 0, 0));
  for (const cityscapes::LabelInfo& info : cityscapes::kLabels)
    lut.at<cv::Vec3b>(info.label_id) = cv::Vec3b(info.r, info.g, info.b);
  cv::Mat three_channel, rgb;
  cv::cvtColor(label_ids, three_channel, cv::COLOR_GRAY2BGR);
  cv::LUT(three_channel, lut, rgb);
  return rgb;
}

cv::Mat overlayLabelIds(const cv::Mat& bgr_image, const cv::Mat& label_ids, double alpha) {
  const cv::Mat colors = colorizeLabelIds(label_ids);
  cv::Mat rgb_image;
  cv::cvtColor(detail::toBgr(bgr_image), rgb_image, cv::COLOR_BGR2RGB);
  if (rgb_image.size() != colors.size())
    throw SegmentationError("overlay: image and label image differ in size");
  cv::Mat blended;
  cv::addWeighted(colors, alpha, rgb_image, 1.0 - alpha, 0.0, blended);
  return blended;
}

cv::Mat labelIdsToTrainIds(const cv::Mat& label_ids) {
  CV_Assert(label_ids.type() == CV_8UC1);
  cv::Mat lut(1, 256, CV_8U);
  for (int i = 0; i < 256; ++i) lut.at<std::uint8_t>(i) = cityscapes::labelIdToTrainId(i);
  cv::Mat train_ids;
  cv::LUT(label_ids, lut, train_ids);
  return train_ids;
}

cv::Mat filterLabels(const Segmentation& segmentation, double min_confidence,
                     int boundary_radius_px) {
  CV_Assert(segmentation.label_ids.type() == CV_8UC1);
  cv::Mat filtered = segmentation.label_ids.clone();
  if (boundary_radius_px > 0) {
    // A pixel is near a boundary when the labels in its window are not all equal: the
    // window's maximum (dilation) differs from its minimum (erosion).
    const cv::Mat window = cv::getStructuringElement(
        cv::MORPH_RECT, cv::Size(2 * boundary_radius_px + 1, 2 * boundary_radius_px + 1));
    cv::Mat window_max, window_min;
    cv::dilate(segmentation.label_ids, window_max, window, cv::Point(-1, -1), 1,
               cv::BORDER_REPLICATE);
    cv::erode(segmentation.label_ids, window_min, window, cv::Point(-1, -1), 1,
              cv::BORDER_REPLICATE);
    filtered.setTo(cityscapes::kUnlabeled, window_max != window_min);
  }
  if (min_confidence > 0.0) {
    CV_Assert(segmentation.confidence.type() == CV_32FC1 &&
              segmentation.confidence.size() == segmentation.label_ids.size());
    filtered.setTo(cityscapes::kUnlabeled, segmentation.confidence < min_confidence);
  }
  return filtered;
}

}  // namespace perception
}  // namespace inekf_semantic_mapping
