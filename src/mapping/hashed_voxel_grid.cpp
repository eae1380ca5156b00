#include "inekf_semantic_mapping/mapping/hashed_voxel_grid.h"

#include <octomap/octomap_utils.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "flat_key_set.h"
#include "grazing_rays.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"

namespace inekf_semantic_mapping {
namespace mapping {

static_assert(HashedVoxelGrid::kBlockBits == 3, "forEachVoxel and the tables assume 8^3 blocks");

namespace {

constexpr int kKeyMax = 32768;  // octomap's tree_max_val at depth 16
// Label ids below this resolve through a per-scan table instead of the class set's hash map.
constexpr std::uint32_t kLabelTableSize = 1024;

std::uint64_t packBlockKey(std::uint32_t bx, std::uint32_t by, std::uint32_t bz) {
  return static_cast<std::uint64_t>(bx) | (static_cast<std::uint64_t>(by) << 13) |
         (static_cast<std::uint64_t>(bz) << 26);
}
int voxelIndex(std::uint32_t kx, std::uint32_t ky, std::uint32_t kz) {
  return static_cast<int>((kx & 7u) | ((ky & 7u) << 3) | ((kz & 7u) << 6));
}

// Local (in-block) Morton order -> linear voxel index, so a block's voxels come out in the order
// of a depth-first walk of the octree.
const std::array<std::uint16_t, HashedVoxelGrid::kBlockVoxels>& mortonToIndex() {
  static const auto table = [] {
    std::array<std::uint16_t, HashedVoxelGrid::kBlockVoxels> t{};
    for (int m = 0; m < HashedVoxelGrid::kBlockVoxels; ++m) {
      int x = 0, y = 0, z = 0;
      for (int bit = 0; bit < 3; ++bit) {
        x |= ((m >> (3 * bit)) & 1) << bit;
        y |= ((m >> (3 * bit + 1)) & 1) << bit;
        z |= ((m >> (3 * bit + 2)) & 1) << bit;
      }
      t[m] = static_cast<std::uint16_t>(x | (y << 3) | (z << 6));
    }
    return t;
  }();
  return table;
}

}  // namespace

HashedVoxelGrid::HashedVoxelGrid(const HashedVoxelGridOptions& options) : options_(options) {
  if (!(options_.resolution_m > 0)) throw std::invalid_argument("HashedVoxelGrid: resolution <= 0");
  // octomap's float log-odds of the same probabilities: bit-equal arithmetic with the octree.
  hit_log_ = octomap::logodds(options_.occupancy.prob_hit);
  miss_log_ = octomap::logodds(options_.occupancy.prob_miss);
  min_log_ = octomap::logodds(options_.occupancy.clamping_min);
  max_log_ = octomap::logodds(options_.occupancy.clamping_max);
  occupied_log_ = octomap::logodds(options_.occupancy_threshold);
  resolution_factor_ = 1.0 / options_.resolution_m;
  rehash(1024);
}

HashedVoxelGrid::~HashedVoxelGrid() = default;

void HashedVoxelGrid::clear() {
  blocks_.clear();
  dirty_blocks_.clear();
  table_keys_.clear();
  table_values_.clear();
  rehash(1024);
  cached_key_ = ~std::uint64_t{0};
  cached_block_ = nullptr;
}

void HashedVoxelGrid::rehash(std::size_t capacity) {
  table_keys_.assign(capacity, 0);
  table_values_.assign(capacity, nullptr);
  table_mask_ = capacity - 1;
  table_shift_ = 64;
  for (std::size_t c = capacity; c > 1; c >>= 1) --table_shift_;
  for (std::size_t b = 0; b < blocks_.size(); ++b) {
    const Block& block = *blocks_[b];
    const std::uint64_t stored = packBlockKey(block.bx, block.by, block.bz) + 1;
    std::size_t i = static_cast<std::size_t>((stored * 0x9E3779B97F4A7C15ULL) >> table_shift_);
    while (table_keys_[i] != 0) i = (i + 1) & table_mask_;
    table_keys_[i] = stored;
    table_values_[i] = blocks_[b].get();
  }
}

HashedVoxelGrid::Block* HashedVoxelGrid::findBlock(std::uint64_t block_key) const {
  const std::uint64_t stored = block_key + 1;
  std::size_t i = static_cast<std::size_t>((stored * 0x9E3779B97F4A7C15ULL) >> table_shift_);
  while (table_keys_[i] != 0) {
    if (table_keys_[i] == stored) return table_values_[i];
    i = (i + 1) & table_mask_;
  }
  return nullptr;
}

HashedVoxelGrid::Block* HashedVoxelGrid::findOrCreateBlock(std::uint64_t block_key) {
  if (block_key == cached_key_) return cached_block_;
  const std::uint64_t stored = block_key + 1;
  std::size_t i = static_cast<std::size_t>((stored * 0x9E3779B97F4A7C15ULL) >> table_shift_);
  while (table_keys_[i] != 0) {
    if (table_keys_[i] == stored) {
      cached_key_ = block_key;
      cached_block_ = table_values_[i];
      return cached_block_;
    }
    i = (i + 1) & table_mask_;
  }
  auto block = std::make_unique<Block>();
  block->stamp.fill(0);
  block->known.fill(0);
  block->bx = static_cast<std::uint16_t>(block_key & 0x1FFF);
  block->by = static_cast<std::uint16_t>((block_key >> 13) & 0x1FFF);
  block->bz = static_cast<std::uint16_t>((block_key >> 26) & 0x1FFF);
  Block* raw = block.get();
  blocks_.push_back(std::move(block));
  if (2 * blocks_.size() > table_keys_.size()) {
    rehash(table_keys_.size() * 2);
  } else {
    table_keys_[i] = stored;
    table_values_[i] = raw;
  }
  cached_key_ = block_key;
  cached_block_ = raw;
  return raw;
}

// octomap's update of one voxel: an unknown voxel starts at log-odds 0, the sum is clamped.
void HashedVoxelGrid::updateLogOdds(Block* block, int v, float delta) {
  float value = block->isKnown(v) ? block->log_odds[v] : 0.f;
  value = std::min(std::max(value + delta, min_log_), max_log_);
  block->log_odds[v] = value;
  block->setKnown(v);
  markDirty(block);
}

void HashedVoxelGrid::markDirty(Block* block) {
  if (!block->dirty) {
    block->dirty = true;
    dirty_blocks_.push_back(block);
  }
}

void HashedVoxelGrid::nextStamp() {
  hit_stamp_ = static_cast<std::uint8_t>(hit_stamp_ + 2);
  if (hit_stamp_ == 0) {  // wrapped after 127 scans: old stamps must not look current
    for (auto& block : blocks_) block->stamp.fill(0);
    hit_stamp_ = 2;
  }
  free_stamp_ = static_cast<std::uint8_t>(hit_stamp_ + 1);
}

ClassSlotIndices* HashedVoxelGrid::slotsOf(Block* block, int index, ClassSlotCounts** counts) {
  if (!block->slot_of) {
    block->slot_of = std::make_unique<std::uint16_t[]>(kBlockVoxels);  // zeroed
  }
  std::uint16_t& slot = block->slot_of[index];
  if (slot == 0) {
    block->slot_classes.push_back({{kNoClass, kNoClass, kNoClass, kNoClass}});
    block->slot_counts.push_back({{0, 0, 0, 0}});
    slot = static_cast<std::uint16_t>(block->slot_classes.size());
  }
  *counts = &block->slot_counts[slot - 1];
  return &block->slot_classes[slot - 1];
}

namespace {
// octomap's coordToKeyChecked for one axis (the same double arithmetic, so the same voxel).
inline bool toKey(double coordinate, double resolution_factor, std::uint16_t* key) {
  const double scaled = std::floor(resolution_factor * coordinate);
  if (!(scaled >= -kKeyMax && scaled < kKeyMax)) return false;  // also NaN
  *key = static_cast<std::uint16_t>(static_cast<int>(scaled) + kKeyMax);
  return true;
}
inline bool toKey(const float p[3], double resolution_factor, std::uint16_t key[3]) {
  return toKey(p[0], resolution_factor, &key[0]) && toKey(p[1], resolution_factor, &key[1]) &&
         toKey(p[2], resolution_factor, &key[2]);
}
}  // namespace

std::size_t HashedVoxelGrid::insertLabeledScan(const LabeledScan& scan, double max_range_m,
                                               const ClassSet& classes) {
  const std::size_t num_points = static_cast<std::size_t>(scan.points_map.cols());
  const bool labeled = !scan.label_ids.empty();
  if (labeled && scan.label_ids.size() != num_points) {
    throw std::invalid_argument("insertLabeledScan: " + std::to_string(scan.label_ids.size()) +
                                " labels for " + std::to_string(num_points) + " points");
  }
  const float origin_f[3] = {scan.sensor_origin_map.x(), scan.sensor_origin_map.y(),
                             scan.sensor_origin_map.z()};
  std::uint16_t origin_key[3];
  if (!toKey(origin_f, resolution_factor_, origin_key)) {
    std::ostringstream what;
    what << "the scan's sensor origin (" << origin_f[0] << ", " << origin_f[1] << ", "
         << origin_f[2] << ") m is outside the map's range (+-" << options_.resolution_m * 32768.0
         << " m at " << options_.resolution_m << " m voxels): a wrong pose or calibration";
    throw std::out_of_range(what.str());
  }
  nextStamp();
  last_ray_visits_ = last_misses_ = 0;

  std::array<ClassIndex, kLabelTableSize> label_index;
  if (labeled) {
    for (std::uint32_t id = 0; id < kLabelTableSize; ++id) label_index[id] = classes.indexOf(id);
  }
  const double truncation_m = options_.grazing_truncation_voxels * options_.resolution_m;
  const bool limit_range = max_range_m > 0.0;

  // Pass 1: endpoints. One hit per voxel per scan (its hit stamp), class evidence per point, and
  // one free ray per endpoint voxel (from its first point) or per clipped ray end voxel.
  std::vector<std::array<double, 3>> ray_ends;
  ray_ends.reserve(num_points / 2 + 16);
  FlatKeySet clipped_keys;  // clipped ray ends of this scan
  std::size_t labeled_points = 0;
  for (std::size_t i = 0; i < num_points; ++i) {
    const float p[3] = {scan.points_map(0, static_cast<Eigen::Index>(i)),
                        scan.points_map(1, static_cast<Eigen::Index>(i)),
                        scan.points_map(2, static_cast<Eigen::Index>(i))};
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) continue;
    const float ray[3] = {p[0] - origin_f[0], p[1] - origin_f[1], p[2] - origin_f[2]};
    const double range =
        std::sqrt(static_cast<double>(ray[0] * ray[0] + ray[1] * ray[1] + ray[2] * ray[2]));
    std::uint16_t key[3];
    if (limit_range && range > max_range_m) {
      const float scale = static_cast<float>(max_range_m / range);
      const float end[3] = {origin_f[0] + ray[0] * scale, origin_f[1] + ray[1] * scale,
                            origin_f[2] + ray[2] * scale};
      if (toKey(end, resolution_factor_, key) &&
          clipped_keys.insert(static_cast<std::uint64_t>(key[0]) << 32 |
                              static_cast<std::uint64_t>(key[1]) << 16 | key[2])) {
        ray_ends.push_back({end[0], end[1], end[2]});
      }
      continue;
    }
    if (!toKey(p, resolution_factor_, key)) continue;
    Block* block = findOrCreateBlock(packBlockKey(key[0] >> 3, key[1] >> 3, key[2] >> 3));
    const int v = voxelIndex(key[0], key[1], key[2]);
    if (block->stamp[v] != hit_stamp_) {
      block->stamp[v] = hit_stamp_;
      updateLogOdds(block, v, hit_log_);
      if (truncation_m > 0.0 && ray[2] < 0.f) {
        // Only rays that go down can graze the road (see SemanticOcTree::setGrazingRayTruncation).
        const double sin_elevation = -ray[2] / range;
        const double cut = grazingRayCut(range, sin_elevation, truncation_m);
        const float keep = static_cast<float>(1.0 - cut / range);
        ray_ends.push_back({origin_f[0] + ray[0] * keep, origin_f[1] + ray[1] * keep,
                            origin_f[2] + ray[2] * keep});
      } else {
        ray_ends.push_back({p[0], p[1], p[2]});
      }
    }
    if (labeled && scan.label_ids[i] != scan.unknown_label_id) {
      const std::uint32_t id = scan.label_ids[i];
      const ClassIndex index = id < kLabelTableSize ? label_index[id] : classes.indexOf(id);
      if (index != kNoClass) {
        ClassSlotCounts* counts = nullptr;
        ClassSlotIndices* slots = slotsOf(block, v, &counts);
        addClassCount(index, 1, slots, counts);
        ++labeled_points;
      }
    }
  }
  // Pass 2: free space, every ray walked from its end back toward the sensor.
  const double origin[3] = {origin_f[0], origin_f[1], origin_f[2]};
  for (const auto& end : ray_ends) castRay(origin, origin_key, end.data());
  return labeled_points;
}

// Amanatides-Woo on octomap keys from the ray's end voxel (excluded, as octomap's computeRayKeys
// excludes it) to the sensor's voxel (included). Each step moves one axis one key toward the
// sensor, so the walk takes exactly the L1 key distance in steps and always ends at the sensor's
// voxel, whatever rounding does to the crossing distances.
void HashedVoxelGrid::castRay(const double origin[3], const std::uint16_t origin_key[3],
                              const double end[3]) {
  std::uint16_t key[3];
  const float end_f[3] = {static_cast<float>(end[0]), static_cast<float>(end[1]),
                          static_cast<float>(end[2])};
  if (!toKey(end_f, resolution_factor_, key)) return;  // octomap skips such a ray too
  if (key[0] == origin_key[0] && key[1] == origin_key[1] && key[2] == origin_key[2]) return;
  const double resolution = options_.resolution_m;
  double dir[3] = {origin[0] - end[0], origin[1] - end[1], origin[2] - end[2]};
  const double length = std::sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
  int remaining[3];
  int step[3];
  double t_max[3];
  double t_delta[3];
  constexpr double kInf = std::numeric_limits<double>::infinity();
  int steps = 0;
  for (int a = 0; a < 3; ++a) {
    const int diff = static_cast<int>(origin_key[a]) - static_cast<int>(key[a]);
    remaining[a] = std::abs(diff);
    steps += remaining[a];
    step[a] = diff > 0 ? 1 : -1;
    if (diff == 0 || length <= 0.0) {
      t_max[a] = t_delta[a] = kInf;
      continue;
    }
    const double d = std::abs(dir[a]) / length;
    const double border =
        (static_cast<double>(static_cast<int>(key[a]) - kKeyMax) + 0.5) * resolution +
        step[a] * 0.5 * resolution;
    t_max[a] = d > 0 ? std::abs(border - end[a]) / d : kInf;
    t_delta[a] = d > 0 ? resolution / d : kInf;
  }
  const int stop_after = options_.early_termination_voxels;
  int cleared_run = 0;
  std::size_t visits = 0, misses = 0;
  std::uint32_t k[3] = {key[0], key[1], key[2]};
  for (int s = 0; s < steps; ++s) {
    int a;
    // The axis whose border comes first among those not yet at the sensor's key.
    if (remaining[0] > 0 && (remaining[1] == 0 || t_max[0] <= t_max[1]) &&
        (remaining[2] == 0 || t_max[0] <= t_max[2])) {
      a = 0;
    } else if (remaining[1] > 0 && (remaining[2] == 0 || t_max[1] <= t_max[2])) {
      a = 1;
    } else {
      a = 2;
    }
    k[a] = static_cast<std::uint32_t>(static_cast<int>(k[a]) + step[a]);
    --remaining[a];
    t_max[a] += t_delta[a];
    ++visits;
    Block* block = findOrCreateBlock(packBlockKey(k[0] >> 3, k[1] >> 3, k[2] >> 3));
    const int v = voxelIndex(k[0], k[1], k[2]);
    const std::uint8_t stamp = block->stamp[v];
    if (stamp == free_stamp_) {
      if (stop_after > 0 && ++cleared_run >= stop_after) break;
      continue;
    }
    cleared_run = 0;
    if (stamp == hit_stamp_) continue;  // an endpoint of this scan: never free in the same scan
    block->stamp[v] = free_stamp_;
    updateLogOdds(block, v, miss_log_);
    ++misses;
  }
  last_ray_visits_ += visits;
  last_misses_ += misses;
}

std::size_t HashedVoxelGrid::addClassEvidence(const LabeledScan& scan, const ClassSet& classes) {
  if (scan.label_ids.size() != static_cast<std::size_t>(scan.points_map.cols())) return 0;
  std::size_t added = 0;
  for (Eigen::Index i = 0; i < scan.points_map.cols(); ++i) {
    const std::uint32_t label = scan.label_ids[static_cast<std::size_t>(i)];
    if (label == scan.unknown_label_id) continue;
    const ClassIndex index = classes.indexOf(label);
    const float p[3] = {scan.points_map(0, i), scan.points_map(1, i), scan.points_map(2, i)};
    std::uint16_t key[3];
    if (index == kNoClass || !std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]) ||
        !toKey(p, resolution_factor_, key)) {
      continue;
    }
    Block* block = findBlock(packBlockKey(key[0] >> 3, key[1] >> 3, key[2] >> 3));
    const int v = voxelIndex(key[0], key[1], key[2]);
    if (!block || !block->isKnown(v) || block->log_odds[v] < occupied_log_) continue;
    ClassSlotCounts* counts = nullptr;
    ClassSlotIndices* slots = slotsOf(block, v, &counts);
    addClassCount(index, 1, slots, counts);
    markDirty(block);
    ++added;
  }
  return added;
}

namespace {

// Blocks per setLeaves call of a sync: the leaf states of a batch are built, written and dropped
// before the next, so a sync holds at most this many blocks' states (256 x 512 x 24 bytes =
// 3 MB) instead of all of them (101 MB for a whole 50-scan drive). Batches are consecutive in
// Morton order, so the tree ends up the same as with one call (each node is visited after its
// last change and pruned then).
constexpr std::size_t kSyncBatchBlocks = 256;

std::uint64_t blockMorton(const HashedVoxelGrid::Block& block) {
  const octomap::OcTreeKey corner(
      static_cast<octomap::key_type>(block.bx << HashedVoxelGrid::kBlockBits),
      static_cast<octomap::key_type>(block.by << HashedVoxelGrid::kBlockBits),
      static_cast<octomap::key_type>(block.bz << HashedVoxelGrid::kBlockBits));
  return SemanticOcTree::mortonCode(corner);
}

// Writes the known voxels of the dirty blocks among [begin, end) (in Morton order) into `tree`
// through `leaves_buffer`; returns their number.
std::size_t writeLeaves(HashedVoxelGrid::Block* const* begin, HashedVoxelGrid::Block* const* end,
                        SemanticOcTree* tree,
                        std::vector<SemanticOcTree::LeafState>* leaves_buffer) {
  // Blocks in Morton order of their coordinates and voxels in local Morton order: the leaves come
  // out in the tree's depth-first order, no sort of the voxels needed.
  const auto& local = mortonToIndex();
  static const ClassSlotIndices kNone{{kNoClass, kNoClass, kNoClass, kNoClass}};
  static const ClassSlotCounts kZero{{0, 0, 0, 0}};
  std::vector<SemanticOcTree::LeafState>& leaves = *leaves_buffer;
  leaves.clear();
  for (HashedVoxelGrid::Block* const* it = begin; it != end; ++it) {
    const HashedVoxelGrid::Block& block = **it;
    if (!block.dirty) continue;  // in the tree already (an earlier sync)
    const std::uint64_t block_morton = blockMorton(block);
    for (int m = 0; m < HashedVoxelGrid::kBlockVoxels; ++m) {
      const int v = local[m];
      if (!block.isKnown(v)) continue;
      const std::uint16_t slot = block.slot_of ? block.slot_of[v] : 0;
      leaves.push_back({block_morton | static_cast<std::uint64_t>(m), block.log_odds[v],
                        slot ? block.slot_classes[slot - 1] : kNone,
                        slot ? block.slot_counts[slot - 1] : kZero});
    }
  }
  if (!leaves.empty()) tree->setLeaves(&leaves);
  return leaves.size();
}

// Writes the dirty ones of `blocks` (in Morton order) into `tree`, kSyncBatchBlocks at a time,
// calling after_batch(first, last) after each batch. Returns the number of leaves written.
template <typename AfterBatch>
std::size_t writeInBatches(const std::vector<HashedVoxelGrid::Block*>& blocks, SemanticOcTree* tree,
                           AfterBatch&& after_batch) {
  std::vector<SemanticOcTree::LeafState> leaves;
  std::size_t written = 0;
  for (std::size_t first = 0; first < blocks.size(); first += kSyncBatchBlocks) {
    const std::size_t last = std::min(blocks.size(), first + kSyncBatchBlocks);
    written += writeLeaves(blocks.data() + first, blocks.data() + last, tree, &leaves);
    after_batch(first, last);
  }
  return written;
}

}  // namespace

std::size_t HashedVoxelGrid::syncTo(SemanticOcTree* tree) {
  if (dirty_blocks_.empty()) return 0;
  std::vector<Block*> ordered;
  ordered.swap(dirty_blocks_);
  std::sort(ordered.begin(), ordered.end(),
            [](const Block* a, const Block* b) { return blockMorton(*a) < blockMorton(*b); });
  return writeInBatches(ordered, tree, [&ordered](std::size_t first, std::size_t last) {
    for (std::size_t i = first; i < last; ++i) ordered[i]->dirty = false;
  });
}

std::size_t HashedVoxelGrid::moveTo(SemanticOcTree* tree) {
  std::sort(blocks_.begin(), blocks_.end(),
            [](const auto& a, const auto& b) { return blockMorton(*a) < blockMorton(*b); });
  // The hash table points into blocks that are freed below: forget it first.
  std::vector<std::uint64_t>().swap(table_keys_);
  std::vector<Block*>().swap(table_values_);
  std::vector<Block*>().swap(dirty_blocks_);
  cached_key_ = ~std::uint64_t{0};
  cached_block_ = nullptr;
  std::vector<Block*> ordered;
  ordered.reserve(blocks_.size());
  for (const auto& block : blocks_) ordered.push_back(block.get());
  const std::size_t written =
      writeInBatches(ordered, tree, [this](std::size_t first, std::size_t last) {
        // The batch's memory goes back before the tree grows by the next one.
        for (std::size_t i = first; i < last; ++i) blocks_[i].reset();
      });
  std::vector<std::unique_ptr<Block>>().swap(blocks_);
  rehash(1024);
  return written;
}

void HashedVoxelGrid::loadFrom(const SemanticOcTree& tree) {
  clear();
  if (std::abs(tree.getResolution() - options_.resolution_m) > 1e-9) {
    throw std::invalid_argument("HashedVoxelGrid::loadFrom: resolution differs");
  }
  const unsigned int max_depth = tree.getTreeDepth();
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    const unsigned int size = 1u << (max_depth - it.getDepth());
    const octomap::OcTreeKey center = it.getKey();
    std::uint32_t base[3];
    for (int a = 0; a < 3; ++a) base[a] = center[a] & ~(size - 1);
    const SemanticOcTreeNode& node = *it;
    const float value = node.getLogOdds();
    const bool semantics = node.hasSemantics();
    for (std::uint32_t z = base[2]; z < base[2] + size; ++z) {
      for (std::uint32_t y = base[1]; y < base[1] + size; ++y) {
        for (std::uint32_t x = base[0]; x < base[0] + size; ++x) {
          Block* block = findOrCreateBlock(packBlockKey(x >> 3, y >> 3, z >> 3));
          const int v = voxelIndex(x, y, z);
          block->log_odds[v] = value;
          block->setKnown(v);
          if (semantics) {
            ClassSlotCounts* counts = nullptr;
            *slotsOf(block, v, &counts) = node.slotClasses();
            *counts = node.slotCounts();
          }
        }
      }
    }
  }
  for (auto& block : blocks_) block->dirty = false;
  dirty_blocks_.clear();
}

bool HashedVoxelGrid::voxel(std::uint16_t kx, std::uint16_t ky, std::uint16_t kz, float* log_odds,
                            ClassSlotIndices* classes, ClassSlotCounts* counts) const {
  const Block* block = findBlock(packBlockKey(kx >> 3, ky >> 3, kz >> 3));
  const int v = voxelIndex(kx, ky, kz);
  if (!block || !block->isKnown(v)) return false;
  *log_odds = block->log_odds[v];
  const std::uint16_t slot = block->slot_of ? block->slot_of[v] : 0;
  if (classes) {
    *classes = slot ? block->slot_classes[slot - 1]
                    : ClassSlotIndices{{kNoClass, kNoClass, kNoClass, kNoClass}};
  }
  if (counts) *counts = slot ? block->slot_counts[slot - 1] : ClassSlotCounts{{0, 0, 0, 0}};
  return true;
}

std::size_t HashedVoxelGrid::knownVoxels() const {
  std::size_t known = 0;
  for (const auto& block : blocks_) {
    for (std::uint64_t word : block->known)
      known += static_cast<std::size_t>(__builtin_popcountll(word));
  }
  return known;
}

std::size_t HashedVoxelGrid::occupiedVoxels() const {
  std::size_t occupied = 0;
  for (const auto& block : blocks_) {
    for (int v = 0; v < kBlockVoxels; ++v) {
      if (block->isKnown(v) && block->log_odds[v] >= occupied_log_) ++occupied;
    }
  }
  return occupied;
}

std::size_t HashedVoxelGrid::memoryUsage() const {
  std::size_t bytes = sizeof(*this) + table_keys_.capacity() * sizeof(std::uint64_t) +
                      table_values_.capacity() * sizeof(Block*) +
                      blocks_.capacity() * sizeof(void*) + dirty_blocks_.capacity() * sizeof(void*);
  for (const auto& block : blocks_) {
    bytes += sizeof(Block);
    if (block->slot_of) bytes += kBlockVoxels * sizeof(std::uint16_t);
    bytes += block->slot_classes.capacity() * sizeof(ClassSlotIndices) +
             block->slot_counts.capacity() * sizeof(ClassSlotCounts);
  }
  return bytes;
}

}  // namespace mapping
}  // namespace inekf_semantic_mapping
