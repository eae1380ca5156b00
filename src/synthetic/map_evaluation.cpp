#include "inekf_semantic_mapping/synthetic/map_evaluation.h"

#include <cstdio>
#include <stdexcept>

#include "inekf_semantic_mapping/perception/cityscapes.h"

namespace inekf_semantic_mapping {
namespace synthetic {

std::vector<ClassIou> LabelIouCounter::classes() const {
  std::vector<ClassIou> present;
  for (int label = 0; label < 256; ++label) {
    ClassIou c = per_label_[label];
    if (c.true_positive + c.false_negative == 0) continue;  // not in the truth
    c.label_id = static_cast<std::uint8_t>(label);
    present.push_back(c);
  }
  return present;
}

double LabelIouCounter::meanIou() const {
  const std::vector<ClassIou> present = classes();
  double sum = 0;
  for (const ClassIou& c : present) sum += c.iou();
  return present.empty() ? 0.0 : sum / present.size();
}

SemanticMapIou semanticMapIou(const SyntheticWorld& world,
                              const std::vector<Eigen::Vector3d>& voxel_centers,
                              const std::vector<std::uint8_t>& labels, double resolution) {
  if (voxel_centers.size() != labels.size()) {
    throw std::invalid_argument("semanticMapIou: " + std::to_string(voxel_centers.size()) +
                                " voxel centres but " + std::to_string(labels.size()) + " labels");
  }
  if (!(resolution > 0)) throw std::invalid_argument("semanticMapIou: resolution must be > 0");
  LabelIouCounter counter;
  SemanticMapIou result;
  const double tolerance = resolution * 0.87;
  for (std::size_t i = 0; i < voxel_centers.size(); ++i) {
    const std::uint8_t truth = world.labelAt(voxel_centers[i], tolerance);
    if (truth == cityscapes::kUnlabeled) {
      ++result.voxels_without_truth;
      continue;
    }
    counter.add(truth, labels[i]);
  }
  result.classes = counter.classes();
  result.mean_iou = counter.meanIou();
  result.voxels = counter.pairs();
  result.correct = counter.correct();
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
