#include "inekf_semantic_mapping/mapping/semantic_octree.h"

#include <octomap/OcTreeKey.h>

#include <algorithm>
#include <cmath>
#include <istream>
#include <ostream>
#include <stdexcept>
#include <unordered_map>

namespace inekf_semantic_mapping {
namespace mapping {

// ---------------------------------------------------------------------------------------------
// SemanticOcTreeNode
// ---------------------------------------------------------------------------------------------

void SemanticOcTreeNode::addClassEvidence(ClassIndex index, std::uint32_t count) {
  if (index == kNoClass || count == 0) return;
  int slot = -1;
  for (int i = 0; i < kSlots; ++i) {
    if (classes_[i] == index || classes_[i] == kNoClass) {
      slot = i;
      break;
    }
  }
  if (slot < 0) {
    // All slots hold other classes: the least observed one gives way.
    slot = static_cast<int>(std::min_element(counts_.begin(), counts_.end()) - counts_.begin());
    counts_[slot] = 0;
  }
  classes_[slot] = index;
  std::uint32_t total = counts_[slot] + std::min<std::uint32_t>(count, kMaxCount);
  while (total > kMaxCount) {
    // Halving every count keeps the ratios (Dirichlet) and the differences stay huge (Bayes).
    for (auto& c : counts_) c = static_cast<std::uint16_t>((c + 1) / 2);
    total = (total + 1) / 2;
  }
  counts_[slot] = static_cast<std::uint16_t>(total);
  // Canonical order (by class index, empty slots last) so equal evidence compares equal.
  for (int i = 1; i < kSlots; ++i) {
    for (int j = i; j > 0 && classes_[j] < classes_[j - 1]; --j) {
      std::swap(classes_[j], classes_[j - 1]);
      std::swap(counts_[j], counts_[j - 1]);
    }
  }
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
  ClassIndex best = kNoClass;
  std::uint16_t best_count = 0;
  for (int i = 0; i < kSlots; ++i) {
    // Slots are sorted by index, so '>' keeps the lower index on ties.
    if (classes_[i] != kNoClass && counts_[i] > best_count) {
      best = classes_[i];
      best_count = counts_[i];
    }
  }
  return best;
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

std::istream& SemanticOcTreeNode::readData(std::istream& s) {
  s.read(reinterpret_cast<char*>(&value), sizeof(value));
  s.read(reinterpret_cast<char*>(classes_.data()), sizeof(ClassIndex) * kSlots);
  s.read(reinterpret_cast<char*>(counts_.data()), sizeof(std::uint16_t) * kSlots);
  return s;
}

std::ostream& SemanticOcTreeNode::writeData(std::ostream& s) const {
  s.write(reinterpret_cast<const char*>(&value), sizeof(value));
  s.write(reinterpret_cast<const char*>(classes_.data()), sizeof(ClassIndex) * kSlots);
  s.write(reinterpret_cast<const char*>(counts_.data()), sizeof(std::uint16_t) * kSlots);
  return s;
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

std::size_t SemanticOcTree::insertLabeledScan(const LabeledScan& scan, double max_range_m) {
  const std::size_t num_points = static_cast<std::size_t>(scan.points_map.cols());
  const bool labeled = !scan.label_ids.empty();
  if (labeled && scan.label_ids.size() != num_points) {
    throw std::invalid_argument("insertLabeledScan: " + std::to_string(scan.label_ids.size()) +
                                " labels for " + std::to_string(num_points) + " points");
  }
  const octomap::point3d origin(scan.sensor_origin_map.x(), scan.sensor_origin_map.y(),
                                scan.sensor_origin_map.z());
  octomap::OcTreeKey origin_key;
  if (!coordToKeyChecked(origin, origin_key)) {
    throw std::out_of_range("insertLabeledScan: sensor origin outside the octree's range");
  }

  // 1. Endpoints grouped per voxel: the class evidence of all points in it and one ray end.
  struct EndpointVoxel {
    octomap::point3d ray_end;
    SemanticOcTreeNode evidence;
  };
  std::unordered_map<octomap::OcTreeKey, EndpointVoxel, octomap::OcTreeKey::KeyHash> endpoints;
  endpoints.reserve(num_points / 2 + 1);
  octomap::KeySet clipped_ray_ends;  // voxels where rays longer than max range stop
  std::vector<octomap::point3d> clipped_ends;
  std::size_t labeled_points = 0;
  const bool limit_range = max_range_m > 0.0;
  for (std::size_t i = 0; i < num_points; ++i) {
    const octomap::point3d point(scan.points_map(0, i), scan.points_map(1, i),
                                 scan.points_map(2, i));
    if (!std::isfinite(point.x()) || !std::isfinite(point.y()) || !std::isfinite(point.z())) {
      continue;
    }
    const double range = (point - origin).norm();
    if (limit_range && range > max_range_m) {
      const octomap::point3d end = origin + (point - origin) * (max_range_m / range);
      octomap::OcTreeKey key;
      if (coordToKeyChecked(end, key) && clipped_ray_ends.insert(key).second) {
        clipped_ends.push_back(end);
      }
      continue;
    }
    octomap::OcTreeKey key;
    if (!coordToKeyChecked(point, key)) continue;
    auto [it, inserted] = endpoints.try_emplace(key);
    if (inserted) it->second.ray_end = point;
    if (labeled && scan.label_ids[i] != scan.unknown_label_id) {
      const ClassIndex index = classes_.indexOf(scan.label_ids[i]);
      if (index != kNoClass) {
        it->second.evidence.addClassEvidence(index, 1);
        ++labeled_points;
      }
    }
  }

  // 2. Free voxels: one ray per endpoint voxel and per clipped ray end, collected into a set.
  octomap::KeySet free_keys;
  octomap::KeyRay& ray = keyrays.at(0);
  auto cast = [&](const octomap::point3d& end) {
    if (computeRayKeys(origin, end, ray)) free_keys.insert(ray.begin(), ray.end());
  };
  for (const auto& [key, voxel] : endpoints) cast(voxel.ray_end);
  for (const octomap::point3d& end : clipped_ends) cast(end);

  // 3. Each voxel updated once: misses first (except where something was hit), then hits.
  for (const octomap::OcTreeKey& key : free_keys) {
    if (endpoints.find(key) == endpoints.end()) updateNode(key, prob_miss_log, false);
  }
  for (const auto& [key, voxel] : endpoints) updateOccupiedWithEvidence(key, voxel.evidence);
  return labeled_points;
}

SemanticOcTreeNode* SemanticOcTree::updateOccupiedVoxel(const octomap::OcTreeKey& key,
                                                        ClassIndex index,
                                                        std::uint32_t class_count) {
  SemanticOcTreeNode evidence;
  evidence.addClassEvidence(index, class_count);
  return updateOccupiedWithEvidence(key, evidence);
}

SemanticOcTreeNode* SemanticOcTree::updateOccupiedWithEvidence(const octomap::OcTreeKey& key,
                                                               const SemanticOcTreeNode& evidence) {
  bool created_root = false;
  if (root == nullptr) {
    root = new SemanticOcTreeNode();
    ++tree_size;
    created_root = true;
  }
  return updateOccupiedRecurs(root, created_root, key, 0, evidence);
}

// octomap's updateNodeRecurs, except that it always reaches the finest depth (octomap returns
// early at a clamped pruned node, which would smear class evidence over a whole block) and adds
// the class evidence at the leaf.
SemanticOcTreeNode* SemanticOcTree::updateOccupiedRecurs(SemanticOcTreeNode* node,
                                                         bool node_just_created,
                                                         const octomap::OcTreeKey& key,
                                                         unsigned int depth,
                                                         const SemanticOcTreeNode& evidence) {
  if (depth < tree_depth) {
    const unsigned int pos = octomap::computeChildIdx(key, tree_depth - 1 - depth);
    bool created_node = false;
    if (!nodeChildExists(node, pos)) {
      if (!nodeHasChildren(node) && !node_just_created) {
        expandNode(node);  // a pruned leaf: its children inherit its data
      } else {
        createNodeChild(node, pos);
        created_node = true;
      }
    }
    SemanticOcTreeNode* leaf =
        updateOccupiedRecurs(getNodeChild(node, pos), created_node, key, depth + 1, evidence);
    if (pruneNode(node)) return node;
    node->updateOccupancyChildren();
    return leaf;
  }
  updateNodeLogOdds(node, prob_hit_log);
  node->mergeClassEvidence(evidence);
  return node;
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

namespace {
constexpr char kSemanticHeaderMagic[] = "ISM_SEMANTIC_OCTREE_V1";

template <typename T>
void writePod(std::ostream& s, const T& value) {
  s.write(reinterpret_cast<const char*>(&value), sizeof(T));
}
template <typename T>
bool readPod(std::istream& s, T* value) {
  return static_cast<bool>(s.read(reinterpret_cast<char*>(value), sizeof(T)));
}
}  // namespace

// The class table and fusion model go before octomap's node data, so a loaded map knows which
// label id each stored class index stands for.
std::ostream& SemanticOcTree::writeData(std::ostream& s) const {
  s.write(kSemanticHeaderMagic, sizeof(kSemanticHeaderMagic));
  writePod(s, static_cast<std::uint8_t>(fusion_.rule));
  writePod(s, fusion_.correct_probability);
  writePod(s, fusion_.dirichlet_prior);
  writePod(s, static_cast<std::uint32_t>(classes_.size()));
  for (const ClassInfo& info : classes_.classes()) {
    writePod(s, info.label_id);
    s.write(reinterpret_cast<const char*>(info.rgb.data()), 3);
    writePod(s, static_cast<std::uint32_t>(info.name.size()));
    s.write(info.name.data(), static_cast<std::streamsize>(info.name.size()));
  }
  return OccupancyOcTreeBase<SemanticOcTreeNode>::writeData(s);
}

std::istream& SemanticOcTree::readData(std::istream& s) {
  char magic[sizeof(kSemanticHeaderMagic)] = {};
  std::uint8_t rule = 0;
  std::uint32_t num_classes = 0;
  FusionModel fusion;
  bool ok = static_cast<bool>(s.read(magic, sizeof(magic))) &&
            std::string(magic) == kSemanticHeaderMagic && readPod(s, &rule) && rule <= 1 &&
            readPod(s, &fusion.correct_probability) && readPod(s, &fusion.dirichlet_prior) &&
            readPod(s, &num_classes) && num_classes <= kMaxClasses;
  std::vector<ClassInfo> classes;
  for (std::uint32_t i = 0; ok && i < num_classes; ++i) {
    ClassInfo info;
    std::uint32_t name_length = 0;
    ok = readPod(s, &info.label_id) && s.read(reinterpret_cast<char*>(info.rgb.data()), 3) &&
         readPod(s, &name_length) && name_length < 4096;
    if (ok) {
      info.name.resize(name_length);
      ok = static_cast<bool>(s.read(info.name.data(), name_length));
    }
    classes.push_back(std::move(info));
  }
  if (!ok) {
    s.setstate(std::ios::failbit);
    return s;
  }
  fusion.rule = static_cast<FusionRule>(rule);
  fusion_ = fusion;
  classes_ = ClassSet(std::move(classes));
  return OccupancyOcTreeBase<SemanticOcTreeNode>::readData(s);
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
