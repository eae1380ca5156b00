// A faster stand-in for OpenCV dnn's bilinear Resize layer with aligned corners (ONNX Resize,
// coordinate_transformation_mode align_corners: how PyTorch's interpolate(align_corners=True)
// exports, e.g. every upsampling of ESPNetv2's decoder). OpenCV 4.6 computes that case one output
// pixel at a time with an inner loop across the channels, a stride of a whole plane per step, on
// one thread: on 2 cores the adapted ESPNetv2's Resize layers took 59 of its 146 ms per 832x256
// KITTI frame. This layer computes the same formula plane by plane, row by row (the column
// weights tabled once), spread over OpenCV's threads, so its output equals the built-in layer's
// value for value.
#pragma once

#include <opencv2/dnn.hpp>

namespace inekf_semantic_mapping {
namespace perception {

// The layer for `params` as OpenCV's ONNX importer gives them to a "Resize" layer: this one for
// interpolation "bilinear" with align_corners and without half-pixel centres, OpenCV's own
// ResizeLayer for everything else (nearest, half-pixel and OpenCV-linear modes keep their
// implementations). Output shapes are always the built-in layer's.
cv::Ptr<cv::dnn::Layer> createResizeLayer(cv::dnn::LayerParams& params);

// Makes createResizeLayer the constructor of OpenCV dnn's "Resize" layers in this process (once;
// thread-safe). Networks read afterwards use it; the Segmenter calls it before reading a model.
void useFastBilinearResize();

}  // namespace perception
}  // namespace inekf_semantic_mapping
