// HashedVoxelGrid on real HDL-64 scans of ../shared: the insertion against SemanticOcTree's (within
// 1 % of voxels) and early ray termination (fewer ray visits, the same map within a few %).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>

#include "inekf_semantic_mapping/kitti/velodyne.h"
#include "inekf_semantic_mapping/mapping/hashed_voxel_grid.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"
#include "test_data.h"
#include "voxel_agreement.h"

namespace inekf_semantic_mapping {
namespace mapping {
namespace {

using namespace test_support;  // NOLINT: the comparison helpers

// The first real HDL-64 scans of KITTI raw drive 0013 (sensor frame; the car barely moves in
// 0.3 s, each scan goes in at its own small offset).
std::vector<LabeledScan> realScans(int count) {
  const std::string dir = test::sharedPath(
      "data/kitti_raw/2011_09_26/2011_09_26_drive_0013_sync/velodyne_points/data/");
  std::vector<LabeledScan> scans;
  for (int frame = 0; frame < count; ++frame) {
    char name[32];
    std::snprintf(name, sizeof(name), "%010d.bin", frame);
    if (!std::filesystem::exists(dir + name)) break;
    const std::vector<float> xyzi = kitti::readVelodyneBin(dir + name).xyzi;
    LabeledScan scan;
    const Eigen::Index n = static_cast<Eigen::Index>(xyzi.size() / 4);
    scan.points_map.resize(3, n);
    const Eigen::Vector3f offset(1.0f * frame, 0.f, 0.f);
    for (Eigen::Index i = 0; i < n; ++i) {
      const Eigen::Vector3f p(xyzi[4 * i], xyzi[4 * i + 1], xyzi[4 * i + 2]);
      scan.points_map.col(i) = p + offset;
      scan.label_ids.push_back(p.z() < -1.4f ? 7u : (std::hypot(p.x(), p.y()) > 20.f ? 11u : 26u));
    }
    scan.sensor_origin_map = offset;
    scans.push_back(std::move(scan));
  }
  return scans;
}

#define REQUIRE_REAL_SCANS(scans)                                                               \
  if ((scans).empty()) {                                                                        \
    std::cerr << "*** SKIPPED: no KITTI raw drive 0013 velodyne scans in " << test::sharedDir() \
              << " (../shared): the real-scan check did not run\n";                             \
    GTEST_SKIP() << "no real KITTI scans in " << test::sharedDir();                             \
  }

TEST(HashedVoxelGrid, MatchesOctreeInsertionOnRealScans) {
  const std::vector<LabeledScan> scans = realScans(3);
  REQUIRE_REAL_SCANS(scans);
  HashedVoxelGrid grid(gridOptions(0.2, 1.0, 0));
  SemanticOcTree tree(0.2);
  tree.setGrazingRayTruncation(1.0);
  for (const LabeledScan& scan : scans) {
    EXPECT_EQ(grid.insertLabeledScan(scan, 50.0, tree.classSet()),
              tree.insertLabeledScan(scan, 50.0));
  }
  const Agreement agreement = compare(voxelsOf(grid), voxelsOf(tree));
  agreement.print("real HDL-64 x3, grazing 1");
  EXPECT_GT(agreement.union_voxels, 500000u);
  EXPECT_LT(agreement.stateFraction(), 0.01);
  EXPECT_LT(agreement.classFraction(), 0.01);
}

TEST(HashedVoxelGrid, EarlyRayTerminationCutsVisitsAndKeepsTheMap) {
  std::vector<LabeledScan> scans = realScans(3);
  const bool real = !scans.empty();
  if (!real) {
    std::cerr << "*** no real KITTI scans in " << test::sharedDir()
              << ": early termination measured on synthetic scans\n";
    for (int s = 0; s < 3; ++s) scans.push_back(syntheticScan(20 + s, {1.f * s, 0, 1.7f}, 100000));
  }
  std::size_t visits[2] = {0, 0}, misses[2] = {0, 0};
  VoxelMap maps[2];
  const int terminations[2] = {0, 10};
  for (int run = 0; run < 2; ++run) {
    HashedVoxelGrid grid(gridOptions(0.2, 1.0, terminations[run]));
    for (const LabeledScan& scan : scans) {
      grid.insertLabeledScan(scan, 50.0, ClassSet::cityscapes());
      visits[run] += grid.lastRayVisits();
      misses[run] += grid.lastMisses();
    }
    maps[run] = voxelsOf(grid);
  }
  const Agreement agreement = compare(maps[0], maps[1]);
  std::printf(
      "[ EARLY    ] %s: termination after 10 cleared voxels: ray visits %zu -> %zu (-%.1f %%), "
      "misses %zu -> %zu (-%.2f %%)\n",
      real ? "real HDL-64 x3" : "synthetic x3", visits[0], visits[1],
      100.0 * (1.0 - double(visits[1]) / visits[0]), misses[0], misses[1],
      100.0 * (1.0 - double(misses[1]) / misses[0]));
  agreement.print("early termination 10 vs none");
  // The effect of other values on the same scans (printed for the config's comment).
  for (const int n : {3, 20, 40}) {
    HashedVoxelGrid grid(gridOptions(0.2, 1.0, n));
    std::size_t v = 0, m = 0;
    for (const LabeledScan& scan : scans) {
      grid.insertLabeledScan(scan, 50.0, ClassSet::cityscapes());
      v += grid.lastRayVisits();
      m += grid.lastMisses();
    }
    const Agreement sweep = compare(maps[0], voxelsOf(grid));
    std::printf(
        "[ EARLY    ] termination after %d: visits -%.1f %%, misses -%.2f %%, occupancy state "
        "differs in %.3f %% of voxels, class in %.3f %%\n",
        n, 100.0 * (1.0 - double(v) / visits[0]), 100.0 * (1.0 - double(m) / misses[0]),
        100.0 * sweep.stateFraction(), 100.0 * sweep.classFraction());
  }
  EXPECT_LT(visits[1], visits[0] * 0.7);
  EXPECT_GT(misses[1], misses[0] * 0.9);
  EXPECT_LT(agreement.stateFraction(), 0.05);
  EXPECT_LT(agreement.classFraction(), 0.01);
}

}  // namespace
}  // namespace mapping
}  // namespace inekf_semantic_mapping
