// Semantic map accuracy against the synthetic world's true surfaces: each occupied voxel's
// truth is the label of the surface nearest its centre (SyntheticWorld::labelAt within
// resolution * 0.87, i.e. about half the voxel diagonal).
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/synthetic/world.h"

namespace inekf_semantic_mapping {
namespace synthetic {

struct ClassIou {
  std::uint8_t label_id = 0;  // Cityscapes labelId
  std::size_t true_positive = 0, false_positive = 0, false_negative = 0;
  double iou() const {
    const std::size_t denominator = true_positive + false_positive + false_negative;
    return denominator ? static_cast<double>(true_positive) / denominator : 0.0;
  }
};

// Per-labelId IoU from (truth, predicted) labelId pairs: the counting behind the map evaluation
// below and the image evaluation of the segmentation tests.
class LabelIouCounter {
 public:
  void add(std::uint8_t truth, std::uint8_t predicted) {
    ++pairs_;
    if (predicted == truth) {
      ++per_label_[truth].true_positive;
      ++correct_;
    } else {
      ++per_label_[predicted].false_positive;
      ++per_label_[truth].false_negative;
    }
  }
  std::vector<ClassIou> classes() const;  // the labelIds present in the truth, ascending
  double meanIou() const;                 // over classes(); 0 without any pair
  std::size_t pairs() const { return pairs_; }
  std::size_t correct() const { return correct_; }

 private:
  std::array<ClassIou, 256> per_label_{};
  std::size_t pairs_ = 0, correct_ = 0;
};

struct SemanticMapIou {
  std::vector<ClassIou> classes;         // classes present in the truth, by labelId
  double mean_iou = 0;                   // over `classes`
  std::size_t voxels = 0;                // evaluated (with a true surface near them)
  std::size_t voxels_without_truth = 0;  // occupied but no surface within the tolerance
  std::size_t correct = 0;

  double accuracy() const { return voxels ? static_cast<double>(correct) / voxels : 0.0; }
  std::string toJson() const;
};

// voxel_centers and labels (Cityscapes labelIds) have the same length, else
// std::invalid_argument. Voxels with label 0 (unlabeled) count as wrong where there is truth.
SemanticMapIou semanticMapIou(const SyntheticWorld& world,
                              const std::vector<Eigen::Vector3d>& voxel_centers,
                              const std::vector<std::uint8_t>& labels, double resolution);

}  // namespace synthetic
}  // namespace inekf_semantic_mapping
