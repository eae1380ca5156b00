#include "inekf_semantic_mapping/mapping/semantic_octree.h"

#include <octomap/OcTreeKey.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <istream>
#include <ostream>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <unordered_map>

#include "flat_key_set.h"

namespace inekf_semantic_mapping {
namespace mapping {

namespace {

// Grazing-ray truncation never withholds more than this fraction of a ray from clearing.
constexpr double kMaxGrazingCutFraction = 0.25;

std::uint64_t packKey(const octomap::OcTreeKey& key) {
  return (static_cast<std::uint64_t>(key[0]) << 32) | (static_cast<std::uint64_t>(key[1]) << 16) |
         key[2];
}
octomap::OcTreeKey unpackKey(std::uint64_t packed) {
  return octomap::OcTreeKey(static_cast<octomap::key_type>(packed >> 32),
                            static_cast<octomap::key_type>(packed >> 16),
                            static_cast<octomap::key_type>(packed));
}

// Interleaves the 3 x 16 key bits (x lowest): keys close in space are close in the order.
std::uint64_t spreadBits(std::uint64_t v) {
  v &= 0xFFFF;
  v = (v | (v << 16)) & 0x0000FF0000FFULL;
  v = (v | (v << 8)) & 0x00F00F00F00FULL;
  v = (v | (v << 4)) & 0x0C30C30C30C3ULL;
  v = (v | (v << 2)) & 0x249249249249ULL;
  return v;
}
// A voxel the scan ends in: the class evidence of all its points and one of them as ray end.
struct EndpointVoxel {
  octomap::point3d ray_end;
  SemanticOcTreeNode evidence;
};
using EndpointVoxels =
    std::unordered_map<octomap::OcTreeKey, EndpointVoxel, octomap::OcTreeKey::KeyHash>;

// Stage 1 of insertLabeledScan: the scan's endpoints grouped per voxel (the class evidence of all
// points in it and one ray end); points beyond max_range_m only end a free ray there
// (`clipped_ends`, one per voxel). Returns the points that added class evidence.
std::size_t groupEndpoints(const SemanticOcTree& tree, const LabeledScan& scan,
                           const octomap::point3d& origin, double max_range_m,
                           EndpointVoxels* endpoints, std::vector<octomap::point3d>* clipped_ends) {
  const std::size_t num_points = static_cast<std::size_t>(scan.points_map.cols());
  const bool labeled = !scan.label_ids.empty();
  endpoints->reserve(num_points / 2 + 1);
  octomap::KeySet clipped_ray_ends;
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
      if (tree.coordToKeyChecked(end, key) && clipped_ray_ends.insert(key).second) {
        clipped_ends->push_back(end);
      }
      continue;
    }
    octomap::OcTreeKey key;
    if (!tree.coordToKeyChecked(point, key)) continue;
    auto [it, inserted] = endpoints->try_emplace(key);
    if (inserted) it->second.ray_end = point;
    if (labeled && scan.label_ids[i] != scan.unknown_label_id) {
      const ClassIndex index = tree.classSet().indexOf(scan.label_ids[i]);
      if (index != kNoClass) {
        it->second.evidence.addClassEvidence(index, 1);
        ++labeled_points;
      }
    }
  }
  return labeled_points;
}

// Stage 2: where the free rays end: one per endpoint voxel and per clipped ray end. A ray going
// down stops short of its hit by truncation_m (grazing rays would otherwise carve the road).
std::vector<octomap::point3d> rayEnds(const EndpointVoxels& endpoints,
                                      const std::vector<octomap::point3d>& clipped_ends,
                                      const octomap::point3d& origin, double truncation_m) {
  std::vector<octomap::point3d> ray_ends;
  ray_ends.reserve(endpoints.size() + clipped_ends.size());
  for (const auto& [key, voxel] : endpoints) {
    const octomap::point3d ray = voxel.ray_end - origin;
    if (truncation_m > 0.0 && ray.z() < 0.0) {
      // Only rays that go down can graze the road. For a hit on flat ground the cut is
      // truncation_m / (sensor height) of the ray (12 % for 1 voxel of 0.2 m at 1.73 m); the cap
      // keeps a nearly level ray to a wall or a car from losing more than a quarter.
      const double length = ray.norm();
      const double sin_elevation = -ray.z() / length;
      const double cut = std::min(kMaxGrazingCutFraction * length, truncation_m / sin_elevation);
      ray_ends.push_back(origin + ray * static_cast<float>(1.0 - cut / length));
    } else {
      ray_ends.push_back(voxel.ray_end);
    }
  }
  ray_ends.insert(ray_ends.end(), clipped_ends.begin(), clipped_ends.end());
  return ray_ends;
}

// Stage 3: the keys the rays cross (free space). Rays near the sensor cross the same voxels over
// and over, so the keys go through a flat open-addressing set (far cheaper than octomap's
// node-allocating KeySet); one set per thread, merged after.
FlatKeySet castFreeRays(const SemanticOcTree& tree, const octomap::point3d& origin,
                        const std::vector<octomap::point3d>& ray_ends, int threads) {
  std::vector<FlatKeySet> free_keys(static_cast<std::size_t>(threads));
  auto cast_range = [&](int t) {
    octomap::KeyRay ray;
    FlatKeySet& keys = free_keys[static_cast<std::size_t>(t)];
    keys.reserve(ray_ends.size() * 4 / static_cast<std::size_t>(threads));
    for (std::size_t i = static_cast<std::size_t>(t); i < ray_ends.size();
         i += static_cast<std::size_t>(threads)) {
      if (tree.computeRayKeys(origin, ray_ends[i], ray)) {
        for (const octomap::OcTreeKey& key : ray) keys.insert(packKey(key));
      }
    }
  };
  std::vector<std::thread> workers;
  for (int t = 1; t < threads; ++t) workers.emplace_back(cast_range, t);
  cast_range(0);
  for (std::thread& worker : workers) worker.join();
  for (std::size_t t = 1; t < free_keys.size(); ++t) free_keys[0].insertAll(free_keys[t]);
  return std::move(free_keys[0]);
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
    // octomap keys are 16 bits per axis around the origin: +-32768 voxels.
    std::ostringstream what;
    what << "the scan's sensor origin (" << origin.x() << ", " << origin.y() << ", " << origin.z()
         << ") m is outside the map's range (+-" << getResolution() * 32768.0 << " m at "
         << getResolution() << " m voxels): a wrong pose or calibration";
    throw std::out_of_range(what.str());
  }

  EndpointVoxels endpoints;
  std::vector<octomap::point3d> clipped_ends;
  const std::size_t labeled_points =
      groupEndpoints(*this, scan, origin, max_range_m, &endpoints, &clipped_ends);
  const std::vector<octomap::point3d> ray_ends =
      rayEnds(endpoints, clipped_ends, origin, grazing_truncation_voxels_ * resolution);
  const int threads = ray_ends.size() < 4000 ? 1 : std::max(1, ray_casting_threads_);
  const FlatKeySet free_keys = castFreeRays(*this, origin, ray_ends, threads);
  // Stage 4: every touched voxel once, a hit (with its class evidence) or a miss.
  std::vector<VoxelUpdate> updates;
  updates.reserve(free_keys.size() + endpoints.size());
  free_keys.forEach([&](std::uint64_t packed) {
    const octomap::OcTreeKey key = unpackKey(packed);
    if (!endpoints.count(key)) updates.push_back({mortonCode(key), nullptr});
  });
  for (const auto& [key, voxel] : endpoints) updates.push_back({mortonCode(key), &voxel.evidence});
  applyVoxelUpdates(&updates);
  return labeled_points;
}

void SemanticOcTree::applyVoxelUpdates(std::vector<VoxelUpdate>* updates) {
  // One pass over the tree: the updates sorted in Morton order are grouped by child at every
  // level, so every touched inner node is visited once (its occupancy and pruning refreshed
  // once) instead of once per voxel below it.
  std::sort(updates->begin(), updates->end(),
            [](const VoxelUpdate& a, const VoxelUpdate& b) { return a.morton < b.morton; });
  if (updates->empty()) return;
  bool created_root = false;
  if (root == nullptr) {
    root = new SemanticOcTreeNode();
    ++tree_size;
    created_root = true;
  }
  updateBatchRecurs(root, created_root, 0, updates->data(), updates->data() + updates->size());
}

void SemanticOcTree::updateBatchRecurs(SemanticOcTreeNode* node, bool node_just_created,
                                       unsigned int depth, const VoxelUpdate* begin,
                                       const VoxelUpdate* end) {
  if (depth == tree_depth) {  // a leaf: exactly one update (keys are unique)
    if (begin->evidence) {
      updateNodeLogOdds(node, prob_hit_log);
      node->mergeClassEvidence(*begin->evidence);
    } else {
      updateNodeLogOdds(node, prob_miss_log);
    }
    return;
  }
  if (!node_just_created && !nodeHasChildren(node) && node->getLogOdds() <= clamping_thres_min &&
      std::all_of(begin, end, [](const VoxelUpdate& u) { return u.evidence == nullptr; })) {
    return;  // misses on a pruned block that is already clamped free change nothing (octomap)
  }
  const unsigned int shift = 3 * (tree_depth - 1 - depth);
  for (const VoxelUpdate* run = begin; run != end;) {
    const unsigned int pos = static_cast<unsigned int>((run->morton >> shift) & 7);
    const VoxelUpdate* run_end = run + 1;
    while (run_end != end && ((run_end->morton >> shift) & 7) == pos) ++run_end;
    bool created_node = false;
    if (!nodeChildExists(node, pos)) {
      if (!nodeHasChildren(node) && !node_just_created) {
        expandNode(node);  // a pruned leaf: its children inherit its data
      } else {
        createNodeChild(node, pos);
        created_node = true;
      }
    }
    updateBatchRecurs(getNodeChild(node, pos), created_node, depth + 1, run, run_end);
    run = run_end;
  }
  if (!pruneNode(node)) node->updateOccupancyChildren();
}

std::uint64_t SemanticOcTree::mortonCode(const octomap::OcTreeKey& key) {
  return spreadBits(key[0]) | (spreadBits(key[1]) << 1) | (spreadBits(key[2]) << 2);
}

void SemanticOcTree::setLeaves(std::vector<LeafState>* leaves) {
  const auto by_morton = [](const LeafState& a, const LeafState& b) { return a.morton < b.morton; };
  if (!std::is_sorted(leaves->begin(), leaves->end(), by_morton)) {
    std::sort(leaves->begin(), leaves->end(), by_morton);
  }
  if (leaves->empty()) return;
  bool created_root = false;
  if (root == nullptr) {
    root = new SemanticOcTreeNode();
    ++tree_size;
    created_root = true;
  }
  setLeavesRecurs(root, created_root, 0, leaves->data(), leaves->data() + leaves->size());
}

// updateBatchRecurs with states instead of sensor updates; always down to the finest level.
void SemanticOcTree::setLeavesRecurs(SemanticOcTreeNode* node, bool node_just_created,
                                     unsigned int depth, const LeafState* begin,
                                     const LeafState* end) {
  if (depth == tree_depth) {
    node->setLogOdds(begin->log_odds);
    node->setSemantics(begin->classes, begin->counts);
    return;
  }
  const unsigned int shift = 3 * (tree_depth - 1 - depth);
  for (const LeafState* run = begin; run != end;) {
    const unsigned int pos = static_cast<unsigned int>((run->morton >> shift) & 7);
    // The child's leaves: a binary search (the child index is non-decreasing in the range), not a
    // scan per level — most of a dense range goes to one child at the upper levels.
    const LeafState* run_end = std::partition_point(
        run + 1, end, [&](const LeafState& leaf) { return ((leaf.morton >> shift) & 7) == pos; });
    bool created_node = false;
    if (!nodeChildExists(node, pos)) {
      if (!nodeHasChildren(node) && !node_just_created) {
        expandNode(node);
      } else {
        createNodeChild(node, pos);
        created_node = true;
      }
    }
    setLeavesRecurs(getNodeChild(node, pos), created_node, depth + 1, run, run_end);
    run = run_end;
  }
  if (!pruneNode(node)) node->updateOccupancyChildren();
}

std::size_t SemanticOcTree::addClassEvidence(const LabeledScan& scan) {
  if (root == nullptr ||
      scan.label_ids.size() != static_cast<std::size_t>(scan.points_map.cols())) {
    return 0;
  }
  std::size_t added = 0;
  for (Eigen::Index i = 0; i < scan.points_map.cols(); ++i) {
    const std::uint32_t label = scan.label_ids[static_cast<std::size_t>(i)];
    if (label == scan.unknown_label_id) continue;
    const ClassIndex index = classes_.indexOf(label);
    octomap::OcTreeKey key;
    if (index == kNoClass || !std::isfinite(scan.points_map(0, i)) ||
        !coordToKeyChecked(
            octomap::point3d(scan.points_map(0, i), scan.points_map(1, i), scan.points_map(2, i)),
            key)) {
      continue;
    }
    // Down to the finest level: a pruned block is expanded (its children copy it), a missing
    // child is unknown space and gets no evidence.
    SemanticOcTreeNode* node = root;
    bool known = true;
    for (int depth = 0; depth < static_cast<int>(tree_depth) && known; ++depth) {
      const unsigned int child = octomap::computeChildIdx(key, tree_depth - 1 - depth);
      if (!nodeHasChildren(node)) {
        if (!isNodeOccupied(node)) {  // a pruned free block: nothing to label in it
          known = false;
          break;
        }
        expandNode(node);
      }
      known = nodeChildExists(node, child);
      if (known) node = getNodeChild(node, child);
    }
    if (!known || !isNodeOccupied(node)) continue;
    node->addClassEvidence(index, 1);
    ++added;
  }
  return added;
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
// V1: class table, then octomap's node data. V2 adds an integrity record before the node data:
// node count, byte length and an FNV-1a checksum, so a corrupt file is refused, never loaded as
// a silently different map.
constexpr char kSemanticHeaderMagicV1[] = "ISM_SEMANTIC_OCTREE_V1";
constexpr char kSemanticHeaderMagicV2[] = "ISM_SEMANTIC_OCTREE_V2";
static_assert(sizeof(kSemanticHeaderMagicV1) == sizeof(kSemanticHeaderMagicV2));
// Bytes of one node in octomap's full format: value, class slots, counts, child bits.
constexpr std::size_t kSerializedNodeBytes =
    sizeof(float) + SemanticOcTreeNode::kSlots * (sizeof(ClassIndex) + sizeof(std::uint16_t)) + 1;

template <typename T>
void writePod(std::ostream& s, const T& value) {
  s.write(reinterpret_cast<const char*>(&value), sizeof(T));
}
template <typename T>
bool readPod(std::istream& s, T* value) {
  return static_cast<bool>(s.read(reinterpret_cast<char*>(value), sizeof(T)));
}

// FNV-1a, 64 bit, fed piecewise (the writer streams the node data, the reader has it whole).
class Fnv1a {
 public:
  void add(char c) {
    hash_ ^= static_cast<std::uint8_t>(c);
    hash_ *= 1099511628211ull;
  }
  std::uint64_t value() const { return hash_; }

 private:
  std::uint64_t hash_ = 1469598103934665603ull;
};

std::uint64_t fnv1a(const std::string& bytes) {
  Fnv1a hash;
  for (const char c : bytes) hash.add(c);
  return hash.value();
}

// A stream sink that keeps only the length and the FNV-1a checksum of what is written: the
// integrity record goes before the node data, and holding the node bytes in memory to learn it
// cost twice their size at save time (an ostringstream that grows by doubling, then its copy).
class ChecksumSink : public std::streambuf {
 public:
  std::uint64_t length() const { return length_; }
  std::uint64_t checksum() const { return hash_.value(); }

 protected:
  int_type overflow(int_type c) override {
    if (!traits_type::eq_int_type(c, traits_type::eof())) add(traits_type::to_char_type(c));
    return traits_type::not_eof(c);
  }
  std::streamsize xsputn(const char* s, std::streamsize n) override {
    for (std::streamsize i = 0; i < n; ++i) add(s[i]);
    return n;
  }

 private:
  void add(char c) {
    hash_.add(c);
    ++length_;
  }
  std::uint64_t length_ = 0;
  Fnv1a hash_;
};
}  // namespace

// The class table and fusion model go before octomap's node data, so a loaded map knows which
// label id each stored class index stands for.
std::ostream& SemanticOcTree::writeData(std::ostream& s) const {
  s.write(kSemanticHeaderMagicV2, sizeof(kSemanticHeaderMagicV2));
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
  // The node data twice: once into the checksum, then to the stream (no copy of it in memory).
  ChecksumSink sink;
  std::ostream checksum_stream(&sink);
  OccupancyOcTreeBase<SemanticOcTreeNode>::writeData(checksum_stream);
  writePod(s, static_cast<std::uint64_t>(size()));
  writePod(s, sink.length());
  writePod(s, sink.checksum());
  OccupancyOcTreeBase<SemanticOcTreeNode>::writeData(s);
  return s;
}

bool SemanticOcTree::fail(std::istream& s, const std::string& why) {
  read_error_ = why;
  s.setstate(std::ios::failbit);
  return false;
}

std::istream& SemanticOcTree::refuse(std::istream& s, const std::string& why) {
  fail(s, why);
  return s;
}

std::istream& SemanticOcTree::readData(std::istream& s) {
  read_error_.clear();
  char magic[sizeof(kSemanticHeaderMagicV2)] = {};
  if (!s.read(magic, sizeof(magic))) return refuse(s, "truncated header");
  const bool v2 = std::memcmp(magic, kSemanticHeaderMagicV2, sizeof(magic)) == 0;
  if (!v2 && std::memcmp(magic, kSemanticHeaderMagicV1, sizeof(magic)) != 0) {
    return refuse(s, "not a semantic octree (bad magic)");
  }
  std::uint8_t rule = 0;
  std::uint32_t num_classes = 0;
  FusionModel fusion;
  if (!(readPod(s, &rule) && rule <= 1 && readPod(s, &fusion.correct_probability) &&
        readPod(s, &fusion.dirichlet_prior) && readPod(s, &num_classes) &&
        num_classes <= static_cast<std::uint32_t>(kMaxClasses))) {
    return refuse(s, "bad fusion model or class count");
  }
  if (!(fusion.correct_probability > 0 && fusion.correct_probability < 1 &&
        fusion.dirichlet_prior > 0 && std::isfinite(fusion.dirichlet_prior))) {
    return refuse(s, "fusion model out of range");
  }
  std::vector<ClassInfo> classes;
  for (std::uint32_t i = 0; i < num_classes; ++i) {
    ClassInfo info;
    std::uint32_t name_length = 0;
    if (!(readPod(s, &info.label_id) && s.read(reinterpret_cast<char*>(info.rgb.data()), 3) &&
          readPod(s, &name_length) && name_length < 4096)) {
      return refuse(s, "bad class table entry " + std::to_string(i));
    }
    info.name.resize(name_length);
    if (!s.read(info.name.data(), name_length)) return refuse(s, "truncated class table");
    classes.push_back(std::move(info));
  }
  try {
    classes_ = ClassSet(std::move(classes));
  } catch (const std::exception& e) {
    return refuse(s, std::string("bad class table: ") + e.what());
  }
  fusion.rule = static_cast<FusionRule>(rule);
  fusion_ = fusion;

  std::string bytes;
  std::uint64_t node_count = 0;
  if (v2) {
    std::uint64_t length = 0, checksum = 0;
    if (!(readPod(s, &node_count) && readPod(s, &length) && readPod(s, &checksum))) {
      return refuse(s, "truncated integrity record");
    }
    if (length != node_count * kSerializedNodeBytes || length > (std::uint64_t{1} << 36)) {
      return refuse(s, "integrity record: " + std::to_string(length) + " bytes for " +
                           std::to_string(node_count) + " nodes");
    }
    bytes.resize(length);
    if (!s.read(bytes.data(), static_cast<std::streamsize>(length))) {
      return refuse(s, "truncated node data (" + std::to_string(length) + " bytes announced)");
    }
    if (fnv1a(bytes) != checksum) return refuse(s, "checksum mismatch: the node data is corrupt");
  } else {
    // V1 files carry no length: the rest of the stream is node data.
    bytes.assign(std::istreambuf_iterator<char>(s), std::istreambuf_iterator<char>());
    node_count = bytes.size() / kSerializedNodeBytes;
  }
  std::istringstream nodes(bytes);
  if (root) return refuse(s, "reading into a tree that is not empty");
  root = new SemanticOcTreeNode();
  std::uint64_t nodes_read = 0;
  if (!readNodesChecked(root, nodes, 0, node_count, &nodes_read)) {
    clear();
    return refuse(s, read_error_);
  }
  if (v2 && nodes_read != node_count) {
    clear();
    return refuse(s, "node count " + std::to_string(nodes_read) + " differs from the recorded " +
                         std::to_string(node_count));
  }
  tree_size = nodes_read;
  size_changed = true;
  return s;
}

// octomap's readNodesRecurs without its dangers: the depth is bounded by the tree depth, the
// node count by the file, and every stored class index and count is checked.
bool SemanticOcTree::readNodesChecked(SemanticOcTreeNode* node, std::istream& s, unsigned int depth,
                                      std::uint64_t max_nodes, std::uint64_t* nodes_read) {
  if (++*nodes_read > max_nodes) return fail(s, "more nodes than the file records");
  node->readData(s);
  std::uint8_t children = 0;
  if (!readPod(s, &children)) return fail(s, "truncated node data");
  if (!std::isfinite(node->getValue())) return fail(s, "non-finite occupancy");
  for (int slot = 0; slot < SemanticOcTreeNode::kSlots; ++slot) {
    const ClassIndex index = node->slotClass(slot);
    if (index != kNoClass && index >= classes_.size()) {
      return fail(s, "class index " + std::to_string(index) + " outside the class table");
    }
  }
  if (children != 0 && depth >= tree_depth) {
    return fail(s, "children below the finest level (depth " + std::to_string(depth) + ")");
  }
  for (unsigned int i = 0; i < 8; ++i) {
    if (children & (1u << i)) {
      if (!readNodesChecked(createNodeChild(node, i), s, depth + 1, max_nodes, nodes_read)) {
        return false;
      }
    }
  }
  return true;
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
