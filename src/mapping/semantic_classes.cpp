#include "inekf_semantic_mapping/mapping/semantic_classes.h"

#include <algorithm>
#include <stdexcept>
#include <utility>

#include "inekf_semantic_mapping/perception/cityscapes.h"

namespace inekf_semantic_mapping {
namespace mapping {

ClassSet::ClassSet(std::vector<ClassInfo> classes) {
  for (const ClassInfo& info : classes) {
    // A second entry of one id would be dropped and shift every later class's index.
    if (indexOf(info.label_id) != kNoClass) {
      throw std::invalid_argument("label id " + std::to_string(info.label_id) +
                                  " is listed twice ('" + classes_[indexOf(info.label_id)].name +
                                  "' and '" + info.name + "')");
    }
    addLabel(info.label_id, info.name, info.rgb);
  }
}

ClassSet ClassSet::cityscapes() {
  std::vector<ClassInfo> classes;
  for (const cityscapes::LabelInfo& label : cityscapes::kLabels) {
    classes.push_back({label.label_id, label.name, {{label.r, label.g, label.b}}});
  }
  return ClassSet(std::move(classes));
}

ClassSet ClassSet::semanticKitti() {
  // semantic-kitti.yaml color_map is BGR; stored here as RGB.
  struct Entry {
    std::uint32_t id;
    const char* name;
    std::uint8_t b, g, r;
  };
  static const Entry kEntries[] = {
      {0, "unlabeled", 0, 0, 0},
      {1, "outlier", 0, 0, 255},
      {10, "car", 245, 150, 100},
      {11, "bicycle", 245, 230, 100},
      {13, "bus", 250, 80, 100},
      {15, "motorcycle", 150, 60, 30},
      {16, "on-rails", 255, 0, 0},
      {18, "truck", 180, 30, 80},
      {20, "other-vehicle", 255, 0, 0},
      {30, "person", 30, 30, 255},
      {31, "bicyclist", 200, 40, 255},
      {32, "motorcyclist", 90, 30, 150},
      {40, "road", 255, 0, 255},
      {44, "parking", 255, 150, 255},
      {48, "sidewalk", 75, 0, 75},
      {49, "other-ground", 75, 0, 175},
      {50, "building", 0, 200, 255},
      {51, "fence", 50, 120, 255},
      {52, "other-structure", 0, 150, 255},
      {60, "lane-marking", 170, 255, 150},
      {70, "vegetation", 0, 175, 0},
      {71, "trunk", 0, 60, 135},
      {72, "terrain", 80, 240, 150},
      {80, "pole", 150, 240, 255},
      {81, "traffic-sign", 0, 0, 255},
      {99, "other-object", 255, 255, 50},
      {252, "moving-car", 245, 150, 100},
      {253, "moving-bicyclist", 200, 40, 255},
      {254, "moving-person", 30, 30, 255},
      {255, "moving-motorcyclist", 90, 30, 150},
      {256, "moving-on-rails", 255, 0, 0},
      {257, "moving-bus", 250, 80, 100},
      {258, "moving-truck", 180, 30, 80},
      {259, "moving-other-vehicle", 255, 0, 0},
  };
  std::vector<ClassInfo> classes;
  for (const Entry& e : kEntries) classes.push_back({e.id, e.name, {{e.r, e.g, e.b}}});
  return ClassSet(std::move(classes));
}

ClassIndex ClassSet::indexOf(std::uint32_t label_id) const {
  const auto it = index_of_label_.find(label_id);
  return it == index_of_label_.end() ? kNoClass : it->second;
}

ClassIndex ClassSet::addLabel(std::uint32_t label_id, const std::string& name,
                              std::array<std::uint8_t, 3> rgb) {
  const ClassIndex existing = indexOf(label_id);
  if (existing != kNoClass) return existing;
  if (size() >= kMaxClasses) {
    throw std::length_error("ClassSet: cannot add label id " + std::to_string(label_id) +
                            ": at most " + std::to_string(kMaxClasses) + " classes");
  }
  const auto index = static_cast<ClassIndex>(classes_.size());
  classes_.push_back({label_id, name.empty() ? "class_" + std::to_string(label_id) : name, rgb});
  index_of_label_[label_id] = index;
  return index;
}

bool ClassSet::operator==(const ClassSet& other) const {
  if (classes_.size() != other.classes_.size()) return false;
  for (std::size_t i = 0; i < classes_.size(); ++i) {
    const ClassInfo& a = classes_[i];
    const ClassInfo& b = other.classes_[i];
    if (a.label_id != b.label_id || a.name != b.name || a.rgb != b.rgb) return false;
  }
  return true;
}

FusionRule parseFusionRule(const std::string& name) {
  if (name == "bayes") return FusionRule::kBayesConfusion;
  if (name == "dirichlet") return FusionRule::kDirichlet;
  throw std::invalid_argument("unknown fusion rule '" + name + "' (expected bayes or dirichlet)");
}

void addClassCount(ClassIndex index, std::uint32_t count, ClassSlotIndices* classes,
                   ClassSlotCounts* counts) {
  if (index == kNoClass || count == 0) return;
  int slot = -1;
  for (int i = 0; i < kClassSlots; ++i) {
    if ((*classes)[i] == index || (*classes)[i] == kNoClass) {
      slot = i;
      break;
    }
  }
  if (slot < 0) {
    // All slots hold other classes: the least observed one gives way.
    slot = static_cast<int>(std::min_element(counts->begin(), counts->end()) - counts->begin());
    (*counts)[slot] = 0;
  }
  (*classes)[slot] = index;
  std::uint32_t total = (*counts)[slot] + std::min<std::uint32_t>(count, kMaxClassCount);
  while (total > kMaxClassCount) {
    // Halving every count keeps the ratios (Dirichlet) and the differences stay huge (Bayes).
    for (auto& c : *counts) c = static_cast<std::uint16_t>((c + 1) / 2);
    total = (total + 1) / 2;
  }
  (*counts)[slot] = static_cast<std::uint16_t>(total);
  // Canonical order (by class index, empty slots last) so equal evidence compares equal.
  for (int i = 1; i < kClassSlots; ++i) {
    for (int j = i; j > 0 && (*classes)[j] < (*classes)[j - 1]; --j) {
      std::swap((*classes)[j], (*classes)[j - 1]);
      std::swap((*counts)[j], (*counts)[j - 1]);
    }
  }
}

ClassIndex mostObservedClass(const ClassSlotIndices& classes, const ClassSlotCounts& counts) {
  ClassIndex best = kNoClass;
  std::uint16_t best_count = 0;
  for (int i = 0; i < kClassSlots; ++i) {
    // Slots are sorted by index, so '>' keeps the lower index on ties.
    if (classes[i] != kNoClass && counts[i] > best_count) {
      best = classes[i];
      best_count = counts[i];
    }
  }
  return best;
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
