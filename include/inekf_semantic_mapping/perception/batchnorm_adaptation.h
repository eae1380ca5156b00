// A network's batch normalization statistics measured again on the target camera's images
// (AdaBN: Li, Wang, Shi, Liu, Hou, "Revisiting batch normalization for practical domain
// adaptation", 2016). A batch normalization layer standardizes each channel with the mean and
// variance it saw in training; on another camera the activations are distributed differently,
// and every later layer sees inputs it was not trained on. Replacing the stored statistics with
// those measured on unlabelled images of the new camera adapts the network without labels and
// without changing a learned weight.
//
// The statistics are data (measured on third-party images with a third-party model): they live
// in a YAML file beside the user's model card, written by `adapt_segmenter`, never in this
// repository.
#pragma once

#include <stdexcept>
#include <string>
#include <vector>

namespace inekf_semantic_mapping {
namespace perception {

struct BatchNormLayerStatistics {
  std::string layer;             // the network's name for the batch normalization layer
  std::vector<double> mean;      // per channel, of the layer's input on the target images
  std::vector<double> variance;  // per channel
};

struct BatchNormAdaptation {
  std::vector<BatchNormLayerStatistics> layers;
  int num_images = 0;          // how many images the statistics were measured on
  int adapted_layers = 0;      // layers whose statistics were measured (the rest keep the trained)
  double target_weight = 1.0;  // the measured statistics' share of the blend with the trained
  std::string source;          // file it was read from (for messages)
  bool empty() const { return layers.empty(); }
};

// Thrown for unreadable or inconsistent statistics; the message names the file (and line).
class BatchNormAdaptationError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

BatchNormAdaptation loadBatchNormAdaptation(const std::string& yaml_path);
// Atomic (temporary file + rename).
void saveBatchNormAdaptation(const BatchNormAdaptation& adaptation, const std::string& yaml_path);

}  // namespace perception
}  // namespace inekf_semantic_mapping
