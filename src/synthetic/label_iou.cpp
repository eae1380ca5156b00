#include "inekf_semantic_mapping/synthetic/label_iou.h"

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

}  // namespace synthetic
}  // namespace inekf_semantic_mapping
