// adapt_segmenter: adapts a segmentation network to a camera without labels by measuring its
// batch normalization statistics again on that camera's images (AdaBN; see
// perception/batchnorm_adaptation.h). Writes the statistics, and optionally a model card that
// uses them, so that segment_image, evaluate_semantics, semantic_map_offline and the
// segmentation_node (model_card parameter) run the adapted network.
//
//   adapt_segmenter --model MODEL [--model-card CARD.yaml] --images DIR [--images DIR ...]
//                   --output STATS.yaml [--card-output CARD.yaml] [--max-images 60]
//                   [--layers N] [--target-weight 0.5] [--focal PX] [--threads 2]
#include <algorithm>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/common/cli_args.h"
#include "inekf_semantic_mapping/perception/batchnorm_adaptation.h"
#include "inekf_semantic_mapping/perception/model_card.h"
#include "inekf_semantic_mapping/perception/segmenter.h"

namespace ism = inekf_semantic_mapping;
namespace perception = inekf_semantic_mapping::perception;
namespace fs = std::filesystem;

namespace {

constexpr char kUsage[] =
    "usage: adapt_segmenter --model MODEL [--model-card CARD.yaml] --images DIR [--images DIR "
    "...]\n"
    "                       --output STATS.yaml [--card-output CARD.yaml] [--max-images 60]\n"
    "                       [--layers N] [--target-weight 0.5] [--focal PX] [--threads 2]\n"
    "  --images       a folder of the target camera's images (.png/.jpg), e.g. a KITTI drive's\n"
    "                 image_02/data; unlabelled. Repeat for several drives. Do not adapt on the\n"
    "                 frames you evaluate on.\n"
    "  --max-images   at most this many, spread evenly over all the images found\n"
    "  --layers       adapt only the first N batch normalization layers (default: all)\n"
    "  --target-weight  the measured statistics' share of the blend with the trained ones\n"
    "                 (1: AdaBN proper; default 0.5)\n"
    "  --focal        the camera's focal length in pixels, for cards with network_focal_px\n"
    "  --card-output  the model card (--model-card, or the model's default card) with\n"
    "                 batchnorm_statistics set to STATS.yaml: pass it as --model-card / "
    "model_card\n";

std::vector<std::string> imagesIn(const std::string& folder) {
  if (!fs::is_directory(folder)) throw ism::common::UsageError("--images: no folder " + folder);
  std::vector<std::string> images;
  for (const auto& entry : fs::directory_iterator(folder)) {
    std::string extension = entry.path().extension().string();
    std::transform(extension.begin(), extension.end(), extension.begin(), ::tolower);
    if (entry.is_regular_file() &&
        (extension == ".png" || extension == ".jpg" || extension == ".jpeg"))
      images.push_back(entry.path().string());
  }
  if (images.empty()) throw ism::common::UsageError("--images: no .png/.jpg images in " + folder);
  std::sort(images.begin(), images.end());
  return images;
}

}  // namespace

int main(int argc, char** argv) {
  using ism::common::UsageError;
  return ism::common::runCli("adapt_segmenter", kUsage, [&] {
    const ism::common::CommandLine cli(
        argc, argv,
        {"--model", "--model-card", "--output", "--card-output", "--max-images", "--layers",
         "--target-weight", "--focal", "--threads"},
        {}, {"--images"});
    if (cli.helpRequested()) return ism::common::printUsage(kUsage);
    const std::string model = cli.require("--model");
    const std::string output = cli.require("--output");
    const int max_images = cli.getInt("--max-images", 60);
    const int max_layers = cli.getInt("--layers", 0);
    const double target_weight =
        cli.getDouble("--target-weight", perception::Segmenter::kDefaultTargetWeight);
    if (!(target_weight >= 0.0 && target_weight <= 1.0))
      throw UsageError("--target-weight must be in [0, 1]");
    const double focal = cli.getDouble("--focal", 0.0);
    const int threads = cli.getInt("--threads", 2);
    if (max_images < 1) throw UsageError("--max-images must be >= 1");
    if (max_layers < 0) throw UsageError("--layers must be >= 0 (0: all)");
    const std::vector<std::string> folders = cli.getAll("--images");
    if (folders.empty()) throw UsageError("--images is required");

    std::vector<std::string> paths;
    for (const std::string& folder : folders) {
      const std::vector<std::string> found = imagesIn(folder);
      paths.insert(paths.end(), found.begin(), found.end());
    }
    std::vector<cv::Mat> images;
    const std::size_t count = std::min<std::size_t>(paths.size(), max_images);
    for (std::size_t i = 0; i < count; ++i) {
      const std::string& path = paths[i * paths.size() / count];
      cv::Mat image = cv::imread(path, cv::IMREAD_COLOR);
      if (image.empty()) throw std::runtime_error("cannot read image " + path);
      images.push_back(std::move(image));
    }

    perception::ModelCard card = cli.has("--model-card")
                                     ? perception::loadModelCard(cli.get("--model-card"))
                                     : perception::defaultModelCardFor(model);
    card.batchnorm_statistics.clear();  // measured from the trained statistics
    perception::Segmenter segmenter(model, card, threads);
    std::cout << "adapt_segmenter: " << images.size() << " of " << paths.size() << " images, "
              << "model " << model << " [card " << card.source << "]" << std::endl;
    const perception::BatchNormAdaptation adaptation = segmenter.adaptBatchNorm(
        images, focal, target_weight, max_layers, [&](int layer, int layers) {
          if ((layer + 1) % 10 == 0 || layer + 1 == layers)
            std::cout << "  layer " << layer + 1 << "/" << layers << std::endl;
        });
    perception::saveBatchNormAdaptation(adaptation, output);
    std::cout << "adapt_segmenter: " << adaptation.adapted_layers << " of "
              << adaptation.layers.size() << " batch normalization layers adapted -> " << output
              << std::endl;
    if (cli.has("--card-output")) {
      const std::string card_output = cli.get("--card-output");
      // Relative to the card when they share a folder, so the two can move together.
      const fs::path stats = fs::absolute(output), card_path = fs::absolute(card_output);
      card.batchnorm_statistics = stats.parent_path() == card_path.parent_path()
                                      ? stats.filename().string()
                                      : stats.string();
      card.name += "_adapted";
      perception::saveModelCard(card, card_output);
      std::cout << "adapt_segmenter: model card -> " << card_output << std::endl;
    }
    return 0;
  });
}
