// HashedVoxelGrid: the fast insertion structure of the semantic map. Voxels live in
// dense 8^3 blocks in an open-addressing hash map keyed by block coordinates; each voxel holds
// octomap's float log-odds (the same hit/miss/clamping arithmetic as SemanticOcTree, so the
// values are bit-equal where the same voxels are updated) and, in blocks with any, the class
// evidence slots of SemanticOcTreeNode. Voxel coordinates are octomap keys, so every voxel is one
// finest-level leaf of a SemanticOcTree of the same resolution.
//
// Insertion of a scan (the octree path's meaning: one hit per endpoint voxel per scan, one class
// observation per labelled point, one miss per free voxel per scan, endpoint voxels never free):
//  - a per-scan stamp per voxel de-duplicates (no key set per scan): hit stamp, free stamp;
//  - free rays are walked from their end back toward the sensor with an integer-key DDA
//    (Amanatides-Woo), and a ray stops after early_termination_voxels consecutive voxels that
//    this scan already cleared (0: never; the rest of the way was cleared by earlier rays);
//  - grazing-ray truncation as SemanticOcTree::setGrazingRayTruncation.
//
// The SemanticOcTree stays the saved and published format: syncTo() writes the blocks changed
// since the last sync into a tree (setLeaves), so the tree follows the grid at save / publish time
// at a cost proportional to what changed. Why not update the tree per scan: its Morton sort and
// descent were 36 % of the octree path's time, more than the whole grid insertion.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "inekf_semantic_mapping/mapping/occupancy_model.h"
#include "inekf_semantic_mapping/mapping/semantic_classes.h"

namespace inekf_semantic_mapping {
namespace mapping {

struct LabeledScan;
class SemanticOcTree;

struct HashedVoxelGridOptions {
  double resolution_m = 0.2;
  OccupancyModel occupancy;
  double occupancy_threshold = 0.5;  // octomap's default: occupied above it
  double grazing_truncation_voxels = 0.0;
  int early_termination_voxels = 0;
};

class HashedVoxelGrid {
 public:
  static constexpr int kBlockBits = 3;
  static constexpr int kBlockSide = 1 << kBlockBits;
  static constexpr int kBlockVoxels = kBlockSide * kBlockSide * kBlockSide;

  explicit HashedVoxelGrid(const HashedVoxelGridOptions& options);
  ~HashedVoxelGrid();
  HashedVoxelGrid(const HashedVoxelGrid&) = delete;
  HashedVoxelGrid& operator=(const HashedVoxelGrid&) = delete;

  const HashedVoxelGridOptions& options() const { return options_; }
  void setEarlyTermination(int voxels) { options_.early_termination_voxels = voxels; }

  // As SemanticOcTree::insertLabeledScan (labels resolved through `classes`); throws
  // std::out_of_range for a sensor origin outside octomap's key range. Returns the points with a
  // label in the class set.
  std::size_t insertLabeledScan(const LabeledScan& scan, double max_range_m,
                                const ClassSet& classes);
  // As SemanticOcTree::addClassEvidence: one observation per labelled point whose voxel is known
  // and occupied.
  std::size_t addClassEvidence(const LabeledScan& scan, const ClassSet& classes);

  // Writes every voxel changed since the last sync (or load) into `tree`; inner class evidence is
  // left to tree->updateInnerOccupancy(). Returns the number of leaves written.
  std::size_t syncTo(SemanticOcTree* tree);
  // syncTo that frees the blocks as they are written: afterwards the grid is empty and `tree`
  // (the one every earlier sync went to) holds the whole map. Memory holds one copy of the map
  // at a time, plus one batch of blocks (the end of a run, before a save).
  std::size_t moveTo(SemanticOcTree* tree);
  // Replaces the grid's contents with the tree's finest-level state (pruned leaves expanded);
  // nothing is dirty afterwards.
  void loadFrom(const SemanticOcTree& tree);
  void clear();
  bool dirty() const { return !dirty_blocks_.empty(); }

  // One voxel by octomap key; false where unknown.
  bool voxel(std::uint16_t kx, std::uint16_t ky, std::uint16_t kz, float* log_odds,
             ClassSlotIndices* classes = nullptr, ClassSlotCounts* counts = nullptr) const;
  // Calls f(kx, ky, kz, log_odds, classes, counts) for every known voxel (block order).
  template <typename F>
  void forEachVoxel(F&& f) const;

  std::size_t blockCount() const { return blocks_.size(); }
  std::size_t knownVoxels() const;
  std::size_t occupiedVoxels() const;
  std::size_t memoryUsage() const;  // bytes (blocks, class slots, hash table)
  // Voxel visits of the ray walks of the last scan (misses + already cleared + endpoints passed).
  std::size_t lastRayVisits() const { return last_ray_visits_; }
  std::size_t lastMisses() const { return last_misses_; }

  struct Block;

 private:
  Block* findBlock(std::uint64_t block_key) const;
  Block* findOrCreateBlock(std::uint64_t block_key);
  void rehash(std::size_t capacity);
  void markDirty(Block* block);
  void updateLogOdds(Block* block, int voxel, float delta);
  void nextStamp();
  void castRay(const double origin[3], const std::uint16_t origin_key[3], const double end[3]);
  ClassSlotIndices* slotsOf(Block* block, int index, ClassSlotCounts** counts);

  HashedVoxelGridOptions options_;
  float hit_log_, miss_log_, min_log_, max_log_, occupied_log_;
  double resolution_factor_;
  // Open addressing: packed block key + 1 (0 = empty slot) -> its block (owned by blocks_).
  std::vector<std::uint64_t> table_keys_;
  std::vector<Block*> table_values_;
  std::size_t table_mask_ = 0;
  int table_shift_ = 64;
  std::vector<std::unique_ptr<Block>> blocks_;
  std::vector<Block*> dirty_blocks_;
  // Scan stamps (hit: even, free: odd; 0 and 1 never current); they wrap every 127 scans, when
  // all stamps are cleared (a memset of 512 bytes per block).
  std::uint8_t hit_stamp_ = 0, free_stamp_ = 1;
  // Cache of the last block a ray walk touched.
  std::uint64_t cached_key_ = ~std::uint64_t{0};
  Block* cached_block_ = nullptr;
  std::size_t last_ray_visits_ = 0, last_misses_ = 0;
};

struct HashedVoxelGrid::Block {
  std::array<float, kBlockVoxels> log_odds;
  std::array<std::uint8_t, kBlockVoxels> stamp;
  std::array<std::uint64_t, kBlockVoxels / 64> known;
  // Class evidence, only for blocks that have any: slot index + 1 per voxel (0: none).
  std::unique_ptr<std::uint16_t[]> slot_of;
  std::vector<ClassSlotIndices> slot_classes;
  std::vector<ClassSlotCounts> slot_counts;
  std::uint16_t bx, by, bz;  // block coordinates (octomap key >> kBlockBits)
  bool dirty = false;

  bool isKnown(int i) const { return (known[i >> 6] >> (i & 63)) & 1u; }
  void setKnown(int i) { known[i >> 6] |= std::uint64_t{1} << (i & 63); }
};

template <typename F>
void HashedVoxelGrid::forEachVoxel(F&& f) const {
  static const ClassSlotIndices kNone{{kNoClass, kNoClass, kNoClass, kNoClass}};
  static const ClassSlotCounts kZero{{0, 0, 0, 0}};
  for (const auto& block : blocks_) {
    for (int i = 0; i < kBlockVoxels; ++i) {
      if (!block->isKnown(i)) continue;
      const std::uint16_t kx = static_cast<std::uint16_t>((block->bx << kBlockBits) | (i & 7));
      const std::uint16_t ky =
          static_cast<std::uint16_t>((block->by << kBlockBits) | ((i >> 3) & 7));
      const std::uint16_t kz = static_cast<std::uint16_t>((block->bz << kBlockBits) | (i >> 6));
      const std::uint16_t slot = block->slot_of ? block->slot_of[i] : 0;
      f(kx, ky, kz, block->log_odds[i], slot ? block->slot_classes[slot - 1] : kNone,
        slot ? block->slot_counts[slot - 1] : kZero);
    }
  }
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
