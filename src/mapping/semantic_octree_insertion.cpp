// SemanticOcTree's updates: batched scan insertion (endpoints grouped per voxel, free rays cast,
// every touched voxel updated once in one pass over the tree), leaf states set in bulk, class
// evidence without occupancy and single occupied voxels.

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <unordered_map>

#include "flat_key_set.h"
#include "grazing_rays.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"

namespace inekf_semantic_mapping {
namespace mapping {

namespace {

std::uint64_t packKey(const octomap::OcTreeKey& key) {
  return (static_cast<std::uint64_t>(key[0]) << 32) | (static_cast<std::uint64_t>(key[1]) << 16) |
         key[2];
}
octomap::OcTreeKey unpackKey(std::uint64_t packed) {
  return octomap::OcTreeKey(static_cast<octomap::key_type>(packed >> 32),
                            static_cast<octomap::key_type>(packed >> 16),
                            static_cast<octomap::key_type>(packed));
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
      // Only rays that go down can graze the road.
      const double length = ray.norm();
      const double sin_elevation = -ray.z() / length;
      const double cut = grazingRayCut(length, sin_elevation, truncation_m);
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

// The one batch recursion of applyVoxelUpdates and setLeaves. [begin, end) are the finest-level
// voxels under `node` in Morton order (one item per key), so at every level they fall into runs
// by child: each touched inner node is visited once (its occupancy and pruning refreshed once)
// instead of once per voxel below it. update_leaf(leaf, item) changes a finest-level node;
// skip_block(node, begin, end) may declare a pruned block unchanged by its items, which leaves it
// pruned. Item: anything with a `morton` member (SemanticOcTree::mortonCode of its key).
template <typename Item, typename UpdateLeaf, typename SkipBlock>
void updateSortedLeaves(SemanticOcTree* tree, SemanticOcTreeNode* node, bool node_just_created,
                        unsigned int depth, const Item* begin, const Item* end,
                        const UpdateLeaf& update_leaf, const SkipBlock& skip_block) {
  const unsigned int tree_depth = tree->getTreeDepth();
  if (depth == tree_depth) {
    update_leaf(node, *begin);
    return;
  }
  if (!node_just_created && !tree->nodeHasChildren(node) && skip_block(node, begin, end)) return;
  const unsigned int shift = 3 * (tree_depth - 1 - depth);
  for (const Item* run = begin; run != end;) {
    const unsigned int pos = static_cast<unsigned int>((run->morton >> shift) & 7);
    // The child's items: a binary search (the child index is non-decreasing in the range), not a
    // scan per level — most of a dense range goes to one child at the upper levels.
    const Item* run_end = std::partition_point(
        run + 1, end, [&](const Item& item) { return ((item.morton >> shift) & 7) == pos; });
    bool created_node = false;
    if (!tree->nodeChildExists(node, pos)) {
      if (!tree->nodeHasChildren(node) && !node_just_created) {
        tree->expandNode(node);  // a pruned leaf: its children inherit its data
      } else {
        tree->createNodeChild(node, pos);
        created_node = true;
      }
    }
    updateSortedLeaves(tree, tree->getNodeChild(node, pos), created_node, depth + 1, run, run_end,
                       update_leaf, skip_block);
    run = run_end;
  }
  if (!tree->pruneNode(node)) node->updateOccupancyChildren();
}

}  // namespace

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
  std::sort(updates->begin(), updates->end(),
            [](const VoxelUpdate& a, const VoxelUpdate& b) { return a.morton < b.morton; });
  if (updates->empty()) return;
  const bool created_root = createRootIfEmpty();
  updateSortedLeaves(
      this, root, created_root, 0, updates->data(), updates->data() + updates->size(),
      [&](SemanticOcTreeNode* leaf, const VoxelUpdate& update) {
        if (update.evidence) {
          updateNodeLogOdds(leaf, prob_hit_log);
          leaf->mergeClassEvidence(*update.evidence);
        } else {
          updateNodeLogOdds(leaf, prob_miss_log);
        }
      },
      [&](const SemanticOcTreeNode* block, const VoxelUpdate* begin, const VoxelUpdate* end) {
        // Misses on a block that is already clamped free change nothing (octomap's shortcut).
        return block->getLogOdds() <= clamping_thres_min &&
               std::all_of(begin, end, [](const VoxelUpdate& u) { return u.evidence == nullptr; });
      });
}

void SemanticOcTree::setLeaves(std::vector<LeafState>* leaves) {
  const auto by_morton = [](const LeafState& a, const LeafState& b) { return a.morton < b.morton; };
  if (!std::is_sorted(leaves->begin(), leaves->end(), by_morton)) {
    std::sort(leaves->begin(), leaves->end(), by_morton);
  }
  if (leaves->empty()) return;
  const bool created_root = createRootIfEmpty();
  // States, not sensor updates: no shortcut, always down to the finest level.
  updateSortedLeaves(
      this, root, created_root, 0, leaves->data(), leaves->data() + leaves->size(),
      [](SemanticOcTreeNode* leaf, const LeafState& state) {
        leaf->setLogOdds(state.log_odds);
        leaf->setSemantics(state.classes, state.counts);
      },
      [](const SemanticOcTreeNode*, const LeafState*, const LeafState*) { return false; });
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
  const bool created_root = createRootIfEmpty();
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

}  // namespace mapping
}  // namespace inekf_semantic_mapping
