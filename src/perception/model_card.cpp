#include "inekf_semantic_mapping/perception/model_card.h"

#include <yaml-cpp/yaml.h>

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
  fail(path, node,
       "resize_policy '" + name + "' is not one of resize | letterbox | pad_to_multiple");
}

void validate(const ModelCard& card, const std::string& path, const YAML::Node& root) {
  if (card.input_width < 0 || card.input_height < 0)
    fail(path, root["input"], "input width/height must be >= 0");
  if (card.resize_policy != ResizePolicy::kPadToMultiple &&
      (card.input_width == 0 || card.input_height == 0))
    fail(path, root["input"], "resize and letterbox need input width and height > 0");
  if (card.pad_multiple < 1) fail(path, root["pad_multiple"], "pad_multiple must be >= 1");
  if (!(card.resize_factor > 0.0 && card.resize_factor <= 8.0))
    fail(path, root["resize_factor"], "resize_factor must be in (0, 8]");
  if (!(card.scale > 0.0)) fail(path, root["scale"], "scale must be > 0");
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
  }
  return "?";
}

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
  card.resize_policy = ResizePolicy::kResize;
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
