#include "inekf_semantic_mapping/perception/model_card.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/perception/cityscapes.h"

namespace inekf_semantic_mapping {
namespace perception {
namespace {

namespace fs = std::filesystem;

[[noreturn]] void fail(const std::string& path, const YAML::Node& node, const std::string& what) {
  std::ostringstream msg;
  msg << "model card " << path;
  if (node.IsDefined() && node.Mark().line >= 0) msg << ":" << node.Mark().line + 1;
  msg << ": " << what;
  throw ModelCardError(msg.str());
}

template <typename T>
T read(const std::string& path, const YAML::Node& parent, const std::string& field) {
  const YAML::Node node = parent[field];
  if (!node) fail(path, parent, "missing field '" + field + "'");
  try {
    return node.as<T>();
  } catch (const YAML::Exception& e) {
    fail(path, node, "field '" + field + "' has the wrong type (" + e.msg + ")");
  }
}

template <typename T>
T readOr(const std::string& path, const YAML::Node& parent, const std::string& field,
         const T& fallback) {
  return parent[field] ? read<T>(path, parent, field) : fallback;
}

ResizePolicy parsePolicy(const std::string& path, const YAML::Node& node) {
  const std::string name = node.as<std::string>();
  if (name == "resize") return ResizePolicy::kResize;
  if (name == "letterbox") return ResizePolicy::kLetterbox;
  if (name == "pad_to_multiple") return ResizePolicy::kPadToMultiple;
  if (name == "tiles") return ResizePolicy::kTiles;
  fail(path, node,
       "resize_policy '" + name + "' is not one of resize | letterbox | pad_to_multiple | tiles");
}

ColorNormalization parseColorNormalization(const std::string& path, const YAML::Node& node) {
  const std::string name = node.as<std::string>();
  if (name == "none") return ColorNormalization::kNone;
  if (name == "standardize") return ColorNormalization::kStandardize;
  fail(path, node, "color_normalization '" + name + "' is not one of none | standardize");
}

std::array<double, 3> readTriple(const std::string& path, const YAML::Node& root,
                                 const std::string& field, const std::array<double, 3>& fallback) {
  if (!root[field]) return fallback;
  const auto values = read<std::vector<double>>(path, root, field);
  if (values.size() != 3) fail(path, root[field], field + " must have 3 values");
  return {values[0], values[1], values[2]};
}

// A misspelt key would silently leave its default in place (the same rule as the configs).
void rejectUnknownKeys(const std::string& path, const YAML::Node& map,
                       const std::vector<std::string>& known, const std::string& prefix) {
  for (const auto& entry : map) {
    const std::string key = entry.first.Scalar();
    if (std::find(known.begin(), known.end(), key) == known.end()) {
      fail(path, entry.first, "unknown key '" + prefix + key + "'");
    }
  }
}

void validate(const ModelCard& card, const std::string& path, const YAML::Node& root) {
  rejectUnknownKeys(
      path, root,
      {"name", "input", "resize_policy", "pad_multiple", "resize_factor", "mean", "scale",
       "swap_rb", "tile_scale", "network_focal_px", "tile_overlap", "tile_bottom_margin",
       "tile_max_width", "flip_average", "suppress_unlabeled", "label_filter", "gamma",
       "color_normalization", "color_mean", "color_std", "output_label_ids", "num_output_channels",
       // Informational (scripts/train_unet.py records the network's validation score).
       "validation_miou"},
      "");
  if (root["input"]) {
    if (!root["input"].IsMap()) fail(path, root["input"], "input must be a map {width, height}");
    rejectUnknownKeys(path, root["input"], {"width", "height"}, "input.");
  }
  if (root["label_filter"]) {
    rejectUnknownKeys(path, root["label_filter"], {"min_confidence", "boundary_radius_px"},
                      "label_filter.");
  }
  for (const auto* triple : {&card.mean, &card.color_mean}) {
    for (double value : *triple) {
      if (!std::isfinite(value)) fail(path, root, "mean / color_mean values must be finite");
    }
  }
  // A network input beyond 16384 pixels a side is a typo, and would fail later inside OpenCV.
  constexpr int kMaxInputSide = 16384;
  if (card.input_width < 0 || card.input_height < 0 || card.input_width > kMaxInputSide ||
      card.input_height > kMaxInputSide)
    fail(path, root["input"], "input width/height must be in [0, 16384]");
  if (card.resize_policy != ResizePolicy::kPadToMultiple &&
      (card.input_width == 0 || card.input_height == 0))
    fail(path, root["input"], "resize, letterbox and tiles need input width and height > 0");
  if (card.pad_multiple < 1) fail(path, root["pad_multiple"], "pad_multiple must be >= 1");
  if (!(card.resize_factor > 0.0 && card.resize_factor <= 8.0))
    fail(path, root["resize_factor"], "resize_factor must be in (0, 8]");
  if (!(card.scale > 0.0)) fail(path, root["scale"], "scale must be > 0");
  if (!(card.tile_scale >= 0.0 && card.tile_scale <= 8.0))
    fail(path, root["tile_scale"], "tile_scale must be in [0, 8] (0: fit one tile)");
  if (!(card.network_focal_px >= 0.0))
    fail(path, root["network_focal_px"], "network_focal_px must be >= 0 (0: unknown)");
  if (card.tile_overlap < 0 ||
      (card.resize_policy == ResizePolicy::kTiles &&
       (2 * card.tile_overlap >= card.input_width || 2 * card.tile_overlap >= card.input_height)))
    fail(path, root["tile_overlap"],
         "tile_overlap must be >= 0 and less than half the input width and height");
  if (card.tile_max_width != 0 &&
      (card.tile_max_width < card.input_width || card.tile_max_width > kMaxInputSide))
    fail(path, root["tile_max_width"], "tile_max_width must be 0 or in [input width, 16384]");
  if (card.tile_bottom_margin < 0 || (card.resize_policy == ResizePolicy::kTiles &&
                                      2 * card.tile_bottom_margin >= card.input_height))
    fail(path, root["tile_bottom_margin"],
         "tile_bottom_margin must be >= 0 and less than half the input height");
  if (!(card.gamma >= ModelCard::kMinGamma && card.gamma <= ModelCard::kMaxGamma))
    fail(path, root["gamma"], "gamma must be in [0.2, 5] (1: no tone curve)");
  for (double value : card.color_std) {
    if (!(value > 0.0)) fail(path, root["color_std"], "color_std values must be > 0");
  }
  if (card.output_label_ids.empty())
    fail(path, root["output_label_ids"], "output_label_ids must list one labelId per channel");
}

}  // namespace

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
    root = YAML::LoadFile(yaml_path);
  } catch (const YAML::BadFile&) {
    throw ModelCardError("model card " + yaml_path + ": cannot open file");
  } catch (const YAML::Exception& e) {
    throw ModelCardError("model card " + yaml_path + ":" + std::to_string(e.mark.line + 1) +
                         ": YAML syntax error: " + e.msg);
  }
  if (!root.IsMap()) throw ModelCardError("model card " + yaml_path + ": top level is not a map");
  try {
    return parseModelCard(yaml_path, root);
  } catch (const YAML::Exception& e) {
    // A field of the wrong shape (a list where a map belongs...) that the checks did not name.
    throw ModelCardError("model card " + yaml_path + ":" + std::to_string(e.mark.line + 1) + ": " +
                         e.msg);
  }
}

namespace {
ModelCard parseModelCard(const std::string& yaml_path, const YAML::Node& root) {
  ModelCard card;
  card.source = yaml_path;
  card.name = readOr<std::string>(yaml_path, root, "name", fs::path(yaml_path).stem().string());
  if (root["input"]) {
    card.input_width = readOr<int>(yaml_path, root["input"], "width", 0);
    card.input_height = readOr<int>(yaml_path, root["input"], "height", 0);
  }
  card.resize_policy =
      parsePolicy(yaml_path, root["resize_policy"] ? root["resize_policy"] : YAML::Node("resize"));
  card.pad_multiple = readOr<int>(yaml_path, root, "pad_multiple", 1);
  card.resize_factor = readOr<double>(yaml_path, root, "resize_factor", 1.0);
  if (root["mean"]) {
    const auto mean = read<std::vector<double>>(yaml_path, root, "mean");
    if (mean.size() != 3) fail(yaml_path, root["mean"], "mean must have 3 values");
    card.mean = {mean[0], mean[1], mean[2]};
  }
  card.scale = readOr<double>(yaml_path, root, "scale", 1.0 / 255.0);
  card.swap_rb = readOr<bool>(yaml_path, root, "swap_rb", true);
  card.tile_scale = readOr<double>(yaml_path, root, "tile_scale", 0.0);
  card.network_focal_px = readOr<double>(yaml_path, root, "network_focal_px", 0.0);
  card.tile_overlap = readOr<int>(yaml_path, root, "tile_overlap", 0);
  card.tile_bottom_margin = readOr<int>(yaml_path, root, "tile_bottom_margin", 0);
  card.tile_max_width = readOr<int>(yaml_path, root, "tile_max_width", 0);
  card.flip_average = readOr<bool>(yaml_path, root, "flip_average", false);
  card.suppress_unlabeled = readOr<bool>(yaml_path, root, "suppress_unlabeled", false);
  if (root["label_filter"]) {
    const YAML::Node filter = root["label_filter"];
    if (!filter.IsMap()) fail(yaml_path, filter, "label_filter must be a map");
    card.label_filter.min_confidence = readOr<double>(yaml_path, filter, "min_confidence", 0.0);
    card.label_filter.boundary_radius_px = readOr<int>(yaml_path, filter, "boundary_radius_px", 0);
    if (!(card.label_filter.min_confidence >= 0 && card.label_filter.min_confidence < 1) ||
        card.label_filter.boundary_radius_px < 0 || card.label_filter.boundary_radius_px > 50)
      fail(yaml_path, filter,
           "label_filter: min_confidence must be in [0, 1), boundary_radius_px in [0, 50]");
  }
  card.gamma = readOr<double>(yaml_path, root, "gamma", 1.0);
  if (root["color_normalization"]) {
    card.color_normalization = parseColorNormalization(yaml_path, root["color_normalization"]);
  }
  card.color_mean = readTriple(yaml_path, root, "color_mean", card.color_mean);
  card.color_std = readTriple(yaml_path, root, "color_std", card.color_std);
  if (card.color_normalization == ColorNormalization::kStandardize &&
      (!root["color_mean"] || !root["color_std"]))
    fail(yaml_path, root["color_normalization"],
         "color_normalization standardize needs color_mean and color_std");
  const auto ids = read<std::vector<int>>(yaml_path, root, "output_label_ids");
  for (int id : ids) {
    if (id < 0 || id >= cityscapes::kNumLabelIds)
      fail(yaml_path, root["output_label_ids"],
           "labelId " + std::to_string(id) + " is outside the Cityscapes range 0..33");
    card.output_label_ids.push_back(static_cast<std::uint8_t>(id));
  }
  if (root["num_output_channels"]) {
    const int declared = read<int>(yaml_path, root, "num_output_channels");
    if (declared != card.numOutputChannels())
      fail(yaml_path, root["num_output_channels"],
           "num_output_channels " + std::to_string(declared) + " but output_label_ids has " +
               std::to_string(card.numOutputChannels()) + " entries");
  }
  validate(card, yaml_path, root);
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
  for (const fs::path& candidate :
       {fs::path(model).replace_extension(".yaml"), fs::path(model_path + ".yaml")}) {
    if (fs::exists(candidate)) return loadModelCard(candidate.string());
  }
  const std::string extension = model.extension().string();
  if (extension == ".net" || extension == ".t7") return builtinEnetCityscapesCard();
  throw ModelCardError("no model card for " + model_path + ": expected " +
                       fs::path(model).replace_extension(".yaml").string() +
                       " beside it (or pass --model-card)");
}

}  // namespace perception
}  // namespace inekf_semantic_mapping
