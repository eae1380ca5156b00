// Per-class IoU of (truth, predicted) label pairs: the image evaluation of the segmentation
// tests. Maps are scored with the package's one map metric instead (perception::mapLabelAt,
// the evaluate_map and evaluate_semantics tools).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

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

}  // namespace synthetic
}  // namespace inekf_semantic_mapping
