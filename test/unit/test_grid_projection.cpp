// Grid projection (projected map and drivable map) on small hand-made trees: the edges of the
// height band, pruned (coarser) leaves, unknown vs free, the ground from path samples and road
// voxels, the class that names a cell's surface, the config keys and the map_server files.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "inekf_semantic_mapping/common/yaml_reader.h"
#include "inekf_semantic_mapping/mapping/grid_projection.h"
#include "inekf_semantic_mapping/mapping/semantic_octree.h"
#include "inekf_semantic_mapping/perception/cityscapes.h"
#include "test_data.h"

namespace inekf_semantic_mapping {
namespace mapping {
namespace {

namespace cs = cityscapes;

// 0.25 m: voxel edges are exact binary fractions, so a voxel that touches a band edge touches
// it exactly.
constexpr double kRes = 0.25;

class GridProjectionTest : public ::testing::Test {
 protected:
  GridProjectionTest() : tree_(kRes, ClassSet::cityscapes(), FusionModel()) {
    config_.min_z = 0.5;
    config_.max_z = 2.0;
    config_.ground_min_z = -1.0;
    config_.ground_z = 0.0;
    config_.drivable_classes = {"road", "parking"};
  }

  // The voxel whose lower corner is (x, y, z) (multiples of kRes).
  octomap::OcTreeKey key(double x, double y, double z) const {
    return tree_.coordToKey(octomap::point3d(x + kRes / 2, y + kRes / 2, z + kRes / 2));
  }
  void occupied(double x, double y, double z, std::uint32_t label) {
    tree_.updateOccupiedVoxel(key(x, y, z), tree_.classSet().indexOf(label), 1);
  }
  void occupiedNoClass(double x, double y, double z) { tree_.updateNode(key(x, y, z), true); }
  void free(double x, double y, double z) { tree_.updateNode(key(x, y, z), false); }

  std::int8_t cell(const Grid2D& grid, double x, double y) const {
    int ix = 0, iy = 0;
    EXPECT_TRUE(grid.cellOf(x + kRes / 2, y + kRes / 2, &ix, &iy)) << x << ", " << y;
    return grid.at(ix, iy);
  }

  ProjectedGrids project(const std::vector<Eigen::Vector3d>& samples = {}) const {
    return projectGrids(tree_, config_, samples);
  }

  SemanticOcTree tree_;
  GridProjectionConfig config_;
};

int leavesAtDepth(const SemanticOcTree& tree, unsigned int depth) {
  int count = 0;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    if (it.getDepth() == depth) ++count;
  }
  return count;
}

TEST_F(GridProjectionTest, BandEdgesFollowOctomapServer) {
  // Each column x = i: what lies where (band [0.5, 2.0] above the plane z = 0).
  occupied(0, 0, 0.25, cs::kBuilding);  // [0.25, 0.5]: touches the lower edge only
  free(0, 0, 0.5);                      // [0.5, 0.75]: inside -> free
  occupied(1, 0, 0.5, cs::kBuilding);   // [0.5, 0.75]: inside
  occupied(2, 0, 2.0, cs::kBuilding);   // [2.0, 2.25]: touches the upper edge only
  occupied(3, 0, 1.75, cs::kBuilding);  // [1.75, 2.0]: inside
  free(4, 0, 1.0);                      // free and occupied in the band: occupied wins
  occupied(4, 0, 1.25, cs::kBuilding);
  free(4, 0, 1.5);
  free(5, 0, 0.0);  // free below the band only: the band is unknown
  const Grid2D grid = project().occupancy;
  EXPECT_EQ(cell(grid, 0, 0), kGridFree);
  EXPECT_EQ(cell(grid, 1, 0), kGridOccupied);
  EXPECT_EQ(cell(grid, 2, 0), kGridUnknown);
  EXPECT_EQ(cell(grid, 3, 0), kGridOccupied);
  EXPECT_EQ(cell(grid, 4, 0), kGridOccupied);
  EXPECT_EQ(cell(grid, 5, 0), kGridUnknown);
  // Cells between the columns were never seen.
  EXPECT_EQ(cell(grid, 0.5, 0), kGridUnknown);
}

TEST_F(GridProjectionTest, GridCoversTheKnownSpaceAtTheTreeResolution) {
  occupied(-2, 1, 1.0, cs::kBuilding);
  free(3, -1.5, 0.0);
  const Grid2D grid = project().occupancy;
  EXPECT_EQ(grid.resolution, kRes);
  EXPECT_EQ(grid.width, static_cast<int>((3 - -2) / kRes) + 1);
  EXPECT_EQ(grid.height, static_cast<int>((1 - -1.5) / kRes) + 1);
  EXPECT_DOUBLE_EQ(grid.origin_x, -2.0);
  EXPECT_DOUBLE_EQ(grid.origin_y, -1.5);
  EXPECT_EQ(grid.cells.size(), static_cast<std::size_t>(grid.width) * grid.height);
  EXPECT_EQ(cell(grid, -2, 1), kGridOccupied);
  EXPECT_EQ(grid.at(0, grid.height - 1), kGridOccupied);  // row-major, row 0 = smallest y
}

TEST_F(GridProjectionTest, PrunedLeavesFillEveryCellAndCountWithTheirFullHeight) {
  // A 2x2x2 block of identical voxels at z [0.0, 0.5] collapses into one leaf one level up
  // whose centre (0.25) is below min_z = 0.4 but whose top (0.5) is in the band.
  config_.min_z = 0.4;
  for (double x : {0.0, kRes}) {
    for (double y : {0.0, kRes}) {
      for (double z : {0.0, kRes}) occupied(x, y, z, cs::kCar);
    }
  }
  // A 4x4x4 free block beside it (two levels up) at z [1.0, 2.0].
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < 4; ++j) {
      for (int k = 0; k < 4; ++k) free(2 + i * kRes, j * kRes, 1.0 + k * kRes);
    }
  }
  tree_.prune();
  ASSERT_EQ(leavesAtDepth(tree_, 15), 1);
  ASSERT_EQ(leavesAtDepth(tree_, 14), 1);
  ASSERT_EQ(leavesAtDepth(tree_, 16), 0);
  const Grid2D grid = project().occupancy;
  for (double x : {0.0, kRes}) {
    for (double y : {0.0, kRes}) EXPECT_EQ(cell(grid, x, y), kGridOccupied) << x << " " << y;
  }
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < 4; ++j) EXPECT_EQ(cell(grid, 2 + i * kRes, j * kRes), kGridFree);
  }
  EXPECT_EQ(cell(grid, 0.5, 0), kGridUnknown);
}

TEST_F(GridProjectionTest, DrivableCellsTakeTheClassOfTheTopmostGroundVoxel) {
  // Columns 2 m apart: each in its own ground raster cell, none with enough drivable columns to
  // move the ground from the plane z = 0.
  occupied(0, 0, -0.25, cs::kRoad);  // road: drivable
  free(0, 0, 0.5);
  occupied(2, 0, -0.25, cs::kParking);   // parking: drivable (chosen)
  occupied(4, 0, -0.25, cs::kSidewalk);  // sidewalk: not chosen -> occupied
  occupied(6, 0, -0.25, cs::kRoad);      // a car on the road: occupied
  occupied(6, 0, 0.75, cs::kCar);
  occupied(8, 0, -0.5, cs::kRoad);  // road under a sidewalk slab (curb edge): the top wins
  occupied(8, 0, 0.0, cs::kSidewalk);
  occupied(10, 0, -0.5, cs::kSidewalk);  // and the other way round
  occupied(10, 0, 0.0, cs::kRoad);
  occupiedNoClass(12, 0, -0.25);      // a ground voxel without class: unknown
  free(14, 0, 0.0);                   // free space says nothing about the surface
  occupied(16, 0, -1.5, cs::kRoad);   // below the ground band: unknown
  occupied(18, 0, -0.25, cs::kRoad);  // a tree crown above max_z does not block the road
  occupied(18, 0, 3.0, cs::kVegetation);
  const ProjectedGrids grids = project();
  const Grid2D& d = grids.drivable;
  EXPECT_EQ(cell(d, 0, 0), kGridFree);
  EXPECT_EQ(cell(d, 2, 0), kGridFree);
  EXPECT_EQ(cell(d, 4, 0), kGridOccupied);
  EXPECT_EQ(cell(d, 6, 0), kGridOccupied);
  EXPECT_EQ(cell(d, 8, 0), kGridOccupied);
  EXPECT_EQ(cell(d, 10, 0), kGridFree);
  EXPECT_EQ(cell(d, 12, 0), kGridUnknown);
  EXPECT_EQ(cell(d, 14, 0), kGridUnknown);
  EXPECT_EQ(cell(d, 16, 0), kGridUnknown);
  EXPECT_EQ(cell(d, 18, 0), kGridFree);
  EXPECT_EQ(cell(grids.occupancy, 18, 0), kGridUnknown);
  // Same geometry for both grids.
  EXPECT_EQ(d.width, grids.occupancy.width);
  EXPECT_EQ(d.origin_x, grids.occupancy.origin_x);

  // The classes come from the config.
  config_.drivable_classes = {"road", "sidewalk"};
  const Grid2D with_sidewalk = project().drivable;
  EXPECT_EQ(cell(with_sidewalk, 2, 0), kGridOccupied);  // parking no longer
  EXPECT_EQ(cell(with_sidewalk, 4, 0), kGridFree);
  EXPECT_EQ(cell(with_sidewalk, 8, 0), kGridFree);
}

TEST_F(GridProjectionTest, UnknownDrivableClassIsAnErrorNamingIt) {
  occupied(0, 0, 0, cs::kRoad);
  config_.drivable_classes = {"road", "rood"};
  try {
    project();
    FAIL() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'rood'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("grid.drivable_classes"), std::string::npos);
  }
}

TEST_F(GridProjectionTest, GroundFollowsThePathSamples) {
  // A hill: the path is at z = 0 near x = -10 and at z = 5 near x = +10. The road on the hill
  // and a car on it are judged from the hill's ground, not from z = 0.
  occupied(-10, 0, -0.25, cs::kRoad);
  occupied(-10, 1, 0.75, cs::kCar);
  occupied(10, 0, 4.75, cs::kRoad);
  occupied(10, 1, 5.75, cs::kCar);
  const std::vector<Eigen::Vector3d> samples = {{-10, 0.5, 0.0}, {10, 0.5, 5.0}};
  const ProjectedGrids grids = project(samples);
  EXPECT_DOUBLE_EQ(grids.occupancy.origin_z, 0.0);  // drawn at the lowest ground
  EXPECT_EQ(cell(grids.drivable, -10, 0), kGridFree);
  EXPECT_EQ(cell(grids.occupancy, -10, 1), kGridOccupied);
  EXPECT_EQ(cell(grids.drivable, 10, 0), kGridFree);
  EXPECT_EQ(cell(grids.occupancy, 10, 1), kGridOccupied);
  // Against the plane z = 0 the hill's road is out of the ground band and its car above the
  // obstacle band.
  const ProjectedGrids flat = project();
  EXPECT_EQ(cell(flat.drivable, 10, 0), kGridUnknown);
  EXPECT_EQ(cell(flat.occupancy, 10, 1), kGridUnknown);
}

TEST_F(GridProjectionTest, RoadVoxelsDefineTheGroundWhereThereAreEnough) {
  // A road 4.875 m up (voxel centres), 3 columns of one 2 m raster cell, a car on it; the path
  // sample beside it (and the plane z = 0) would put both out of their bands.
  for (double x : {0.0, kRes, 2 * kRes}) occupied(x, 0, 4.75, cs::kRoad);
  occupied(1.0, 0.25, 5.75, cs::kCar);
  const std::vector<Eigen::Vector3d> samples = {{1.0, 1.0, 0.0}};
  for (const auto& ground : {std::vector<Eigen::Vector3d>{}, samples}) {
    const ProjectedGrids grids = project(ground);
    EXPECT_DOUBLE_EQ(grids.drivable.origin_z, 4.875);
    EXPECT_EQ(cell(grids.drivable, 0, 0), kGridFree);
    EXPECT_EQ(cell(grids.occupancy, 1.0, 0.25), kGridOccupied);
  }
  // Two columns are not enough (a few mislabelled voxels do not move the ground).
  tree_.clear();
  for (double x : {0.0, kRes}) occupied(x, 0, 4.75, cs::kRoad);
  occupied(1.0, 0.25, 5.75, cs::kCar);
  const ProjectedGrids few = project(samples);
  EXPECT_EQ(cell(few.drivable, 0, 0), kGridUnknown);
  EXPECT_EQ(cell(few.occupancy, 1.0, 0.25), kGridUnknown);
}

// Without a path sample or enough road to seed it, the ground is the plane ground_z (a map shown
// in the sensor's frame, the ground below it), not z = 0.
TEST_F(GridProjectionTest, WithoutSeedsTheGroundIsThePlaneGroundZ) {
  config_.ground_z = -2.0;
  occupied(0, 0, -2.25, cs::kRoad);  // one column of road: no seed, its top on the plane
  occupied(1, 0, -1.25, cs::kCar);   // 0.75 m above the plane
  const ProjectedGrids grids = project();
  EXPECT_DOUBLE_EQ(grids.occupancy.origin_z, -2.0);
  EXPECT_EQ(cell(grids.drivable, 0, 0), kGridFree);
  EXPECT_EQ(cell(grids.occupancy, 1, 0), kGridOccupied);
}

TEST(GridProjection, TooLargeKnownSpaceIsRefusedBeforeAllocating) {
  SemanticOcTree tree(0.2, ClassSet::cityscapes(), FusionModel());
  tree.updateNode(octomap::point3d(0, 0, 0), true);
  tree.updateNode(octomap::point3d(500, 500, 0), true);  // 2500 x 2500 cells: fine
  EXPECT_EQ(projectGrids(tree, GridProjectionConfig(), {}).occupancy.width, 2501);
  tree.updateNode(octomap::point3d(2000, 2000, 0), true);  // 10^8 cells
  EXPECT_THROW(projectGrids(tree, GridProjectionConfig(), {}), std::runtime_error);
}

TEST(GroundTrace, OneSamplePerSpacingBelowTheSensor) {
  GroundTrace trace(1.73, 0.5);
  trace.addSensorOrigin({0, 0, 2});
  trace.addSensorOrigin({0.2, 0, 2});  // too close
  trace.addSensorOrigin({0.6, 0, 2.1});
  ASSERT_EQ(trace.samples().size(), 2u);
  EXPECT_TRUE(trace.samples()[0].isApprox(Eigen::Vector3d(0, 0, 2 - 1.73)));
  EXPECT_TRUE(trace.samples()[1].isApprox(Eigen::Vector3d(0.6, 0, 2.1 - 1.73)));
  trace.clear();
  EXPECT_TRUE(trace.samples().empty());
}

TEST(GridProjectionConfig, TheShippedYamlHoldsTheDefaults) {
  const std::string path = test::repoPath("config/semantic_mapping.yaml");
  const GridProjectionConfig from_yaml = readGridProjectionConfig(YAML::LoadFile(path), path);
  const GridProjectionConfig defaults;
  EXPECT_EQ(from_yaml.min_z, defaults.min_z);
  EXPECT_EQ(from_yaml.max_z, defaults.max_z);
  EXPECT_EQ(from_yaml.ground_min_z, defaults.ground_min_z);
  EXPECT_EQ(from_yaml.drivable_classes, defaults.drivable_classes);
  EXPECT_EQ(from_yaml.sensor_height, defaults.sensor_height);
  EXPECT_EQ(from_yaml.ground_z, defaults.ground_z);
  // Every key of the section is in the file (a default that only the struct knows is hidden).
  const YAML::Node grid = YAML::LoadFile(path)["grid"];
  ASSERT_TRUE(grid.IsMap());
  for (const char* key : {"min_z_m", "max_z_m", "ground_min_z_m", "drivable_classes",
                          "sensor_height_m", "ground_z_m"}) {
    EXPECT_TRUE(grid[key].IsDefined()) << key;
  }
}

TEST(GridProjectionConfig, ErrorsNameTheSourceAndTheKey) {
  const auto message = [](const std::string& yaml) {
    try {
      readGridProjectionConfig(YAML::Load(yaml), "test.yaml");
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message("grid: {mn_z: 0.2}").find("test.yaml: key 'grid.mn_z' is not a known key"),
            std::string::npos);
  EXPECT_NE(message("grid: {min_z_m: 2.0, max_z_m: 1.0}").find("test.yaml: grid.max_z_m"),
            std::string::npos);
  EXPECT_NE(message("grid: {drivable_classes: road}").find("'grid.drivable_classes'"),
            std::string::npos);
  EXPECT_NE(message("grid: {drivable_classes: []}").find("grid.drivable_classes"),
            std::string::npos);
  EXPECT_NE(message("grid: {min_z_m: high}").find("'grid.min_z_m' is not a number"),
            std::string::npos);
  // The rest of the file is another reader's.
  EXPECT_EQ(message("resolution_m: 0.1\nsensor_model: {hit: 0.7}\ngrid: {max_z_m: 3.0}"),
            "no error");
  // The names before the unit suffix: still read, with a warning; both names: an error.
  const GridProjectionConfig old_names = readGridProjectionConfig(
      YAML::Load("grid: {min_z: 0.4, sensor_height: 2.0, ground_z: -3.0}"), "old.yaml");
  EXPECT_DOUBLE_EQ(old_names.min_z, 0.4);
  EXPECT_DOUBLE_EQ(old_names.sensor_height, 2.0);
  EXPECT_DOUBLE_EQ(old_names.ground_z, -3.0);
  EXPECT_NE(message("grid: {max_z: 3.0, max_z_m: 2.5}").find("which is set too"),
            std::string::npos);
}

TEST(MapServerGrid, WritesPgmTopRowFirstAndItsYaml) {
  Grid2D grid;
  grid.width = 3;
  grid.height = 2;
  grid.resolution = 0.5;
  grid.origin_x = -1.25;
  grid.origin_y = 4.0;
  grid.cells = {kGridFree,     kGridOccupied, kGridUnknown,  // row y = 0
                kGridOccupied, kGridUnknown,  kGridFree};    // row y = 1
  const std::string dir = test::makeTempDir("grid_projection_pgm");
  const auto paths = writeMapServerGrid(grid, dir + "/map");
  ASSERT_EQ(paths.size(), 2u);
  std::ifstream pgm(dir + "/map.pgm", std::ios::binary);
  std::string magic;
  int w = 0, h = 0, maxval = 0;
  pgm >> magic >> w >> h >> maxval;
  pgm.get();
  EXPECT_EQ(magic, "P5");
  EXPECT_EQ(w, 3);
  EXPECT_EQ(h, 2);
  EXPECT_EQ(maxval, 255);
  std::string pixels(6, '\0');
  pgm.read(&pixels[0], 6);
  ASSERT_TRUE(pgm);
  const std::vector<int> expected = {0, 205, 254, 254, 0, 205};  // top row is y = 1
  for (int i = 0; i < 6; ++i) EXPECT_EQ(static_cast<unsigned char>(pixels[i]), expected[i]) << i;
  const YAML::Node yaml = YAML::LoadFile(dir + "/map.yaml");
  EXPECT_EQ(yaml["image"].as<std::string>(), "map.pgm");
  EXPECT_EQ(yaml["resolution"].as<double>(), 0.5);
  EXPECT_EQ(yaml["origin"][0].as<double>(), -1.25);
  EXPECT_EQ(yaml["origin"][1].as<double>(), 4.0);
  EXPECT_EQ(yaml["negate"].as<int>(), 0);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace mapping
}  // namespace inekf_semantic_mapping
