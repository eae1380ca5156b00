// SemanticOcTree's tree logic: the node's class evidence and posterior, the tree type's
// registration, Morton codes, inner-node aggregation and pruning. Insertion is in
// semantic_octree_insertion.cpp, the file format in semantic_octree_io.cpp.
#include "inekf_semantic_mapping/mapping/semantic_octree.h"

#include <algorithm>
#include <cmath>

namespace inekf_semantic_mapping {
namespace mapping {

namespace {

// Interleaves the 3 x 16 key bits (x lowest): keys close in space are close in the order.
std::uint64_t spreadBits(std::uint64_t v) {
  v &= 0xFFFF;
  v = (v | (v << 16)) & 0x0000FF0000FFULL;
  v = (v | (v << 8)) & 0x00F00F00F00FULL;
  v = (v | (v << 4)) & 0x0C30C30C30C3ULL;
  v = (v | (v << 2)) & 0x249249249249ULL;
  return v;
}
}  // namespace

// ---------------------------------------------------------------------------------------------
// SemanticOcTreeNode
// ---------------------------------------------------------------------------------------------

// The memory budget the header promises (plain OcTreeNode: 16 bytes).
static_assert(sizeof(SemanticOcTreeNode) <= 24, "SemanticOcTreeNode grew past 24 bytes");

void SemanticOcTreeNode::addClassEvidence(ClassIndex index, std::uint32_t count) {
  addClassCount(index, count, &classes_, &counts_);
}

void SemanticOcTreeNode::mergeClassEvidence(const SemanticOcTreeNode& other) {
  for (int i = 0; i < kSlots; ++i) addClassEvidence(other.classes_[i], other.counts_[i]);
}

std::uint32_t SemanticOcTreeNode::totalCount() const {
  std::uint32_t total = 0;
  for (auto c : counts_) total += c;
  return total;
}

ClassIndex SemanticOcTreeNode::mostLikelyClass() const {
  return mostObservedClass(classes_, counts_);
}

double SemanticOcTreeNode::classProbability(ClassIndex index, const FusionModel& model,
                                            int num_classes) const {
  if (num_classes <= 0 || index == kNoClass || index >= num_classes) return 0.0;
  std::uint32_t count_of_index = 0;
  int stored = 0;
  std::uint16_t max_count = 0;
  for (int i = 0; i < kSlots; ++i) {
    if (classes_[i] == kNoClass) continue;
    ++stored;
    max_count = std::max(max_count, counts_[i]);
    if (classes_[i] == index) count_of_index = counts_[i];
  }
  if (model.rule == FusionRule::kDirichlet) {
    const double alpha = model.dirichlet_prior;
    return (count_of_index + alpha) / (totalCount() + num_classes * alpha);
  }
  if (num_classes == 1) return 1.0;
  const double c = model.correct_probability;
  const double log_ratio = std::log(c * (num_classes - 1) / (1.0 - c));
  // Weights exp(L n_k) relative to the largest, so nothing overflows.
  double normalizer = (num_classes - stored) * std::exp(-log_ratio * max_count);
  for (int i = 0; i < kSlots; ++i) {
    if (classes_[i] != kNoClass) {
      normalizer += std::exp(log_ratio * (static_cast<double>(counts_[i]) - max_count));
    }
  }
  return std::exp(log_ratio * (static_cast<double>(count_of_index) - max_count)) / normalizer;
}

// ---------------------------------------------------------------------------------------------
// SemanticOcTree
// ---------------------------------------------------------------------------------------------

SemanticOcTree::StaticMemberInitializer SemanticOcTree::semantic_octree_member_init_;

SemanticOcTree::StaticMemberInitializer::StaticMemberInitializer() {
  auto* prototype = new SemanticOcTree(0.1);
  prototype->clearKeyRays();
  octomap::AbstractOcTree::registerTreeType(prototype);
}

SemanticOcTree::SemanticOcTree(double resolution)
    : SemanticOcTree(resolution, ClassSet::cityscapes(), FusionModel()) {}

SemanticOcTree::SemanticOcTree(double resolution, ClassSet classes, FusionModel fusion)
    : OccupancyOcTreeBase<SemanticOcTreeNode>(resolution),
      classes_(std::move(classes)),
      fusion_(fusion) {
  semantic_octree_member_init_.ensureLinking();
}

void SemanticOcTree::setOccupancyModel(const OccupancyModel& model) {
  setProbHit(model.prob_hit);
  setProbMiss(model.prob_miss);
  setClampingThresMin(model.clamping_min);
  setClampingThresMax(model.clamping_max);
}

bool SemanticOcTree::createRootIfEmpty() {
  if (root != nullptr) return false;
  root = new SemanticOcTreeNode();
  ++tree_size;
  return true;
}

std::uint64_t SemanticOcTree::mortonCode(const octomap::OcTreeKey& key) {
  return spreadBits(key[0]) | (spreadBits(key[1]) << 1) | (spreadBits(key[2]) << 2);
}

void SemanticOcTree::updateInnerOccupancy() {
  if (root) updateInnerOccupancyRecurs(root, 0);
}

void SemanticOcTree::updateInnerOccupancyRecurs(SemanticOcTreeNode* node, unsigned int depth) {
  if (!nodeHasChildren(node)) return;
  if (depth < tree_depth) {
    for (unsigned int i = 0; i < 8; ++i) {
      if (nodeChildExists(node, i)) updateInnerOccupancyRecurs(getNodeChild(node, i), depth + 1);
    }
  }
  node->updateOccupancyChildren();
  node->clearSemantics();
  for (unsigned int i = 0; i < 8; ++i) {
    if (nodeChildExists(node, i)) node->mergeClassEvidence(*getNodeChild(node, i));
  }
}

bool SemanticOcTree::isNodeCollapsible(const SemanticOcTreeNode* node) const {
  if (!nodeChildExists(node, 0)) return false;
  const SemanticOcTreeNode* first = getNodeChild(node, 0);
  if (nodeHasChildren(first)) return false;
  for (unsigned int i = 1; i < 8; ++i) {
    if (!nodeChildExists(node, i)) return false;
    const SemanticOcTreeNode* child = getNodeChild(node, i);
    if (nodeHasChildren(child) || !(*child == *first)) return false;
  }
  return true;
}

bool SemanticOcTree::pruneNode(SemanticOcTreeNode* node) {
  if (!isNodeCollapsible(node)) return false;
  node->copyData(*getNodeChild(node, 0));
  for (unsigned int i = 0; i < 8; ++i) deleteNodeChild(node, i);
  delete[] node->children;
  node->children = nullptr;
  return true;
}

std::uint32_t SemanticOcTree::mostLikelyLabel(const SemanticOcTreeNode& node,
                                              std::uint32_t fallback) const {
  const ClassIndex index = node.mostLikelyClass();
  if (index == kNoClass || index >= classes_.size()) return fallback;
  return classes_.info(index).label_id;
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
