// segment_image: semantic segmentation of one image file with the same Segmenter the
// segmentation_node uses. Writes a mono8 label PNG (Cityscapes labelIds or trainIds), and
// optionally a color overlay and a confidence image.
//
//   segment_image --model MODEL [--model-card CARD.yaml] --input IMG.png --output LABELS.png
//                 [--overlay OVERLAY.png] [--ids labelid|trainid] [--confidence CONF.png]
//                 [--alpha 0.5] [--repeat N] [--threads 2]
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "inekf_semantic_mapping/common/timing.h"
#include "inekf_semantic_mapping/perception/model_card.h"
#include "inekf_semantic_mapping/perception/segmenter.h"

namespace ism = inekf_semantic_mapping;
namespace perception = inekf_semantic_mapping::perception;

namespace {

constexpr char kUsage[] =
    "usage: segment_image --model MODEL [--model-card CARD.yaml] --input IMG.png "
    "--output LABELS.png\n"
    "                     [--overlay OVERLAY.png] [--ids labelid|trainid] [--confidence CONF.png]\n"
    "                     [--alpha 0.5] [--repeat N] [--threads 2]\n"
    "  --model       .onnx (card: <model>.yaml beside it) or Torch7 .net (built-in ENet card)\n"
    "  --ids         ids written to LABELS.png: Cityscapes labelIds (default) or trainIds\n"
    "  --confidence  8-bit image of the softmax probability of the chosen class (x255)\n"
    "  --repeat      run the segmentation N times and print the stage timing (benchmarking)\n";

// Writes via a temporary file and a rename, so a reader never sees half an image.
void writeImageAtomically(const std::string& path, const cv::Mat& image) {
  const std::filesystem::path target(path);
  const std::string tmp_path =
      (target.parent_path() / (".tmp_" + target.filename().string())).string();
  // The temporary name keeps the extension: imwrite picks the format from it.
  if (!cv::imwrite(tmp_path, image)) throw std::runtime_error("cannot write " + tmp_path);
  std::filesystem::rename(tmp_path, path);
}

}  // namespace

int main(int argc, char** argv) {
  std::map<std::string, std::string> options = {
      {"--ids", "labelid"}, {"--alpha", "0.5"}, {"--repeat", "1"}, {"--threads", "2"}};
  const std::map<std::string, bool> known = {
      {"--model", true},   {"--model-card", true}, {"--input", true},      {"--output", true},
      {"--overlay", true}, {"--ids", true},        {"--confidence", true}, {"--alpha", true},
      {"--repeat", true},  {"--threads", true}};
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "-h" || arg == "--help") {
      std::cout << kUsage;
      return 0;
    }
    if (!known.count(arg) || i + 1 >= argc) {
      std::cerr << "segment_image: "
                << (known.count(arg) ? "missing value for " : "unknown option ") << arg << "\n"
                << kUsage;
      return 2;
    }
    options[arg] = argv[++i];
  }
  for (const char* required : {"--model", "--input", "--output"}) {
    if (!options.count(required)) {
      std::cerr << "segment_image: " << required << " is required\n" << kUsage;
      return 2;
    }
  }
  const std::string ids = options["--ids"];
  if (ids != "labelid" && ids != "trainid") {
    std::cerr << "segment_image: --ids must be labelid or trainid, not '" << ids << "'\n";
    return 2;
  }

  try {
    const std::string model = options["--model"];
    const perception::ModelCard card = options.count("--model-card")
                                           ? perception::loadModelCard(options["--model-card"])
                                           : perception::defaultModelCardFor(model);
    const int repeat = std::stoi(options["--repeat"]);
    const double alpha = std::stod(options["--alpha"]);

    const cv::Mat image = cv::imread(options["--input"], cv::IMREAD_COLOR);
    if (image.empty()) throw std::runtime_error("cannot read image " + options["--input"]);

    perception::Segmenter segmenter(model, card, std::stoi(options["--threads"]));
    ism::TimingRegistry::instance().reset();  // the warm-up pass is not part of the figures
    perception::Segmentation result;
    for (int i = 0; i < std::max(1, repeat); ++i) {
      ism::ScopedTimer timer("segmentation/total");
      result = segmenter.segment(image);
    }

    writeImageAtomically(options["--output"], ids == "trainid"
                                                  ? perception::labelIdsToTrainIds(result.label_ids)
                                                  : result.label_ids);
    if (options.count("--overlay")) {
      cv::Mat overlay_bgr;
      cv::cvtColor(perception::overlayLabelIds(image, result.label_ids, alpha), overlay_bgr,
                   cv::COLOR_RGB2BGR);
      writeImageAtomically(options["--overlay"], overlay_bgr);
    }
    if (options.count("--confidence")) {
      cv::Mat confidence_8u;
      result.confidence.convertTo(confidence_8u, CV_8U, 255.0);
      writeImageAtomically(options["--confidence"], confidence_8u);
    }
    std::cout << "segment_image: " << options["--input"] << " (" << image.cols << "x" << image.rows
              << ") with " << model << " [card " << card.source << "] -> " << options["--output"]
              << "\n"
              << ism::TimingRegistry::instance().report();
  } catch (const std::exception& e) {
    std::cerr << "segment_image: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
