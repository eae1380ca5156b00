// The class set of a semantic map: which label ids (in the input's own id space: Cityscapes
// labelIds, SemanticKITTI ids, ...) the map knows, their compact index inside a voxel, names and
// display colors; and the fusion rule that turns a voxel's per-class evidence into probabilities.
// ROS-free and octomap-free.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

namespace inekf_semantic_mapping {
namespace mapping {

// Compact class index stored in a voxel; kNoClass marks "no evidence" / unknown label.
using ClassIndex = std::uint8_t;
constexpr ClassIndex kNoClass = 255;
constexpr int kMaxClasses = 255;  // indices 0..254

// Class evidence of one voxel: the kClassSlots most observed classes and how often, in canonical
// order (by class index, empty slots last). SemanticOcTreeNode and HashedVoxelGrid share it.
constexpr int kClassSlots = 4;
constexpr std::uint16_t kMaxClassCount = 0xFFFF;
using ClassSlotIndices = std::array<ClassIndex, kClassSlots>;
using ClassSlotCounts = std::array<std::uint16_t, kClassSlots>;
// Adds `count` observations of class `index` (saturating; all counts are halved when one would
// overflow, which keeps their ratios); a (kClassSlots+1)-th class replaces the least observed.
void addClassCount(ClassIndex index, std::uint32_t count, ClassSlotIndices* classes,
                   ClassSlotCounts* counts);
// The class with most evidence (kNoClass if none). Ties: the lower index.
ClassIndex mostObservedClass(const ClassSlotIndices& classes, const ClassSlotCounts& counts);

struct ClassInfo {
  std::uint32_t label_id = 0;
  std::string name;
  std::array<std::uint8_t, 3> rgb{{255, 255, 255}};
};

// Bidirectional label id <-> compact index table, sized by configuration.
class ClassSet {
 public:
  ClassSet() = default;
  // Throws std::invalid_argument when a label id is listed twice.
  explicit ClassSet(std::vector<ClassInfo> classes);

  // The 34 Cityscapes labelIds with their official palette (the package's default id space).
  static ClassSet cityscapes();
  // The SemanticKITTI learning-map classes (ids 0..259) with the semantic-kitti.yaml palette.
  static ClassSet semanticKitti();

  int size() const { return static_cast<int>(classes_.size()); }
  // kNoClass for a label id the set does not know.
  ClassIndex indexOf(std::uint32_t label_id) const;
  const ClassInfo& info(ClassIndex index) const { return classes_.at(index); }
  const std::vector<ClassInfo>& classes() const { return classes_; }
  // Adds a label id if new (throws std::length_error past kMaxClasses); returns its index.
  ClassIndex addLabel(std::uint32_t label_id, const std::string& name = "",
                      std::array<std::uint8_t, 3> rgb = {{255, 255, 255}});

  bool operator==(const ClassSet& other) const;

 private:
  std::vector<ClassInfo> classes_;
  std::unordered_map<std::uint32_t, ClassIndex> index_of_label_;
};

enum class FusionRule : std::uint8_t {
  // Recursive Bayes with a symmetric confusion model: the segmentation is right with
  // probability c and otherwise uniformly wrong. Each observation of class j multiplies p(j) by
  // c and every other class by (1-c)/(N-1), so the posterior is p(k) ∝ exp(L n_k) with
  // L = log(c (N-1) / (1-c)) and n_k the number of observations of k: counts are sufficient.
  kBayesConfusion = 0,
  // Dirichlet counting: p(k) = (n_k + alpha) / (sum n + N alpha).
  kDirichlet = 1,
};

struct FusionModel {
  FusionRule rule = FusionRule::kBayesConfusion;
  double correct_probability = 0.8;  // c, for kBayesConfusion; in (1/N, 1)
  double dirichlet_prior = 0.5;      // alpha, for kDirichlet
};

FusionRule parseFusionRule(const std::string& name);  // "bayes" | "dirichlet"; throws otherwise

}  // namespace mapping
}  // namespace inekf_semantic_mapping
