// HashedVoxelGrid: the hashed-block insertion against SemanticOcTree's insertion
// (occupancy state and most likely class within 1 % of voxels on synthetic scans), per-scan
// de-duplication, the grid -> tree sync, and the session's hashed_grid path through save and load.
// The real HDL-64 scans: test/data/test_hashed_voxel_grid_data.cpp.
#include <gtest/gtest.h>
#include <octomap/AbstractOcTree.h>
#include <octomap/octomap_utils.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>
#include <sstream>
#include <unordered_map>

#include "inekf_semantic_mapping/mapping/hashed_voxel_grid.h"
#include "inekf_semantic_mapping/mapping/map_io.h"
#include "inekf_semantic_mapping/mapping/semantic_mapping_session.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"
#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "test_data.h"
#include "voxel_agreement.h"

namespace inekf_semantic_mapping {
namespace mapping {
namespace {

using namespace test_support;  // NOLINT: the comparison helpers

TEST(HashedVoxelGrid, SyncedTreeHoldsExactlyTheGridsVoxels) {
  HashedVoxelGrid grid(gridOptions(0.2, 1.0, 0));
  SemanticOcTree tree(0.2);
  const ClassSet classes = ClassSet::cityscapes();
  grid.insertLabeledScan(syntheticScan(1, {0, 0, 1.7f}), 30.0, classes);
  EXPECT_TRUE(grid.dirty());
  EXPECT_GT(grid.syncTo(&tree), 1000u);
  EXPECT_FALSE(grid.dirty());
  // Incremental: only the changed blocks are written the second time.
  grid.insertLabeledScan(syntheticScan(2, {3.f, 0.5f, 1.7f}), 30.0, classes);
  grid.insertLabeledScan(syntheticScan(3, {6.f, 1.f, 1.7f}), 30.0, classes);
  grid.syncTo(&tree);
  const VoxelMap from_grid = voxelsOf(grid);
  const VoxelMap from_tree = voxelsOf(tree);
  EXPECT_EQ(from_grid.size(), grid.knownVoxels());
  ASSERT_EQ(from_tree.size(), from_grid.size());
  for (const auto& [key, v] : from_grid) {
    const auto it = from_tree.find(key);
    ASSERT_NE(it, from_tree.end());
    ASSERT_EQ(it->second.log_odds, v.log_odds);
    ASSERT_EQ(it->second.best, v.best);
  }
  // Full slot equality on a sample of voxels.
  std::size_t checked = 0;
  grid.forEachVoxel([&](std::uint16_t x, std::uint16_t y, std::uint16_t z, float,
                        const ClassSlotIndices& c, const ClassSlotCounts& n) {
    if (++checked % 97 != 0) return;
    const SemanticOcTreeNode* node = tree.search(octomap::OcTreeKey(x, y, z));
    ASSERT_NE(node, nullptr);
    EXPECT_EQ(node->slotClasses(), c);
    EXPECT_EQ(node->slotCounts(), n);
  });
  EXPECT_GT(grid.occupiedVoxels(), 1000u);
}

// The tree's serialized bytes (what a save writes), inner nodes refreshed first.
std::string treeBytes(SemanticOcTree* tree) {
  tree->updateInnerOccupancy();
  std::ostringstream out;
  tree->write(out);
  return out.str();
}

// syncTo writes in batches of blocks (bounded memory); the tree must be the one a single
// setLeaves of every voxel builds, byte for byte (same pruning, same inner values).
TEST(HashedVoxelGrid, BatchedSyncBuildsTheSameTreeAsOneSetLeaves) {
  HashedVoxelGrid grid(gridOptions(0.2, 1.0, 0));
  const ClassSet classes = ClassSet::cityscapes();
  for (int s = 0; s < 3; ++s) {
    grid.insertLabeledScan(syntheticScan(60 + s, {2.f * s, 0.5f * s, 1.7f}), 40.0, classes);
  }
  ASSERT_GT(grid.blockCount(), 4u * 256u);  // several batches
  SemanticOcTree batched(0.2, classes, FusionModel());
  EXPECT_EQ(grid.syncTo(&batched), grid.knownVoxels());

  std::vector<SemanticOcTree::LeafState> leaves;
  grid.forEachVoxel([&](std::uint16_t x, std::uint16_t y, std::uint16_t z, float log_odds,
                        const ClassSlotIndices& c, const ClassSlotCounts& n) {
    leaves.push_back({SemanticOcTree::mortonCode(octomap::OcTreeKey(x, y, z)), log_odds, c, n});
  });
  SemanticOcTree at_once(0.2, classes, FusionModel());
  at_once.setLeaves(&leaves);
  EXPECT_EQ(batched.size(), at_once.size());
  EXPECT_TRUE(treeBytes(&batched) == treeBytes(&at_once));
}

// moveTo: the tree an incremental sync would have built, while the grid's memory goes; the grid
// rebuilt from that tree holds the same voxels and goes on like the grid that kept them.
TEST(HashedVoxelGrid, MoveToBuildsTheSyncedTreeAndEmptiesTheGrid) {
  const ClassSet classes = ClassSet::cityscapes();
  HashedVoxelGrid kept(gridOptions(0.2, 1.0, 20));
  HashedVoxelGrid moved(gridOptions(0.2, 1.0, 20));
  SemanticOcTree synced(0.2, classes, FusionModel());
  SemanticOcTree target(0.2, classes, FusionModel());
  for (HashedVoxelGrid* grid : {&kept, &moved}) {
    grid->insertLabeledScan(syntheticScan(70, {0.f, 0.f, 1.7f}), 40.0, classes);
  }
  kept.syncTo(&synced);
  moved.syncTo(&target);  // an earlier sync: moveTo writes only what changed since
  for (int s = 1; s < 3; ++s) {
    for (HashedVoxelGrid* grid : {&kept, &moved}) {
      grid->insertLabeledScan(syntheticScan(70 + s, {3.f * s, 0.5f * s, 1.7f}), 40.0, classes);
    }
  }
  kept.syncTo(&synced);
  const std::size_t grid_bytes = moved.memoryUsage();
  EXPECT_GT(moved.moveTo(&target), 0u);
  EXPECT_EQ(moved.blockCount(), 0u);
  EXPECT_EQ(moved.knownVoxels(), 0u);
  EXPECT_FALSE(moved.dirty());
  EXPECT_LT(moved.memoryUsage(), grid_bytes / 100);
  EXPECT_TRUE(treeBytes(&target) == treeBytes(&synced));

  moved.loadFrom(target);
  EXPECT_EQ(moved.knownVoxels(), kept.knownVoxels());
  const LabeledScan more = syntheticScan(80, {8.f, 1.f, 1.7f});
  kept.insertLabeledScan(more, 40.0, classes);
  moved.insertLabeledScan(more, 40.0, classes);
  const Agreement agreement = compare(voxelsOf(moved), voxelsOf(kept));
  EXPECT_EQ(agreement.state_differs, 0u);
  EXPECT_EQ(agreement.class_differs, 0u);
  EXPECT_EQ(agreement.log_odds_equal, agreement.union_voxels);
}

TEST(HashedVoxelGrid, MatchesOctreeInsertionOnSyntheticScans) {
  for (const double grazing : {0.0, 1.0}) {
    HashedVoxelGrid grid(gridOptions(0.2, grazing, 0));
    SemanticOcTree tree(0.2);
    tree.setGrazingRayTruncation(grazing);
    for (int s = 0; s < 4; ++s) {
      const LabeledScan scan = syntheticScan(10 + s, {2.5f * s, 0.3f * s, 1.7f});
      EXPECT_EQ(grid.insertLabeledScan(scan, 30.0, tree.classSet()),
                tree.insertLabeledScan(scan, 30.0));
    }
    const Agreement agreement = compare(voxelsOf(grid), voxelsOf(tree));
    agreement.print(grazing > 0 ? "synthetic, grazing 1" : "synthetic, grazing 0");
    EXPECT_GT(agreement.union_voxels, 50000u);
    EXPECT_LT(agreement.stateFraction(), 0.01);
    EXPECT_LT(agreement.classFraction(), 0.01);
  }
}

TEST(HashedVoxelGrid, EachVoxelIsUpdatedOncePerScan) {
  // 2000 rays fanned into a 1 x 1 m patch 10 m away: the voxels near the sensor are crossed by
  // hundreds of rays, the patch voxels hit by many points each.
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> unit(0.f, 1.f);
  LabeledScan scan;
  scan.points_map.resize(3, 2000);
  for (int i = 0; i < 2000; ++i) {
    scan.points_map.col(i) << 10.05f, 0.02f + unit(rng), 0.02f + unit(rng);
    scan.label_ids.push_back(26);
  }
  scan.sensor_origin_map = Eigen::Vector3f(0.05f, 0.5f, 0.5f);
  HashedVoxelGrid grid(gridOptions(0.1, 0.0, 0));
  const ClassSet classes = ClassSet::cityscapes();
  grid.insertLabeledScan(scan, 0.0, classes);
  const float miss = octomap::logodds(0.4), hit = octomap::logodds(0.7);
  std::size_t free_voxels = 0, occupied = 0;
  std::uint32_t evidence = 0;
  grid.forEachVoxel([&](std::uint16_t, std::uint16_t, std::uint16_t, float log_odds,
                        const ClassSlotIndices& c, const ClassSlotCounts& n) {
    if (log_odds < 0) {
      EXPECT_EQ(log_odds, miss);
      ++free_voxels;
    } else {
      EXPECT_EQ(log_odds, hit);
      ++occupied;
      evidence += n[0];
      EXPECT_EQ(c[0], classes.indexOf(26));
    }
  });
  EXPECT_GT(free_voxels, 500u);
  EXPECT_GT(occupied, 50u);
  EXPECT_EQ(evidence, 2000u);                              // one class observation per point
  EXPECT_GT(grid.lastRayVisits(), 3 * grid.lastMisses());  // the repetition the stamps absorb
  // A second scan: one more miss / hit each.
  grid.insertLabeledScan(scan, 0.0, classes);
  grid.forEachVoxel([&](std::uint16_t, std::uint16_t, std::uint16_t, float log_odds,
                        const ClassSlotIndices&, const ClassSlotCounts&) {
    EXPECT_TRUE(log_odds == miss + miss || log_odds == hit + hit) << log_odds;
  });
}

TEST(HashedVoxelGrid, EndpointsAreNeverFreedBySameScan) {
  // Two points on one line: the ray to the far one crosses the near one's voxel.
  LabeledScan scan;
  scan.points_map.resize(3, 2);
  scan.points_map.col(0) << 2.05f, 0.05f, 0.05f;
  scan.points_map.col(1) << 6.05f, 0.05f, 0.05f;
  scan.sensor_origin_map = Eigen::Vector3f(0.05f, 0.05f, 0.05f);
  HashedVoxelGrid grid(gridOptions(0.1, 0.0, 0));
  grid.insertLabeledScan(scan, 0.0, ClassSet::cityscapes());
  float log_odds = 0;
  ASSERT_TRUE(grid.voxel(32768 + 20, 32768, 32768, &log_odds));
  EXPECT_EQ(log_odds, octomap::logodds(0.7));
  ASSERT_TRUE(grid.voxel(32768 + 40, 32768, 32768, &log_odds));
  EXPECT_EQ(log_odds, octomap::logodds(0.4));
  ASSERT_TRUE(grid.voxel(32768, 32768, 32768, &log_odds));        // the sensor's voxel is free
  EXPECT_FALSE(grid.voxel(32768 + 61, 32768, 32768, &log_odds));  // beyond: unknown
}

TEST(HashedVoxelGrid, ScanStampsWrapWithoutChangingTheMap) {
  // 300 small scans: the 8-bit stamps wrap twice (every 127 scans).
  HashedVoxelGrid grid(gridOptions(0.2, 1.0, 0));
  SemanticOcTree tree(0.2);
  tree.setGrazingRayTruncation(1.0);
  for (int s = 0; s < 300; ++s) {
    const LabeledScan scan = syntheticScan(100 + s, {0.05f * (s % 40), 0.f, 1.7f}, 200);
    grid.insertLabeledScan(scan, 20.0, tree.classSet());
    tree.insertLabeledScan(scan, 20.0);
  }
  const Agreement agreement = compare(voxelsOf(grid), voxelsOf(tree));
  EXPECT_GT(agreement.union_voxels, 10000u);
  EXPECT_LT(agreement.stateFraction(), 0.001);
  EXPECT_EQ(agreement.class_differs, 0u);
}

TEST(HashedVoxelGrid, LoadFromATreeExpandsPrunedLeaves) {
  SemanticOcTree tree(0.2);
  tree.setGrazingRayTruncation(1.0);
  for (int s = 0; s < 2; ++s)
    tree.insertLabeledScan(syntheticScan(30 + s, {1.f * s, 0, 1.7f}), 30.0);
  HashedVoxelGrid grid(gridOptions(0.2, 1.0, 0));
  grid.loadFrom(tree);
  EXPECT_FALSE(grid.dirty());
  const Agreement agreement = compare(voxelsOf(grid), voxelsOf(tree));
  EXPECT_EQ(agreement.state_differs, 0u);
  EXPECT_EQ(agreement.class_differs, 0u);
  EXPECT_EQ(agreement.log_odds_equal, agreement.union_voxels);
}

SemanticMappingConfig sessionConfig(InsertionStructure insertion) {
  SemanticMappingConfig config;
  config.insertion = insertion;
  config.early_ray_termination_voxels = 0;  // the octree's exact meaning
  config.max_range_m = 30.0;
  config.label_geometry_check = false;
  return config;
}

TEST(HashedVoxelGridSession, SameMapAsTheOctreeSessionThroughSaveAndLoad) {
  SemanticMappingSession octree(sessionConfig(InsertionStructure::kOctree));
  SemanticMappingSession grid(sessionConfig(InsertionStructure::kHashedGrid));
  ASSERT_NE(grid.grid(), nullptr);
  EXPECT_EQ(octree.grid(), nullptr);
  for (int s = 0; s < 3; ++s) {
    const LabeledScan scan = syntheticScan(40 + s, {0, 0, 0});
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.translation() << 2.0 * s, 0.5 * s, 1.7;
    octree.insertScanWithPointLabels(scan.points_map, pose, scan.label_ids, 0);
    grid.insertScanWithPointLabels(scan.points_map, pose, scan.label_ids, 0);
  }
  EXPECT_EQ(grid.statistics().points_with_class, octree.statistics().points_with_class);
  const Agreement agreement = compare(voxelsOf(grid.tree()), voxelsOf(octree.tree()));
  agreement.print("session hashed_grid vs octree");
  EXPECT_LT(agreement.stateFraction(), 0.01);
  EXPECT_LT(agreement.classFraction(), 0.01);

  // Save -> load: the .ot is a SemanticOcTree file octomap's factory (octovis) reads, and a
  // loaded session goes on from the same state.
  const std::string dir = test::makeTempDir("hashed_grid_session");
  const std::string path = dir + "/map.ot";
  EXPECT_GT(grid.save(path, MapFormat::kSemanticOt), 1000u);
  std::unique_ptr<octomap::AbstractOcTree> raw(octomap::AbstractOcTree::read(path));
  ASSERT_NE(raw, nullptr);
  EXPECT_EQ(raw->getTreeType(), "SemanticOcTree");
  SemanticMappingSession loaded(sessionConfig(InsertionStructure::kHashedGrid));
  loaded.load(path);
  // The loaded map is held once (the tree) until something is inserted.
  EXPECT_TRUE(loaded.gridReleased());
  EXPECT_EQ(loaded.grid()->blockCount(), 0u);
  EXPECT_FALSE(loaded.grid()->dirty());
  const LabeledScan more = syntheticScan(50, {0, 0, 0});
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() << 7.0, 1.0, 1.7;
  grid.insertScanWithPointLabels(more.points_map, pose, more.label_ids, 0);
  loaded.insertScanWithPointLabels(more.points_map, pose, more.label_ids, 0);
  EXPECT_FALSE(loaded.gridReleased());
  EXPECT_EQ(loaded.grid()->knownVoxels(), grid.grid()->knownVoxels());
  const Agreement after = compare(voxelsOf(loaded.tree()), voxelsOf(grid.tree()));
  EXPECT_EQ(after.state_differs, 0u);
  EXPECT_EQ(after.class_differs, 0u);
  EXPECT_EQ(after.log_odds_equal, after.union_voxels);
  std::filesystem::remove_all(dir);

  // Reset empties both structures.
  grid.reset();
  EXPECT_EQ(grid.grid()->blockCount(), 0u);
  EXPECT_EQ(grid.tree().size(), 0u);
}

TEST(HashedVoxelGridSession, ConfigKeys) {
  // The defaults are the YAML's (hashed grid, early termination after 20 cleared voxels).
  const SemanticMappingConfig from_file =
      loadSemanticMappingConfig(test::repoPath("config/semantic_mapping.yaml"));
  EXPECT_EQ(from_file.insertion, SemanticMappingConfig().insertion);
  EXPECT_EQ(from_file.early_ray_termination_voxels,
            SemanticMappingConfig().early_ray_termination_voxels);
  YAML::Node root = YAML::Load("insertion: hashed_grid\nearly_ray_termination_voxels: 10\n");
  const SemanticMappingConfig config = readSemanticMappingConfig(root, "test");
  EXPECT_EQ(config.insertion, InsertionStructure::kHashedGrid);
  EXPECT_EQ(config.early_ray_termination_voxels, 10);
  EXPECT_THROW(readSemanticMappingConfig(YAML::Load("insertion: voxblox\n"), "test"),
               std::exception);
  EXPECT_THROW(readSemanticMappingConfig(YAML::Load("early_ray_termination_voxels: -1\n"), "test"),
               std::exception);
}

TEST(HashedVoxelGrid, GridLogOddsStayWithinTheClampingBounds) {
  HashedVoxelGridOptions options = gridOptions(0.2, 0.0, 0);
  HashedVoxelGrid grid(options);
  const ClassSet classes = ClassSet::cityscapes();
  const LabeledScan scan = syntheticScan(1, {0, 0, 1.7f});
  for (int i = 0; i < 10; ++i) grid.insertLabeledScan(scan, 30.0, classes);
  const float lo = octomap::logodds(options.occupancy.clamping_min);
  const float hi = octomap::logodds(options.occupancy.clamping_max);
  std::size_t below = 0, above = 0;
  grid.forEachVoxel([&](std::uint16_t, std::uint16_t, std::uint16_t, float l,
                        const ClassSlotIndices&, const ClassSlotCounts&) {
    below += l < lo - 1e-6f;
    above += l > hi + 1e-6f;
  });
  EXPECT_EQ(below, 0u);
  EXPECT_EQ(above, 0u);
}

TEST(HashedVoxelGrid, GridClassEvidenceGoesToOccupiedVoxelsOnly) {
  HashedVoxelGrid grid(gridOptions(0.2, 0.0, 0));
  const ClassSet classes = ClassSet::cityscapes();
  LabeledScan hit;
  hit.points_map.resize(3, 1);
  hit.points_map.col(0) << 10.1f, 0.1f, 0.1f;
  hit.sensor_origin_map = Eigen::Vector3f(0.1f, 0.1f, 0.1f);
  grid.insertLabeledScan(hit, 0.0, classes);
  LabeledScan labels;
  labels.points_map.resize(3, 2);
  labels.points_map.col(0) << 5.1f, 0.1f, 0.1f;   // on the ray: free
  labels.points_map.col(1) << 10.1f, 0.1f, 0.1f;  // the hit: occupied
  labels.label_ids = {cityscapes::kCar, cityscapes::kCar};
  EXPECT_EQ(grid.addClassEvidence(labels, classes), 1u);
}
}  // namespace
}  // namespace mapping
}  // namespace inekf_semantic_mapping
