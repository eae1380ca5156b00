// Voxel-by-voxel comparison of a HashedVoxelGrid with a SemanticOcTree (occupancy state, log-odds,
// most likely class) and the street-like synthetic scans both are fed; shared by the data-free
// hashed-grid tests (test/unit) and the real-scan ones (test/data).
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <unordered_map>

#include "inekf_semantic_mapping/mapping/hashed_voxel_grid.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"

namespace inekf_semantic_mapping {
namespace mapping {
namespace test_support {

inline std::uint64_t pack(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
  return (static_cast<std::uint64_t>(x) << 32) | (static_cast<std::uint64_t>(y) << 16) | z;
}

struct VoxelState {
  float log_odds;
  ClassIndex best;
};
using VoxelMap = std::unordered_map<std::uint64_t, VoxelState>;

// Every known finest voxel of a tree (pruned leaves expanded).
inline VoxelMap voxelsOf(const SemanticOcTree& tree) {
  VoxelMap voxels;
  const unsigned int max_depth = tree.getTreeDepth();
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    const std::uint32_t size = 1u << (max_depth - it.getDepth());
    std::uint32_t base[3];
    for (int a = 0; a < 3; ++a) base[a] = it.getKey()[a] & ~(size - 1);
    for (std::uint32_t z = base[2]; z < base[2] + size; ++z) {
      for (std::uint32_t y = base[1]; y < base[1] + size; ++y) {
        for (std::uint32_t x = base[0]; x < base[0] + size; ++x) {
          voxels[pack(x, y, z)] = {it->getLogOdds(), it->mostLikelyClass()};
        }
      }
    }
  }
  return voxels;
}

inline VoxelMap voxelsOf(const HashedVoxelGrid& grid) {
  VoxelMap voxels;
  grid.forEachVoxel([&](std::uint16_t x, std::uint16_t y, std::uint16_t z, float log_odds,
                        const ClassSlotIndices& classes, const ClassSlotCounts& counts) {
    voxels[pack(x, y, z)] = {log_odds, mostObservedClass(classes, counts)};
  });
  return voxels;
}

struct Agreement {
  std::size_t union_voxels = 0;
  std::size_t state_differs = 0;  // unknown / free / occupied
  std::size_t both_occupied = 0;
  std::size_t class_differs = 0;  // of the voxels occupied in both
  std::size_t log_odds_equal = 0;
  double stateFraction() const { return union_voxels ? double(state_differs) / union_voxels : 0; }
  double classFraction() const { return both_occupied ? double(class_differs) / both_occupied : 0; }
  void print(const char* what) const {
    std::printf(
        "[ AGREE    ] %s: %zu voxels, occupancy state differs in %zu (%.3f %%), log-odds "
        "bit-equal in %.3f %%, class differs in %zu of %zu occupied (%.3f %%)\n",
        what, union_voxels, state_differs, 100.0 * stateFraction(),
        union_voxels ? 100.0 * log_odds_equal / union_voxels : 0.0, class_differs, both_occupied,
        100.0 * classFraction());
  }
};

inline Agreement compare(const VoxelMap& a, const VoxelMap& b) {
  const auto state = [](const VoxelMap& m, std::uint64_t key) {
    const auto it = m.find(key);
    return it == m.end() ? 0 : (it->second.log_odds >= 0.f ? 2 : 1);
  };
  Agreement agreement;
  const auto count = [&](std::uint64_t key) {
    const int sa = state(a, key), sb = state(b, key);
    ++agreement.union_voxels;
    if (sa != sb) ++agreement.state_differs;
    if (sa != 0 && sb != 0 && a.at(key).log_odds == b.at(key).log_odds) ++agreement.log_odds_equal;
    if (sa == 2 && sb == 2) {
      ++agreement.both_occupied;
      if (a.at(key).best != b.at(key).best) ++agreement.class_differs;
    }
  };
  for (const auto& [key, v] : a) count(key);
  for (const auto& [key, v] : b) {
    if (!a.count(key)) count(key);
  }
  return agreement;
}

inline HashedVoxelGridOptions gridOptions(double resolution, double grazing, int early) {
  HashedVoxelGridOptions options;
  options.resolution_m = resolution;
  options.grazing_truncation_voxels = grazing;
  options.early_termination_voxels = early;
  return options;
}

// A street-like synthetic scan: ground 1.7 m below the sensor, walls and boxes, labels by height.
inline LabeledScan syntheticScan(int seed, const Eigen::Vector3f& origin, int points = 30000) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.f, 1.f);
  LabeledScan scan;
  scan.points_map.resize(3, points);
  scan.sensor_origin_map = origin;
  for (int i = 0; i < points; ++i) {
    const float azimuth = 6.2831853f * unit(rng);
    const float elevation = -0.4f + 0.45f * unit(rng);
    float range = 4.f + 50.f * unit(rng);
    if (elevation < 0) range = std::min(range, 1.7f / -std::sin(elevation));
    const Eigen::Vector3f p =
        origin + range * Eigen::Vector3f(std::cos(elevation) * std::cos(azimuth),
                                         std::cos(elevation) * std::sin(azimuth),
                                         std::sin(elevation));
    scan.points_map.col(i) = p;
    const float z = p.z() - origin.z();
    std::uint32_t label = z < -1.5f ? 7 : (z > 1.f ? 11 : 26);
    if (unit(rng) < 0.15f) label = 21;  // label noise
    if (unit(rng) < 0.05f) label = 0;   // carries no evidence
    scan.label_ids.push_back(label);
  }
  scan.unknown_label_id = 0;
  return scan;
}

}  // namespace test_support
}  // namespace mapping
}  // namespace inekf_semantic_mapping
