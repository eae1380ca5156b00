#include "inekf_semantic_mapping/perception/model_card.h"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <filesystem>

#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/perception/cityscapes.h"

namespace inekf_semantic_mapping {
namespace perception {
namespace {

namespace fs = std::filesystem;

using common::YamlReader;

ResizePolicy parsePolicy(YamlReader* card) {
  std::string name = "resize";
  card->read("resize_policy", &name);
  if (name == "resize") return ResizePolicy::kResize;
  if (name == "letterbox") return ResizePolicy::kLetterbox;
  if (name == "pad_to_multiple") return ResizePolicy::kPadToMultiple;
  if (name == "tiles") return ResizePolicy::kTiles;
  card->fail("resize_policy",
             "'" + name + "' is not one of resize | letterbox | pad_to_multiple | tiles");
}

ColorNormalization parseColorNormalization(YamlReader* card) {
  std::string name = "none";
  card->read("color_normalization", &name);
  if (name == "none") return ColorNormalization::kNone;
  if (name == "standardize") return ColorNormalization::kStandardize;
  card->fail("color_normalization", "'" + name + "' is not one of none | standardize");
}

void readTriple(YamlReader* card, const std::string& key, std::array<double, 3>* out) {
  std::vector<double> values(out->begin(), out->end());
  card->read(key, &values);
  if (values.size() != 3) card->fail(key, "must have 3 values");
  *out = {values[0], values[1], values[2]};
}

// A section that is there must be a map: the reader would read nothing from a scalar.
void requireMap(YamlReader* card, const YAML::Node& root, const std::string& key,
                const std::string& shape) {
  const YAML::Node& const_root = root;  // operator[] must not add the key
  const YAML::Node node = const_root[key];
  if (node.IsDefined() && !node.IsMap()) card->fail(key, "must be a map " + shape);
}

}  // namespace

void checkModelCard(const ModelCard& card, const ModelCardCheckFailure& fail) {
  // A network input beyond 16384 pixels a side is a typo, and would fail later inside OpenCV.
  constexpr int kMaxInputSide = 16384;
  if (card.input_width < 0 || card.input_height < 0 || card.input_width > kMaxInputSide ||
      card.input_height > kMaxInputSide)
    fail("input", "width/height must be in [0, 16384]");
  if (card.resize_policy != ResizePolicy::kPadToMultiple &&
      (card.input_width == 0 || card.input_height == 0))
    fail("input", "needs width and height > 0 for resize, letterbox and tiles");
  // pad_to_multiple takes a fixed size only with both (one alone was ignored without a word).
  if ((card.input_width == 0) != (card.input_height == 0))
    fail("input",
         "must have width and height both 0 (any size, padded to pad_multiple) or both "
         "> 0 (a fixed input size), not " +
             std::to_string(card.input_width) + "x" + std::to_string(card.input_height));
  // Network strides are up to 64; a larger multiple pads the image into a canvas OpenCV cannot
  // allocate (1e9 asked for 3e18 bytes).
  if (card.pad_multiple < 1 || card.pad_multiple > 1024)
    fail("pad_multiple", "must be in [1, 1024]");
  if (!(card.resize_factor > 0.0 && card.resize_factor <= 8.0))
    fail("resize_factor", "must be in (0, 8]");
  // (pixel - mean) * scale is computed in float: beyond these it overflows to inf and every
  // pixel becomes one class with full confidence.
  constexpr double kMaxPixelStatistic = 1e6;
  if (!(card.scale > 0.0 && card.scale <= kMaxPixelStatistic)) fail("scale", "must be in (0, 1e6]");
  for (double value : card.mean) {
    if (!(std::abs(value) <= kMaxPixelStatistic)) fail("mean", "values must be in [-1e6, 1e6]");
  }
  if (!(card.tile_scale >= 0.0 && card.tile_scale <= 8.0))
    fail("tile_scale", "must be in [0, 8] (0: fit one tile)");
  if (!(card.network_focal_px >= 0.0)) fail("network_focal_px", "must be >= 0 (0: unknown)");
  if (card.tile_overlap < 0 ||
      (card.resize_policy == ResizePolicy::kTiles &&
       (2 * card.tile_overlap >= card.input_width || 2 * card.tile_overlap >= card.input_height)))
    fail("tile_overlap", "must be >= 0 and less than half the input width and height");
  if (card.tile_max_width != 0 &&
      (card.tile_max_width < card.input_width || card.tile_max_width > kMaxInputSide))
    fail("tile_max_width", "must be 0 or in [input width, 16384]");
  if (card.tile_bottom_margin < 0 || (card.resize_policy == ResizePolicy::kTiles &&
                                      2 * card.tile_bottom_margin >= card.input_height))
    fail("tile_bottom_margin", "must be >= 0 and less than half the input height");
  if (!(card.gamma >= ModelCard::kMinGamma && card.gamma <= ModelCard::kMaxGamma))
    fail("gamma", "must be in [0.2, 5] (1: no tone curve)");
  for (double value : card.color_std) {
    if (!(value > 0.0 && value <= kMaxPixelStatistic))
      fail("color_std", "values must be in (0, 1e6]");
  }
  const LabelFilterOptions& filter = card.label_filter;
  if (!(filter.min_confidence >= 0 && filter.min_confidence < 1))
    fail("label_filter.min_confidence", "must be in [0, 1)");
  if (filter.boundary_radius_px < 0 || filter.boundary_radius_px > 50)
    fail("label_filter.boundary_radius_px", "must be in [0, 50]");
  for (double value : card.color_mean) {
    if (!(std::abs(value) <= kMaxPixelStatistic))
      fail("color_mean", "values must be in [-1e6, 1e6]");
  }
}

const char* resizePolicyName(ResizePolicy policy) {
  switch (policy) {
    case ResizePolicy::kResize:
      return "resize";
    case ResizePolicy::kLetterbox:
      return "letterbox";
    case ResizePolicy::kPadToMultiple:
      return "pad_to_multiple";
    case ResizePolicy::kTiles:
      return "tiles";
  }
  return "?";
}

const char* colorNormalizationName(ColorNormalization normalization) {
  switch (normalization) {
    case ColorNormalization::kNone:
      return "none";
    case ColorNormalization::kStandardize:
      return "standardize";
  }
  return "?";
}

namespace {
ModelCard parseModelCard(const std::string& yaml_path, const YAML::Node& root);
}  // namespace

ModelCard loadModelCard(const std::string& yaml_path) {
  YAML::Node root;
  try {
    root = common::loadYamlFile(yaml_path);
  } catch (const common::ConfigError& e) {
    throw ModelCardError(std::string("model card ") + e.what());
  }
  if (!root.IsMap()) throw ModelCardError("model card " + yaml_path + ": top level is not a map");
  try {
    return parseModelCard(yaml_path, root);
  } catch (const common::ConfigError& e) {
    throw ModelCardError(e.what());
  } catch (const YAML::Exception& e) {
    // A field of the wrong shape (a list where a map belongs...) that the checks did not name.
    throw ModelCardError("model card " + yaml_path + ":" + std::to_string(e.mark.line + 1) + ": " +
                         e.msg);
  }
}

namespace {
ModelCard parseModelCard(const std::string& yaml_path, const YAML::Node& root) {
  YamlReader r("model card " + yaml_path, root, /*cite_lines=*/true);
  ModelCard card;
  card.source = yaml_path;
  card.name = fs::path(yaml_path).stem().string();
  r.read("name", &card.name);
  requireMap(&r, root, "input", "{width, height}");
  r.read("input.width", &card.input_width);
  r.read("input.height", &card.input_height);
  card.resize_policy = parsePolicy(&r);
  r.read("pad_multiple", &card.pad_multiple);
  r.read("resize_factor", &card.resize_factor);
  readTriple(&r, "mean", &card.mean);
  r.read("scale", &card.scale);
  r.read("swap_rb", &card.swap_rb);
  r.read("tile_scale", &card.tile_scale);
  r.read("network_focal_px", &card.network_focal_px);
  r.read("tile_overlap", &card.tile_overlap);
  r.read("tile_bottom_margin", &card.tile_bottom_margin);
  r.read("tile_max_width", &card.tile_max_width);
  r.read("flip_average", &card.flip_average);
  r.read("suppress_unlabeled", &card.suppress_unlabeled);
  r.read("output_name", &card.output_name);
  requireMap(&r, root, "label_filter", "{min_confidence, boundary_radius_px}");
  card.label_filter = LabelFilterOptions{0.0, 0};  // a card without a filter filters nothing
  r.read("label_filter.min_confidence", &card.label_filter.min_confidence);
  r.read("label_filter.boundary_radius_px", &card.label_filter.boundary_radius_px);
  r.read("gamma", &card.gamma);
  card.color_normalization = parseColorNormalization(&r);
  const bool has_color_statistics = r.has("color_mean") && r.has("color_std");
  readTriple(&r, "color_mean", &card.color_mean);
  readTriple(&r, "color_std", &card.color_std);
  if (card.color_normalization == ColorNormalization::kStandardize && !has_color_statistics)
    r.fail("color_normalization", "standardize needs color_mean and color_std");
  if (!r.has("output_label_ids"))
    r.fail("output_label_ids", "is missing: one Cityscapes labelId per network channel");
  std::vector<int> ids;
  r.read("output_label_ids", &ids);
  for (int id : ids) {
    if (id < 0 || id >= cityscapes::kNumLabelIds)
      r.fail("output_label_ids",
             "holds labelId " + std::to_string(id) + ", outside the Cityscapes range 0..33");
    card.output_label_ids.push_back(static_cast<std::uint8_t>(id));
  }
  if (card.output_label_ids.empty())
    r.fail("output_label_ids", "must list one labelId per channel");
  int declared = card.numOutputChannels();
  r.read("num_output_channels", &declared);
  if (declared != card.numOutputChannels())
    r.fail("num_output_channels", "is " + std::to_string(declared) + " but output_label_ids has " +
                                      std::to_string(card.numOutputChannels()) + " entries");
  r.allow("validation_miou");  // informational (the training scripts record their score)
  r.rejectUnknown();           // a misspelt key would leave its default silently in place
  checkModelCard(card, [&r](const std::string& key, const std::string& why) { r.fail(key, why); });
  return card;
}
}  // namespace

void saveModelCard(const ModelCard& card, const std::string& yaml_path) {
  YAML::Emitter out;
  out << YAML::BeginMap;
  out << YAML::Key << "name" << YAML::Value << card.name;
  out << YAML::Key << "input" << YAML::Value << YAML::Flow << YAML::BeginMap << YAML::Key << "width"
      << YAML::Value << card.input_width << YAML::Key << "height" << YAML::Value
      << card.input_height << YAML::EndMap;
  out << YAML::Key << "resize_policy" << YAML::Value << resizePolicyName(card.resize_policy);
  out << YAML::Key << "pad_multiple" << YAML::Value << card.pad_multiple;
  out << YAML::Key << "resize_factor" << YAML::Value << card.resize_factor;
  out << YAML::Key << "mean" << YAML::Value << YAML::Flow << YAML::BeginSeq << card.mean[0]
      << card.mean[1] << card.mean[2] << YAML::EndSeq;
  out << YAML::Key << "scale" << YAML::Value << card.scale;
  out << YAML::Key << "swap_rb" << YAML::Value << card.swap_rb;
  out << YAML::Key << "tile_scale" << YAML::Value << card.tile_scale;
  out << YAML::Key << "network_focal_px" << YAML::Value << card.network_focal_px;
  out << YAML::Key << "tile_overlap" << YAML::Value << card.tile_overlap;
  out << YAML::Key << "tile_bottom_margin" << YAML::Value << card.tile_bottom_margin;
  out << YAML::Key << "tile_max_width" << YAML::Value << card.tile_max_width;
  out << YAML::Key << "flip_average" << YAML::Value << card.flip_average;
  out << YAML::Key << "suppress_unlabeled" << YAML::Value << card.suppress_unlabeled;
  if (!card.output_name.empty()) {
    out << YAML::Key << "output_name" << YAML::Value << card.output_name;
  }
  out << YAML::Key << "label_filter" << YAML::Value << YAML::BeginMap << YAML::Key
      << "min_confidence" << YAML::Value << card.label_filter.min_confidence << YAML::Key
      << "boundary_radius_px" << YAML::Value << card.label_filter.boundary_radius_px
      << YAML::EndMap;
  out << YAML::Key << "gamma" << YAML::Value << card.gamma;
  out << YAML::Key << "color_normalization" << YAML::Value
      << colorNormalizationName(card.color_normalization);
  out << YAML::Key << "color_mean" << YAML::Value << YAML::Flow << YAML::BeginSeq
      << card.color_mean[0] << card.color_mean[1] << card.color_mean[2] << YAML::EndSeq;
  out << YAML::Key << "color_std" << YAML::Value << YAML::Flow << YAML::BeginSeq
      << card.color_std[0] << card.color_std[1] << card.color_std[2] << YAML::EndSeq;
  out << YAML::Key << "num_output_channels" << YAML::Value << card.numOutputChannels();
  out << YAML::Key << "output_label_ids" << YAML::Value << YAML::Flow << YAML::BeginSeq;
  for (std::uint8_t id : card.output_label_ids) out << static_cast<int>(id);
  out << YAML::EndSeq << YAML::EndMap;

  try {
    common::writeTextAtomically(yaml_path, std::string(out.c_str()) + "\n");
  } catch (const common::AtomicWriteError& error) {
    throw ModelCardError("model card " + yaml_path + ": " + error.reason());
  }
}

ModelCard builtinEnetCityscapesCard() {
  ModelCard card;
  card.name = "enet_cityscapes";
  card.source = "built-in ENet Cityscapes card";
  card.input_width = 1024;
  card.input_height = 512;
  // Measured on SemanticKITTI 05 / 08 (docs/results.md): stretching KITTI's 3.3:1 frames to
  // 2:1 distorts every object; scaling them without distortion until they fill the input height
  // (less the bottom margin) and running two overlapping tiles labels more points right.
  // Matching Cityscapes' focal length instead (network_focal_px) needs four tiles for no
  // measurable gain, so it is left off.
  card.resize_policy = ResizePolicy::kTiles;
  card.tile_scale = 0.0;
  card.network_focal_px = 0.0;
  card.tile_overlap = 64;
  // About the bottom fifth of a Cityscapes frame shows the ego car's bonnet, which the network
  // learned to call "unlabeled": KITTI's near road must not land there.
  card.tile_bottom_margin = 96;
  // KITTI's wide frame (1378 x 416 after scaling) in one 1392 x 512 pass instead of two
  // overlapping 1024 x 512 tiles: the same labels (README) for about 0.6 of the time.
  card.tile_max_width = 2048;
  card.flip_average = false;  // twice the cost for little gain
  // The network is trained on 1/255 pixels of Cityscapes' cameras: other cameras' exposure and
  // white balance confuse it far more than their geometry, so each image is standardized to
  // Cityscapes' colour statistics first.
  card.color_normalization = ColorNormalization::kStandardize;
  // ... after lifting the shadows and midtones: the affine standardization matches the mean and
  // spread of the colours, not the shape of their distribution. Measured (README): raw point
  // accuracy 0.817 -> 0.841 on SemanticKITTI 05, 0.708 -> 0.712 on 08, pixel accuracy 0.788 ->
  // 0.828 on the Cityscapes sample; 0.6 and 0.8 within noise of 0.7, 1.25 worse everywhere.
  card.gamma = 0.7;
  for (int c = 0; c < 3; ++c) {
    card.color_mean[c] = kCityscapesRgbMean[c];  // RGB: the network's channel order
    card.color_std[c] = kCityscapesRgbStd[c];
  }
  card.suppress_unlabeled = true;
  card.label_filter = LabelFilterOptions{};  // the measured defaults
  card.pad_multiple = 1;
  card.scale = 1.0 / 255.0;
  card.swap_rb = true;
  card.output_label_ids.push_back(cityscapes::kUnlabeled);
  for (int train_id = 0; train_id < cityscapes::kNumTrainIds; ++train_id)
    card.output_label_ids.push_back(cityscapes::trainIdToLabelId(train_id));
  return card;
}

ModelCard defaultModelCardFor(const std::string& model_path) {
  const fs::path model(model_path);
  // Named first: "no model card for X" sent users looking for a card when X itself was a typo.
  if (!fs::exists(model)) throw ModelCardError(model_path + ": no such model file");
  for (const fs::path& candidate :
       {fs::path(model).replace_extension(".yaml"), fs::path(model_path + ".yaml")}) {
    if (fs::exists(candidate)) return loadModelCard(candidate.string());
  }
  const std::string extension = model.extension().string();
  if (extension == ".net" || extension == ".t7") return builtinEnetCityscapesCard();
  throw ModelCardError(
      "no model card for " + model_path + ": expected " +
      fs::path(model).replace_extension(".yaml").string() +
      " beside it (or give the card's path: the tools' --model-card, segmentation_node's "
      "~model_card)");
}

}  // namespace perception
}  // namespace inekf_semantic_mapping
