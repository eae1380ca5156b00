// A model card: everything the Segmenter must know about a network besides its weights — input
// size and normalization, how KITTI's wide images are fitted to the network, and which
// Cityscapes labelId each output channel stands for. Cards are YAML files in models/.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
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
  kTiles,          // scale the image keeping its aspect (tile_scale, or the focal-length ratio),
                   // cover it with input_width x input_height tiles that overlap by at least
                   // tile_overlap pixels, average the tiles' softmax probabilities
};

// Per-image colour normalization before the network's own mean/scale.
enum class ColorNormalization {
  kNone,
  // Each channel is mapped affinely so the image's mean and standard deviation become
  // color_mean / color_std: a camera with another exposure and white balance than the training
  // camera then gives the network the colour statistics it was trained on.
  kStandardize,
};

// Which labels a map should trust: pixels whose softmax confidence is below min_confidence, or
// within boundary_radius_px of a label edge, become "unlabeled" (no class evidence). The
// defaults are the knee of accuracy against coverage measured on SemanticKITTI 05 / 08 with the
// built-in ENet card (docs/results.md); confidence is calibrated differently by every network,
// so each card carries its own (cards without the key: no filter).
struct LabelFilterOptions {
  double min_confidence = 0.6;  // 0: keep every confidence
  int boundary_radius_px = 2;   // 0: keep boundaries
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
  // kTiles: the factor the image is scaled by before tiling. 0: the smallest factor with which
  // the image covers one tile (no distortion, no tiling for an image of the input's aspect).
  // Used when the camera's focal length is not known (see network_focal_px).
  double tile_scale = 0.0;
  // kTiles: the focal length, in network input pixels, of the images the network was trained
  // on. When > 0 and segment() is given the camera's focal length, the image is scaled by
  // network_focal_px / camera focal so objects appear at the size the network learned.
  double network_focal_px = 0.0;
  // kTiles: the least overlap of neighbouring tiles, in network input pixels; tiles blend over
  // half of it.
  int tile_overlap = 0;
  // kTiles: network input rows at the bottom that are padding, not image: a network trained on
  // images whose bottom rows show the ego vehicle calls whatever it sees there "unlabeled".
  // The fitted scale leaves them free.
  int tile_bottom_margin = 0;
  // kTiles: an image wider than input_width after scaling goes through in one pass up to this
  // many network input pixels wide (its width rounded up to a multiple of pad_multiple, or of 16
  // when that is 1: ENet's labels are garbage at 1384 = 8 x 173 and right at 1392 = 16 x 87);
  // wider ones are cut into tiles of this width. 0: tiles are input_width wide. A fully
  // convolutional network takes such widths, and one wide pass costs less than overlapping
  // tiles.
  int tile_max_width = 0;
  // Average the probabilities with those of the horizontally mirrored image (every policy):
  // twice the network's time.
  bool flip_average = false;
  // true: channels mapped to labelId 0 ("unlabeled") never win the argmax; their probability
  // still counts in the softmax, so where the network saw void the chosen class has a low
  // confidence. Cityscapes' void is mostly the ego car's bonnet at the bottom of the frame, which
  // a network trained there paints over the road of cameras without a bonnet in view.
  bool suppress_unlabeled = false;
  // The output holding the class scores, for a model with more than one (an auxiliary head:
  // DeepLab, PSPNet, BiSeNet); "" for a model with one. OpenCV lists a model's outputs in an order
  // of its own, so a model with several and no name here is refused, not guessed.
  std::string output_name;
  // Tone curve applied to every pixel before the colour normalization: v' = 255 (v / 255)^gamma
  // (< 1 lifts the shadows and midtones). 1: none. Valid: [kMinGamma, kMaxGamma].
  double gamma = 1.0;
  static constexpr double kMinGamma = 0.2, kMaxGamma = 5.0;
  ColorNormalization color_normalization = ColorNormalization::kNone;
  // kStandardize targets, per channel in the order of `mean` (pixel values 0..255).
  std::array<double, 3> color_mean{{0.0, 0.0, 0.0}};
  std::array<double, 3> color_std{{1.0, 1.0, 1.0}};
  // Output channel index -> Cityscapes labelId; its size is the number of output channels.
  std::vector<std::uint8_t> output_label_ids;
  // What segmentation_node and semantic_map_offline apply before labels reach a map (YAML
  // label_filter: {min_confidence, boundary_radius_px}).
  LabelFilterOptions label_filter{0.0, 0};

  int numOutputChannels() const { return static_cast<int>(output_label_ids.size()); }
};

// Cityscapes' colour statistics (train split, RGB, pixel values 0..255): the color_mean /
// color_std of the built-in ENet card.
constexpr double kCityscapesRgbMean[3] = {73.16, 82.91, 72.39};
constexpr double kCityscapesRgbStd[3] = {47.68, 48.49, 47.74};

// Thrown for unreadable or inconsistent model cards; the message names the file and field.
class ModelCardError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Parses a model card YAML file (format: models/unet_synthetic.yaml).
ModelCard loadModelCard(const std::string& yaml_path);

// The value checks loadModelCard makes, for a card changed after loading (a tool's overrides):
// calls fail(key, why) for the first value out of its range; fail must throw.
using ModelCardCheckFailure = std::function<void(const std::string& key, const std::string& why)>;
void checkModelCard(const ModelCard& card, const ModelCardCheckFailure& fail);

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
const char* colorNormalizationName(ColorNormalization normalization);

}  // namespace perception
}  // namespace inekf_semantic_mapping
