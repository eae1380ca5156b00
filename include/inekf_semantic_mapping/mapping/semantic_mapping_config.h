// SemanticMappingConfig: every parameter of a mapping run, read from the keys of
// config/semantic_mapping.yaml. The semantic_octomap_node (its ROS parameters) and
// semantic_map_offline --config read the same keys with the same reader, so a run means the same
// whichever face of SemanticMappingSession starts it.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "inekf_semantic_mapping/mapping/occupancy_model.h"
#include "inekf_semantic_mapping/mapping/semantic_classes.h"

namespace YAML {
class Node;
}

namespace inekf_semantic_mapping {
namespace mapping {

// The class set of the map's labels: the camera networks' (Cityscapes labelIds) or SemanticKITTI's
// lidar labels.
enum class MapClassSet { kCityscapes, kSemanticKitti };
// "cityscapes" | "semantickitti"; throws std::invalid_argument naming the choices otherwise.
MapClassSet parseMapClassSet(const std::string& name);
const char* mapClassSetName(MapClassSet set);
// The classes (label ids and names) a map of that set starts with.
ClassSet classSetOf(MapClassSet set);

// Where scans are inserted: a HashedVoxelGrid, synced into the tree when the tree is asked for
// (save, publish), or the SemanticOcTree itself (insertLabeledScan). The same map
// (test_hashed_voxel_grid); the grid is several times faster.
enum class InsertionStructure { kHashedGrid, kOctree };
// "hashed_grid" | "octree"; throws std::invalid_argument naming the choices otherwise.
InsertionStructure parseInsertionStructure(const std::string& name);
const char* insertionStructureName(InsertionStructure structure);

// Every parameter of a mapping run; the keys of config/semantic_mapping.yaml (the node's ROS
// parameters and semantic_map_offline --config read the same keys with the same reader). Names
// of choices are parsed once, by the reader: the fields hold enums.
struct SemanticMappingConfig {
  double resolution_m = 0.2;
  double max_range_m = 50.0;
  OccupancyModel occupancy;  // sensor_model.hit, .miss, .clamping_min, .clamping_max
  MapClassSet class_set = MapClassSet::kCityscapes;
  FusionModel fusion;
  double grazing_ray_truncation_voxels = 1.0;
  int ray_casting_threads = 1;
  InsertionStructure insertion = InsertionStructure::kHashedGrid;
  // hashed_grid: a free ray stops after this many consecutive voxels that the same scan already
  // cleared (0: never, every ray to the sensor; docs/results.md has what it costs in accuracy).
  int early_ray_termination_voxels = 20;
  // Points outside the camera image: inserted for occupancy (true) or left out (false: the map
  // holds what the camera sees). Without any camera (lidar-only runs) scans go in whole.
  bool insert_points_outside_image = false;
  // Lidar points the camera cannot see (lidar-camera parallax) take no label from the pixel
  // they fall on (perception::rejectOccludedPoints with its measured defaults).
  bool reject_occluded_points = true;
  // Labels the lidar geometry rules out take no class evidence (perception/label_geometry.h):
  // a flat class (road, sidewalk, terrain...) more than label_geometry_max_flat_height_m above
  // the scan's local ground (sensor frame, z up), a traffic sign or light less than
  // label_geometry_min_raised_height_m above it. Cityscapes class set only.
  bool label_geometry_check = true;
  double label_geometry_max_flat_height_m = 0.2;
  double label_geometry_min_raised_height_m = 0.2;
  // ... and terrain above label_geometry_max_flat_height_m counts as vegetation instead.
  bool label_geometry_high_terrain_is_vegetation = true;
  // ... and road beyond a curb on the scan's laser rings counts as sidewalk
  // (perception::markPointsBeyondCurbs: scans in ring order, as KITTI's).
  bool label_geometry_curbs = true;
  // Pairing: a label image belongs to the scan whose stamp is within this tolerance (s).
  double label_stamp_tolerance_s = 0.05;
  // How long (data time, s) a scan waits for its label image before it goes in without one.
  double label_wait_s = 3.0;
  // A scan that goes in without a label image of its own borrows the class evidence of one
  // within this time (s) of it: its map points projected into that image from the sensor's pose
  // at the image's stamp (exact for what does not move). 0: only a scan's own label image.
  double label_neighbour_s = 0.1;
  // How long (data time, s) a scan waits for its pose before it is dropped.
  double pose_wait_s = 1.0;

  // Throws std::invalid_argument naming the key of the first bad value.
  void validate() const;
};

// The keys of the same YAML that semantic_octomap_node reads itself (display, frames, files).
const std::vector<std::string>& semanticMappingNodeKeys();
// Keys that gained their unit (old, new): the old name is still read in this release, with a
// warning naming the new one (common::YamlReader::renamed).
const std::vector<std::pair<std::string, std::string>>& renamedSemanticMappingKeys();

// Reads the keys above from a YAML map (the node's keys are allowed and left alone); unknown keys
// and bad values throw std::invalid_argument (common::ConfigError) naming `source` and the key.
SemanticMappingConfig readSemanticMappingConfig(const YAML::Node& root, const std::string& source);
SemanticMappingConfig loadSemanticMappingConfig(const std::string& yaml_path);

}  // namespace mapping
}  // namespace inekf_semantic_mapping
