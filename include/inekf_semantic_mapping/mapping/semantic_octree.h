// SemanticOcTree: an OctoMap occupancy octree whose voxels also carry class evidence.
//
// Each node keeps octomap's occupancy log-odds plus a small fixed array of (class index, count)
// pairs: the classes observed in that voxel and how often. With the symmetric confusion model
// the Bayesian posterior depends only on these counts (see FusionRule), so the same node serves
// the Bayes and the Dirichlet rule. Keeping the kSlots most observed classes bounds the node at
// 24 bytes (plain OcTreeNode: 16) whatever the size of the class set. When a voxel sees a
// (kSlots+1)-th class, the least observed slot is replaced: its evidence is lost, which only
// matters for voxels that have seen more than kSlots classes.
//
// The tree registers itself with octomap's factory, so AbstractOcTree::read("map.ot") returns a
// SemanticOcTree; its class table (label id <-> index) is written before the node data.
#pragma once

#include <octomap/OcTreeNode.h>
#include <octomap/OccupancyOcTreeBase.h>

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/kitti/mercator.h"
#include "inekf_semantic_mapping/mapping/occupancy_model.h"
#include "inekf_semantic_mapping/mapping/semantic_classes.h"

namespace inekf_semantic_mapping {
namespace mapping {

class SemanticOcTree;

class SemanticOcTreeNode : public octomap::OcTreeNode {
 public:
  static constexpr int kSlots = kClassSlots;
  static constexpr std::uint16_t kMaxCount = kMaxClassCount;

  SemanticOcTreeNode() : OcTreeNode() { clearSemantics(); }
  SemanticOcTreeNode(const SemanticOcTreeNode& rhs) = default;

  bool operator==(const SemanticOcTreeNode& rhs) const {
    return rhs.value == value && sameSemantics(rhs);
  }
  bool sameSemantics(const SemanticOcTreeNode& rhs) const {
    return classes_ == rhs.classes_ && counts_ == rhs.counts_;
  }
  void copyData(const SemanticOcTreeNode& from) {
    OcTreeNode::copyData(from);
    classes_ = from.classes_;
    counts_ = from.counts_;
  }

  // Adds `count` observations of class `index` (saturating; all counts are halved when one
  // would overflow, which keeps their ratios).
  void addClassEvidence(ClassIndex index, std::uint32_t count = 1);
  // Merges another node's evidence (inner-node aggregation).
  void mergeClassEvidence(const SemanticOcTreeNode& other);
  void clearSemantics() {
    classes_.fill(kNoClass);
    counts_.fill(0);
  }

  // Replaces the class evidence (slots in canonical order, see addClassCount).
  void setSemantics(const ClassSlotIndices& classes, const ClassSlotCounts& counts) {
    classes_ = classes;
    counts_ = counts;
  }
  const ClassSlotIndices& slotClasses() const { return classes_; }
  const ClassSlotCounts& slotCounts() const { return counts_; }
  // Slot accessors (unused slots: class kNoClass, count 0).
  ClassIndex slotClass(int slot) const { return classes_[slot]; }
  std::uint16_t slotCount(int slot) const { return counts_[slot]; }
  std::uint32_t totalCount() const;
  bool hasSemantics() const { return classes_[0] != kNoClass; }
  // The class with most evidence (kNoClass if none). Ties: the lower index.
  ClassIndex mostLikelyClass() const;
  // Posterior probability of class `index` under `model` with `num_classes` classes.
  double classProbability(ClassIndex index, const FusionModel& model, int num_classes) const;

  std::istream& readData(std::istream& s);
  std::ostream& writeData(std::ostream& s) const;

 protected:
  ClassSlotIndices classes_;
  ClassSlotCounts counts_;
  friend class SemanticOcTree;
};

// One scan to insert: points in the map frame, the sensor origin, one label id per point.
struct LabeledScan {
  Eigen::Matrix3Xf points_map;  // 3 x N
  Eigen::Vector3f sensor_origin_map{0, 0, 0};
  std::vector<std::uint32_t> label_ids;         // N, or empty (no semantics)
  std::uint32_t unknown_label_id = 0xFFFFFFFF;  // label id that carries no class evidence
};

// Where a map's frame lies on the Earth: the localization's map origin when the map was saved.
// A map resumed under another origin would be written a second time, shifted.
using GeodeticOrigin = kitti::GeodeticOrigin;

class SemanticOcTree : public octomap::OccupancyOcTreeBase<SemanticOcTreeNode> {
 public:
  explicit SemanticOcTree(double resolution);
  SemanticOcTree(double resolution, ClassSet classes, FusionModel fusion);

  SemanticOcTree* create() const override { return new SemanticOcTree(resolution); }
  std::string getTreeType() const override { return "SemanticOcTree"; }

  const ClassSet& classSet() const { return classes_; }
  ClassSet& mutableClassSet() { return classes_; }
  const FusionModel& fusionModel() const { return fusion_; }
  void setFusionModel(const FusionModel& fusion) { fusion_ = fusion; }
  // Saved with the map and read back (none: unknown, e.g. a map of a sequence's own poses).
  const std::optional<GeodeticOrigin>& geodeticOrigin() const { return geodetic_origin_; }
  void setGeodeticOrigin(const std::optional<GeodeticOrigin>& origin) { geodetic_origin_ = origin; }
  // octomap's setProbHit, setProbMiss and clamping thresholds in one call (a new tree has
  // octomap's defaults, clamping 0.1192 / 0.971, not OccupancyModel's).
  void setOccupancyModel(const OccupancyModel& model);

  // Batched scan insertion: endpoints are grouped per voxel (each occupied voxel gets one hit
  // per scan, and one class observation per point), free voxels along all rays are collected
  // into a key set (endpoints removed) and each is updated once. Rays longer than max_range_m
  // (<= 0: unlimited) clear free space up to max_range_m and insert no endpoint. Updates inner
  // occupancy and prunes along the way; class evidence of inner nodes is refreshed by
  // updateInnerOccupancy(). Returns the number of points with a label in the class set.
  std::size_t insertLabeledScan(const LabeledScan& scan, double max_range_m);

  // Threads for the ray casting of insertLabeledScan (1: none started). Results do not depend
  // on it: every free voxel is still updated once.
  void setRayCastingThreads(int threads) { ray_casting_threads_ = threads < 1 ? 1 : threads; }

  // Grazing rays: a ray that meets a horizontal surface (the road) at elevation angle e runs
  // within one voxel of it for the last resolution / sin(e) metres, and octomap's ray casting
  // marks those surface voxels free (the README's semantic-map results measure how many). With
  // voxels > 0 the free part of each downward ray that ends in a hit stops voxels * resolution /
  // sin(e) before the hit (at most a quarter of the ray): what the ray cannot tell from the road is
  // left as it is. The price: the last metres in front of low obstacles are cleared only by steeper
  // rays (a moving car's trace lasts longer). 0: octomap's behaviour.
  void setGrazingRayTruncation(double voxels) { grazing_truncation_voxels_ = voxels; }

  // Class evidence without an occupancy update (a label image that came after its scan went
  // in): one observation per labelled point whose finest-level voxel exists and is occupied;
  // pruned blocks are expanded. Returns the number of points that added evidence. Inner nodes
  // are refreshed by updateInnerOccupancy().
  std::size_t addClassEvidence(const LabeledScan& scan);

  // Adds one hit with class evidence at a leaf (max depth), expanding pruned nodes.
  SemanticOcTreeNode* updateOccupiedVoxel(const octomap::OcTreeKey& key, ClassIndex index,
                                          std::uint32_t class_count);

  // A finest-level voxel's whole state (HashedVoxelGrid -> tree). morton: mortonCode(key).
  struct LeafState {
    std::uint64_t morton;
    float log_odds;
    ClassSlotIndices classes;
    ClassSlotCounts counts;
  };
  // Interleaved key bits (x lowest): the order of a depth-first walk of the tree.
  static std::uint64_t mortonCode(const octomap::OcTreeKey& key);
  // Sets finest-level voxels to the given states (pruned nodes expanded, missing ones created):
  // no sensor model, the states replace what was there. Inner occupancy is refreshed and nodes
  // pruned along the way (inner class evidence: updateInnerOccupancy()). One key at most once;
  // sorted here unless already in Morton order.
  void setLeaves(std::vector<LeafState>* leaves);

  // Recomputes all inner nodes: occupancy = max of children, class evidence = merged children.
  void updateInnerOccupancy();

  // Children collapse only with identical occupancy AND identical class evidence.
  bool isNodeCollapsible(const SemanticOcTreeNode* node) const override;
  bool pruneNode(SemanticOcTreeNode* node) override;

  // Most likely label id of a node in the input id space; `fallback` when it has no evidence.
  std::uint32_t mostLikelyLabel(const SemanticOcTreeNode& node, std::uint32_t fallback) const;

  // Reading checks an integrity record (node count, length, checksum) and bounds the depth and
  // node count; a refused file sets the stream's failbit and readError() says why.
  std::istream& readData(std::istream& s) override;
  std::ostream& writeData(std::ostream& s) const override;
  const std::string& readError() const { return read_error_; }

 protected:
  bool fail(std::istream& s, const std::string& why);
  std::istream& refuse(std::istream& s, const std::string& why);
  // The coarsest leaf a file may hold (levels above the finest) and the most voxels its leaves
  // may stand for (what the grid and the PLY writer expand them to).
  static constexpr unsigned int kMaxLeafSpanLevels = 8;
  static constexpr std::uint64_t kMaxMapVoxels = std::uint64_t{1} << 36;
  bool readNodesChecked(SemanticOcTreeNode* node, std::istream& s, unsigned int depth,
                        std::uint64_t max_nodes, std::uint64_t* nodes_read, std::uint64_t* voxels);
  void updateInnerOccupancyRecurs(SemanticOcTreeNode* node, unsigned int depth);
  // One voxel update of a batch: Morton code of its key; class evidence for a hit, null for a
  // miss.
  struct VoxelUpdate {
    std::uint64_t morton;
    const SemanticOcTreeNode* evidence;
  };
  // The last stage of insertLabeledScan (the earlier ones, and the batch recursion it shares
  // with setLeaves, are free functions in semantic_octree_insertion.cpp).
  void applyVoxelUpdates(std::vector<VoxelUpdate>* updates);
  // Creates an empty root when the tree has none; true when it did.
  bool createRootIfEmpty();
  SemanticOcTreeNode* updateOccupiedWithEvidence(const octomap::OcTreeKey& key,
                                                 const SemanticOcTreeNode& evidence);
  SemanticOcTreeNode* updateOccupiedRecurs(SemanticOcTreeNode* node, bool node_just_created,
                                           const octomap::OcTreeKey& key, unsigned int depth,
                                           const SemanticOcTreeNode& evidence);

  ClassSet classes_;
  FusionModel fusion_;
  std::optional<GeodeticOrigin> geodetic_origin_;
  int ray_casting_threads_ = 1;
  double grazing_truncation_voxels_ = 0.0;
  std::string read_error_;

  // Registers the tree type with octomap's factory once (ColorOcTree's idiom).
  class StaticMemberInitializer {
   public:
    StaticMemberInitializer();
    void ensureLinking() {}
  };
  static StaticMemberInitializer semantic_octree_member_init_;
};

}  // namespace mapping
}  // namespace inekf_semantic_mapping
