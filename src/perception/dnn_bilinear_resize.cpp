// The aligned-corners bilinear Resize layer (see the header for why it exists). The arithmetic
// is the built-in layer's, term for term and in the same order: sample position y * scale
// truncated to its row, the fraction, and out = a + fy (c - a) + fx (b - a + fy (d - b - c + a)),
// so that both give the same floats; only the loop order and the threading differ.
#include "inekf_semantic_mapping/perception/dnn_bilinear_resize.h"

#include <algorithm>
#include <mutex>
#include <opencv2/core.hpp>
#include <opencv2/dnn/all_layers.hpp>
#include <vector>

namespace inekf_semantic_mapping {
namespace perception {
namespace {

// Where each output index samples one input axis with aligned corners: the lower neighbour, the
// upper one (clamped) and the fraction between them.
struct SampleTable {
  SampleTable() = default;
  SampleTable(int in_size, int out_size) : lower(out_size), upper(out_size), fraction(out_size) {
    const float scale = out_size > 1 ? static_cast<float>(in_size - 1) / (out_size - 1)
                                     : static_cast<float>(in_size) / out_size;
    for (int i = 0; i < out_size; ++i) {
      const float position = i * scale;
      lower[i] = static_cast<int>(position);
      upper[i] = std::min(lower[i] + 1, in_size - 1);
      fraction[i] = position - lower[i];
    }
  }
  std::vector<int> lower, upper;
  std::vector<float> fraction;
};

class AlignedBilinearResizeLayer : public cv::dnn::Layer {
 public:
  explicit AlignedBilinearResizeLayer(const cv::dnn::LayerParams& params)
      : builtin_(cv::dnn::ResizeLayer::create(params)) {
    setParamsFrom(params);
  }

  bool getMemoryShapes(const std::vector<cv::dnn::MatShape>& inputs, const int required_outputs,
                       std::vector<cv::dnn::MatShape>& outputs,
                       std::vector<cv::dnn::MatShape>& internals) const override {
    return builtin_->getMemoryShapes(inputs, required_outputs, outputs, internals);
  }

  bool supportBackend(int backend_id) override { return backend_id == cv::dnn::DNN_BACKEND_OPENCV; }

  void finalize(cv::InputArrayOfArrays inputs_arr, cv::OutputArrayOfArrays outputs_arr) override {
    builtin_->finalize(inputs_arr, outputs_arr);  // for the fallback of other depths
    std::vector<cv::Mat> inputs, outputs;
    inputs_arr.getMatVector(inputs);
    outputs_arr.getMatVector(outputs);
    in_height_ = inputs[0].size[2];
    in_width_ = inputs[0].size[3];
    out_height_ = outputs[0].size[2];
    out_width_ = outputs[0].size[3];
    rows_ = SampleTable(in_height_, out_height_);
    cols_ = SampleTable(in_width_, out_width_);
  }

  void forward(cv::InputArrayOfArrays inputs_arr, cv::OutputArrayOfArrays outputs_arr,
               cv::OutputArrayOfArrays internals_arr) override {
    if (inputs_arr.depth() != CV_32F) {
      builtin_->forward(inputs_arr, outputs_arr, internals_arr);
      return;
    }
    std::vector<cv::Mat> inputs, outputs;
    inputs_arr.getMatVector(inputs);
    outputs_arr.getMatVector(outputs);
    const cv::Mat& input = inputs[0];
    cv::Mat& output = outputs[0];
    if (out_height_ == in_height_ && out_width_ == in_width_) {
      if (input.data != output.data) input.copyTo(output);
      return;
    }
    CV_Assert(input.isContinuous() && output.isContinuous());
    const int planes = input.size[0] * input.size[1];
    const std::size_t in_plane = static_cast<std::size_t>(in_height_) * in_width_;
    const std::size_t out_plane = static_cast<std::size_t>(out_height_) * out_width_;
    const float* source = input.ptr<float>();
    float* target = output.ptr<float>();
    // One task per output row of one plane; nstripes keeps OpenCV from scheduling thousands.
    const int rows = planes * out_height_;
    cv::parallel_for_(
        cv::Range(0, rows),
        [&](const cv::Range& range) {
          for (int r = range.start; r < range.end; ++r) {
            const int plane = r / out_height_;
            const int y = r % out_height_;
            const float* r0 =
                source + plane * in_plane + static_cast<std::size_t>(rows_.lower[y]) * in_width_;
            const float* r1 =
                source + plane * in_plane + static_cast<std::size_t>(rows_.upper[y]) * in_width_;
            float* out = target + plane * out_plane + static_cast<std::size_t>(y) * out_width_;
            const float fy = rows_.fraction[y];
            for (int x = 0; x < out_width_; ++x) {
              const int x0 = cols_.lower[x];
              const int x1 = cols_.upper[x];
              out[x] =
                  r0[x0] + fy * (r1[x0] - r0[x0]) +
                  cols_.fraction[x] * (r0[x1] - r0[x0] + fy * (r1[x1] - r0[x1] - r1[x0] + r0[x0]));
            }
          }
        },
        std::max(1.0, rows / 64.0));
  }

 private:
  cv::Ptr<cv::dnn::ResizeLayer> builtin_;
  int in_height_ = 0, in_width_ = 0, out_height_ = 0, out_width_ = 0;
  SampleTable rows_, cols_;
};

}  // namespace

cv::Ptr<cv::dnn::Layer> createResizeLayer(cv::dnn::LayerParams& params) {
  const bool aligned_bilinear = params.get<cv::String>("interpolation", "") == "bilinear" &&
                                params.get<bool>("align_corners", false) &&
                                !params.get<bool>("half_pixel_centers", false);
  if (aligned_bilinear) return cv::makePtr<AlignedBilinearResizeLayer>(params);
  return cv::dnn::ResizeLayer::create(params);
}

void useFastBilinearResize() {
  static std::once_flag once;
  std::call_once(once, [] { cv::dnn::LayerFactory::registerLayer("Resize", createResizeLayer); });
}

}  // namespace perception
}  // namespace inekf_semantic_mapping
