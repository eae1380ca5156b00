// segment_image: semantic segmentation of one image file with the same Segmenter the
// segmentation_node uses. Writes a mono8 label PNG (Cityscapes labelIds or trainIds), and
// optionally a color overlay and a confidence image.
//
//   segment_image --model MODEL [--model-card CARD.yaml] --input IMG.png --output LABELS.png
//                 [--overlay OVERLAY.png] [--ids labelid|trainid] [--confidence CONF.png]
//                 [--alpha 0.5] [--repeat N] [--threads 2]
#include <cstdio>
#include <iostream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/common/cli_args.h"
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

// Adds an image to the run's outputs: written to a temporary file, renamed into place with the
// others once all are written (a reader never sees half an image, nor labels without overlay).
void addImage(ism::common::AtomicFileSet* outputs, const std::string& path, const cv::Mat& image) {
  // The temporary name keeps the extension: imwrite picks the format from it.
  outputs->add(path, [&](const std::string& tmp_path) {
    if (!cv::imwrite(tmp_path, image)) throw std::runtime_error("cannot write " + path);
  });
}

}  // namespace

int main(int argc, char** argv) {
  using ism::common::UsageError;
  return ism::common::runCli("segment_image", kUsage, [&] {
    const ism::common::CommandLine cli(
        argc, argv,
        {"--model", "--model-card", "--input", "--output", "--overlay", "--ids", "--confidence",
         "--alpha", "--repeat", "--threads"});
    if (cli.helpRequested()) return ism::common::printUsage(kUsage);
    const std::string model = cli.require("--model");
    const std::string input = cli.require("--input");
    const std::string output = cli.require("--output");
    const std::string ids = cli.get("--ids", "labelid");
    if (ids != "labelid" && ids != "trainid") {
      throw UsageError("--ids must be labelid or trainid, not '" + ids + "'");
    }
    const int repeat = cli.getInt("--repeat", 1);
    const double alpha = cli.getDouble("--alpha", 0.5);
    const int threads = cli.getInt("--threads", 2);
    if (repeat < 1) throw UsageError("--repeat must be >= 1");
    if (!(alpha >= 0.0 && alpha <= 1.0)) throw UsageError("--alpha must be in [0, 1]");
    if (threads < 1) throw UsageError("--threads must be >= 1");
    // Checked before the network runs. Labels and confidences are data: a lossy format (.jpg)
    // changed the ids of one pixel in ten.
    for (const char* flag : {"--output", "--confidence"}) {
      const std::string path = cli.get(flag);
      const std::string extension = path.size() >= 4 ? path.substr(path.size() - 4) : "";
      if (cli.has(flag) && extension != ".png" && extension != ".PNG") {
        throw UsageError(std::string(flag) + " must be a .png file (lossless), not '" + path + "'");
      }
    }
    const std::vector<std::string> output_paths =
        cli.valuesOf({"--output", "--overlay", "--confidence"});
    ism::common::checkOutputPaths(output_paths);
    ism::common::checkOutputsAreNotInputs(output_paths,
                                          cli.valuesOf({"--input", "--model", "--model-card"}));
    if (cli.has("--overlay") && !cv::haveImageWriter(cli.get("--overlay"))) {
      throw UsageError("--overlay: OpenCV writes no image format named by the extension of '" +
                       cli.get("--overlay") + "'");
    }

    const perception::ModelCard card = cli.has("--model-card")
                                           ? perception::loadModelCard(cli.get("--model-card"))
                                           : perception::defaultModelCardFor(model);

    const cv::Mat image = cv::imread(input, cv::IMREAD_COLOR);
    if (image.empty()) throw std::runtime_error("cannot read image " + input);

    perception::Segmenter segmenter(model, card, threads);
    ism::TimingRegistry::instance().reset();  // the warm-up pass is not part of the figures
    perception::Segmentation result;
    for (int i = 0; i < repeat; ++i) {
      ism::ScopedTimer timer("segmentation/total");
      result = segmenter.segment(image);
    }

    ism::common::AtomicFileSet outputs;
    addImage(
        &outputs, output,
        ids == "trainid" ? perception::labelIdsToTrainIds(result.label_ids) : result.label_ids);
    if (cli.has("--overlay")) {
      cv::Mat overlay_bgr;
      cv::cvtColor(perception::overlayLabelIds(image, result.label_ids, alpha), overlay_bgr,
                   cv::COLOR_RGB2BGR);
      addImage(&outputs, cli.get("--overlay"), overlay_bgr);
    }
    if (cli.has("--confidence")) {
      cv::Mat confidence_8u;
      result.confidence.convertTo(confidence_8u, CV_8U, 255.0);
      addImage(&outputs, cli.get("--confidence"), confidence_8u);
    }
    outputs.commit();
    std::cout << "segment_image: " << input << " (" << image.cols << "x" << image.rows << ") with "
              << model << " [card " << card.source << "] -> " << output << "\n"
              << ism::TimingRegistry::instance().report();
    return 0;
  });
}
