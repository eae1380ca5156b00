// mapSequence (semantic_map_offline's core, through a SemanticMappingSession) on a small sequence
// written here: scans land where the pose chain puts them; bad inputs name the file. The tool:
// test/cli/test_semantic_map_offline.cpp; a real drive: test/data/.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "inekf_semantic_mapping/kitti/mercator.h"
#include "inekf_semantic_mapping/kitti/oxts.h"
#include "inekf_semantic_mapping/kitti/poses.h"
#include "inekf_semantic_mapping/mapping/map_io.h"
#include "inekf_semantic_mapping/mapping/offline_mapping.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"
#include "offline_mapping_fixture.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace mapping {
namespace {

TEST_F(OfflineMappingTest, ScansLandWhereThePoseChainPutsThem) {
  auto session = buildMap(options());
  SemanticOcTree* tree = &session->tree();
  // Scan 0 is the map frame: its points stay where they are.
  const SemanticOcTreeNode* first = tree->search(10.05, 0.05, 0.05);
  ASSERT_NE(first, nullptr);
  EXPECT_TRUE(tree->isNodeOccupied(first));
  EXPECT_EQ(tree->mostLikelyLabel(*first, 0), 50u);  // instance bits ignored
  // Scan 1: cam0 moved 3 m along cam z (= velo x) and 1 m along cam x (= velo -y).
  const SemanticOcTreeNode* second = tree->search(13.05, -0.95, 0.05);
  ASSERT_NE(second, nullptr);
  EXPECT_TRUE(tree->isNodeOccupied(second));
  EXPECT_EQ(tree->mostLikelyLabel(*second, 0), 50u);
  // The unknown id got its own class; unlabeled points give occupancy without evidence.
  const SemanticOcTreeNode* other = tree->search(5.05, 4.05, 0.05);
  ASSERT_NE(other, nullptr);
  EXPECT_EQ(tree->mostLikelyLabel(*other, 0), 300u);
  const SemanticOcTreeNode* unlabeled = tree->search(6.05, -3.05, 0.05);
  ASSERT_NE(unlabeled, nullptr);
  EXPECT_TRUE(tree->isNodeOccupied(unlabeled));
  EXPECT_FALSE(unlabeled->hasSemantics());
  EXPECT_NE(tree->classSet().indexOf(300), kNoClass);

  // PLY labels are in the input id space.
  const std::string ply = dir_ + "/map.ply";
  EXPECT_EQ(saveMap(*tree, ply, MapFormat::kPly), 6u);
  std::ifstream in(ply);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find(" 300 "), std::string::npos);
  EXPECT_NE(text.find(" 50 "), std::string::npos);

  OfflineSequence one = options();
  one.max_scans = 1;
  auto single = buildMap(one);
  EXPECT_EQ(single->tree().search(13.05, -0.95, 0.05), nullptr);
}

TEST_F(OfflineMappingTest, BadInputsNameTheFile) {
  writeBinary<std::uint32_t>(dir_ + "/labels/000001.label", {50u, 50u});  // 2 labels, 3 points
  try {
    buildMap(options());
    FAIL() << "expected an error";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("000001.label"), std::string::npos) << e.what();
  }
  std::ofstream(dir_ + "/poses.txt") << "1 0 0 0 0 1 0 0 0 0 1\n";
  try {
    kitti::readKittiPoses(dir_ + "/poses.txt");
    FAIL() << "expected an error";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("poses.txt:1"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace mapping
}  // namespace inekf_semantic_mapping
