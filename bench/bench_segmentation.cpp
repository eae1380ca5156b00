// Per-frame segmentation throughput on a KITTI-sized image (1242x375), the whole path the node
// runs per frame: fit to the network (resize / reflect-pad / tiles), blob, forward, argmax +
// softmax confidence, crop, back to the image size. Models: the Cityscapes ENet from ../shared
// (skipped when absent) with its built-in card (colour standardization, two undistorted tiles)
// and, for comparison, with the former card (one pass on the image stretched to 1024x512); the
// committed default U-Net; the network adapted to the KITTI camera (scripts/adapt_segmentation.sh:
// $ISM_ADAPTED_MODEL, else output/models/kitti/kitti_adapted.onnx, else
// ../shared/models/kitti-adapted/kitti_adapted.onnx; skipped when there is none) with its card.
// Compare BM_KittiAdaptedKittiFrame with BM_EnetCityscapesKittiFrame: the ratio of their times
// (BM_KittiAdaptedKittiFrameFlipAveraged: the same network averaged with its mirror image).
// BM_ResizeLayer*: ESPNetv2's last upsampling (20 channels, 416x128 -> 832x256, aligned corners)
// in OpenCV dnn's own Resize layer and in the one the Segmenter registers
// (perception/dnn_bilinear_resize.h).
// filterLabels: the confidence / boundary filter at its defaults.
// Threads: 2 (the machine).
//
//   bench_segmentation [--benchmark_min_time=5]
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <memory>
#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>
#include <opencv2/dnn/all_layers.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/perception/dnn_bilinear_resize.h"
#include "inekf_semantic_mapping/perception/model_card.h"
#include "inekf_semantic_mapping/perception/segmenter.h"

namespace perception = inekf_semantic_mapping::perception;

namespace {

std::string sharedDir() {
  const char* from_env = std::getenv("ISM_SHARED_DIR");
  return from_env && *from_env ? from_env : ISM_SHARED_DIR_DEFAULT;
}

// A real KITTI frame when ../shared has one (real content matters little for the cost, but
// keeps the figures honest), else noise of the same size.
cv::Mat kittiImage() {
  const std::string path = sharedDir() + "/data/kitti_object/training/image_2/000000.png";
  cv::Mat image = cv::imread(path, cv::IMREAD_COLOR);
  if (!image.empty() && image.size() != cv::Size(1242, 375)) {
    cv::Mat padded;
    cv::copyMakeBorder(image, padded, 0, std::max(0, 375 - image.rows), 0,
                       std::max(0, 1242 - image.cols), cv::BORDER_REFLECT_101);
    image = padded(cv::Rect(0, 0, 1242, 375)).clone();
  }
  if (image.empty()) {
    image.create(375, 1242, CV_8UC3);
    cv::randu(image, cv::Scalar::all(0), cv::Scalar::all(255));
  }
  return image;
}

void runSegmenter(benchmark::State& state, const std::string& model,
                  const perception::ModelCard& card) {
  if (!std::filesystem::exists(model)) {
    state.SkipWithError(("model not found: " + model).c_str());
    return;
  }
  perception::Segmenter segmenter(model, card, static_cast<int>(state.range(0)));
  const cv::Mat image = kittiImage();
  // The first frame of a size the network has not run at reads it again and allocates its
  // buffers (Segmenter::forward): a camera stream pays that once, so it is not timed.
  segmenter.segment(image);
  for (auto _ : state) {
    perception::Segmentation result = segmenter.segment(image);
    benchmark::DoNotOptimize(result.label_ids.data);
  }
  state.counters["frames_per_s"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

std::string enetPath() { return sharedDir() + "/models/enet-cityscapes/enet-model.net"; }

void BM_EnetCityscapesKittiFrame(benchmark::State& state) {
  runSegmenter(state, enetPath(), perception::builtinEnetCityscapesCard());
}

// The built-in card before tile_max_width: two overlapping 1024x512 tiles.
void BM_EnetCityscapesKittiFrameTwoTiles(benchmark::State& state) {
  perception::ModelCard card = perception::builtinEnetCityscapesCard();
  card.tile_max_width = 0;
  runSegmenter(state, enetPath(), card);
}

void BM_EnetCityscapesKittiFrameStretched(benchmark::State& state) {
  perception::ModelCard card = perception::builtinEnetCityscapesCard();
  card.resize_policy = perception::ResizePolicy::kResize;
  card.color_normalization = perception::ColorNormalization::kNone;
  card.suppress_unlabeled = false;
  runSegmenter(state, enetPath(), card);
}

void BM_UnetSyntheticKittiFrame(benchmark::State& state) {
  const std::string model = std::string(ISM_REPO_ROOT) + "/models/unet_synthetic.onnx";
  if (!std::filesystem::exists(model)) {
    state.SkipWithError(("model not found: " + model).c_str());
    return;
  }
  runSegmenter(state, model, perception::defaultModelCardFor(model));
}

// The adapted network: the first of the places scripts/adapt_segmentation.sh's output is kept.
std::string adaptedModelPath() {
  const char* from_env = std::getenv("ISM_ADAPTED_MODEL");
  if (from_env && *from_env) return from_env;
  const std::string in_repo =
      std::string(ISM_REPO_ROOT) + "/output/models/kitti/kitti_adapted.onnx";
  if (std::filesystem::exists(in_repo)) return in_repo;
  return sharedDir() + "/models/kitti-adapted/kitti_adapted.onnx";
}

void BM_KittiAdaptedKittiFrame(benchmark::State& state) {
  const std::string model = adaptedModelPath();
  if (!std::filesystem::exists(model)) {
    state.SkipWithError(("no adapted model (scripts/adapt_segmentation.sh): " + model).c_str());
    return;
  }
  runSegmenter(state, model, perception::defaultModelCardFor(model));
}

// The same with its mirror image averaged (flip_average): the price of the option.
void BM_KittiAdaptedKittiFrameFlipAveraged(benchmark::State& state) {
  const std::string model = adaptedModelPath();
  if (!std::filesystem::exists(model)) {
    state.SkipWithError(("no adapted model (scripts/adapt_segmentation.sh): " + model).c_str());
    return;
  }
  perception::ModelCard card = perception::defaultModelCardFor(model);
  card.flip_average = true;
  runSegmenter(state, model, card);
}

void runResizeLayer(benchmark::State& state, const cv::Ptr<cv::dnn::Layer>& layer) {
  cv::setNumThreads(static_cast<int>(state.range(0)));
  const int input_sizes[] = {1, 20, 128, 416};
  const int output_sizes[] = {1, 20, 256, 832};
  std::vector<cv::Mat> inputs{cv::Mat(4, input_sizes, CV_32F)};
  std::vector<cv::Mat> outputs{cv::Mat(4, output_sizes, CV_32F)};
  std::vector<cv::Mat> internals;
  cv::randn(inputs[0], 0.0, 3.0);
  layer->finalize(cv::_InputArray(inputs), cv::_OutputArray(outputs));
  for (auto _ : state) {
    layer->forward(cv::_InputArray(inputs), cv::_OutputArray(outputs), cv::_OutputArray(internals));
    benchmark::DoNotOptimize(outputs[0].data);
  }
}

cv::dnn::LayerParams alignedBilinearParams() {
  cv::dnn::LayerParams params;
  params.name = "upsample";
  params.type = "Resize";
  params.set("interpolation", "bilinear");
  params.set("align_corners", true);
  params.set("height", 256);
  params.set("width", 832);
  return params;
}

void BM_ResizeLayerOpenCv(benchmark::State& state) {
  runResizeLayer(state, cv::dnn::ResizeLayer::create(alignedBilinearParams()));
}

void BM_ResizeLayerRegistered(benchmark::State& state) {
  cv::dnn::LayerParams params = alignedBilinearParams();
  runResizeLayer(state, perception::createResizeLayer(params));
}

void BM_FilterLabelsKittiFrame(benchmark::State& state) {
  perception::Segmentation segmentation;
  segmentation.label_ids.create(375, 1242, CV_8UC1);
  cv::randu(segmentation.label_ids, 0, 34);
  segmentation.confidence.create(375, 1242, CV_32FC1);
  cv::randu(segmentation.confidence, 0.0, 1.0);
  for (auto _ : state) {
    cv::Mat filtered = perception::filterLabels(segmentation, perception::LabelFilterOptions{});
    benchmark::DoNotOptimize(filtered.data);
  }
}

void BM_OverlayKittiFrame(benchmark::State& state) {
  const cv::Mat image = kittiImage();
  cv::Mat labels(image.size(), CV_8UC1);
  cv::randu(labels, 0, 34);
  for (auto _ : state) {
    cv::Mat overlay = perception::overlayLabelIds(image, labels, 0.5);
    benchmark::DoNotOptimize(overlay.data);
  }
}

}  // namespace

BENCHMARK(BM_EnetCityscapesKittiFrame)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_EnetCityscapesKittiFrameTwoTiles)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_EnetCityscapesKittiFrameStretched)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_UnetSyntheticKittiFrame)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_KittiAdaptedKittiFrame)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_KittiAdaptedKittiFrameFlipAveraged)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_ResizeLayerOpenCv)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ResizeLayerRegistered)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_FilterLabelsKittiFrame)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_OverlayKittiFrame)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_MAIN();
