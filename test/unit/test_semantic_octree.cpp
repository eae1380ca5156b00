// SemanticOcTree: Bayesian fusion math, free-space carving, label-aware pruning, .ot/.ply I/O,
// and the fusion target on a ray-cast synthetic scene with 20 % wrong labels.
#include <gtest/gtest.h>
#include <octomap/AbstractOcTree.h>
#include <octomap/ColorOcTree.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <sstream>

#include "inekf_semantic_mapping/common/atomic_file.h"
#include "inekf_semantic_mapping/mapping/map_io.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"
#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace mapping {
namespace {

namespace cs = cityscapes;

// Reference posterior by direct recursive Bayes: start uniform, multiply the observed class by
// c and every other class by (1-c)/(N-1), normalize. Independent of the count formulation.
std::vector<double> directBayes(const std::vector<int>& observations, int num_classes, double c) {
  std::vector<double> p(num_classes, 1.0 / num_classes);
  for (int observed : observations) {
    double sum = 0;
    for (int k = 0; k < num_classes; ++k) {
      p[k] *= (k == observed) ? c : (1.0 - c) / (num_classes - 1);
      sum += p[k];
    }
    for (double& value : p) value /= sum;
  }
  return p;
}

TEST(SemanticOcTreeNode, ConsistentObservationsMatchClosedForm) {
  const int num_classes = 34;
  FusionModel model;
  model.correct_probability = 0.7;
  for (int k = 1; k <= 6; ++k) {
    SemanticOcTreeNode node;
    for (int i = 0; i < k; ++i) node.addClassEvidence(5);
    const double c = model.correct_probability;
    const double closed_form =
        std::pow(c, k) /
        (std::pow(c, k) + (num_classes - 1) * std::pow((1 - c) / (num_classes - 1), k));
    EXPECT_NEAR(node.classProbability(5, model, num_classes), closed_form, 1e-12) << "k=" << k;
    EXPECT_NEAR(node.classProbability(5, model, num_classes),
                directBayes(std::vector<int>(k, 5), num_classes, c)[5], 1e-12);
    // The other classes share the rest equally.
    EXPECT_NEAR(node.classProbability(9, model, num_classes), (1 - closed_form) / (num_classes - 1),
                1e-12);
    EXPECT_EQ(node.mostLikelyClass(), 5);
  }
}

TEST(SemanticOcTreeNode, ConflictingEvidence) {
  const int num_classes = 10;
  FusionModel bayes;
  bayes.correct_probability = 0.8;
  const std::vector<int> observations = {2, 7, 2, 7, 7, 3};
  SemanticOcTreeNode node;
  for (int observed : observations) node.addClassEvidence(static_cast<ClassIndex>(observed));
  const std::vector<double> expected = directBayes(observations, num_classes, 0.8);
  double sum = 0;
  for (int k = 0; k < num_classes; ++k) {
    const double p = node.classProbability(static_cast<ClassIndex>(k), bayes, num_classes);
    EXPECT_NEAR(p, expected[k], 1e-12) << "class " << k;
    sum += p;
  }
  EXPECT_NEAR(sum, 1.0, 1e-12);
  EXPECT_EQ(node.mostLikelyClass(), 7);

  FusionModel dirichlet;
  dirichlet.rule = FusionRule::kDirichlet;
  dirichlet.dirichlet_prior = 0.5;
  EXPECT_NEAR(node.classProbability(7, dirichlet, num_classes), (3 + 0.5) / (6 + 10 * 0.5), 1e-12);
  EXPECT_NEAR(node.classProbability(0, dirichlet, num_classes), 0.5 / (6 + 10 * 0.5), 1e-12);
}

TEST(SemanticOcTreeNode, SlotsKeepTheMostObservedClassesAndSaturate) {
  SemanticOcTreeNode node;
  for (int i = 0; i < 5; ++i) node.addClassEvidence(1);
  for (int i = 0; i < 4; ++i) node.addClassEvidence(2);
  for (int i = 0; i < 3; ++i) node.addClassEvidence(3);
  node.addClassEvidence(4);
  node.addClassEvidence(9);  // fifth class: evicts the least observed (class 4)
  std::set<int> stored;
  for (int s = 0; s < SemanticOcTreeNode::kSlots; ++s) stored.insert(node.slotClass(s));
  EXPECT_EQ(stored, (std::set<int>{1, 2, 3, 9}));
  EXPECT_EQ(node.mostLikelyClass(), 1);

  SemanticOcTreeNode saturated;
  saturated.addClassEvidence(1, 60000);
  saturated.addClassEvidence(2, 20000);
  saturated.addClassEvidence(1, 20000);  // 80000 > 65535: everything halves
  EXPECT_EQ(saturated.mostLikelyClass(), 1);
  EXPECT_LE(saturated.totalCount(), 2u * SemanticOcTreeNode::kMaxCount);
  EXPECT_NEAR(static_cast<double>(saturated.slotCount(0)) / saturated.slotCount(1), 4.0, 0.01);

  // A class seen once keeps a count through the halving (rounded up): a slot with a class and a
  // count of 0 would be the first evicted though it was observed.
  SemanticOcTreeNode rare;
  rare.addClassEvidence(5);
  rare.addClassEvidence(1, 60000);
  rare.addClassEvidence(1, 20000);
  int rare_slot = -1;
  for (int s = 0; s < SemanticOcTreeNode::kSlots; ++s) {
    if (rare.slotClass(s) == 5) rare_slot = s;
  }
  ASSERT_GE(rare_slot, 0);
  EXPECT_EQ(rare.slotCount(rare_slot), 1u);
}

TEST(SemanticOcTree, FreeSpaceCarvingAndMaxRange) {
  SemanticOcTree tree(0.2, ClassSet::cityscapes(), FusionModel());
  LabeledScan scan;
  scan.points_map.resize(3, 2);
  scan.points_map.col(0) << 10.05f, 0.05f, 0.05f;  // a hit at 10 m
  scan.points_map.col(1) << 0.05f, 30.05f, 0.05f;  // beyond the 15 m max range
  scan.label_ids = {cs::kBuilding, cs::kCar};
  scan.sensor_origin_map = Eigen::Vector3f(0.05f, 0.05f, 0.05f);
  EXPECT_EQ(tree.insertLabeledScan(scan, 15.0), 1u);  // only the in-range point is labeled

  const SemanticOcTreeNode* hit = tree.search(10.05, 0.05, 0.05);
  ASSERT_NE(hit, nullptr);
  EXPECT_TRUE(tree.isNodeOccupied(hit));
  EXPECT_EQ(tree.mostLikelyLabel(*hit, 0), cs::kBuilding);
  const SemanticOcTreeNode* on_ray = tree.search(5.05, 0.05, 0.05);
  ASSERT_NE(on_ray, nullptr);
  EXPECT_FALSE(tree.isNodeOccupied(on_ray));
  // The long ray clears up to 15 m and no further, and inserts no endpoint.
  const SemanticOcTreeNode* cleared = tree.search(0.05, 14.05, 0.05);
  ASSERT_NE(cleared, nullptr);
  EXPECT_FALSE(tree.isNodeOccupied(cleared));
  EXPECT_EQ(tree.search(0.05, 16.05, 0.05), nullptr);
  EXPECT_EQ(tree.search(0.05, 30.05, 0.05), nullptr);

  // A later scan seeing through the hit voxel lowers its occupancy.
  const float before = hit->getLogOdds();
  LabeledScan through;
  through.points_map.resize(3, 1);
  through.points_map.col(0) << 12.05f, 0.05f, 0.05f;
  through.sensor_origin_map = scan.sensor_origin_map;
  tree.insertLabeledScan(through, 15.0);
  EXPECT_LT(tree.search(10.05, 0.05, 0.05)->getLogOdds(), before);
}

// A lidar 1.73 m above flat ground drives along x and scans the road ahead at the HDL-64's
// lower elevations; returns the fraction of the road voxels it hit that the map holds occupied.
double roadCoverage(double grazing_truncation_voxels) {
  constexpr double kResolution = 0.2, kSensorHeight = 1.73;
  SemanticOcTree tree(kResolution, ClassSet::cityscapes(), FusionModel());
  tree.setGrazingRayTruncation(grazing_truncation_voxels);
  octomap::KeySet road;
  for (int step = 0; step < 20; ++step) {
    const Eigen::Vector3f origin(0.5f * step + 0.05f, 0.05f, static_cast<float>(kSensorHeight));
    std::vector<Eigen::Vector3f> points;
    for (double elevation_deg = -24.0; elevation_deg <= -2.0; elevation_deg += 0.4) {
      const double range_on_ground = kSensorHeight / std::tan(-elevation_deg * M_PI / 180.0);
      for (double azimuth_deg = -30.0; azimuth_deg <= 30.0; azimuth_deg += 0.5) {
        const double azimuth = azimuth_deg * M_PI / 180.0;
        points.emplace_back(origin.x() + range_on_ground * std::cos(azimuth),
                            origin.y() + range_on_ground * std::sin(azimuth), 0.05f);
      }
    }
    LabeledScan scan;
    scan.sensor_origin_map = origin;
    scan.points_map.resize(3, static_cast<Eigen::Index>(points.size()));
    for (std::size_t i = 0; i < points.size(); ++i) {
      scan.points_map.col(static_cast<Eigen::Index>(i)) = points[i];
      road.insert(tree.coordToKey(points[i].x(), points[i].y(), points[i].z()));
    }
    scan.label_ids.assign(points.size(), cs::kRoad);
    tree.insertLabeledScan(scan, 50.0);
  }
  std::size_t kept = 0;
  for (const octomap::OcTreeKey& key : road) {
    const SemanticOcTreeNode* node = tree.search(key);
    if (node != nullptr && tree.isNodeOccupied(node)) ++kept;
  }
  return static_cast<double>(kept) / static_cast<double>(road.size());
}

TEST(SemanticOcTree, GrazingRayTruncationKeepsTheRoad) {
  // Octomap's ray casting: rays to farther road points pass within a voxel of the nearer road
  // and clear it.
  const double cleared_by_grazing_rays = roadCoverage(0.0);
  const double truncated = roadCoverage(1.0);
  std::printf("[ ROAD     ] road voxels kept occupied: %.3f plain, %.3f with 1 voxel truncation\n",
              cleared_by_grazing_rays, truncated);
  EXPECT_LT(cleared_by_grazing_rays, 0.5);
  EXPECT_GT(truncated, 0.98);
}

// The 8 finest voxels under one depth-15 node.
std::vector<octomap::OcTreeKey> siblingKeys(const SemanticOcTree& tree) {
  const octomap::OcTreeKey base = tree.coordToKey(octomap::point3d(1.01f, 1.01f, 1.01f));
  std::vector<octomap::OcTreeKey> keys;
  for (int i = 0; i < 8; ++i) {
    keys.emplace_back((base[0] & ~1) + (i & 1), (base[1] & ~1) + ((i >> 1) & 1),
                      (base[2] & ~1) + ((i >> 2) & 1));
  }
  return keys;
}

int leavesAtDepth(const SemanticOcTree& tree, unsigned int depth) {
  int count = 0;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    if (it.getDepth() == depth) ++count;
  }
  return count;
}

TEST(SemanticOcTree, PruningRespectsLabels) {
  SemanticOcTree same(0.1);
  for (const auto& key : siblingKeys(same)) same.updateOccupiedVoxel(key, 3, 2);
  EXPECT_EQ(leavesAtDepth(same, 16), 0);  // identical children collapsed into one leaf
  EXPECT_EQ(leavesAtDepth(same, 15), 1);
  const SemanticOcTreeNode* merged = same.search(siblingKeys(same)[5]);
  ASSERT_NE(merged, nullptr);
  EXPECT_EQ(merged->mostLikelyClass(), 3);

  SemanticOcTree mixed(0.1);
  const auto keys = siblingKeys(mixed);
  for (std::size_t i = 0; i < keys.size(); ++i) {
    mixed.updateOccupiedVoxel(keys[i], i == 6 ? 4 : 3, 2);  // one child labeled differently
  }
  EXPECT_EQ(leavesAtDepth(mixed, 16), 8);
  EXPECT_EQ(mixed.search(keys[6])->mostLikelyClass(), 4);
  EXPECT_EQ(mixed.search(keys[5])->mostLikelyClass(), 3);
  mixed.prune();
  EXPECT_EQ(leavesAtDepth(mixed, 16), 8);

  // Updating a pruned leaf expands it and labels only the updated voxel.
  same.updateOccupiedVoxel(keys[2], 7, 5);
  EXPECT_EQ(leavesAtDepth(same, 16), 8);
  EXPECT_EQ(same.search(keys[2])->mostLikelyClass(), 7);
  EXPECT_EQ(same.search(keys[3])->mostLikelyClass(), 3);

  // Inner nodes aggregate: max occupancy and merged evidence.
  same.updateInnerOccupancy();
  const SemanticOcTreeNode* parent = same.search(keys[0], 15);
  ASSERT_NE(parent, nullptr);
  EXPECT_FLOAT_EQ(parent->getLogOdds(), same.search(keys[2])->getLogOdds());
  EXPECT_EQ(parent->totalCount(), 7u * 2u + 2u + 5u);
}

// A small random map with mixed labels, free space and pruned parts.
SemanticOcTree makeRandomMap(unsigned seed) {
  SemanticOcTree tree(0.25, ClassSet::cityscapes(), FusionModel());
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> coord(-4.f, 4.f);
  std::uniform_int_distribution<int> label(0, cs::kNumLabelIds - 1);
  for (int s = 0; s < 3; ++s) {
    LabeledScan scan;
    scan.points_map.resize(3, 400);
    for (int i = 0; i < 400; ++i) {
      scan.points_map.col(i) << coord(rng), coord(rng), coord(rng) * 0.25f;
      scan.label_ids.push_back(static_cast<std::uint32_t>(label(rng)));
    }
    scan.sensor_origin_map = Eigen::Vector3f(0.1f * s, 0.f, 1.f);
    tree.insertLabeledScan(scan, 5.0);
  }
  return tree;
}

std::string serialize(const SemanticOcTree& tree) {
  std::ostringstream out;
  tree.write(out);
  return out.str();
}

TEST(SemanticOcTreeIo, OtRoundTripIsBitIdenticalAndGoesThroughTheFactory) {
  SemanticOcTree tree = makeRandomMap(7);
  FusionModel fusion;
  fusion.correct_probability = 0.65;
  tree.setFusionModel(fusion);
  const std::string dir = test::makeTempDir("semantic_octree_io");
  const std::string path = dir + "/map.ot";
  const std::size_t occupied = saveMap(tree, path, MapFormat::kSemanticOt);
  EXPECT_GT(occupied, 100u);
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    EXPECT_EQ(entry.path().filename().string(), "map.ot");  // no temporary left behind
  }

  std::unique_ptr<octomap::AbstractOcTree> raw(octomap::AbstractOcTree::read(path));
  ASSERT_NE(raw, nullptr);
  EXPECT_EQ(raw->getTreeType(), "SemanticOcTree");
  ASSERT_NE(dynamic_cast<SemanticOcTree*>(raw.get()), nullptr);

  std::unique_ptr<SemanticOcTree> loaded = loadSemanticOcTree(path);
  EXPECT_EQ(loaded->size(), tree.size());
  EXPECT_EQ(loaded->classSet(), tree.classSet());
  EXPECT_DOUBLE_EQ(loaded->fusionModel().correct_probability, 0.65);
  // Every node (inner and leaf): same key, depth, log-odds bits and class evidence.
  auto a = tree.begin_tree(), a_end = tree.end_tree();
  auto b = loaded->begin_tree(), b_end = loaded->end_tree();
  std::size_t compared = 0;
  for (; a != a_end && b != b_end; ++a, ++b, ++compared) {
    ASSERT_EQ(a.getKey(), b.getKey());
    ASSERT_EQ(a.getDepth(), b.getDepth());
    ASSERT_TRUE(*a == *b) << "node " << compared;
  }
  EXPECT_TRUE(a == a_end && b == b_end);
  EXPECT_EQ(compared, tree.size());
  EXPECT_EQ(serialize(*loaded), serialize(tree));
  std::filesystem::remove_all(dir);
}

// A sink that cannot seek (a pipe, a socket): tellp() answers -1.
class UnseekableBuffer : public std::stringbuf {
 protected:
  pos_type seekoff(off_type, std::ios_base::seekdir, std::ios_base::openmode) override {
    return pos_type(off_type(-1));
  }
  pos_type seekpos(pos_type, std::ios_base::openmode) override { return pos_type(off_type(-1)); }
};

TEST(SemanticOcTreeIo, TheNodeDataIsOctomapsFullFormatByteForByteOnAnyStream) {
  const SemanticOcTree tree = makeRandomMap(11);
  ASSERT_GT(tree.size(), 1000u);
  // octomap's own serialisation of the same nodes (non-virtual call of the base writer).
  std::ostringstream octomap_nodes;
  tree.octomap::OcTreeBaseImpl<SemanticOcTreeNode, octomap::AbstractOccupancyOcTree>::writeData(
      octomap_nodes);
  const std::string expected_nodes = octomap_nodes.str();
  ASSERT_FALSE(expected_nodes.empty());

  const std::string seekable = serialize(tree);
  UnseekableBuffer buffer;
  std::ostream unseekable(&buffer);
  ASSERT_EQ(unseekable.tellp(), std::streampos(-1));
  tree.write(unseekable);
  EXPECT_EQ(buffer.str(), seekable);  // the checksum patched in, or learnt in a first pass
  ASSERT_GE(seekable.size(), expected_nodes.size());
  EXPECT_EQ(seekable.substr(seekable.size() - expected_nodes.size()), expected_nodes);
  // The integrity record before the nodes: count, length, and the FNV-1a of the fusion model and
  // class table (between the magic and the record) followed by exactly those node bytes.
  const std::size_t record = seekable.size() - expected_nodes.size() - 24;
  std::uint64_t count = 0, length = 0, checksum = 0;
  std::memcpy(&count, seekable.data() + record, 8);
  std::memcpy(&length, seekable.data() + record + 8, 8);
  std::memcpy(&checksum, seekable.data() + record + 16, 8);
  EXPECT_EQ(count, tree.size());
  EXPECT_EQ(length, expected_nodes.size());
  const auto fnv1a = [](const std::string& bytes) {
    std::uint64_t fnv = 1469598103934665603ull;
    for (const char c : bytes) {
      fnv ^= static_cast<std::uint8_t>(c);
      fnv *= 1099511628211ull;
    }
    return fnv;
  };
  const std::size_t magic_at = seekable.find("\ndata\n") + 6;
  const std::size_t table_at = magic_at + sizeof("ISM_SEMANTIC_OCTREE_V4");
  ASSERT_EQ(seekable.substr(magic_at, 22), "ISM_SEMANTIC_OCTREE_V4");
  // The fusion model and class table, then the resolution in binary, all under the checksum.
  const std::string table = seekable.substr(table_at, record - table_at);
  // ... then the resolution and the geodetic origin record (1 + 3 x 8 bytes; none here).
  constexpr std::size_t kOriginBytes = 25;
  double recorded_resolution = 0.0;
  std::memcpy(&recorded_resolution, seekable.data() + record - kOriginBytes - 8, 8);
  EXPECT_EQ(recorded_resolution, tree.getResolution());
  EXPECT_EQ(seekable[record - kOriginBytes], '\0');
  EXPECT_EQ(checksum, fnv1a(table + expected_nodes));
  // A bit flipped in a class's name (as well in a label id): refused, the table is checked too.
  std::string renamed = seekable;
  const std::size_t last_name_byte = record - kOriginBytes - 9;
  renamed[last_name_byte] = static_cast<char>(renamed[last_name_byte] ^ 0x20);
  std::istringstream renamed_file(renamed);
  std::unique_ptr<octomap::AbstractOcTree> refused(octomap::AbstractOcTree::read(renamed_file));
  ASSERT_NE(dynamic_cast<SemanticOcTree*>(refused.get()), nullptr);
  EXPECT_NE(dynamic_cast<SemanticOcTree*>(refused.get())->readError().find("class table"),
            std::string::npos);
  // octomap's text header edited to another resolution: refused (it was loaded as a map 1.5
  // times the size).
  const std::size_t res_at = seekable.find("\nres ") + 5;
  const std::size_t res_end = seekable.find('\n', res_at);
  ASSERT_EQ(seekable.substr(res_at, res_end - res_at), "0.25");
  const std::string edited = seekable.substr(0, res_at) + "0.375" + seekable.substr(res_end);
  std::istringstream edited_file(edited);
  std::unique_ptr<octomap::AbstractOcTree> rescaled(octomap::AbstractOcTree::read(edited_file));
  ASSERT_NE(dynamic_cast<SemanticOcTree*>(rescaled.get()), nullptr);
  EXPECT_NE(dynamic_cast<SemanticOcTree*>(rescaled.get())
                ->readError()
                .find("res 0.375 differs from the map's resolution 0.25"),
            std::string::npos)
      << dynamic_cast<SemanticOcTree*>(rescaled.get())->readError();
  // Files of the previous formats still load: V3 (no resolution under the checksum) and V2 (the
  // checksum of the node data alone).
  constexpr std::size_t kV4Bytes = 8 + kOriginBytes;
  std::string v3 = seekable;
  v3.erase(record - kV4Bytes, kV4Bytes);
  v3.replace(magic_at, 22, "ISM_SEMANTIC_OCTREE_V3");
  const std::uint64_t without_resolution =
      fnv1a(table.substr(0, table.size() - kV4Bytes) + expected_nodes);
  std::memcpy(&v3[record - kV4Bytes + 16], &without_resolution, 8);
  std::istringstream v3_file(v3);
  std::unique_ptr<octomap::AbstractOcTree> v3_format(octomap::AbstractOcTree::read(v3_file));
  ASSERT_NE(dynamic_cast<SemanticOcTree*>(v3_format.get()), nullptr);
  EXPECT_EQ(dynamic_cast<SemanticOcTree*>(v3_format.get())->readError(), "");
  EXPECT_EQ(v3_format->size(), tree.size());
  std::string v2 = v3;
  v2.replace(magic_at, 22, "ISM_SEMANTIC_OCTREE_V2");
  const std::uint64_t nodes_only = fnv1a(expected_nodes);
  std::memcpy(&v2[record - kV4Bytes + 16], &nodes_only, 8);
  std::istringstream v2_file(v2);
  std::unique_ptr<octomap::AbstractOcTree> old_format(octomap::AbstractOcTree::read(v2_file));
  ASSERT_NE(dynamic_cast<SemanticOcTree*>(old_format.get()), nullptr);
  EXPECT_EQ(dynamic_cast<SemanticOcTree*>(old_format.get())->readError(), "");
  EXPECT_EQ(old_format->size(), tree.size());
  // An empty tree: an empty record, and it loads back empty.
  SemanticOcTree empty(0.2);
  std::stringstream empty_file;
  empty.write(empty_file);
  std::unique_ptr<octomap::AbstractOcTree> loaded(octomap::AbstractOcTree::read(empty_file));
  ASSERT_NE(loaded, nullptr);
  EXPECT_EQ(loaded->size(), 0u);
}

TEST(SemanticOcTree, ParallelRayCastingGivesTheSameMap) {
  // Enough rays that the second thread really starts (the insert stays serial below 4000).
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> unit(-1.f, 1.f);
  LabeledScan scan;
  scan.points_map.resize(3, 20000);
  for (int i = 0; i < 20000; ++i) {
    scan.points_map.col(i) << 20.f * unit(rng), 20.f * unit(rng), 3.f * unit(rng);
    scan.label_ids.push_back(static_cast<std::uint32_t>(7 + (i % 3) * 4));
  }
  SemanticOcTree serial(0.2), parallel(0.2);
  parallel.setRayCastingThreads(2);
  for (int pass = 0; pass < 2; ++pass) {
    scan.sensor_origin_map = Eigen::Vector3f(0.5f * pass, 0.f, 1.5f);
    serial.insertLabeledScan(scan, 15.0);
    parallel.insertLabeledScan(scan, 15.0);
  }
  EXPECT_GT(serial.size(), 10000u);
  EXPECT_EQ(serialize(parallel), serialize(serial));
}

// The batched insertion against the obvious per-voxel one (octomap's updateNode for each free
// key, updateOccupiedVoxel for each hit), written with public API only: same final tree.
TEST(SemanticOcTree, BatchedInsertEqualsPerVoxelUpdates) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> unit(-1.f, 1.f);
  SemanticOcTree batched(0.25), reference(0.25);
  for (int pass = 0; pass < 3; ++pass) {
    LabeledScan scan;
    scan.points_map.resize(3, 3000);
    for (int i = 0; i < 3000; ++i) {
      // A box room (walls at +-6 m, some points beyond the 8 m max range) with mixed labels.
      const float x = 6.f * unit(rng), y = (i % 2 ? 6.f : -6.f) * (i % 7 == 0 ? 1.6f : 1.f);
      scan.points_map.col(i) << x, y, 2.f * unit(rng);
      scan.label_ids.push_back(i % 5 == 0 ? cs::kCar : cs::kBuilding);
    }
    scan.sensor_origin_map = Eigen::Vector3f(0.3f * pass, 0.1f, 0.2f);
    batched.insertLabeledScan(scan, 8.0);

    const octomap::point3d origin(scan.sensor_origin_map.x(), scan.sensor_origin_map.y(),
                                  scan.sensor_origin_map.z());
    std::map<octomap::OcTreeKey, std::pair<octomap::point3d, std::vector<ClassIndex>>,
             bool (*)(const octomap::OcTreeKey&, const octomap::OcTreeKey&)>
        hits([](const octomap::OcTreeKey& a, const octomap::OcTreeKey& b) {
          return std::tie(a[0], a[1], a[2]) < std::tie(b[0], b[1], b[2]);
        });
    octomap::KeySet clipped_keys;
    std::vector<octomap::point3d> ray_ends;
    for (int i = 0; i < 3000; ++i) {
      const octomap::point3d p(scan.points_map(0, i), scan.points_map(1, i), scan.points_map(2, i));
      const double range = (p - origin).norm();
      if (range > 8.0) {
        const octomap::point3d end = origin + (p - origin) * (8.0 / range);
        if (clipped_keys.insert(reference.coordToKey(end)).second) ray_ends.push_back(end);
        continue;
      }
      auto [it, inserted] = hits.try_emplace(reference.coordToKey(p));
      if (inserted) it->second.first = p;  // the first point of a voxel is its ray end
      it->second.second.push_back(reference.classSet().indexOf(scan.label_ids[i]));
    }
    for (const auto& [key, hit] : hits) ray_ends.push_back(hit.first);
    octomap::KeySet free_keys;
    octomap::KeyRay ray;
    for (const auto& end : ray_ends) {
      ASSERT_TRUE(reference.computeRayKeys(origin, end, ray));
      free_keys.insert(ray.begin(), ray.end());
    }
    for (const auto& key : free_keys) {
      if (!hits.count(key)) reference.updateNode(key, reference.getProbMissLog(), false);
    }
    for (const auto& [key, hit] : hits) {
      SemanticOcTreeNode* leaf = reference.updateOccupiedVoxel(key, hit.second[0], 1);
      ASSERT_NE(leaf, nullptr);
      for (std::size_t k = 1; k < hit.second.size(); ++k) leaf->addClassEvidence(hit.second[k]);
    }
  }
  batched.updateInnerOccupancy();
  reference.updateInnerOccupancy();
  EXPECT_GT(batched.size(), 5000u);
  EXPECT_EQ(serialize(batched), serialize(reference));
}

TEST(SemanticOcTreeIo, ColorOtLoadsAsColorOcTreeWithPaletteColors) {
  SemanticOcTree tree(0.2);
  const octomap::OcTreeKey key = tree.coordToKey(octomap::point3d(2.f, 1.f, 0.5f));
  tree.updateOccupiedVoxel(key, tree.classSet().indexOf(cs::kCar), 3);
  const std::string dir = test::makeTempDir("semantic_octree_color");
  saveMap(tree, dir + "/map_color.ot", MapFormat::kColorOt);
  std::unique_ptr<octomap::AbstractOcTree> raw(
      octomap::AbstractOcTree::read(dir + "/map_color.ot"));
  auto* color = dynamic_cast<octomap::ColorOcTree*>(raw.get());
  ASSERT_NE(color, nullptr);
  EXPECT_EQ(color->size(), tree.size());
  const octomap::ColorOcTreeNode* node = color->search(key);
  ASSERT_NE(node, nullptr);
  EXPECT_TRUE(color->isNodeOccupied(node));
  EXPECT_EQ(node->getColor(), octomap::ColorOcTreeNode::Color(0, 0, 142));  // Cityscapes car
  std::filesystem::remove_all(dir);
}

TEST(SemanticOcTreeIo, PlyListsEveryOccupiedFinestVoxelWithItsLabel) {
  SemanticOcTree tree(0.1);
  const auto keys = siblingKeys(tree);
  for (const auto& key : keys) tree.updateOccupiedVoxel(key, tree.classSet().indexOf(cs::kRoad), 1);
  const octomap::OcTreeKey lone = tree.coordToKey(octomap::point3d(-3.f, 2.f, 0.f));
  tree.updateOccupiedVoxel(lone, tree.classSet().indexOf(cs::kPole), 1);
  ASSERT_EQ(leavesAtDepth(tree, 15), 1);  // the 8 road voxels are one pruned leaf

  const std::string dir = test::makeTempDir("semantic_octree_ply");
  const std::string path = dir + "/map.ply";
  EXPECT_EQ(saveMap(tree, path, MapFormat::kPly), 9u);
  // Every format counts the map's voxels, not its stored leaves (the .ot said 2, the .ply 9:
  // save_map gave another count for the same map by the format asked for).
  EXPECT_EQ(saveMap(tree, dir + "/map.ot", MapFormat::kSemanticOt), 9u);
  EXPECT_EQ(saveMap(tree, dir + "/map_color.ot", MapFormat::kColorOt), 9u);
  std::ifstream in(path);
  std::string line;
  std::vector<std::string> header;
  while (std::getline(in, line) && line != "end_header") header.push_back(line);
  EXPECT_NE(std::find(header.begin(), header.end(), "element vertex 9"), header.end());
  EXPECT_NE(std::find(header.begin(), header.end(), "property uint label"), header.end());
  std::map<std::uint32_t, int> label_counts;
  std::set<octomap::OcTreeKey, bool (*)(const octomap::OcTreeKey&, const octomap::OcTreeKey&)>
      seen_keys([](const octomap::OcTreeKey& x, const octomap::OcTreeKey& y) {
        return std::tie(x[0], x[1], x[2]) < std::tie(y[0], y[1], y[2]);
      });
  float x, y, z;
  unsigned label, r, g, b;
  while (in >> x >> y >> z >> label >> r >> g >> b) {
    ++label_counts[label];
    const octomap::OcTreeKey key = tree.coordToKey(octomap::point3d(x, y, z));
    seen_keys.insert(key);
    const auto& info = cs::kLabels[label];
    EXPECT_EQ(std::tie(r, g, b),
              std::make_tuple(unsigned{info.r}, unsigned{info.g}, unsigned{info.b}));
  }
  EXPECT_EQ(label_counts[cs::kRoad], 8);
  EXPECT_EQ(label_counts[cs::kPole], 1);
  for (const auto& key : keys) EXPECT_EQ(seen_keys.count(key), 1u);
  EXPECT_EQ(seen_keys.count(lone), 1u);
  std::filesystem::remove_all(dir);
}

TEST(SemanticOcTreeIo, UnwritablePathFailsClearly) {
  SemanticOcTree tree = makeRandomMap(3);
  const std::string bad = "/nonexistent_dir_ism/map.ot";
  try {
    saveMap(tree, bad, MapFormat::kSemanticOt);
    FAIL() << "expected MapIoError";
  } catch (const MapIoError& e) {
    EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
  }
  EXPECT_THROW(loadSemanticOcTree("/nonexistent_dir_ism/missing.ot"), MapIoError);
  EXPECT_THROW(parseMapFormat("bt", "x.bt"), MapIoError);
  EXPECT_EQ(parseMapFormat("", "x.ply"), MapFormat::kPly);
  EXPECT_EQ(parseMapFormat("", "x.ot"), MapFormat::kSemanticOt);
  // Found by review: without a format, x.bt got a semantic octree that octomap's tools expect to
  // be their own binary format; any extension but .ply did.
  for (const char* path : {"x.bt", "x.xyz", "x"}) {
    EXPECT_THROW(parseMapFormat("", path), MapIoError) << path;
  }
  // Found by review: a format asked for by name under another format's extension was written
  // (PLY text as y.ot, an octree as z.ply, a semantic octree as x.bt): refused; another extension
  // is the user's choice.
  for (const auto& [format, path] : std::vector<std::pair<std::string, std::string>>{
           {"ot", "x.bt"}, {"ot", "x.ply"}, {"color_ot", "z.ply"}, {"ply", "y.ot"}}) {
    EXPECT_THROW(parseMapFormat(format, path), MapIoError) << format << " " << path;
  }
  EXPECT_EQ(parseMapFormat("ot", "x.map"), MapFormat::kSemanticOt);
  EXPECT_EQ(parseMapFormat("color_ot", "x.ot"), MapFormat::kColorOt);
  EXPECT_EQ(parseMapFormat("ply", "x"), MapFormat::kPly);
}

// A tool's map and its exports appear together or not at all.
TEST(SemanticOcTreeIo, SeveralFormatsAreWrittenAsASet) {
  SemanticOcTree tree = makeRandomMap(3);
  const std::string dir = test::makeTempDir("map_set");
  std::filesystem::create_directories(dir + "/blocked.ply");
  EXPECT_THROW(saveMaps(tree, {{dir + "/map.ot", MapFormat::kSemanticOt},
                               {dir + "/blocked.ply", MapFormat::kPly}}),
               MapIoError);
  EXPECT_FALSE(std::filesystem::exists(dir + "/map.ot"));
  // A tool's other outputs staged with the map (semantic_map_offline's grids): one that cannot
  // be written, and the map is not written either.
  EXPECT_THROW(saveMaps(tree, {{dir + "/map.ot", MapFormat::kSemanticOt}},
                        [&](common::AtomicFileSet* files) {
                          files->addStream(dir + "/no_such_folder/grid.pgm",
                                           [](std::ostream& out) { out << "P5"; });
                        }),
               MapIoError);
  EXPECT_FALSE(std::filesystem::exists(dir + "/map.ot"));
  const std::vector<std::size_t> counts = saveMaps(
      tree, {{dir + "/map.ot", MapFormat::kSemanticOt}, {dir + "/map.ply", MapFormat::kPly}});
  ASSERT_EQ(counts.size(), 2u);
  EXPECT_EQ(counts[0], saveMap(tree, dir + "/again.ot", MapFormat::kSemanticOt));
  EXPECT_EQ(counts[1], countOccupiedFinestVoxels(tree));
  EXPECT_EQ(loadSemanticOcTree(dir + "/map.ot")->size(), tree.size());
  std::size_t entries = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir))
    entries += !entry.path().empty();
  EXPECT_EQ(entries, 4u);  // blocked.ply, map.ot, map.ply, again.ot: no temporaries
  std::filesystem::remove_all(dir);
}

// ---------------------------------------------------------------------------------------------
// Fusion target: a ray-cast scene (ground, building, car, pole, vegetation), 4 scans from
// different poses, 20 % of the point labels replaced by a random other class of the scene.
// ---------------------------------------------------------------------------------------------
struct Box {
  Eigen::Vector3f min, max;
  std::uint32_t label;
};

// Nearest intersection of a ray with the boxes (slab method); -1 if none within max_t.
int castRay(const std::vector<Box>& boxes, const Eigen::Vector3f& origin,
            const Eigen::Vector3f& direction, float max_t, float* hit_t) {
  int best = -1;
  float best_t = max_t;
  for (std::size_t b = 0; b < boxes.size(); ++b) {
    float t_near = 0.f, t_far = best_t;
    bool miss = false;
    for (int axis = 0; axis < 3 && !miss; ++axis) {
      const float inv = 1.f / direction[axis];
      float t0 = (boxes[b].min[axis] - origin[axis]) * inv;
      float t1 = (boxes[b].max[axis] - origin[axis]) * inv;
      if (t0 > t1) std::swap(t0, t1);
      t_near = std::max(t_near, t0);
      t_far = std::min(t_far, t1);
      miss = t_near > t_far;
    }
    if (!miss && t_near < best_t) {
      best_t = t_near;
      best = static_cast<int>(b);
    }
  }
  *hit_t = best_t;
  return best;
}

TEST(SemanticOcTreeFusion, NoisyLabelsFuseToHighVoxelMiou) {
  const std::vector<Box> scene = {
      {{-10, -10, -0.5f}, {10, 10, -0.1f}, cs::kRoad},
      {{9, -10, -0.1f}, {12, 10, 8}, cs::kBuilding},
      {{3, 3, -0.1f}, {7.5f, 5, 1.5f}, cs::kCar},
      {{4, -4.2f, -0.1f}, {4.3f, -3.9f, 5}, cs::kPole},
      {{-8, -9, -0.1f}, {2, -6, 3}, cs::kVegetation},
  };
  std::vector<std::uint32_t> scene_labels;
  for (const Box& box : scene) scene_labels.push_back(box.label);
  const float resolution = 0.2f;
  SemanticOcTree tree(resolution, ClassSet::cityscapes(), FusionModel());

  std::mt19937 rng(42);
  std::uniform_real_distribution<float> uniform(0.f, 1.f);
  std::uniform_int_distribution<int> other(0, static_cast<int>(scene.size()) - 2);
  std::map<octomap::OcTreeKey, std::map<std::uint32_t, int>,
           bool (*)(const octomap::OcTreeKey&, const octomap::OcTreeKey&)>
      truth_votes([](const octomap::OcTreeKey& x, const octomap::OcTreeKey& y) {
        return std::tie(x[0], x[1], x[2]) < std::tie(y[0], y[1], y[2]);
      });
  std::map<std::uint32_t, std::array<double, 3>> point_stats;  // tp, fp, fn per class
  const std::vector<Eigen::Vector3f> sensor_positions = {
      {0, 0, 1.7f}, {2, -1, 1.7f}, {-3, 1, 1.7f}, {1, 6, 1.7f}};
  for (const Eigen::Vector3f& origin : sensor_positions) {
    LabeledScan scan;
    std::vector<Eigen::Vector3f> points;
    for (float elevation_deg = -24.f; elevation_deg <= 4.f; elevation_deg += 0.4f) {
      for (float azimuth_deg = 0.f; azimuth_deg < 360.f; azimuth_deg += 0.2f) {
        const float el = elevation_deg * static_cast<float>(M_PI) / 180.f;
        const float az = azimuth_deg * static_cast<float>(M_PI) / 180.f;
        const Eigen::Vector3f direction(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az),
                                        std::sin(el));
        float t = 0;
        const int hit = castRay(scene, origin, direction, 30.f, &t);
        if (hit < 0) continue;
        const Eigen::Vector3f point = origin + t * direction;
        const std::uint32_t truth = scene[hit].label;
        std::uint32_t observed = truth;
        if (uniform(rng) < 0.2f) {
          int pick = other(rng);
          if (pick >= hit) ++pick;
          observed = scene[pick].label;
        }
        points.push_back(point);
        scan.label_ids.push_back(observed);
        ++truth_votes[tree.coordToKey(octomap::point3d(point.x(), point.y(), point.z()))][truth];
        if (observed == truth) {
          point_stats[truth][0] += 1;
        } else {
          point_stats[observed][1] += 1;
          point_stats[truth][2] += 1;
        }
      }
    }
    scan.points_map.resize(3, static_cast<Eigen::Index>(points.size()));
    for (std::size_t i = 0; i < points.size(); ++i) scan.points_map.col(i) = points[i];
    scan.sensor_origin_map = origin;
    tree.insertLabeledScan(scan, 30.0);
  }

  // Voxel IoU: ground truth = majority true label of the points in a voxel; prediction = most
  // likely class of the map's occupied voxel. Map voxels occupied where no point fell count as
  // false positives; ground-truth voxels the map holds as free are counted apart (occupancy).
  std::size_t ground_truth_voxels_not_occupied = 0;
  std::map<std::uint32_t, std::array<double, 3>> voxel_stats;
  std::set<octomap::OcTreeKey, bool (*)(const octomap::OcTreeKey&, const octomap::OcTreeKey&)>
      counted(truth_votes.key_comp());
  for (const auto& [key, votes] : truth_votes) {
    const std::uint32_t truth =
        std::max_element(votes.begin(), votes.end(), [](const auto& x, const auto& y) {
          return x.second < y.second;
        })->first;
    const SemanticOcTreeNode* node = tree.search(key);
    const bool occupied = node && tree.isNodeOccupied(node);
    const std::uint32_t predicted = occupied ? tree.mostLikelyLabel(*node, 0) : 0xFFFF;
    counted.insert(key);
    if (!occupied) {
      // Carved by rays of other scans (grazing ground, box edges): an occupancy question,
      // reported as recall below, not a labeling error.
      ++ground_truth_voxels_not_occupied;
      continue;
    }
    if (predicted == truth) {
      voxel_stats[truth][0] += 1;
    } else {
      voxel_stats[truth][2] += 1;
      voxel_stats[predicted][1] += 1;
    }
  }
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    if (!tree.isNodeOccupied(*it) || counted.count(it.getKey())) continue;
    voxel_stats[tree.mostLikelyLabel(*it, 0)][1] += 1;  // occupied where nothing was seen
  }
  auto meanIou = [&](const std::map<std::uint32_t, std::array<double, 3>>& stats,
                     const char* what) {
    double sum = 0;
    for (std::uint32_t label : scene_labels) {
      const auto& s = stats.at(label);
      const double iou = s[0] / (s[0] + s[1] + s[2]);
      std::cout << "  " << what << " IoU " << cs::labelName(label) << ": " << iou << " (tp " << s[0]
                << ", fp " << s[1] << ", fn " << s[2] << ")\n";
      sum += iou;
    }
    return sum / scene_labels.size();
  };
  const double point_miou = meanIou(point_stats, "per-point input");
  const double voxel_miou = meanIou(voxel_stats, "fused voxel");
  std::cout << "per-point input mIoU " << point_miou << ", fused voxel mIoU " << voxel_miou << " ("
            << truth_votes.size() << " ground-truth voxels, occupancy recall "
            << 1.0 - static_cast<double>(ground_truth_voxels_not_occupied) / truth_votes.size()
            << ")\n";
  EXPECT_GE(voxel_miou, 0.90);
  EXPECT_GE(voxel_miou - point_miou, 0.10);
  EXPECT_LE(ground_truth_voxels_not_occupied, truth_votes.size() / 5);
}

LabeledScan pointsScan(const std::vector<Eigen::Vector3f>& points, const Eigen::Vector3f& origin,
                       std::uint32_t label) {
  LabeledScan scan;
  scan.points_map.resize(3, static_cast<Eigen::Index>(points.size()));
  for (std::size_t i = 0; i < points.size(); ++i) scan.points_map.col(i) = points[i];
  scan.label_ids.assign(points.size(), label);
  scan.sensor_origin_map = origin;
  return scan;
}

// A new obstacle inside free space already clamped (and pruned) must still be hit.
TEST(SemanticOcTree, AHitInAClampedFreeBlockIsApplied) {
  SemanticOcTree tree(0.2);
  std::vector<Eigen::Vector3f> wall;
  for (float y = -1.f; y <= 1.f; y += 0.025f)
    for (float z = -1.f; z <= 1.f; z += 0.025f) wall.emplace_back(5.05f, y, z);
  const Eigen::Vector3f origin(0.01f, 0.01f, 0.01f);
  for (int i = 0; i < 10; ++i) tree.insertLabeledScan(pointsScan(wall, origin, cs::kBuilding), 0.0);
  const octomap::point3d target(2.5f, 0.1f, 0.1f);
  const SemanticOcTreeNode* before = tree.search(target);
  ASSERT_NE(before, nullptr);
  ASSERT_LE(before->getLogOdds(), tree.getClampingThresMinLog() + 1e-6f);
  tree.insertLabeledScan(pointsScan({Eigen::Vector3f(2.5f, 0.1f, 0.1f)}, origin, cs::kCar), 0.0);
  const SemanticOcTreeNode* after = tree.search(target);
  ASSERT_NE(after, nullptr);
  EXPECT_GT(after->getLogOdds(), tree.getClampingThresMinLog() + 0.5f);
  EXPECT_EQ(after->totalCount(), 1u);
}

// addClassEvidence(scan) labels occupied voxels only.
TEST(SemanticOcTree, ClassEvidenceGoesToOccupiedVoxelsOnly) {
  SemanticOcTree tree(0.2);
  tree.updateNode(octomap::point3d(1.1f, 1.1f, 1.1f), false);
  tree.updateNode(octomap::point3d(3.1f, 1.1f, 1.1f), true);
  const LabeledScan scan = pointsScan(
      {Eigen::Vector3f(1.1f, 1.1f, 1.1f), Eigen::Vector3f(3.1f, 1.1f, 1.1f)}, {0, 0, 0}, cs::kCar);
  EXPECT_EQ(tree.addClassEvidence(scan), 1u);
  EXPECT_EQ(tree.search(1.1, 1.1, 1.1)->totalCount(), 0u);
  EXPECT_EQ(tree.search(3.1, 1.1, 1.1)->totalCount(), 1u);
}

// A nearly level ray to a wall 20 m away loses at most a quarter of its length to the grazing
// truncation (here 0.2 m / sin(1.15 deg) = 10 m uncapped): it still clears out to 15 m.
TEST(SemanticOcTree, GrazingTruncationIsCappedOnNearlyLevelRays) {
  SemanticOcTree tree(0.2);
  tree.setGrazingRayTruncation(1.0);
  tree.insertLabeledScan(pointsScan({Eigen::Vector3f(20.1f, 0.1f, 0.1f)},
                                    Eigen::Vector3f(0.1f, 0.1f, 0.5f), cs::kBuilding),
                         0.0);
  const SemanticOcTreeNode* at_12m = tree.search(12.1, 0.1, 0.26);
  ASSERT_NE(at_12m, nullptr);
  EXPECT_FALSE(tree.isNodeOccupied(at_12m));
}
}  // namespace
}  // namespace mapping
}  // namespace inekf_semantic_mapping
