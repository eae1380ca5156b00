#include "inekf_semantic_mapping/synthetic/map_evaluation.h"

#include <array>
#include <cstdio>
#include <stdexcept>

#include "inekf_semantic_mapping/perception/cityscapes.h"

namespace inekf_semantic_mapping {
namespace synthetic {

SemanticMapIou semanticMapIou(const SyntheticWorld& world,
                              const std::vector<Eigen::Vector3d>& voxel_centers,
                              const std::vector<std::uint8_t>& labels, double resolution) {
  if (voxel_centers.size() != labels.size()) {
    throw std::invalid_argument("semanticMapIou: " + std::to_string(voxel_centers.size()) +
                                " voxel centres but " + std::to_string(labels.size()) + " labels");
  }
  if (!(resolution > 0)) throw std::invalid_argument("semanticMapIou: resolution must be > 0");
  std::array<ClassIou, 256> per_label{};
  SemanticMapIou result;
  const double tolerance = resolution * 0.87;
  for (std::size_t i = 0; i < voxel_centers.size(); ++i) {
    const std::uint8_t truth = world.labelAt(voxel_centers[i], tolerance);
    if (truth == cityscapes::kUnlabeled) {
      ++result.voxels_without_truth;
      continue;
    }
    ++result.voxels;
    if (labels[i] == truth) {
      ++per_label[truth].true_positive;
      ++result.correct;
    } else {
      ++per_label[labels[i]].false_positive;
      ++per_label[truth].false_negative;
    }
  }
  double sum = 0;
  for (int label = 0; label < 256; ++label) {
    ClassIou& c = per_label[label];
    if (c.true_positive + c.false_negative == 0) continue;  // not in the truth
    c.label_id = static_cast<std::uint8_t>(label);
    result.classes.push_back(c);
    sum += c.iou();
  }
  result.mean_iou = result.classes.empty() ? 0.0 : sum / result.classes.size();
  return result;
}

std::string SemanticMapIou::toJson() const {
  std::string json = "{\"mean_iou\": ";
  char number[64];
  std::snprintf(number, sizeof(number), "%.6f", mean_iou);
  json += number;
  std::snprintf(number, sizeof(number), "%.6f", accuracy());
  json += ", \"accuracy\": " + std::string(number) + ", \"voxels\": " + std::to_string(voxels) +
          ", \"voxels_without_truth\": " + std::to_string(voxels_without_truth) +
          ", \"classes\": {";
  for (std::size_t i = 0; i < classes.size(); ++i) {
    std::snprintf(number, sizeof(number), "%.6f", classes[i].iou());
    json += std::string(i ? ", " : "") + "\"" + cityscapes::labelName(classes[i].label_id) +
            "\": " + number;
  }
  return json + "}}";
}

}  // namespace synthetic
}  // namespace inekf_semantic_mapping
