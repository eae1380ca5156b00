// The aligned-corners bilinear Resize layer against OpenCV's own: the same floats for every
// shape (upsampling as ESPNetv2's decoder does, odd sizes, downsampling, one row, no change), the
// built-in layer kept for the other modes, and the registration that makes networks use it.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>
#include <opencv2/dnn/all_layers.hpp>
#include <opencv2/dnn/shape_utils.hpp>
#include <vector>

#include "inekf_semantic_mapping/perception/dnn_bilinear_resize.h"

namespace perception = inekf_semantic_mapping::perception;

namespace {

cv::dnn::LayerParams resizeParams(const std::string& interpolation, bool align_corners,
                                  int out_height, int out_width) {
  cv::dnn::LayerParams params;
  params.name = "up";
  params.type = "Resize";
  params.set("interpolation", interpolation);
  params.set("align_corners", align_corners);
  params.set("height", out_height);
  params.set("width", out_width);
  return params;
}

cv::Mat randomBlob(int channels, int height, int width) {
  const int sizes[] = {1, channels, height, width};
  cv::Mat blob(4, sizes, CV_32F);
  cv::randn(blob, 0.0, 3.0);
  return blob;
}

// One layer's forward pass through the Layer interface, as a Net drives it.
cv::Mat runLayer(const cv::Ptr<cv::dnn::Layer>& layer, const cv::Mat& input) {
  std::vector<cv::dnn::MatShape> input_shapes{cv::dnn::shape(input)}, output_shapes, internals;
  layer->getMemoryShapes(input_shapes, 1, output_shapes, internals);
  std::vector<cv::Mat> inputs{input};
  std::vector<cv::Mat> outputs{cv::Mat(output_shapes[0], CV_32F, cv::Scalar(-1e30))};
  std::vector<cv::Mat> internal_blobs;
  layer->finalize(cv::_InputArray(inputs), cv::_OutputArray(outputs));
  layer->forward(cv::_InputArray(inputs), cv::_OutputArray(outputs),
                 cv::_OutputArray(internal_blobs));
  return outputs[0];
}

double maxAbsDifference(const cv::Mat& a, const cv::Mat& b) {
  EXPECT_EQ(cv::dnn::shape(a), cv::dnn::shape(b));
  return cv::norm(a.reshape(1, 1), b.reshape(1, 1), cv::NORM_INF);
}

}  // namespace

TEST(DnnBilinearResize, EqualsOpenCvsLayerForEveryShape) {
  cv::setRNGSeed(7);
  struct Case {
    int channels, in_h, in_w, out_h, out_w;
  };
  const std::vector<Case> cases = {
      {20, 128, 416, 256, 832},  // ESPNetv2's last upsampling at 832x256
      {32, 64, 208, 128, 416},   // a decoder step
      {3, 5, 7, 9, 13},          // odd sizes
      {4, 11, 9, 4, 5},          // downsampling
      {2, 6, 8, 1, 15},          // one output row
      {2, 6, 8, 12, 1},          // one output column
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(cv::format("%d x %dx%d -> %dx%d", c.channels, c.in_h, c.in_w, c.out_h, c.out_w));
    const cv::Mat input = randomBlob(c.channels, c.in_h, c.in_w);
    cv::dnn::LayerParams params = resizeParams("bilinear", true, c.out_h, c.out_w);
    const cv::Mat expected = runLayer(cv::dnn::ResizeLayer::create(params), input);
    const cv::Mat actual = runLayer(perception::createResizeLayer(params), input);
    EXPECT_EQ(maxAbsDifference(expected, actual), 0.0);
  }
}

TEST(DnnBilinearResize, SameSizeCopiesTheInput) {
  const cv::Mat input = randomBlob(3, 6, 10);
  cv::dnn::LayerParams params = resizeParams("bilinear", true, 6, 10);
  EXPECT_EQ(maxAbsDifference(runLayer(perception::createResizeLayer(params), input), input), 0.0);
}

TEST(DnnBilinearResize, OtherModesKeepOpenCvsLayer) {
  cv::dnn::LayerParams aligned = resizeParams("bilinear", true, 8, 8);
  EXPECT_TRUE(perception::createResizeLayer(aligned).dynamicCast<cv::dnn::ResizeLayer>().empty());
  cv::dnn::LayerParams nearest = resizeParams("nearest", false, 8, 8);
  cv::dnn::LayerParams asymmetric = resizeParams("bilinear", false, 8, 8);
  cv::dnn::LayerParams half_pixel = resizeParams("bilinear", false, 8, 8);
  half_pixel.set("half_pixel_centers", true);
  cv::dnn::LayerParams opencv_linear = resizeParams("opencv_linear", false, 8, 8);
  for (cv::dnn::LayerParams* params : {&nearest, &asymmetric, &half_pixel, &opencv_linear}) {
    SCOPED_TRACE(params->get<cv::String>("interpolation"));
    EXPECT_FALSE(
        perception::createResizeLayer(*params).dynamicCast<cv::dnn::ResizeLayer>().empty());
  }
}

TEST(DnnBilinearResize, NetworksReadAfterRegistrationUseIt) {
  perception::useFastBilinearResize();
  perception::useFastBilinearResize();  // a second call changes nothing
  cv::dnn::LayerParams params = resizeParams("bilinear", true, 24, 40);
  cv::dnn::Net net;
  const int id = net.addLayerToPrev(params.name, params.type, params);
  net.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
  const cv::Mat input = randomBlob(5, 12, 20);
  net.setInput(input);
  const cv::Mat output = net.forward();
  EXPECT_TRUE(net.getLayer(id).dynamicCast<cv::dnn::ResizeLayer>().empty())
      << "the network's Resize layer is OpenCV's own";
  const cv::Mat expected = runLayer(cv::dnn::ResizeLayer::create(params), input);
  EXPECT_EQ(maxAbsDifference(expected, output), 0.0);
}
