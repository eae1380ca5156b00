// A model card: everything the Segmenter must know about a network besides its weights — input
// size and normalization, how KITTI's wide images are fitted to the network, and which
// Cityscapes labelId each output channel stands for. Cards are YAML files in models/.
#pragma once

#include <array>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace inekf_semantic_mapping {
namespace perception {

// How an image of arbitrary size is fitted to the network input.
enum class ResizePolicy {
  kResize,         // stretch to input_width x input_height (aspect ratio not kept)
  kLetterbox,      // scale to fit inside the input size keeping the aspect, pad the rest
  kPadToMultiple,  // (optionally resize to input size, then) reflect-pad to pad_multiple, crop
                   // output
};

struct ModelCard {
  std::string name;
  std::string source;  // the YAML file it came from, or "built-in ..." (for error messages)
  // Network input size; for kPadToMultiple 0 x 0 means "the image's own size".
  int input_width = 0;
  int input_height = 0;
  ResizePolicy resize_policy = ResizePolicy::kResize;
  int pad_multiple = 1;
  // kPadToMultiple with a 0 x 0 input size: the image is first scaled by this factor (a network
  // trained at half resolution keeps its scale on any image size).
  double resize_factor = 1.0;
  // blob = (pixel - mean) * scale, in the channel order the network expects.
  std::array<double, 3> mean{{0.0, 0.0, 0.0}};
  double scale = 1.0 / 255.0;
  // true: the network expects RGB (images arrive as BGR from OpenCV).
  bool swap_rb = true;
  // Output channel index -> Cityscapes labelId; its size is the number of output channels.
  std::vector<std::uint8_t> output_label_ids;

  int numOutputChannels() const { return static_cast<int>(output_label_ids.size()); }
};

// Thrown for unreadable or inconsistent model cards; the message names the file and field.
class ModelCardError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Parses a model card YAML file (format: models/unet_synthetic.yaml).
ModelCard loadModelCard(const std::string& yaml_path);

// Writes a card in the format loadModelCard reads (atomic: temporary file + rename).
void saveModelCard(const ModelCard& card, const std::string& yaml_path);

// The e-lab ENet trained on Cityscapes (Torch7 .net): 1024x512 RGB / 255, 20 outputs where
// index 0 is "unlabeled" and index k is trainId k-1.
ModelCard builtinEnetCityscapesCard();

// The card for a model file when none is given: `<model without extension>.yaml` or
// `<model>.yaml` beside it if present, otherwise the built-in ENet card for `.net`.
// Throws ModelCardError when there is none.
ModelCard defaultModelCardFor(const std::string& model_path);

const char* resizePolicyName(ResizePolicy policy);

}  // namespace perception
}  // namespace inekf_semantic_mapping
