// Per-frame segmentation throughput on a KITTI-sized image (1242x375), the whole path the node
// runs per frame: fit to the network (resize / reflect-pad), blob, forward, argmax + softmax
// confidence, crop, nearest-neighbour back to the image size. Models: the Cityscapes ENet from
// ../shared (skipped when absent) and the committed default U-Net. Threads: 2 (the machine).
//
//   bench_segmentation [--benchmark_min_time=5]
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <memory>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>

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

void runSegmenter(benchmark::State& state, const std::string& model) {
  if (!std::filesystem::exists(model)) {
    state.SkipWithError(("model not found: " + model).c_str());
    return;
  }
  perception::Segmenter segmenter(model, perception::defaultModelCardFor(model),
                                  static_cast<int>(state.range(0)));
  const cv::Mat image = kittiImage();
  for (auto _ : state) {
    perception::Segmentation result = segmenter.segment(image);
    benchmark::DoNotOptimize(result.label_ids.data);
  }
  state.counters["frames_per_s"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

void BM_EnetCityscapesKittiFrame(benchmark::State& state) {
  runSegmenter(state, sharedDir() + "/models/enet-cityscapes/enet-model.net");
}

void BM_UnetSyntheticKittiFrame(benchmark::State& state) {
  runSegmenter(state, std::string(ISM_REPO_ROOT) + "/models/unet_synthetic.onnx");
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
BENCHMARK(BM_UnetSyntheticKittiFrame)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_OverlayKittiFrame)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_MAIN();
