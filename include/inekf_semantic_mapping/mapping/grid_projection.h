// 2D grids projected from a SemanticOcTree, what octomap_server users expect from a map node:
//
// - the projected map (octomap_server's projected_map): a cell is occupied (100) when an
//   occupied voxel overlaps the height band [min_z, max_z] above the ground, free (0) when only
//   free voxels overlap it, unknown (-1) when the map knows nothing of that band there.
//   octomap_server tests a voxel's extent against occupancy_min_z / occupancy_max_z, absolute
//   heights in its frame; here the band is measured from the ground under the cell, so that a
//   drive that climbs a hill keeps the road out of the band and the cars in it.
// - the drivable map: what the surface of the cell is. The topmost occupied voxel with class
//   evidence that overlaps the ground band [ground_min_z, min_z] names the surface; a
//   drivable class (drivable_classes, e.g. road and parking) makes the cell free (0) unless the
//   projected map holds an obstacle there; any other class (sidewalk unless chosen, vegetation,
//   building) or an obstacle makes it occupied (100); no classed ground voxel leaves it unknown
//   (-1), also where the map saw free space only (free air says nothing about the surface).
//
// The ground, on a raster 8 cells coarse: where a raster cell holds drivable voxels (at least 3
// of its 64 columns), the lowest of them; elsewhere the vehicle's path (each ground sample is a
// point on the road under the sensor: sensor origin minus its height above the road); every other
// cell takes the height of its nearest such cell. The road found in the map carries the ground
// into side streets that climb away from the path; the path covers what has no road class
// (lidar-only maps). Without either, the plane z = ground_z of the map frame (octomap_server's
// convention).
//
// Cells are the tree's voxels seen from above (resolution = tree resolution, aligned with its
// keys) over the bounds of the map's known space. Pruned leaves (coarser than the finest depth)
// fill every cell they cover and are tested with their full height. ROS-free, octomap only in
// the .cpp.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

namespace inekf_semantic_mapping {
namespace common {
class AtomicFileSet;
}  // namespace common
}  // namespace inekf_semantic_mapping

namespace YAML {
class Node;
}

namespace inekf_semantic_mapping {
namespace mapping {

class SemanticOcTree;
class ClassSet;

struct GridProjectionConfig {
  // Obstacle band above the ground (m), both grids.
  double min_z = 0.5;
  double max_z = 2.0;
  // Lower end of the ground band [ground_min_z, min_z] where the drivable grid looks for the
  // surface's class (m above the ground).
  double ground_min_z = -1.0;
  // Class names (of the map's class set) a vehicle may drive on.
  std::vector<std::string> drivable_classes = {"road", "parking"};
  // Height of the lidar above the road (m): ground samples = sensor origins minus this (KITTI's
  // HDL-64: 1.73 m).
  double sensor_height = 1.73;
  // The ground plane (map frame z, m) while there are no ground samples.
  double ground_z = 0.0;

  // Throws std::invalid_argument naming the key of the first bad value.
  void validate() const;
};

// Reads the grid.* keys of a semantic_mapping.yaml map (other keys are left alone); bad values
// throw common::ConfigError naming `source` and the key.
GridProjectionConfig readGridProjectionConfig(const YAML::Node& root, const std::string& source);

// Cell values of nav_msgs/OccupancyGrid.
constexpr std::int8_t kGridUnknown = -1;
constexpr std::int8_t kGridFree = 0;
constexpr std::int8_t kGridOccupied = 100;

// A row-major grid (cell (ix, iy) at cells[iy * width + ix]), nav_msgs/OccupancyGrid's layout;
// origin is the corner of cell (0, 0) in the map frame; origin_z, the lowest ground height, is
// only where a viewer draws the grid (below the map rather than through it).
struct Grid2D {
  int width = 0;
  int height = 0;
  double resolution = 0.0;
  double origin_x = 0.0;
  double origin_y = 0.0;
  double origin_z = 0.0;
  std::vector<std::int8_t> cells;

  std::int8_t at(int ix, int iy) const { return cells[static_cast<std::size_t>(iy) * width + ix]; }
  // The cell of map point (x, y); false outside the grid.
  bool cellOf(double x, double y, int* ix, int* iy) const;
};

struct ProjectedGrids {
  Grid2D occupancy;  // the projected map
  Grid2D drivable;   // the drivable map (same geometry)
};

// Both grids from the leaves of `tree` (its inner nodes need not be up to date). ground_samples:
// points on the ground (map frame), e.g. a GroundTrace's samples. Throws
// std::invalid_argument when a drivable class is not in the tree's class set (naming it),
// std::runtime_error when the known space spans more than 2^26 cells.
ProjectedGrids projectGrids(const SemanticOcTree& tree, const GridProjectionConfig& config,
                            const std::vector<Eigen::Vector3d>& ground_samples);

// Accumulates the ground under a sensor path, one sample per `spacing` metres travelled (a
// vehicle that stands still adds nothing).
class GroundTrace {
 public:
  explicit GroundTrace(double sensor_height, double spacing = 0.5)
      : sensor_height_(sensor_height), spacing_(spacing) {}
  void addSensorOrigin(const Eigen::Vector3d& origin_map);
  const std::vector<Eigen::Vector3d>& samples() const { return samples_; }
  void clear() { samples_.clear(); }

 private:
  double sensor_height_;
  double spacing_;
  std::vector<Eigen::Vector3d> samples_;
};

// map_server's format: `<stem>.pgm` (free 254, occupied 0, unknown 205, top row = largest y)
// and `<stem>.yaml` (image (quoted), resolution, origin, negate, thresholds), written as one set:
// both or neither. Returns the two paths written (mapServerGridPaths).
std::vector<std::string> writeMapServerGrid(const Grid2D& grid, const std::string& stem);
// The same two files staged in `files`, which the caller commits with its other outputs.
std::vector<std::string> addMapServerGrid(const Grid2D& grid, const std::string& stem,
                                          common::AtomicFileSet* files);
// The two files writeMapServerGrid writes for `stem`: {stem.pgm, stem.yaml}.
std::vector<std::string> mapServerGridPaths(const std::string& stem);

}  // namespace mapping
}  // namespace inekf_semantic_mapping
